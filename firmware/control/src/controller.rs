//! The firmware's whole logic as one plain struct: `Controller::step(now_us, &Inputs) -> Outputs`.
//!
//! Per 1 ms step, in this order:
//! 1. MCU-link bytes received since the last step go through [`Link`]; the commands they carry are
//!    applied to the [`Machine`] (so a drive command acts in the step it arrives);
//! 2. the machine steps with the ESC feedback frames received since the last step and the CAN
//!    state, and returns the four currents of the 0x200 frame;
//! 3. odometry goes out every `odometry_period_us` (default 10 ms), status every
//!    `status_period_us` (default 100 ms) and within [`STATUS_MIN_GAP_US`] of any change of mode,
//!    interlocks or ESC faults;
//! 4. the status LED pattern is chosen.
//!
//! The embassy shell (firmware/stm32) and the simulator (hil-sim) only move bytes and frames.

use protocol::esc::{CMD_ID_1_4, EscError};
use protocol::mcu::{DriveMode, EscFaults, Interlocks};

use crate::config::{Config, ConfigError};
use crate::link::{Link, Request, TxBuffer};
use crate::machine::{Command, EscSample, Machine, Reject};
use crate::safety::BusState;

/// Shortest gap between two status reports sent because something changed, microseconds.
pub const STATUS_MIN_GAP_US: u64 = 5_000;

/// Everything that arrived since the last step.
#[derive(Debug, Clone, Copy)]
pub struct Inputs<'a> {
    /// ESC feedback frames, decoded and timestamped by the CAN receive task.
    pub esc: &'a [EscSample],
    /// Raw bytes from the MCU-link UART (any chunking).
    pub link_rx: &'a [u8],
    /// CAN controller state.
    pub bus: BusState,
    /// Battery voltage this step, mV (0: not measured; see [`crate::battery`]).
    pub battery_mv: u16,
}

/// What the shell must do after a step.
#[derive(Debug, Clone)]
pub struct Outputs {
    /// Raw currents for the 0x200 frame, slot `i` for ESC id `i + 1` (send every step).
    pub currents_raw: [i16; 4],
    /// Encoded frames for the MCU-link UART.
    pub link_tx: TxBuffer,
    /// Status LED pattern.
    pub led: LedPattern,
    /// Restart the CAN controller (it went bus-off).
    pub recover_bus: bool,
    /// Drive the motor contactor closed (motor power on): no fault is latched
    /// ([`crate::Machine::contactor_closed`]). The shell keeps it open from reset until the first
    /// step and opens it on a panic.
    pub contactor_closed: bool,
}

impl Outputs {
    /// The 0x200 command frame for these currents, for any `embedded_can` frame type.
    pub fn command_frame<F: embedded_can::Frame>(&self) -> Result<F, EscError> {
        command_frame(self.currents_raw)
    }
}

/// The 0x200 command frame (ESC ids 1..=4) for raw currents, for any `embedded_can` frame type.
pub fn command_frame<F: embedded_can::Frame>(currents_raw: [i16; 4]) -> Result<F, EscError> {
    protocol::esc::command_frame(CMD_ID_1_4, currents_raw)
}

/// Status LED patterns (RGB LED), highest priority first.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LedPattern {
    /// Red, steady: CAN bus-off.
    BusOff,
    /// Red, 5 Hz blink: an ESC fault is latched.
    EscFault,
    /// Blue, 1 Hz blink: no host (`Hello`) or no heartbeat.
    WaitingForHost,
    /// Green, 5 Hz blink: ramping down or holding after a stop.
    Stopping,
    /// Green, steady: driving.
    Driving,
    /// Green, short flash every second: idle and ready.
    Idle,
}

impl LedPattern {
    /// Name for logs.
    pub fn name(self) -> &'static str {
        match self {
            Self::BusOff => "bus-off",
            Self::EscFault => "esc-fault",
            Self::WaitingForHost => "waiting-for-host",
            Self::Stopping => "stopping",
            Self::Driving => "driving",
            Self::Idle => "idle",
        }
    }

    /// Which of (red, green, blue) is lit at `now_us`.
    pub fn rgb(self, now_us: u64) -> [bool; 3] {
        let fast = (now_us / 100_000).is_multiple_of(2); // 5 Hz, 50 %
        let slow = (now_us / 500_000).is_multiple_of(2); // 1 Hz, 50 %
        let flash = now_us % 1_000_000 < 100_000; // 1 Hz, 10 %
        match self {
            Self::BusOff => [true, false, false],
            Self::EscFault => [fast, false, false],
            Self::WaitingForHost => [false, false, slow],
            Self::Stopping => [false, fast, false],
            Self::Driving => [false, true, false],
            Self::Idle => [false, flash, false],
        }
    }

    fn from_state(mode: DriveMode, interlocks: Interlocks) -> Self {
        let esc_faults = Interlocks::ESC_FEEDBACK_MISSING
            .union(Interlocks::ESC_OVER_TEMPERATURE)
            .union(Interlocks::ESC_OVER_CURRENT)
            .union(Interlocks::ESC_STALLED)
            .union(Interlocks::ESC_NOT_FOLLOWING);
        if interlocks.contains(Interlocks::CAN_BUS_OFF) {
            Self::BusOff
        } else if mode == DriveMode::Faulted
            || (interlocks.0 & esc_faults.0 != 0 && mode != DriveMode::Idle)
        {
            Self::EscFault
        } else if interlocks.0 & (Interlocks::NO_HOST.0 | Interlocks::HEARTBEAT_LOST.0) != 0
            && mode == DriveMode::Idle
        {
            Self::WaitingForHost
        } else {
            match mode {
                DriveMode::Stopping => Self::Stopping,
                DriveMode::Ramping | DriveMode::Cruising => Self::Driving,
                DriveMode::Idle | DriveMode::Faulted => Self::Idle,
            }
        }
    }
}

/// What a status report is re-sent on when it changes.
type StatusKey = (DriveMode, Interlocks, [EscFaults; 4]);

/// The firmware logic (see the module docs).
#[derive(Debug, Clone)]
pub struct Controller {
    machine: Machine,
    link: Link,
    next_odometry_us: u64,
    next_status_us: u64,
    last_status_us: Option<u64>,
    last_status_key: Option<StatusKey>,
    step_max_us: u16,
}

impl Controller {
    /// A controller at rest with `config`.
    pub fn new(config: Config) -> Result<Self, ConfigError> {
        Ok(Self {
            machine: Machine::new(config)?,
            link: Link::new(),
            next_odometry_us: 0,
            next_status_us: 0,
            last_status_us: None,
            last_status_key: None,
            step_max_us: 0,
        })
    }

    /// The drive state machine (for telemetry and tests).
    pub fn machine(&self) -> &Machine {
        &self.machine
    }

    /// The MCU-link state (counters).
    pub fn link(&self) -> &Link {
        &self.link
    }

    /// Records how long a control step took, microseconds, as the shell measured it (the STM32
    /// shell reads the DWT cycle counter); status reports carry the longest since boot.
    pub fn record_step_time(&mut self, step_us: u32) {
        let step_us = u16::try_from(step_us).unwrap_or(u16::MAX);
        self.step_max_us = self.step_max_us.max(step_us);
    }

    /// The longest control step recorded since boot, microseconds.
    pub fn step_max_us(&self) -> u16 {
        self.step_max_us
    }

    /// One control period at `now_us` (MCU clock).
    pub fn step(&mut self, now_us: u64, inputs: &Inputs<'_>) -> Outputs {
        let mut link_tx = TxBuffer::new();
        let machine = &mut self.machine;
        self.link.receive(inputs.link_rx, &mut link_tx, |request| {
            apply(machine, now_us, request)
        });

        self.machine.update_battery(now_us, inputs.battery_mv);
        let step = self.machine.step(now_us, inputs.esc, inputs.bus);

        let config = *self.machine.config();
        if now_us >= self.next_odometry_us {
            self.link
                .send(&self.machine.odometry_report(now_us), &mut link_tx);
            self.next_odometry_us =
                advance(self.next_odometry_us, config.odometry_period_us, now_us);
        }
        let mut status = self.machine.status(now_us);
        let key = (status.mode, status.interlocks, status.esc.map(|e| e.faults));
        let changed = self.last_status_key != Some(key);
        let gap_ok = self
            .last_status_us
            .is_none_or(|t| now_us.saturating_sub(t) >= STATUS_MIN_GAP_US);
        if now_us >= self.next_status_us || (changed && gap_ok) {
            status.link_errors = self.link.link_errors();
            status.rejected_count = self.link.rejected_count();
            status.control_step_max_us = self.step_max_us;
            self.link.send(&status, &mut link_tx);
            self.last_status_key = Some(key);
            self.last_status_us = Some(now_us);
            self.next_status_us = now_us.saturating_add(config.status_period_us);
        }
        Outputs {
            currents_raw: step.currents_raw,
            link_tx,
            led: LedPattern::from_state(status.mode, status.interlocks),
            recover_bus: step.recover_bus,
            contactor_closed: self.machine.contactor_closed(),
        }
    }
}

/// Applies one link request to the machine.
fn apply(machine: &mut Machine, now_us: u64, request: Request) -> Result<(), Reject> {
    match request {
        Request::Command(command) => machine.command(now_us, command),
        Request::SetConfig(mcu) => {
            let config = machine.config().with_mcu(&mcu);
            machine.command(now_us, Command::SetConfig(config))
        }
    }
}

/// The next deadline of a periodic report: one period on, or one period from now if late.
fn advance(deadline_us: u64, period_us: u64, now_us: u64) -> u64 {
    let next = deadline_us.saturating_add(period_us);
    if next <= now_us {
        now_us.saturating_add(period_us)
    } else {
        next
    }
}
