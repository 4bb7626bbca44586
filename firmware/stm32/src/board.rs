//! Board wiring: clock tree, pins, DMA streams and interrupt bindings, one block per chip feature.
//!
//! RoboMaster Development Board Type C (STM32F407IGH6, 12 MHz HSE crystal):
//!
//! | function              | peripheral       | pins                       | board connector          |
//! |-----------------------|------------------|----------------------------|--------------------------|
//! | ESC bus, 1 Mbit/s     | CAN1             | PD0 = RX, PD1 = TX         | CAN1 (2-pin, 4 x C620)   |
//! | MCU link, 921600 8N1  | USART6 + DMA2    | PG9 = RX, PG14 = TX        | UART1 (4-pin)            |
//! | UART6 DMA             | DMA2 stream 6 TX, stream 1 RX (channel 5) |   |                          |
//! | status LED (RGB)      | GPIO, active high| PH12 = red, PH11 = green, PH10 = blue | on-board LED |
//! | time driver           | TIM2             |                            |                          |
//! | watchdog              | IWDG             |                            |                          |
//! | battery sense         | ADC3 channel 8   | PF10 (200k/22k divider)    | on-board, from XT30 in   |
//!
//! Another board or chip (F427 Type A, a G4 with FDCAN) is a new `cfg` block here, the chip
//! feature in Cargo.toml and `--chip` in .cargo/config.toml; main.rs does not change (except for a
//! G4's FDCAN driver, whose API differs from bxCAN).

use embassy_stm32::time::Hertz;
use embassy_stm32::{Config, Peri, bind_interrupts, can, dma, peripherals, usart};

#[cfg(not(feature = "stm32f407ig"))]
compile_error!("select a chip feature (default: stm32f407ig)");

bind_interrupts!(pub struct Irqs {
    CAN1_TX => can::TxInterruptHandler<peripherals::CAN1>;
    CAN1_RX0 => can::Rx0InterruptHandler<peripherals::CAN1>;
    CAN1_RX1 => can::Rx1InterruptHandler<peripherals::CAN1>;
    CAN1_SCE => can::SceInterruptHandler<peripherals::CAN1>;
    USART6 => usart::InterruptHandler<peripherals::USART6>;
    DMA2_STREAM6 => dma::InterruptHandler<peripherals::DMA2_CH6>;
    DMA2_STREAM1 => dma::InterruptHandler<peripherals::DMA2_CH1>;
});

/// Clock tree: 12 MHz HSE -> PLL (/6, x168, /2) = 168 MHz SYSCLK, APB1 42 MHz (CAN: 1 Mbit/s is
/// 42 time quanta, an exact fit), APB2 84 MHz (USART6: 921600 baud within 0.2 %), PLL Q 48 MHz.
pub fn clocks() -> Config {
    use embassy_stm32::rcc::{
        AHBPrescaler, APBPrescaler, Hse, HseMode, Pll, PllMul, PllPDiv, PllPreDiv, PllQDiv,
        PllSource, Sysclk,
    };
    let mut config = Config::default();
    config.rcc.hse = Some(Hse {
        freq: Hertz(12_000_000),
        mode: HseMode::Oscillator,
    });
    config.rcc.pll_src = PllSource::HSE;
    config.rcc.pll = Some(Pll {
        prediv: PllPreDiv::DIV6,
        mul: PllMul::MUL168,
        divp: Some(PllPDiv::DIV2),
        divq: Some(PllQDiv::DIV7),
        divr: None,
    });
    config.rcc.sys = Sysclk::PLL1_P;
    config.rcc.ahb_pre = AHBPrescaler::DIV1;
    config.rcc.apb1_pre = APBPrescaler::DIV4;
    config.rcc.apb2_pre = APBPrescaler::DIV2;
    config
}

/// The peripherals this firmware uses, taken out of `embassy_stm32::Peripherals`.
pub struct Board {
    pub can: Peri<'static, peripherals::CAN1>,
    pub can_rx: Peri<'static, peripherals::PD0>,
    pub can_tx: Peri<'static, peripherals::PD1>,
    pub uart: Peri<'static, peripherals::USART6>,
    pub uart_rx: Peri<'static, peripherals::PG9>,
    pub uart_tx: Peri<'static, peripherals::PG14>,
    pub uart_tx_dma: Peri<'static, peripherals::DMA2_CH6>,
    pub uart_rx_dma: Peri<'static, peripherals::DMA2_CH1>,
    pub led_red: Peri<'static, peripherals::PH12>,
    pub led_green: Peri<'static, peripherals::PH11>,
    pub led_blue: Peri<'static, peripherals::PH10>,
    pub iwdg: Peri<'static, peripherals::IWDG>,
    pub battery_adc: Peri<'static, peripherals::ADC3>,
    pub battery_sense: Peri<'static, peripherals::PF10>,
}

impl Board {
    /// Takes this board's peripherals.
    pub fn take(p: embassy_stm32::Peripherals) -> Self {
        Self {
            can: p.CAN1,
            can_rx: p.PD0,
            can_tx: p.PD1,
            uart: p.USART6,
            uart_rx: p.PG9,
            uart_tx: p.PG14,
            uart_tx_dma: p.DMA2_CH6,
            uart_rx_dma: p.DMA2_CH1,
            led_red: p.PH12,
            led_green: p.PH11,
            led_blue: p.PH10,
            iwdg: p.IWDG,
            battery_adc: p.ADC3,
            battery_sense: p.PF10,
        }
    }
}

/// Reads the CAN controller's error state (bus-off / error-passive flags of CAN1's ESR).
pub fn can_bus_state() -> control::BusState {
    let esr = embassy_stm32::pac::CAN1.esr().read();
    if esr.boff() {
        control::BusState::BusOff
    } else if esr.epvf() {
        control::BusState::Passive
    } else {
        control::BusState::Active
    }
}
