//! passangle robot firmware: embassy wiring around `control::Controller` (DESIGN.md section 5).
//!
//! Tasks and what connects them (all logic lives in the host-tested `control` crate):
//!
//! ```text
//!  CAN1 RX irq -> [can_rx] --ESC_FEEDBACK channel--> [control, 1 kHz] --CURRENTS signal--> [can_tx] -> 0x200
//!  USART6 RX DMA ring -> [link_rx] --LINK_RX pipe--> [control] --LINK_TX pipe--> [link_tx] -> USART6 TX DMA
//!  ADC3 (PF10, battery) ----------------------------> [control] -> RGB LED, IWDG pet
//! ```
//!
//! The control task is the only one that decides anything: every millisecond it drains what
//! arrived, calls `Controller::step(now_us, &inputs)`, and hands the outputs to the other tasks.
//! Safety does not depend on the other tasks: if the control task stalls, the IWDG resets the MCU
//! (the C620s then see no new command; the onboard sees the link go quiet).
#![no_std]
#![no_main]

mod board;

use control::machine::EscSample;
use control::{Config, Controller, Inputs};
use defmt::{info, unwrap, warn};
use embassy_executor::Spawner;
use embassy_stm32::adc::{Adc, SampleTime};
use embassy_stm32::can::filter::ListEntry16;
use embassy_stm32::can::{Can, CanTx, Fifo, Frame, Mailbox, RxBuf, StandardId};
use embassy_stm32::gpio::{Level, Output, Speed};
use embassy_stm32::mode::Async;
use embassy_stm32::usart::{self, RingBufferedUartRx, Uart, UartTx};
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::channel::Channel;
use embassy_sync::pipe::Pipe;
use embassy_sync::signal::Signal;
use embassy_time::{Duration, Instant, Ticker};
use static_cell::StaticCell;
use {defmt_rtt as _, panic_probe as _};

use crate::board::{Board, Irqs};

/// MCU-link baud rate.
const LINK_BAUD: u32 = 921_600;
/// Independent watchdog timeout: 50 control periods.
const WATCHDOG_TIMEOUT_US: u32 = 50_000;

/// ESC feedback frames, timestamped on arrival (4 per ms; room for 8 ms of backlog).
static ESC_FEEDBACK: Channel<CriticalSectionRawMutex, EscSample, 32> = Channel::new();
/// Bytes received on the MCU link (about 92 bytes per ms at 921600 baud).
static LINK_RX: Pipe<CriticalSectionRawMutex, 1024> = Pipe::new();
/// Frames to send on the MCU link.
static LINK_TX: Pipe<CriticalSectionRawMutex, 2048> = Pipe::new();
/// The latest wheel currents for the 0x200 frame (latest value wins).
static CURRENTS: Signal<CriticalSectionRawMutex, [i16; 4]> = Signal::new();

static CAN: StaticCell<Can<'static>> = StaticCell::new();
static CAN_RX_BUF: StaticCell<RxBuf<16>> = StaticCell::new();
static UART_RX_DMA: StaticCell<[u8; 512]> = StaticCell::new();

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    let p = embassy_stm32::init(board::clocks());
    let b = Board::take(p);
    info!("passangle firmware {}", env!("CARGO_PKG_VERSION"));

    // CAN1 at 1 Mbit/s, accepting only the four chassis ESCs' feedback (0x201..=0x204).
    let can = CAN.init(Can::new(b.can, b.can_rx, b.can_tx, Irqs));
    let ids = [0x201u16, 0x202, 0x203, 0x204]
        .map(|id| ListEntry16::data_frames_with_id(unwrap!(StandardId::new(id))));
    can.modify_filters().enable_bank(0, Fifo::Fifo0, ids);
    can.modify_config()
        .set_bitrate(1_000_000)
        .set_automatic_retransmit(true);
    // `enable` also turns on automatic bus-off management: the controller rejoins by itself after
    // 128 x 11 recessive bits; the control logic zeroes the currents and latches CAN_BUS_OFF.
    can.enable().await;
    // A C620 holds its last command: after a reset (watchdog, brown-out) the wheels could still be
    // driven by the current sent before it. Zero them before anything else starts.
    if let Ok(zero) = control::controller::command_frame::<Frame>([0; 4]) {
        let _ = can.try_write(&zero);
    }
    let (can_tx, can_rx) = can.split();
    let can_rx = can_rx.buffered(CAN_RX_BUF.init(RxBuf::new()));

    let mut uart_config = usart::Config::default();
    uart_config.baudrate = LINK_BAUD;
    let uart = unwrap!(Uart::new(
        b.uart,
        b.uart_rx,
        b.uart_tx,
        b.uart_tx_dma,
        b.uart_rx_dma,
        Irqs,
        uart_config
    ));
    let (uart_tx, uart_rx) = uart.split();
    let uart_rx = uart_rx.into_ring_buffered(UART_RX_DMA.init([0; 512]));

    let leds = [
        Output::new(b.led_red, Level::Low, Speed::Low),
        Output::new(b.led_green, Level::Low, Speed::Low),
        Output::new(b.led_blue, Level::Low, Speed::Low),
    ];
    let mut watchdog = IndependentWatchdog::new(b.iwdg, WATCHDOG_TIMEOUT_US);
    watchdog.unleash();

    let battery = BatterySense {
        adc: Adc::new(b.battery_adc),
        pin: b.battery_sense,
    };
    let controller = unwrap!(Controller::new(Config::default()).ok());
    spawner.spawn(unwrap!(can_rx_task(can_rx)));
    spawner.spawn(unwrap!(can_tx_task(can_tx)));
    spawner.spawn(unwrap!(link_rx_task(uart_rx)));
    spawner.spawn(unwrap!(link_tx_task(uart_tx)));
    spawner.spawn(unwrap!(control_task(controller, leds, watchdog, battery)));
}

/// The battery divider on ADC3 (see `control::battery` for the scaling).
struct BatterySense {
    adc: Adc<'static, embassy_stm32::peripherals::ADC3>,
    pin: embassy_stm32::Peri<'static, embassy_stm32::peripherals::PF10>,
}

impl BatterySense {
    /// One conversion (144 cycles at 21 MHz: about 8 us), in mV.
    fn read_mv(&mut self) -> u16 {
        control::battery::adc_to_mv(self.adc.blocking_read(&mut self.pin, SampleTime::CYCLES144))
    }
}

/// Decodes ESC feedback frames and timestamps them on the MCU clock.
#[embassy_executor::task]
async fn can_rx_task(mut rx: embassy_stm32::can::BufferedCanRx<'static, 16>) {
    let mut dropped: u32 = 0;
    loop {
        let envelope = match rx.read().await {
            Ok(envelope) => envelope,
            Err(e) => {
                warn!("CAN bus error: {}", e);
                continue;
            }
        };
        let Ok((esc_id, feedback)) = protocol::esc::parse_feedback_frame(&envelope.frame) else {
            warn!("CAN frame that is not C620 feedback");
            continue;
        };
        let sample = EscSample {
            esc_id,
            feedback,
            stamp_us: Instant::now().as_micros(),
        };
        if ESC_FEEDBACK.try_send(sample).is_err() {
            dropped = dropped.wrapping_add(1);
            warn!("ESC feedback queue full ({} dropped)", dropped);
        }
    }
}

/// Sends the latest currents on 0x200. A frame still pending from an earlier step is aborted
/// first, so after a bus outage the ESCs never receive stale non-zero currents.
#[embassy_executor::task]
async fn can_tx_task(mut tx: CanTx<'static>) {
    loop {
        let currents = CURRENTS.wait().await;
        let frame = control::controller::command_frame::<Frame>(currents);
        let Ok(frame) = frame else { continue };
        if !tx.is_idle() {
            for mailbox in [Mailbox::Mailbox0, Mailbox::Mailbox1, Mailbox::Mailbox2] {
                tx.abort(mailbox);
            }
        }
        if tx.try_write(&frame).is_err() {
            warn!("CAN TX mailboxes full");
        }
    }
}

/// Moves MCU-link bytes from the DMA ring buffer into the control task's pipe.
#[embassy_executor::task]
async fn link_rx_task(mut rx: RingBufferedUartRx<'static>) {
    let mut buf = [0u8; 128];
    loop {
        match rx.read(&mut buf).await {
            Ok(n) => {
                if LINK_RX.try_write(&buf[..n]).map_or(true, |w| w < n) {
                    warn!("MCU link RX pipe full");
                }
            }
            // Overrun or framing error: the deframer resynchronises at the next delimiter.
            Err(e) => warn!("MCU link RX error: {}", e),
        }
    }
}

/// Sends MCU-link frames from the control task's pipe by DMA.
#[embassy_executor::task]
async fn link_tx_task(mut tx: UartTx<'static, Async>) {
    let mut buf = [0u8; 256];
    loop {
        let n = LINK_TX.read(&mut buf).await;
        if let Err(e) = tx.write(&buf[..n]).await {
            warn!("MCU link TX error: {}", e);
        }
    }
}

/// The 1 kHz control loop: gather inputs, step the controller, dispatch outputs, pet the watchdog.
#[embassy_executor::task]
async fn control_task(
    mut controller: Controller,
    mut leds: [Output<'static>; 3],
    mut watchdog: IndependentWatchdog<'static, embassy_stm32::peripherals::IWDG>,
    mut battery: BatterySense,
) {
    let mut ticker = Ticker::every(Duration::from_millis(1));
    let mut esc = heapless::Vec::<EscSample, 32>::new();
    let mut link_rx = [0u8; 1024];
    let mut last_led = None;
    loop {
        ticker.next().await;
        let now_us = Instant::now().as_micros();
        esc.clear();
        while let Ok(sample) = ESC_FEEDBACK.try_receive() {
            if esc.push(sample).is_err() {
                break;
            }
        }
        let n = LINK_RX.try_read(&mut link_rx).unwrap_or(0);
        let inputs = Inputs {
            esc: &esc,
            link_rx: &link_rx[..n],
            bus: board::can_bus_state(),
            battery_mv: battery.read_mv(),
        };
        let out = controller.step(now_us, &inputs);

        CURRENTS.signal(out.currents_raw);
        // Whole frames only: a partial write would corrupt the next frame too.
        if !out.link_tx.is_empty() {
            if LINK_TX.free_capacity() >= out.link_tx.len() {
                let _ = LINK_TX.try_write(&out.link_tx);
            } else {
                warn!("MCU link TX pipe full, {} bytes dropped", out.link_tx.len());
            }
        }
        for (led, on) in leds.iter_mut().zip(out.led.rgb(now_us)) {
            led.set_level(if on { Level::High } else { Level::Low });
        }
        if last_led != Some(out.led) {
            info!("state: {}", out.led.name());
            last_led = Some(out.led);
        }
        if out.recover_bus {
            warn!("CAN bus-off: currents zeroed, hardware recovery running");
        }
        watchdog.pet();
    }
}
