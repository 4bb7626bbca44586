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
//! | watchdog              | IWDG (PAC, started before clock init) |       |                          |
//! | battery sense         | ADC3 channel 8   | PF10 (200k/22k divider)    | on-board, from XT30 in   |
//! | motor contactor       | GPIO, active high| PE9 ([`CONTACTOR_PIN`])    | PWM header C1 -> relay driver |
//! | control executor      | UART4 IRQ (unused peripheral), priority [`CONTROL_PRIORITY`] | |       |
//!
//! The contactor (or relay) switches the battery feed of the four C620s. High closes it; at reset
//! the pin is a floating input, so the relay driver needs a pull-down: motor power is off from
//! reset until the first control step, on any latched fault and on a panic or HardFault.
//!
//! Another board or chip (F427 Type A, a G4 with FDCAN) is a new `cfg` block here, the chip
//! feature in Cargo.toml and `--chip` in .cargo/config.toml; main.rs does not change (except for a
//! G4's FDCAN driver, whose API differs from bxCAN).

use core::num::{NonZeroU8, NonZeroU16};

use embassy_stm32::can::util::NominalBitTiming;
use embassy_stm32::interrupt::Priority;
use embassy_stm32::pac;
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

/// Clock tree: 12 MHz HSE -> PLL (/6, x168, /2) = 168 MHz SYSCLK, APB1 42 MHz, APB2 84 MHz
/// (USART6: 921600 baud within 0.2 %), PLL Q 48 MHz. CAN1 runs from APB1: see [`can_bit_timing`].
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
    pub contactor: Peri<'static, peripherals::PE9>,
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
            contactor: p.PE9,
            battery_adc: p.ADC3,
            battery_sense: p.PF10,
        }
    }
}

/// Reads the CAN controller's error state (bus-off / error-passive flags of CAN1's ESR).
pub fn can_bus_state() -> control::BusState {
    let esr = pac::CAN1.esr().read();
    if esr.boff() {
        control::BusState::BusOff
    } else if esr.epvf() {
        control::BusState::Passive
    } else {
        control::BusState::Active
    }
}

/// The contactor pin: port E, pin 9 (must match `Board::contactor`; the panic path drives it
/// through the PAC, without the HAL).
pub const CONTACTOR_PIN: (pac::gpio::Gpio, usize) = (pac::GPIOE, 9);

/// Priority of the interrupt executor that runs the control step and the CAN tasks: below the
/// peripheral interrupts (their handlers only move data and wake tasks), above thread mode
/// where the MCU-link tasks run, so no link task's poll can delay a control step.
pub const CONTROL_PRIORITY: Priority = Priority::P6;

/// CAN1 bit timing for 1 Mbit/s from the 42 MHz APB1 clock, as DJI's Board C project sets it:
/// prescaler 3 (14 MHz, 71.4 ns quanta), BS1 10, BS2 3, SJW 1: 1 + 10 + 3 = 14 quanta per bit,
/// sample point (1 + 10) / 14 = 78.6 %. The C620s are tuned against that controller, and a
/// 14-quantum bit leaves room for resynchronisation (embassy's own choice at 42 MHz is 7 quanta,
/// sample point 85.7 %).
pub fn can_bit_timing() -> NominalBitTiming {
    NominalBitTiming {
        prescaler: NonZeroU16::new(3).unwrap_or(NonZeroU16::MIN),
        seg1: NonZeroU8::new(10).unwrap_or(NonZeroU8::MIN),
        seg2: NonZeroU8::new(3).unwrap_or(NonZeroU8::MIN),
        sync_jump_width: NonZeroU8::MIN,
    }
}

/// Starts the independent watchdog through the PAC: it runs from the LSI, so this works before
/// the clock tree is set up and covers everything after it (clock init, CAN synchronisation).
/// Prescaler /4 (8 kHz at the nominal 32 kHz LSI), reload 399: 50 ms, 50 control periods
/// (34-94 ms over the LSI's 17-47 kHz range).
pub fn start_watchdog() {
    use pac::iwdg::vals::{Key, Pr};
    const RELOAD: u16 = 399;
    let iwdg = pac::IWDG;
    iwdg.kr().write(|w| w.set_key(Key::START));
    iwdg.kr().write(|w| w.set_key(Key::ENABLE));
    iwdg.pr().write(|w| w.set_pr(Pr::DIVIDE_BY4));
    iwdg.rlr().write(|w| w.set_rl(RELOAD));
    iwdg.kr().write(|w| w.set_key(Key::RESET));
}

/// Reloads the independent watchdog.
pub fn pet_watchdog() {
    pac::IWDG
        .kr()
        .write(|w| w.set_key(pac::iwdg::vals::Key::RESET));
}

/// Sets NART (no automatic retransmission) on CAN1; only takes effect in initialisation mode.
/// embassy-stm32 0.6's `set_automatic_retransmit(true)` writes NART = 1 (upstream issue 5944),
/// so the bit is written here directly, with its hardware meaning.
pub fn can_disable_automatic_retransmission() {
    pac::CAN1.mcr().modify(|w| w.set_nart(true));
}

/// Spin bound of the panic path's CAN waits (each iteration is a few APB1 reads, so this is
/// well under 2 ms at 168 MHz; one 8-byte frame takes about 0.13 ms at 1 Mbit/s).
const PANIC_SPIN: u32 = 20_000;

/// The last thing the MCU does after a panic or HardFault: opens the motor contactor, puts an
/// all-zero 0x200 frame in a CAN1 TX mailbox through the PAC (aborting whatever is pending), waits
/// a bounded time for it to leave, and resets. No allocation, no HAL state, no locks: it works
/// whatever state the tasks were left in, and does nothing harmful if CAN1 is not set up yet.
pub fn safe_stop() -> ! {
    cortex_m::interrupt::disable();
    let (port, pin) = CONTACTOR_PIN;
    port.bsrr().write(|w| w.set_br(pin, true));

    let can = pac::CAN1;
    can.tsr().write(|w| {
        for mailbox in 0..3 {
            w.set_abrq(mailbox, true);
        }
    });
    let mut empty = None;
    for _ in 0..PANIC_SPIN {
        let tsr = can.tsr().read();
        empty = (0..3).find(|&m| tsr.tme(m));
        if empty.is_some() {
            break;
        }
    }
    if let Some(mailbox) = empty {
        let tx = can.tx(mailbox);
        tx.tdtr().write(|w| w.set_dlc(8));
        tx.tdlr().write(|_| {});
        tx.tdhr().write(|_| {});
        tx.tir().write(|w| {
            w.set_stid(protocol::esc::CMD_ID_1_4);
            w.set_txrq(true);
        });
        for _ in 0..PANIC_SPIN {
            if can.tsr().read().rqcp(mailbox) {
                break;
            }
        }
    }
    cortex_m::peripheral::SCB::sys_reset()
}
