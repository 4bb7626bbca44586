//! Firmware in the loop: the real firmware logic (`control::Controller`, the same struct the STM32
//! binary steps) against the simulated ESCs and robot, over a CAN bus and an MCU-link byte pipe.
//!
//! The runner reproduces the firmware's task timing: one 1 ms period per [`Fil::tick`], in which
//! 1. the ESCs take the 0x200 command frame the firmware sent in the previous period (a C620 holds
//!    its last command),
//! 2. the ESC and robot physics advance 1 ms ([`crate::esc_model`], [`crate::robot`]),
//! 3. every answering ESC sends its feedback frame (1 kHz, as a C620 does),
//! 4. scripted events due now are applied (faults, host messages, bus-off),
//! 5. the simulated onboard computer sends its heartbeat (every 20 ms) and scripted messages,
//! 6. the firmware's CAN receive task collects the feedback frames, its UART task the link bytes,
//! 7. `Controller::step(now, inputs)` runs; its currents go out as one 0x200 frame, its replies
//!    (odometry at the configured rate, status, acks, rejections) on the link, and its motor
//!    contactor output switches the ESCs' power from the next period (open at reset; an ESC
//!    without power drives no current and is silent, [`crate::esc_model::Esc::set_powered`]),
//! 8. the onboard stand-in reads and decodes the replies into the [`Trace`].
//!
//! Time is the simulation's: [`Pacing::Virtual`] runs as fast as the host can (deterministic for a
//! seed over the in-process bus and pipe), [`Pacing::RealTime`] sleeps to the wall clock so a pty
//! or a real SocketCAN interface sees real timing. The MCU clock of the firmware is the simulation
//! clock, so its odometry stamps compare directly with the ground truth ([`Trace::truth`]).
//!
//! CAN bus-off is modelled at the firmware's controller: while off it neither sends nor receives
//! (the ESCs keep their last command), it reports `BusState::BusOff`, and after the firmware asks
//! for recovery it is back 128 x 11 bit times (1.41 ms at 1 Mbit/s) after the disturbance ends.

use std::time::{Duration, Instant};

use control::{BusState, Controller, EscSample, Inputs};
use protocol::frame::{Deframer, Flags, MAX_FRAME_LEN};
use protocol::mcu::{FromFirmware, Status, ToFirmware};
use protocol::{DecodeError, Heartbeat};

use crate::can_bus::{CanBus, CanError, CanFrame, recv_expected};
use crate::esc_model::{Esc, EscFault, EscParams};
use crate::pty::ByteLink;
use crate::robot::{PoseHistory, PoseSample, Robot, RobotParams};

/// One control period, microseconds.
pub const TICK_US: u64 = 1_000;
/// Bus-off recovery time of a CAN controller: 128 x 11 recessive bits at 1 Mbit/s, microseconds.
pub const BUS_OFF_RECOVERY_US: u64 = 1_408;

/// How simulated time relates to the wall clock.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pacing {
    /// As fast as possible.
    Virtual,
    /// One simulated millisecond per wall-clock millisecond.
    RealTime,
}

/// Everything a run is configured by.
#[derive(Debug, Clone)]
pub struct FilConfig {
    /// The robot's mechanics (its `esc_ids` and `wheel_signs` must match the firmware's map).
    pub robot: RobotParams,
    /// The ESC/motor model.
    pub esc: EscParams,
    /// The firmware's built-in configuration.
    pub firmware: control::Config,
    /// Seed of every random choice (ESC noise).
    pub seed: u64,
    /// Period of the onboard stand-in's heartbeat, microseconds (the onboard sends every 20 ms).
    pub heartbeat_period_us: u64,
    /// Time pacing.
    pub pacing: Pacing,
    /// How long a receiver waits (wall clock) for frames it knows were sent, on buses with
    /// asynchronous delivery (SocketCAN). Irrelevant in-process.
    pub can_wait: Duration,
    /// The battery the ESCs and the board run from.
    pub battery: BatteryModel,
}

/// The battery: an open-circuit voltage behind an internal resistance, so the voltage the board
/// measures sags with the motor currents (`v = ocv - r * sum |i|`). Approximate on purpose: the
/// ESCs' input current is taken as the motor current (a C620 at low duty draws less from the
/// pack than it drives through the motor), which overstates the sag, the conservative side for
/// the firmware's under-voltage filter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BatteryModel {
    /// Open-circuit voltage, V (a TB47D 6S pack: 25.2 V full, 22.2 V nominal).
    pub open_circuit_v: f32,
    /// Internal resistance including wiring, ohm.
    pub internal_ohm: f32,
}

impl Default for BatteryModel {
    fn default() -> Self {
        Self {
            open_circuit_v: 24.0,
            internal_ohm: 0.06,
        }
    }
}

impl BatteryModel {
    /// What the board's ADC reads at `load_a`, through the firmware's own conversion (12-bit
    /// quantisation of the divider included), mV.
    pub fn measured_mv(&self, load_a: f32) -> u16 {
        let v = (self.open_circuit_v - self.internal_ohm * load_a).max(0.0);
        let full_scale_v =
            control::battery::ADC_REF_MV as f32 * 1e-3 * control::battery::DIVIDER_NUM as f32
                / control::battery::DIVIDER_DEN as f32;
        let raw = (v / full_scale_v * control::battery::ADC_FULL_SCALE as f32)
            .round()
            .clamp(0.0, control::battery::ADC_FULL_SCALE as f32) as u16;
        control::battery::adc_to_mv(raw)
    }
}

impl Default for FilConfig {
    fn default() -> Self {
        Self {
            robot: RobotParams::default(),
            esc: EscParams::default(),
            firmware: control::Config::default(),
            seed: 1,
            heartbeat_period_us: 20_000,
            pacing: Pacing::Virtual,
            can_wait: Duration::from_millis(50),
            battery: BatteryModel::default(),
        }
    }
}

/// A scripted action.
#[derive(Debug, Clone, PartialEq)]
pub enum Action {
    /// The onboard stand-in sends this message (ack requested for commands).
    Send(ToFirmware),
    /// The onboard stand-in's heartbeat on or off.
    Heartbeats(bool),
    /// Inject a fault into ESC `esc_id`.
    Fault {
        /// ESC id 1..=4.
        esc_id: u8,
        /// The fault.
        fault: EscFault,
    },
    /// Remove the injected faults of ESC `esc_id`.
    ClearEscFaults {
        /// ESC id 1..=4.
        esc_id: u8,
    },
    /// The firmware's CAN controller goes bus-off, the disturbance lasting this long.
    BusOff {
        /// Disturbance length, microseconds.
        duration_us: u64,
    },
    /// The onboard stand-in writes these raw bytes on the link (malformed-input tests).
    RawBytes(Vec<u8>),
    /// One wheel's traction limit is scaled (1 = nominal).
    Traction {
        /// Wheel index (FL, FR, RL, RR).
        wheel: usize,
        /// Scale.
        scale: f32,
    },
    /// The battery's open-circuit voltage changes (a flat or a fresh pack), V.
    BatteryOpenCircuit(f32),
}

/// An action at a time.
#[derive(Debug, Clone, PartialEq)]
pub struct Event {
    /// Simulation time, microseconds.
    pub at_us: u64,
    /// What happens.
    pub action: Action,
}

/// Everything observed during a run.
#[derive(Debug, Clone, Default)]
pub struct Trace {
    /// The robot's true pose, one sample per millisecond.
    pub truth: PoseHistory,
    /// Currents of each 0x200 frame the ESCs received, with the time they took effect.
    pub commands: Vec<(u64, [i16; 4])>,
    /// Messages the onboard stand-in received from the firmware, with the receive time.
    pub received: Vec<(u64, FromFirmware)>,
    /// Acks the onboard stand-in received.
    pub acks: u32,
    /// Link frames from the firmware that did not decode (must stay 0).
    pub host_decode_errors: u32,
    /// Feedback frames the ESCs sent that the firmware's CAN task did not get in time although
    /// its controller was on the bus (lost or late: must stay 0 on a clean bus).
    pub feedback_frames_lost: u64,
    /// Feedback frames the firmware's controller missed because it was bus-off (by design).
    pub feedback_frames_missed_bus_off: u64,
    /// Feedback frames each ESC put on the bus, by ESC id (an ESC without power or silenced by
    /// a fault sends none).
    pub feedback_frames_sent: std::collections::BTreeMap<u8, u64>,
    /// When the onboard stand-in sent each heartbeat.
    pub heartbeats_sent: Vec<u64>,
    /// Scripted events as applied, for reports.
    pub log: Vec<(u64, String)>,
    /// Every change of the motor contactor the firmware drives (time, closed), starting open at
    /// reset: while it is open the ESCs have no power.
    pub contactor: Vec<(u64, bool)>,
    /// Which bus carried the frames.
    pub bus: String,
}

impl Trace {
    /// Status reports, in time order.
    pub fn statuses(&self) -> impl Iterator<Item = (u64, &Status)> {
        self.received.iter().filter_map(|(t, m)| match m {
            FromFirmware::Status(s) => Some((*t, s)),
            _ => None,
        })
    }

    /// Odometry reports, in time order.
    pub fn odometry(&self) -> impl Iterator<Item = (u64, &protocol::mcu::Odometry)> {
        self.received.iter().filter_map(|(t, m)| match m {
            FromFirmware::Odometry(o) => Some((*t, o)),
            _ => None,
        })
    }

    /// Rejections, in time order.
    pub fn rejections(&self) -> impl Iterator<Item = (u64, &protocol::mcu::Rejected)> {
        self.received.iter().filter_map(|(t, m)| match m {
            FromFirmware::Rejected(r) => Some((*t, r)),
            _ => None,
        })
    }
}

/// The onboard computer's side of the MCU link, scripted.
#[derive(Debug)]
struct Host {
    seq: u16,
    deframer: Deframer<MAX_FRAME_LEN>,
    heartbeats: bool,
    heartbeat_counter: u32,
    next_heartbeat_us: u64,
}

impl Host {
    fn encode(&mut self, msg: &ToFirmware) -> Vec<u8> {
        let mut buf = [0u8; MAX_FRAME_LEN];
        let flags = match msg {
            ToFirmware::Heartbeat(_) => Flags::NONE,
            _ => Flags::ACK_REQUESTED,
        };
        let seq = self.seq;
        self.seq = self.seq.wrapping_add(1);
        match msg.encode_frame(seq, flags, &mut buf) {
            Ok(len) => buf[..len].to_vec(),
            // Every ToFirmware message fits MAX_FRAME_LEN (checked at compile time in protocol).
            Err(_) => Vec::new(),
        }
    }

    fn receive(&mut self, now_us: u64, bytes: &[u8], trace: &mut Trace) {
        self.deframer.feed_all(bytes, |frame| match frame {
            Ok(frame) => match FromFirmware::decode(&frame) {
                Ok(msg) => trace.received.push((now_us, msg)),
                Err(DecodeError::IsAck) => trace.acks += 1,
                Err(_) => trace.host_decode_errors += 1,
            },
            Err(_) => trace.host_decode_errors += 1,
        });
    }
}

/// Errors of a run.
#[derive(Debug, thiserror::Error)]
pub enum FilError {
    /// The firmware configuration failed validation.
    #[error("firmware configuration is invalid: {0}")]
    Config(String),
    /// No scenario has this name.
    #[error("unknown scenario `{name}`; known: {known}")]
    UnknownScenario {
        /// The name asked for.
        name: String,
        /// The known names, comma-separated.
        known: String,
    },
    /// The robot's wheel map disagrees with the firmware's.
    #[error(
        "robot wheel map (esc ids {robot_ids:?}, signs {robot_signs:?}) differs from the \
         firmware's ({fw_ids:?}, {fw_signs:?}): the firmware would drive the wrong wheels"
    )]
    WheelMap {
        /// Robot ESC ids.
        robot_ids: [u8; 4],
        /// Robot signs.
        robot_signs: [i8; 4],
        /// Firmware ESC ids.
        fw_ids: [u8; 4],
        /// Firmware signs.
        fw_signs: [i8; 4],
    },
    /// A bus node failed.
    #[error(transparent)]
    Can(#[from] CanError),
    /// The controller's 0x200 frame could not be built.
    #[error("building the 0x200 command frame failed: {0}")]
    Esc(#[from] protocol::esc::EscError),
    /// The MCU link failed.
    #[error("MCU link I/O failed: {0}")]
    Link(#[from] std::io::Error),
}

/// The firmware-in-the-loop runner (see the module docs).
pub struct Fil {
    config: FilConfig,
    controller: Controller,
    robot: Robot,
    escs: Vec<Esc>,
    fw_can: Box<dyn CanBus>,
    esc_can: Box<dyn CanBus>,
    fw_uart: Box<dyn ByteLink>,
    host_uart: Box<dyn ByteLink>,
    host: Host,
    now_us: u64,
    /// 0x200 frames the firmware sent last tick and the ESCs have yet to read.
    commands_in_flight: usize,
    can_off: bool,
    can_off_until_us: u64,
    can_recover_at_us: Option<u64>,
    /// The motor contactor as the firmware last drove it (open at reset).
    contactor_closed: bool,
    pending: Vec<Event>,
    trace: Trace,
    started: Option<Instant>,
    link_rx: Vec<u8>,
    host_rx: Vec<u8>,
}

impl std::fmt::Debug for Fil {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Fil")
            .field("now_us", &self.now_us)
            .field("bus", &self.trace.bus)
            .finish_non_exhaustive()
    }
}

impl Fil {
    /// A runner at time 0 with the robot at rest. `fw_can` and `esc_can` are two nodes of the same
    /// bus; `fw_uart` and `host_uart` the two ends of the MCU link.
    pub fn new(
        config: FilConfig,
        fw_can: Box<dyn CanBus>,
        esc_can: Box<dyn CanBus>,
        fw_uart: Box<dyn ByteLink>,
        host_uart: Box<dyn ByteLink>,
    ) -> Result<Self, FilError> {
        let controller =
            Controller::new(config.firmware).map_err(|e| FilError::Config(e.to_string()))?;
        let wheels = config.firmware.wheels;
        if wheels.esc_id != config.robot.esc_ids || wheels.sign != config.robot.wheel_signs {
            return Err(FilError::WheelMap {
                robot_ids: config.robot.esc_ids,
                robot_signs: config.robot.wheel_signs,
                fw_ids: wheels.esc_id,
                fw_signs: wheels.sign,
            });
        }
        // The contactor is open at reset: the ESCs have no power until the firmware closes it.
        let escs = config
            .robot
            .esc_ids
            .iter()
            .map(|&id| {
                let mut esc = Esc::new(id, config.esc, config.seed);
                esc.set_powered(false);
                esc
            })
            .collect();
        let mut trace = Trace {
            bus: fw_can.name(),
            ..Trace::default()
        };
        let robot = Robot::new(config.robot);
        trace.truth.samples.push(robot.sample(0));
        trace.contactor.push((0, false));
        Ok(Self {
            controller,
            robot,
            escs,
            fw_can,
            esc_can,
            fw_uart,
            host_uart,
            host: Host {
                seq: 0,
                deframer: Deframer::new(),
                heartbeats: false,
                heartbeat_counter: 0,
                next_heartbeat_us: 0,
            },
            now_us: 0,
            commands_in_flight: 0,
            can_off: false,
            can_off_until_us: 0,
            can_recover_at_us: None,
            contactor_closed: false,
            pending: Vec::new(),
            trace,
            started: None,
            link_rx: Vec::new(),
            host_rx: Vec::new(),
            config,
        })
    }

    /// Adds scripted events (any order; applied at the first tick at or after their time).
    pub fn schedule(&mut self, events: impl IntoIterator<Item = Event>) {
        self.pending.extend(events);
        self.pending.sort_by_key(|e| e.at_us);
    }

    /// Simulation time, microseconds.
    pub fn now_us(&self) -> u64 {
        self.now_us
    }

    /// The firmware logic under test.
    pub fn controller(&self) -> &Controller {
        &self.controller
    }

    /// The true robot state now.
    pub fn truth(&self) -> PoseSample {
        self.robot.sample(self.now_us)
    }

    /// Runs ticks until `end_us`; returns the trace so far.
    pub fn run_until(&mut self, end_us: u64) -> Result<&Trace, FilError> {
        while self.now_us + TICK_US <= end_us {
            self.tick()?;
        }
        Ok(&self.trace)
    }

    /// Hands over the trace so far, leaving an empty one.
    pub fn take_trace(&mut self) -> Trace {
        let bus = self.trace.bus.clone();
        std::mem::replace(
            &mut self.trace,
            Trace {
                bus,
                ..Trace::default()
            },
        )
    }

    /// Ends the run and hands over the trace.
    pub fn into_trace(self) -> Trace {
        self.trace
    }

    /// One 1 ms control period (see the module docs for the order).
    pub fn tick(&mut self) -> Result<(), FilError> {
        let now = self.now_us + TICK_US;
        self.fw_can.set_time_us(now);
        self.esc_can.set_time_us(now);
        self.esc_receive(now)?;
        self.physics(now);
        let sent = self.esc_feedback()?;
        self.apply_due_events(now)?;
        self.host_send(now)?;
        let samples = self.firmware_can_receive(now, sent)?;
        self.link_rx.clear();
        self.fw_uart.read_available(&mut self.link_rx)?;
        if self.can_off && self.can_recover_at_us.is_some_and(|t| now >= t) {
            self.can_off = false;
            self.can_recover_at_us = None;
            self.trace
                .log
                .push((now, "CAN controller recovered from bus-off".into()));
        }
        let bus = if self.can_off {
            BusState::BusOff
        } else {
            BusState::Active
        };
        let out = self.controller.step(
            now,
            &Inputs {
                esc: &samples,
                link_rx: &self.link_rx,
                bus,
                battery_mv: self
                    .config
                    .battery
                    .measured_mv(self.escs.iter().map(|e| e.current_a().abs()).sum()),
            },
        );
        if out.contactor_closed != self.contactor_closed {
            self.contactor_closed = out.contactor_closed;
            for esc in &mut self.escs {
                esc.set_powered(out.contactor_closed);
            }
            self.trace.contactor.push((now, out.contactor_closed));
            self.trace.log.push((
                now,
                format!(
                    "motor contactor {}",
                    if out.contactor_closed {
                        "closed"
                    } else {
                        "opened"
                    }
                ),
            ));
        }
        if out.recover_bus && self.can_off && self.can_recover_at_us.is_none() {
            self.can_recover_at_us = Some(self.can_off_until_us.max(now) + BUS_OFF_RECOVERY_US);
        }
        self.commands_in_flight = 0;
        if !self.can_off {
            let frame: CanFrame = out.command_frame()?;
            self.fw_can.send(&frame)?;
            self.commands_in_flight = 1;
        }
        self.fw_uart.write_all(&out.link_tx)?;
        self.host_rx.clear();
        self.host_uart.read_available(&mut self.host_rx)?;
        let bytes = std::mem::take(&mut self.host_rx);
        self.host.receive(now, &bytes, &mut self.trace);
        self.host_rx = bytes;
        self.now_us = now;
        self.pace(now);
        Ok(())
    }

    fn esc_receive(&mut self, now: u64) -> Result<(), FilError> {
        let frames = recv_expected(
            self.esc_can.as_mut(),
            self.commands_in_flight,
            self.config.can_wait,
        )?;
        for frame in &frames {
            let mut applied = false;
            for esc in &mut self.escs {
                applied |= esc.on_frame(frame);
            }
            // The commands on the bus, whether or not an ESC has power to take them.
            if (applied || !self.contactor_closed)
                && let Ok((_, currents)) = protocol::esc::parse_command_frame(frame)
            {
                self.trace.commands.push((now - TICK_US, currents));
            }
        }
        // Anything else on the bus (another node, a candump) is drained and ignored.
        while self.esc_can.try_recv()?.is_some() {}
        Ok(())
    }

    fn physics(&mut self, now: u64) {
        let dt_s = TICK_US as f32 * 1e-6;
        let mut torque = [0.0f32; 4];
        for (wheel, esc) in self.escs.iter_mut().enumerate() {
            esc.advance(dt_s);
            torque[wheel] = esc.torque_nm();
        }
        self.robot.advance(torque, dt_s);
        self.trace.truth.samples.push(self.robot.sample(now));
    }

    fn esc_feedback(&mut self) -> Result<usize, FilError> {
        let mut sent = 0;
        for (wheel, esc) in self.escs.iter_mut().enumerate() {
            let (angle, speed) = self.robot.motor_shaft(wheel);
            if let Some(frame) = esc.feedback(angle, speed) {
                self.esc_can.send(&frame)?;
                sent += 1;
                *self
                    .trace
                    .feedback_frames_sent
                    .entry(esc.esc_id)
                    .or_default() += 1;
            }
        }
        Ok(sent)
    }

    fn firmware_can_receive(&mut self, now: u64, sent: usize) -> Result<Vec<EscSample>, FilError> {
        let frames = recv_expected(self.fw_can.as_mut(), sent, self.config.can_wait)?;
        if self.can_off {
            self.trace.feedback_frames_missed_bus_off += sent as u64;
            while self.fw_can.try_recv()?.is_some() {}
            return Ok(Vec::new());
        }
        self.trace.feedback_frames_lost += (sent - frames.len().min(sent)) as u64;
        Ok(frames
            .iter()
            .filter_map(|f| protocol::esc::parse_feedback_frame(f).ok())
            .map(|(esc_id, feedback)| EscSample {
                esc_id,
                feedback,
                stamp_us: now,
            })
            .collect())
    }

    fn apply_due_events(&mut self, now: u64) -> Result<(), FilError> {
        let due = self.pending.iter().take_while(|e| e.at_us <= now).count();
        let events: Vec<Event> = self.pending.drain(..due).collect();
        for event in events {
            self.apply(now, event.action)?;
        }
        Ok(())
    }

    fn apply(&mut self, now: u64, action: Action) -> Result<(), FilError> {
        let text = describe(&action);
        match action {
            Action::Send(msg) => {
                let bytes = self.host.encode(&msg);
                self.host_uart.write_all(&bytes)?;
            }
            Action::Heartbeats(on) => {
                self.host.heartbeats = on;
                self.host.next_heartbeat_us = now;
            }
            Action::Fault { esc_id, fault } => {
                if let Some(esc) = self.escs.iter_mut().find(|e| e.esc_id == esc_id) {
                    esc.inject(fault);
                }
            }
            Action::ClearEscFaults { esc_id } => {
                if let Some(esc) = self.escs.iter_mut().find(|e| e.esc_id == esc_id) {
                    esc.clear_faults();
                }
            }
            Action::BusOff { duration_us } => {
                self.can_off = true;
                self.can_off_until_us = now + duration_us;
                self.can_recover_at_us = None;
            }
            Action::RawBytes(bytes) => self.host_uart.write_all(&bytes)?,
            Action::Traction { wheel, scale } => self.robot.set_traction_scale(wheel, scale),
            Action::BatteryOpenCircuit(v) => self.config.battery.open_circuit_v = v,
        }
        self.trace.log.push((now, text));
        Ok(())
    }

    fn host_send(&mut self, now: u64) -> Result<(), FilError> {
        if self.host.heartbeats && now >= self.host.next_heartbeat_us {
            let msg = ToFirmware::Heartbeat(Heartbeat {
                counter: self.host.heartbeat_counter,
            });
            self.host.heartbeat_counter = self.host.heartbeat_counter.wrapping_add(1);
            self.host.next_heartbeat_us = now + self.config.heartbeat_period_us;
            let bytes = self.host.encode(&msg);
            self.host_uart.write_all(&bytes)?;
            self.trace.heartbeats_sent.push(now);
        }
        Ok(())
    }

    fn pace(&mut self, now: u64) {
        if self.config.pacing == Pacing::RealTime {
            let start = *self.started.get_or_insert_with(Instant::now);
            let due = start + Duration::from_micros(now);
            if let Some(wait) = due.checked_duration_since(Instant::now()) {
                std::thread::sleep(wait);
            }
        }
    }
}

fn describe(action: &Action) -> String {
    match action {
        Action::Send(msg) => format!("host sends {}", msg.name()),
        Action::Heartbeats(on) => format!("host heartbeat {}", if *on { "on" } else { "off" }),
        Action::Fault { esc_id, fault } => format!("ESC {esc_id}: inject {fault:?}"),
        Action::ClearEscFaults { esc_id } => format!("ESC {esc_id}: faults removed"),
        Action::BusOff { duration_us } => {
            format!("firmware CAN controller bus-off ({duration_us} us disturbance)")
        }
        Action::RawBytes(b) => format!("host writes {} raw bytes", b.len()),
        Action::Traction { wheel, scale } => format!("wheel {wheel}: traction x{scale}"),
        Action::BatteryOpenCircuit(v) => format!("battery open-circuit voltage {v} V"),
    }
}
