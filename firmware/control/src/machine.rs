//! The drive state machine: commands and ESC feedback in, wheel currents and reports out.
//!
//! [`Machine`] owns everything between the MCU link and the CAN bus except the byte framing
//! ([`crate::link`]): the safety monitors, the setpoint ramps, the wheel PIDs and the odometry.
//! It is driven by two calls, both with the time on the MCU clock:
//! - [`Machine::command`] applies one decoded command (drive, stop, heartbeat, clear faults,
//!   config) or says why it refused it;
//! - [`Machine::step`] runs one control period (1 ms on the board): ingest ESC feedback, supervise,
//!   ramp, run the PIDs, integrate odometry, and return the four currents for the 0x200 frame.
//!
//! Modes: `Idle` (currents zero) -> `Driving` (ramping to / cruising at the commanded twist) ->
//! `Stopping` (ramping to zero after `Stop` or a lost heartbeat) -> `Holding` (zero speed held by
//! the PIDs for `hold_after_stop_us`) -> `Idle`. `Stop { immediate: true }` goes straight to
//! `Idle`. `Faulted` (currents zero) whenever an ESC fault or a bus-off is latched; only an
//! accepted `ClearFaults` leaves it, to `Idle`. The safety rules are tabled in [`crate::safety`].

use protocol::esc::EscFeedback;
use protocol::mcu::{DriveMode, EscStatus, Odometry as OdometryReport, Status};

use crate::battery::BatteryMonitor;
use crate::config::{Config, ConfigError};
use crate::kinematics::{self, Twist};
use crate::odometry::{self, EncoderUnwrap, Odometry, Pose};
use crate::pid::Pid;
use crate::profile::{Limits, Ramp};
use crate::safety::{BusState, EscFaults, EscMonitor, HARD_INTERLOCKS, Interlocks, interlocks_of};

/// Longest step used for integration and PID `dt`; a longer gap (a stalled task) is clamped so a
/// late step cannot produce a large integral jump.
const MAX_STEP_US: u64 = 10_000;
/// `dt` of the very first step.
const FIRST_STEP_US: u64 = 1_000;

/// One ESC feedback frame as the CAN receive task timestamps it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EscSample {
    /// ESC id (1..=8) from the frame's CAN id.
    pub esc_id: u8,
    /// The decoded frame.
    pub feedback: EscFeedback,
    /// Arrival time, MCU clock, microseconds.
    pub stamp_us: u64,
}

/// A drive command: a constant body twist reached through a ramp.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriveCommand {
    /// Target twist (body frame).
    pub twist: Twist,
    /// Ramp acceleration, m/s^2 (> 0; the yaw axis uses this divided by k).
    pub accel_mps2: f32,
    /// Ramp jerk, m/s^3 (> 0), or 0 for a trapezoid ramp.
    pub jerk_mps3: f32,
}

/// A decoded command from the onboard computer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Command {
    /// Ramp to and hold a twist.
    Drive(DriveCommand),
    /// The onboard computer said `Hello` with our protocol version.
    Hello,
    /// Ramp to zero with the current ramp limits, then hold and go idle; or, with `immediate`,
    /// zero the currents now (the wheels coast).
    Stop {
        /// Zero currents at once instead of ramping.
        immediate: bool,
    },
    /// The onboard computer is alive.
    Heartbeat,
    /// Clear latched faults whose cause is gone.
    ClearFaults,
    /// Replace the configuration (only while idle or faulted; a new wheel map only while idle).
    SetConfig(Config),
}

/// Why a command was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reject {
    /// A command field is not finite or out of its configured range; the field is named.
    OutOfRange(&'static str),
    /// Interlocks block motion (every blocking one is set).
    Interlocked(Interlocks),
    /// The new configuration failed validation.
    BadConfig(ConfigError),
    /// The configuration can only change while the robot is idle or faulted (a new wheel map
    /// only while idle).
    Busy,
    /// Some faults are still present after `ClearFaults` (what still blocks is set).
    FaultsPersist(Interlocks),
}

impl core::fmt::Display for Reject {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::OutOfRange(field) => write!(f, "command field `{field}` out of range"),
            Self::Interlocked(i) | Self::FaultsPersist(i) => {
                f.write_str(if matches!(self, Self::Interlocked(_)) {
                    "blocked by interlocks:"
                } else {
                    "faults persist:"
                })?;
                for name in i.names() {
                    write!(f, " {name}")?;
                }
                Ok(())
            }
            Self::BadConfig(e) => write!(f, "{e}"),
            Self::Busy => f.write_str("configuration can only change while idle"),
        }
    }
}

/// Motion mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// At rest, currents zero.
    Idle,
    /// Ramping to or cruising at the commanded twist.
    Driving,
    /// Ramping to zero.
    Stopping,
    /// Zero speed held by the wheel PIDs, then idle.
    Holding,
    /// A fault is latched: currents zero.
    Faulted,
}

impl Mode {
    /// Name for reports.
    pub fn name(self) -> &'static str {
        match self {
            Self::Idle => "idle",
            Self::Driving => "driving",
            Self::Stopping => "stopping",
            Self::Holding => "holding",
            Self::Faulted => "faulted",
        }
    }
}

/// What one step produces.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StepOutput {
    /// Raw currents for the 0x200 frame, slot `i` for ESC id `i + 1`.
    pub currents_raw: [i16; 4],
    /// The shell should restart the CAN controller (bus-off seen this step).
    pub recover_bus: bool,
}

/// The drive state machine (see the module docs).
#[derive(Debug, Clone)]
pub struct Machine {
    config: Config,
    mode: Mode,
    /// Per wheel (FL, FR, RL, RR), not per ESC id.
    escs: [EscMonitor; 4],
    encoders: [EncoderUnwrap; 4],
    pids: [Pid; 4],
    /// vx, vy, wz.
    ramps: [Ramp; 3],
    target: Twist,
    limits: [Limits; 3],
    odometry: Odometry,
    last_heartbeat_us: Option<u64>,
    host_seen: bool,
    /// Latched `HEARTBEAT_LOST`, `CAN_BUS_OFF` and `STOP_REQUESTED`.
    latched: Interlocks,
    bus: BusState,
    bus_off_count: u16,
    last_step_us: Option<u64>,
    hold_until_us: u64,
    setpoint: Twist,
    command_a: [f32; 4],
    unknown_esc_frames: u32,
    battery: BatteryMonitor,
}

impl Machine {
    /// A machine at rest with `config`. Fails if the configuration does not validate.
    pub fn new(config: Config) -> Result<Self, ConfigError> {
        config.validate()?;
        Ok(Self {
            config,
            mode: Mode::Idle,
            escs: [EscMonitor::new(); 4],
            encoders: [EncoderUnwrap::new(); 4],
            pids: [Pid::new(); 4],
            ramps: [Ramp::new(); 3],
            target: Twist::ZERO,
            limits: [Limits {
                accel: 1.0,
                jerk: None,
            }; 3],
            odometry: Odometry::new(),
            last_heartbeat_us: None,
            host_seen: false,
            latched: Interlocks::EMPTY,
            bus: BusState::Active,
            bus_off_count: 0,
            last_step_us: None,
            hold_until_us: 0,
            setpoint: Twist::ZERO,
            command_a: [0.0; 4],
            unknown_esc_frames: 0,
            battery: BatteryMonitor::new(),
        })
    }

    /// The active configuration.
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// Current mode.
    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// Integrated pose.
    pub fn pose(&self) -> Pose {
        self.odometry.pose()
    }

    /// Odometry (pose, twist, wheel speeds).
    pub fn odometry(&self) -> &Odometry {
        &self.odometry
    }

    /// The ramped twist setpoint of the last step.
    pub fn setpoint(&self) -> Twist {
        self.setpoint
    }

    /// Feedback frames from ESC ids not in the wheel map, since boot.
    pub fn unknown_esc_frames(&self) -> u32 {
        self.unknown_esc_frames
    }

    fn heartbeat_fresh(&self, now_us: u64) -> bool {
        self.last_heartbeat_us
            .is_some_and(|t| now_us.saturating_sub(t) < self.config.heartbeat_timeout_us)
    }

    /// Latched faults that zero the currents (ESC faults of ESCs that have reported, bus-off).
    fn hard_faults(&self) -> Interlocks {
        let mut i = Interlocks::EMPTY;
        for e in &self.escs {
            i.insert(interlocks_of(e.faults()));
        }
        i.insert(self.latched);
        Interlocks(i.0 & HARD_INTERLOCKS.0)
    }

    /// Per-wheel ESC faults, with `MISSING` also set (live) for ESCs that never reported.
    fn esc_faults(&self) -> [EscFaults; 4] {
        self.escs.map(|e| {
            let mut f = e.faults();
            if !e.seen() {
                f.insert(EscFaults::MISSING);
            }
            f
        })
    }

    /// Everything that blocks motion at `now_us`.
    pub fn interlocks(&self, now_us: u64) -> Interlocks {
        let mut i = Interlocks::EMPTY;
        if !self.host_seen {
            i.insert(Interlocks::NO_HOST);
        }
        if self.latched.contains(Interlocks::HEARTBEAT_LOST) || !self.heartbeat_fresh(now_us) {
            i.insert(Interlocks::HEARTBEAT_LOST);
        }
        for f in self.esc_faults() {
            i.insert(interlocks_of(f));
        }
        if self.battery.is_low() {
            i.insert(Interlocks::BATTERY_LOW);
        }
        i.insert(self.latched);
        i
    }

    /// Takes the battery reading of this step, mV (0: not measured); see [`crate::battery`].
    pub fn update_battery(&mut self, now_us: u64, battery_mv: u16) {
        self.battery
            .update(&self.config.battery, battery_mv, now_us);
    }

    /// The battery monitor.
    pub fn battery(&self) -> &BatteryMonitor {
        &self.battery
    }

    /// The mode as the MCU link reports it.
    pub fn drive_mode(&self) -> DriveMode {
        match self.mode {
            Mode::Idle => DriveMode::Idle,
            Mode::Driving => {
                let target = [self.target.vx_mps, self.target.vy_mps, self.target.wz_radps];
                let cruising = self
                    .ramps
                    .iter()
                    .zip(target)
                    .all(|(r, t)| r.is_settled_at(t));
                if cruising {
                    DriveMode::Cruising
                } else {
                    DriveMode::Ramping
                }
            }
            Mode::Stopping | Mode::Holding => DriveMode::Stopping,
            Mode::Faulted => DriveMode::Faulted,
        }
    }

    /// The status report at `now_us` (the link fills in its own counters).
    pub fn status(&self, now_us: u64) -> Status {
        let faults = self.esc_faults();
        let esc = core::array::from_fn(|wheel| {
            let last = self.escs[wheel].last();
            EscStatus {
                esc_id: self.config.wheels.esc_id[wheel],
                faults: faults[wheel],
                temperature_c: last.temperature_c,
                current_a: protocol::esc::raw_to_amps(last.current_raw),
                command_a: self.command_a[wheel],
            }
        });
        Status {
            stamp_us: now_us,
            mode: self.drive_mode(),
            interlocks: self.interlocks(now_us),
            esc,
            bus_off_count: self.bus_off_count,
            link_errors: 0,
            rejected_count: 0,
            battery_mv: self.battery.filtered_mv(),
            control_step_max_us: 0,
        }
    }

    /// The odometry report at `now_us`.
    pub fn odometry_report(&self, now_us: u64) -> OdometryReport {
        let pose = self.odometry.pose();
        let twist = self.odometry.twist();
        OdometryReport {
            stamp_us: now_us,
            x_m: pose.x_m,
            y_m: pose.y_m,
            yaw_rad: pose.yaw_rad,
            vx_mps: twist.vx_mps,
            vy_mps: twist.vy_mps,
            wz_radps: twist.wz_radps,
            wheel_speed_radps: self.odometry.wheel_radps(),
        }
    }

    /// Applies one command received at `now_us`.
    pub fn command(&mut self, now_us: u64, command: Command) -> Result<(), Reject> {
        match command {
            Command::Heartbeat => {
                self.last_heartbeat_us = Some(now_us);
                Ok(())
            }
            Command::Hello => {
                self.host_seen = true;
                Ok(())
            }
            Command::Drive(drive) => self.drive(now_us, &drive),
            Command::Stop { immediate } => {
                self.latched.insert(Interlocks::STOP_REQUESTED);
                match self.mode {
                    Mode::Faulted | Mode::Idle => {}
                    _ if immediate => {
                        self.mode = Mode::Idle;
                        self.rest();
                    }
                    Mode::Driving => {
                        self.target = Twist::ZERO;
                        self.mode = Mode::Stopping;
                    }
                    Mode::Stopping | Mode::Holding => {}
                }
                Ok(())
            }
            Command::ClearFaults => self.clear_faults(now_us),
            Command::SetConfig(config) => {
                // A new wheel map changes which ESC each monitor and encoder stands for, so it
                // is accepted only when idle (no latched faults to lose) and restarts them.
                let remap = config.wheels != self.config.wheels;
                let allowed = if remap {
                    self.mode == Mode::Idle
                } else {
                    matches!(self.mode, Mode::Idle | Mode::Faulted)
                };
                if !allowed {
                    return Err(Reject::Busy);
                }
                config.validate().map_err(Reject::BadConfig)?;
                self.config = config;
                if remap {
                    self.escs = [EscMonitor::new(); 4];
                    self.encoders = [EncoderUnwrap::new(); 4];
                }
                Ok(())
            }
        }
    }

    fn drive(&mut self, now_us: u64, drive: &DriveCommand) -> Result<(), Reject> {
        let c = &self.config;
        let t = &drive.twist;
        let finite_in = |x: f32, max: f32| x.is_finite() && x.abs() <= max;
        if !finite_in(t.vx_mps, c.max_speed_mps) {
            return Err(Reject::OutOfRange("vx_mps"));
        }
        if !finite_in(t.vy_mps, c.max_speed_mps) {
            return Err(Reject::OutOfRange("vy_mps"));
        }
        if !finite_in(t.wz_radps, c.max_yaw_rate_radps) {
            return Err(Reject::OutOfRange("wz_radps"));
        }
        if !(finite_in(drive.accel_mps2, c.max_accel_mps2) && drive.accel_mps2 > 0.0) {
            return Err(Reject::OutOfRange("accel_mps2"));
        }
        if !(finite_in(drive.jerk_mps3, c.max_jerk_mps3) && drive.jerk_mps3 >= 0.0) {
            return Err(Reject::OutOfRange("jerk_mps3"));
        }
        let mut blocking = self.interlocks(now_us);
        // A stop or a lost heartbeat only asks for a new start: this drive command is that start
        // (the heartbeat must be flowing again).
        blocking.remove(Interlocks::STOP_REQUESTED);
        if self.heartbeat_fresh(now_us) {
            blocking.remove(Interlocks::HEARTBEAT_LOST);
        }
        if !blocking.is_empty() {
            return Err(Reject::Interlocked(blocking));
        }
        self.latched.remove(Interlocks::HEARTBEAT_LOST);
        self.latched.remove(Interlocks::STOP_REQUESTED);
        self.target = drive.twist;
        self.limits = ramp_limits(c, drive.accel_mps2, drive.jerk_mps3);
        self.mode = Mode::Driving;
        Ok(())
    }

    /// Whether the motor contactor (motor power) may be closed: no fault is latched. It opens in
    /// the step a fault latches and stays open until an accepted `ClearFaults`; the shell keeps it
    /// open from reset until the first step and on a panic.
    pub fn contactor_closed(&self) -> bool {
        self.mode != Mode::Faulted && self.hard_faults().is_empty()
    }

    fn clear_faults(&mut self, now_us: u64) -> Result<(), Reject> {
        // With the contactor open the ESCs may be unpowered, so a silent ESC says nothing about
        // its health: it restarts as never seen. A drive stays refused (`ESC_FEEDBACK_MISSING`)
        // until it reports again, and its first reports are checked like any other (a motor
        // that was too hot must report below the clearing temperature).
        let contactor_open = !self.contactor_closed();
        for (esc, encoder) in self.escs.iter_mut().zip(&mut self.encoders) {
            if contactor_open && !esc.fresh(&self.config, now_us) {
                *esc = esc.restarted();
                *encoder = EncoderUnwrap::new();
            } else {
                esc.clear(&self.config, now_us);
            }
        }
        if self.bus != BusState::BusOff {
            self.latched.remove(Interlocks::CAN_BUS_OFF);
        }
        let persisting = self.hard_faults();
        if persisting.is_empty() && self.mode == Mode::Faulted {
            self.mode = Mode::Idle;
        }
        if persisting.is_empty() {
            Ok(())
        } else {
            Err(Reject::FaultsPersist(persisting))
        }
    }

    /// One control period at `now_us`: `esc` holds the feedback frames received since the last
    /// step, `bus` the CAN controller state.
    pub fn step(&mut self, now_us: u64, esc: &[EscSample], bus: BusState) -> StepOutput {
        let dt_us = self.last_step_us.map_or(FIRST_STEP_US, |last| {
            now_us.saturating_sub(last).min(MAX_STEP_US)
        });
        self.last_step_us = Some(now_us);
        #[allow(clippy::cast_precision_loss)]
        let dt_s = dt_us as f32 * 1e-6;

        for sample in esc {
            self.ingest(sample);
        }
        self.odometry.integrate(&self.config.geometry);
        let recover_bus = self.supervise(now_us, bus);
        let currents_raw = self.motion(now_us, dt_s);
        StepOutput {
            currents_raw,
            recover_bus,
        }
    }

    fn ingest(&mut self, sample: &EscSample) {
        let Some(wheel) = self.config.wheels.wheel_of_esc(sample.esc_id) else {
            self.unknown_esc_frames = self.unknown_esc_frames.saturating_add(1);
            return;
        };
        let sign = self.config.wheels.sign_f(wheel);
        let command_a = self.command_a[wheel];
        let fb = &sample.feedback;
        let (Some(encoder), Some(monitor)) =
            (self.encoders.get_mut(wheel), self.escs.get_mut(wheel))
        else {
            return;
        };
        let delta = encoder.update(fb.angle_raw, fb.speed_rpm, sample.stamp_us);
        let wheel_radps = sign * odometry::rpm_to_wheel_radps(fb.speed_rpm);
        self.odometry.add_wheel(
            wheel,
            sign * odometry::counts_to_wheel_rad(delta),
            wheel_radps,
        );
        monitor.on_feedback(&self.config, fb, wheel_radps, sample.stamp_us);
        monitor.check_following(command_a, sample.stamp_us);
    }

    /// Updates latches and mode from the monitors; returns whether the bus needs recovery.
    fn supervise(&mut self, now_us: u64, bus: BusState) -> bool {
        for esc in &mut self.escs {
            esc.check_timeout(&self.config, now_us);
        }
        let recover_bus = bus == BusState::BusOff;
        if recover_bus {
            if self.bus != BusState::BusOff {
                self.bus_off_count = self.bus_off_count.saturating_add(1);
            }
            self.latched.insert(Interlocks::CAN_BUS_OFF);
        }
        self.bus = bus;

        let moving = matches!(self.mode, Mode::Driving | Mode::Stopping);
        if moving
            && !self.heartbeat_fresh(now_us)
            && !self.latched.contains(Interlocks::HEARTBEAT_LOST)
        {
            self.latched.insert(Interlocks::HEARTBEAT_LOST);
            self.safety_stop();
        }
        if self.mode == Mode::Driving && self.battery.is_low() {
            // Not latched: drives are refused while it holds (see `interlocks`).
            self.safety_stop();
        }
        if !self.hard_faults().is_empty() {
            self.mode = Mode::Faulted;
        }
        recover_bus
    }

    /// Ramps, runs the PIDs and returns the raw currents per ESC slot.
    fn motion(&mut self, now_us: u64, dt_s: f32) -> [i16; 4] {
        match self.mode {
            Mode::Idle | Mode::Faulted => {
                self.rest();
                return [0; 4];
            }
            Mode::Driving | Mode::Stopping => {
                let target = [self.target.vx_mps, self.target.vy_mps, self.target.wz_radps];
                for ((ramp, limits), target) in self.ramps.iter_mut().zip(&self.limits).zip(target)
                {
                    ramp.step(target, limits, dt_s);
                }
                if self.mode == Mode::Stopping && self.ramps.iter().all(Ramp::is_at_rest) {
                    self.mode = Mode::Holding;
                    self.hold_until_us = now_us.saturating_add(self.config.hold_after_stop_us);
                }
            }
            Mode::Holding => {
                if now_us >= self.hold_until_us {
                    self.mode = Mode::Idle;
                    self.rest();
                    return [0; 4];
                }
            }
        }
        let [vx, vy, wz] = self.ramps.map(|r| r.velocity());
        self.setpoint = Twist::new(vx, vy, wz);
        let wheel_setpoints = kinematics::limit_wheel_speeds(
            kinematics::inverse(&self.config.geometry, self.setpoint),
            self.config.max_wheel_radps,
        );
        let measured = self.odometry.wheel_radps();
        let mut currents_raw = [0i16; 4];
        for wheel in 0..4 {
            let amps = self.pids[wheel].update(
                &self.config.pid,
                wheel_setpoints[wheel],
                measured[wheel],
                dt_s,
            );
            let motor_amps = self.config.wheels.sign_f(wheel) * amps;
            self.command_a[wheel] = motor_amps;
            let slot = usize::from(self.config.wheels.esc_id[wheel]).wrapping_sub(1);
            if let Some(c) = currents_raw.get_mut(slot) {
                *c = protocol::esc::amps_to_raw(motor_amps);
            }
        }
        currents_raw
    }

    /// Drops the drive command and ramps to zero with the safety-stop limits.
    fn safety_stop(&mut self) {
        self.target = Twist::ZERO;
        self.limits = ramp_limits(
            &self.config,
            self.config.stop_accel_mps2,
            self.config.stop_jerk_mps3,
        );
        self.mode = Mode::Stopping;
    }

    fn rest(&mut self) {
        for pid in &mut self.pids {
            pid.reset();
        }
        for ramp in &mut self.ramps {
            ramp.reset();
        }
        self.target = Twist::ZERO;
        self.setpoint = Twist::ZERO;
        self.command_a = [0.0; 4];
    }
}

/// Per-axis ramp limits from a linear acceleration and jerk (jerk 0 = trapezoid); the yaw axis
/// gets the same wheel-rim acceleration (divided by k).
fn ramp_limits(config: &Config, accel_mps2: f32, jerk_mps3: f32) -> [Limits; 3] {
    let k = config.geometry.k_m();
    let jerk = (jerk_mps3 > 0.0).then_some(jerk_mps3);
    let linear = Limits {
        accel: accel_mps2,
        jerk,
    };
    let yaw = Limits {
        accel: accel_mps2 / k,
        jerk: jerk.map(|j| j / k),
    };
    [linear, linear, yaw]
}
