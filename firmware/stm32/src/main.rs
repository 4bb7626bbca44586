//! passangle robot firmware: embassy wiring around `control::Controller` (docs/architecture.md section 5).
//!
//! Tasks, where they run, and what connects them (all logic lives in the host-tested `control`
//! crate):
//!
//! ```text
//!  high-priority interrupt executor (UART4 IRQ, board::CONTROL_PRIORITY):
//!    CAN1 RX irq -> [can_rx] --ESC_FEEDBACK channel--> [control, 1 kHz] -> 0x200 on CAN1 TX
//!                                                               |-> contactor GPIO, LEDs, IWDG
//!  thread mode:
//!    USART6 RX DMA ring -> [link_rx] --LINK_RX pipe--> [control] --LINK_TX pipe--> [link_tx]
//!  ADC3 (PF10, battery): one conversion started per step, its result read in the next step
//! ```
//!
//! The control task is the only one that decides anything: every millisecond it drains what
//! arrived, calls `Controller::step(now_us, &inputs)`, sends the 0x200 frame itself and hands the
//! link bytes to the link task. It runs on an interrupt executor above thread mode, so the link
//! tasks cannot delay it. Safety does not depend on the other tasks: if the control task stalls,
//! the IWDG (started before anything else) resets the MCU; a panic or HardFault opens the motor
//! contactor, puts a zero 0x200 frame on the bus and resets ([`board::safe_stop`]).
#![no_std]
#![no_main]

mod board;

use control::machine::EscSample;
use control::{Config, Controller, Inputs};
use defmt::{info, unwrap, warn};
use defmt_rtt as _;
use embassy_executor::{InterruptExecutor, Spawner};
use embassy_stm32::adc::{Adc, SampleTime};
use embassy_stm32::can::filter::ListEntry16;
use embassy_stm32::can::{Can, CanTx, Fifo, Frame, Mailbox, RxBuf, StandardId};
use embassy_stm32::gpio::{Level, Output, Speed};
use embassy_stm32::interrupt;
use embassy_stm32::interrupt::InterruptExt;
use embassy_stm32::mode::Async;
use embassy_stm32::pac;
use embassy_stm32::usart::{self, RingBufferedUartRx, Uart, UartTx};
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::channel::Channel;
use embassy_sync::pipe::Pipe;
use embassy_time::{Duration, Instant, Ticker};
use static_cell::StaticCell;

use crate::board::{Board, Irqs};

/// MCU-link baud rate.
const LINK_BAUD: u32 = 921_600;
/// Longest wait for the CAN controller to see the bus idle (11 recessive bits) at start-up. A bus
/// stuck dominant must not keep the link silent: the firmware starts anyway, the controller
/// joins the bus by itself once it goes idle, and until then no ESC reports (drives refused).
const CAN_SYNC_TIMEOUT: Duration = Duration::from_millis(20);
/// SYSCLK, for converting DWT cycles to microseconds.
const CYCLES_PER_US: u32 = 168;

/// ESC feedback frames, timestamped on arrival (4 per ms; room for 8 ms of backlog).
static ESC_FEEDBACK: Channel<CriticalSectionRawMutex, EscSample, 32> = Channel::new();
/// Bytes received on the MCU link (about 92 bytes per ms at 921600 baud).
static LINK_RX: Pipe<CriticalSectionRawMutex, 1024> = Pipe::new();
/// Frames to send on the MCU link.
static LINK_TX: Pipe<CriticalSectionRawMutex, 2048> = Pipe::new();

static CAN: StaticCell<Can<'static>> = StaticCell::new();
static CAN_RX_BUF: StaticCell<RxBuf<16>> = StaticCell::new();
static UART_RX_DMA: StaticCell<[u8; 512]> = StaticCell::new();

/// Runs the control and CAN tasks from the UART4 interrupt (a peripheral this board leaves unused).
static CONTROL_EXECUTOR: InterruptExecutor = InterruptExecutor::new();

#[allow(unsafe_code)]
#[interrupt]
unsafe fn UART4() {
    // SAFETY: called only from its own interrupt, which `main` unmasks after starting it.
    unsafe { CONTROL_EXECUTOR.on_interrupt() }
}

/// A panic anywhere stops the motors and resets ([`board::safe_stop`]).
#[panic_handler]
fn panic(_info: &core::panic::PanicInfo<'_>) -> ! {
    board::safe_stop()
}

/// A HardFault (a bad access, an undefined instruction) does the same as a panic. A stack
/// overflow's HardFault cannot: its trampoline pushes onto the overflowed stack, the core locks up
/// and the IWDG resets it.
#[allow(unsafe_code)]
#[cortex_m_rt::exception]
unsafe fn HardFault(_frame: &cortex_m_rt::ExceptionFrame) -> ! {
    board::safe_stop()
}

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    // First of all: a stall from here on (clock init, CAN synchronisation) ends in a reset.
    board::start_watchdog();
    let p = embassy_stm32::init(board::clocks());
    let b = Board::take(p);
    // Motor power stays off until the first control step says otherwise.
    let contactor = Output::new(b.contactor, Level::Low, Speed::Low);
    info!("passangle firmware {}", env!("CARGO_PKG_VERSION"));

    if let Some(mut core) = cortex_m::Peripherals::take() {
        core.DCB.enable_trace();
        core.DWT.enable_cycle_counter();
    }

    // CAN1 at 1 Mbit/s, accepting only the four chassis ESCs' feedback (0x201..=0x204).
    let can = CAN.init(Can::new(b.can, b.can_rx, b.can_tx, Irqs));
    let ids = [0x201u16, 0x202, 0x203, 0x204]
        .map(|id| ListEntry16::data_frames_with_id(unwrap!(StandardId::new(id))));
    can.modify_filters().enable_bank(0, Fifo::Fifo0, ids);
    {
        let config = can.modify_config().set_bit_timing(board::can_bit_timing());
        // No automatic retransmission: a 0x200 frame that fails (lost arbitration does not
        // happen on this bus, so an error) is dropped, and the next step's frame, 1 ms later,
        // carries the current command. With retransmission a frame could reach the ESCs late,
        // after a newer (possibly zero) one was decided, and retries of a frame that cannot get
        // through would fill the mailboxes.
        board::can_disable_automatic_retransmission();
        drop(config);
    }
    // `enable` also turns on automatic bus-off management: the controller rejoins by itself after
    // 128 x 11 recessive bits; the control logic zeroes the currents and latches CAN_BUS_OFF.
    if embassy_time::with_timeout(CAN_SYNC_TIMEOUT, can.enable())
        .await
        .is_err()
    {
        warn!("CAN bus not idle after 20 ms: starting without it");
    }
    // A C620 holds its last command: after a reset (watchdog, brown-out, panic) the wheels could
    // still be driven by the current sent before it. Zero them before anything else starts.
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
    let battery = BatterySense::new(Adc::new(b.battery_adc), b.battery_sense);
    let controller = unwrap!(Controller::new(Config::default()).ok());
    let pins = Pins { leds, contactor };

    interrupt::UART4.set_priority(board::CONTROL_PRIORITY);
    let control = CONTROL_EXECUTOR.start(interrupt::UART4);
    control.spawn(unwrap!(can_rx_task(can_rx)));
    control.spawn(unwrap!(control_task(controller, pins, can_tx, battery)));
    spawner.spawn(unwrap!(link_rx_task(uart_rx)));
    spawner.spawn(unwrap!(link_tx_task(uart_tx)));
}

/// The outputs the control task drives directly.
struct Pins {
    leds: [Output<'static>; 3],
    contactor: Output<'static>,
}

/// The battery divider on ADC3 (see `control::battery` for the scaling), read without waiting:
/// each step takes the result of the conversion the previous step started (144 cycles at
/// 21 MHz, about 8 us, long done 1 ms later) and starts the next one.
struct BatterySense {
    last_mv: u16,
}

impl BatterySense {
    /// Configures ADC3 for channel 8 (PF10) with one blocking conversion (start-up only). The HAL
    /// objects are dropped without touching the ADC: it stays on and configured.
    fn new(
        mut adc: Adc<'static, embassy_stm32::peripherals::ADC3>,
        mut pin: embassy_stm32::Peri<'static, embassy_stm32::peripherals::PF10>,
    ) -> Self {
        let raw = adc.blocking_read(&mut pin, SampleTime::CYCLES144);
        core::mem::forget(adc);
        pac::ADC3.cr2().modify(|w| w.set_swstart(true));
        Self {
            last_mv: control::battery::adc_to_mv(raw),
        }
    }

    /// The latest battery reading, mV; starts the next conversion.
    fn poll_mv(&mut self) -> u16 {
        let adc = pac::ADC3;
        if adc.sr().read().eoc() {
            self.last_mv = control::battery::adc_to_mv(adc.dr().read().data());
        }
        adc.cr2().modify(|w| w.set_swstart(true));
        self.last_mv
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

/// Sends one step's currents on 0x200. A frame still pending from an earlier step is aborted
/// first, so after a bus outage the ESCs never receive stale non-zero currents.
fn send_currents(tx: &mut CanTx<'static>, currents: [i16; 4]) {
    let Ok(frame) = control::controller::command_frame::<Frame>(currents) else {
        return;
    };
    if !tx.is_idle() {
        for mailbox in [Mailbox::Mailbox0, Mailbox::Mailbox1, Mailbox::Mailbox2] {
            tx.abort(mailbox);
        }
    }
    if tx.try_write(&frame).is_err() {
        warn!("CAN TX mailboxes full");
    }
}

/// Moves MCU-link bytes from the DMA ring buffer into the control task's pipe. It waits for room
/// rather than dropping part of a chunk (which would corrupt a frame); the control task empties
/// the pipe every millisecond, and the 512-byte DMA ring holds 5 ms of link traffic meanwhile.
#[embassy_executor::task]
async fn link_rx_task(mut rx: RingBufferedUartRx<'static>) {
    let mut buf = [0u8; 128];
    loop {
        match rx.read(&mut buf).await {
            Ok(n) => LINK_RX.write_all(&buf[..n]).await,
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

/// Writes all of `bytes` into `pipe` now, or nothing if it does not fit: the receiver's deframer
/// would drop a partial frame and the frame after it. `Pipe::try_write` only fills up to the
/// ring's end, so a write that wraps takes two calls.
fn write_whole<const N: usize>(pipe: &Pipe<CriticalSectionRawMutex, N>, bytes: &[u8]) -> bool {
    if pipe.free_capacity() < bytes.len() {
        return false;
    }
    let mut rest = bytes;
    while !rest.is_empty() {
        match pipe.try_write(rest) {
            Ok(n) if n > 0 => rest = &rest[n..],
            // Only the control task writes this pipe, so the room checked above cannot shrink.
            _ => return false,
        }
    }
    true
}

/// Reads everything `pipe` holds into `buf` (up to its length); returns how many bytes.
fn read_all<const N: usize>(pipe: &Pipe<CriticalSectionRawMutex, N>, buf: &mut [u8]) -> usize {
    let mut n = 0;
    while n < buf.len() {
        match pipe.try_read(&mut buf[n..]) {
            Ok(k) if k > 0 => n += k,
            _ => break,
        }
    }
    n
}

/// The 1 kHz control loop: gather inputs, step the controller, send the currents, drive the
/// contactor and LEDs, queue the link frames, pet the watchdog, record the step's duration.
#[embassy_executor::task]
async fn control_task(
    mut controller: Controller,
    mut pins: Pins,
    mut can_tx: CanTx<'static>,
    mut battery: BatterySense,
) {
    let mut ticker = Ticker::every(Duration::from_millis(1));
    let mut esc = heapless::Vec::<EscSample, 32>::new();
    let mut link_rx = [0u8; 1024];
    let mut last_led = None;
    let mut bus_off = false;
    loop {
        ticker.next().await;
        let start = cortex_m::peripheral::DWT::cycle_count();
        let now_us = Instant::now().as_micros();
        esc.clear();
        while let Ok(sample) = ESC_FEEDBACK.try_receive() {
            if esc.push(sample).is_err() {
                break;
            }
        }
        let n = read_all(&LINK_RX, &mut link_rx);
        let inputs = Inputs {
            esc: &esc,
            link_rx: &link_rx[..n],
            bus: board::can_bus_state(),
            battery_mv: battery.poll_mv(),
        };
        let out = controller.step(now_us, &inputs);

        send_currents(&mut can_tx, out.currents_raw);
        pins.contactor.set_level(if out.contactor_closed {
            Level::High
        } else {
            Level::Low
        });
        if !out.link_tx.is_empty() && !write_whole(&LINK_TX, &out.link_tx) {
            warn!("MCU link TX pipe full, {} bytes dropped", out.link_tx.len());
        }
        for (led, on) in pins.leds.iter_mut().zip(out.led.rgb(now_us)) {
            led.set_level(if on { Level::High } else { Level::Low });
        }
        if last_led != Some(out.led) {
            info!("state: {}", out.led.name());
            last_led = Some(out.led);
        }
        if out.recover_bus && !bus_off {
            warn!("CAN bus-off: currents zeroed, hardware recovery running");
        }
        bus_off = out.recover_bus;
        board::pet_watchdog();
        let cycles = cortex_m::peripheral::DWT::cycle_count().wrapping_sub(start);
        controller.record_step_time(cycles / CYCLES_PER_US);
    }
}
