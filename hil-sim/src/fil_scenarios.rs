//! The firmware-in-the-loop scenarios of issue 8, each a script of [`Event`]s plus the figures and
//! pass/fail checks computed from its [`Trace`]. The same scenario bodies run on the in-process
//! bus (`cargo test`), on SocketCAN `vcan0` (in the vcan guest, `hil-sim/vcan-vm/ci.sh`) and from
//! the command line (`passangle-sim fil`).
//!
//! | scenario | what happens | what is checked |
//! |---|---|---|
//! | `cruise` | start, S-curve ramp, 0.2 m/s for 5 s, stop | true velocity ripple (std/mean) < 1 %, odometry error reported |
//! | `heartbeat-loss` | heartbeats stop at cruise | `HEARTBEAT_LOST` reported, currents zero and robot at rest in bounded time |
//! | `esc-silent` | ESC 3 stops answering at cruise | fault latched within 10 ms naming ESC 3, zero currents on the bus |
//! | `over-temperature` | ESC 2 reports 95 degC at cruise | fault named, zero currents, contactor opened; after `ClearFaults` the hot motor latches the fault again on its first report, `Drive` refused, no current |
//! | `bus-off` | the firmware's CAN controller goes bus-off | reported and counted, zero currents after recovery, cleared and driving again |
//! | `stuck-current` | ESC 1's current sticks at 18 A at cruise (a C620 fault the firmware cannot override) | over-current named within 5 ms, all-zero commands from then on, the motor contactor opened in the step the fault latches (cutting the stuck ESC's power), robot at rest within 1.5 s |
//! | `link-flood` | seeded garbage and malformed frames on the MCU link, idle then at cruise | nothing moves at idle, errors counted and rejections sent, cruise unaffected |
//! | `battery-low` | the pack's open-circuit voltage falls from 24 V to 19.2 V at cruise (a short sag to 16 V before it does not count) | the sag does not stop the run; `BATTERY_LOW` within 2.5 s of the drop, robot ramped to rest, a new drive refused naming it, the reported voltage |
//!
//! All figures are measured on the simulation: true velocities from [`crate::robot`], commands as
//! the ESCs received them from the bus, reports as the onboard stand-in decoded them.

use std::fmt;
use std::time::Instant;

use protocol::frame::{Flags, Header, MAX_FRAME_LEN};
use protocol::mcu::{
    ClearFaults, Drive, DriveMode, EscFaults, Interlocks, RejectReason, Stop, ToFirmware,
};
use protocol::{Hello, Role};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::can_bus::{CanBus, InProcessBus, SocketCanBus};
use crate::esc_model::EscFault;
use crate::fil::{Action, Event, Fil, FilConfig, FilError, Trace};
use crate::pty::{ByteLink, MemPipe, PtyLink};

/// Cruise speed of every scenario, m/s.
pub const CRUISE_MPS: f32 = 0.2;
/// When the drive command is sent, microseconds.
pub const DRIVE_AT_US: u64 = 20_000;
/// When the ramp is certainly over and cruise measurements start, microseconds.
pub const CRUISE_FROM_US: u64 = 1_000_000;

/// Which CAN bus a run uses.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum BusChoice {
    /// The in-memory bus; `record` keeps a `candump -l` log of every frame.
    InProcess {
        /// Record frames.
        record: bool,
    },
    /// Two raw sockets on this SocketCAN interface (e.g. `vcan0`).
    SocketCan(String),
}

/// Which byte pipe carries the MCU link.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinkChoice {
    /// In memory.
    Memory,
    /// A pseudo-terminal pair.
    Pty,
}

/// Builds a runner on the chosen bus and link. Returns the in-process bus too, when used, so its
/// recording can be read.
pub fn build(
    config: FilConfig,
    bus: &BusChoice,
    link: LinkChoice,
) -> Result<(Fil, Option<InProcessBus>), FilError> {
    let (fw_can, esc_can, in_process): (Box<dyn CanBus>, Box<dyn CanBus>, _) = match bus {
        BusChoice::InProcess { record } => {
            let bus = InProcessBus::new();
            if *record {
                bus.record();
            }
            (Box::new(bus.node()), Box::new(bus.node()), Some(bus))
        }
        BusChoice::SocketCan(iface) => (
            Box::new(SocketCanBus::open(iface)?),
            Box::new(SocketCanBus::open(iface)?),
            None,
        ),
    };
    let (fw_uart, host_uart): (Box<dyn ByteLink>, Box<dyn ByteLink>) = match link {
        LinkChoice::Memory => {
            let (a, b) = MemPipe::pair();
            (Box::new(a), Box::new(b))
        }
        LinkChoice::Pty => {
            let (a, b) = PtyLink::pair().map_err(|e| FilError::Link(std::io::Error::other(e)))?;
            (Box::new(a), Box::new(b))
        }
    };
    let fil = Fil::new(config, fw_can, esc_can, fw_uart, host_uart)?;
    Ok((fil, in_process))
}

/// One measured figure.
#[derive(Debug, Clone, PartialEq)]
pub struct Figure {
    /// What it is.
    pub name: &'static str,
    /// Its value.
    pub value: f64,
    /// Its unit.
    pub unit: &'static str,
}

/// One pass/fail check.
#[derive(Debug, Clone, PartialEq)]
pub struct Check {
    /// What is required.
    pub what: String,
    /// Whether it held.
    pub ok: bool,
    /// What was seen.
    pub detail: String,
}

/// The outcome of one scenario.
#[derive(Debug, Clone)]
pub struct Outcome {
    /// Scenario name.
    pub name: &'static str,
    /// The bus it ran on.
    pub bus: String,
    /// Measured figures.
    pub figures: Vec<Figure>,
    /// Checks.
    pub checks: Vec<Check>,
    /// Wall-clock time of the run, s.
    pub wall_s: f64,
    /// The full trace.
    pub trace: Trace,
}

impl Outcome {
    /// Whether every check held.
    pub fn passed(&self) -> bool {
        self.checks.iter().all(|c| c.ok)
    }

    /// A figure by name.
    pub fn figure(&self, name: &str) -> Option<f64> {
        self.figures
            .iter()
            .find(|f| f.name == name)
            .map(|f| f.value)
    }

    fn figure_push(&mut self, name: &'static str, value: f64, unit: &'static str) {
        self.figures.push(Figure { name, value, unit });
    }

    fn check(&mut self, what: impl Into<String>, ok: bool, detail: impl Into<String>) {
        self.checks.push(Check {
            what: what.into(),
            ok,
            detail: detail.into(),
        });
    }
}

impl fmt::Display for Outcome {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "scenario {} on {} ({:.2} s wall): {}",
            self.name,
            self.bus,
            self.wall_s,
            if self.passed() { "PASS" } else { "FAIL" }
        )?;
        for fig in &self.figures {
            writeln!(f, "  {:<44} {:>12.4} {}", fig.name, fig.value, fig.unit)?;
        }
        for c in &self.checks {
            writeln!(
                f,
                "  [{}] {} ({})",
                if c.ok { "ok" } else { "FAILED" },
                c.what,
                c.detail
            )?;
        }
        Ok(())
    }
}

/// The scenario names, in table order.
pub const NAMES: [&str; 8] = [
    "cruise",
    "heartbeat-loss",
    "esc-silent",
    "over-temperature",
    "bus-off",
    "link-flood",
    "stuck-current",
    "battery-low",
];

/// Runs scenario `name` on a freshly built runner.
pub fn run(
    name: &str,
    config: FilConfig,
    bus: &BusChoice,
    link: LinkChoice,
) -> Result<Outcome, FilError> {
    let seed = config.seed;
    let (mut fil, _) = build(config, bus, link)?;
    run_on(name, &mut fil, seed)
}

/// What judges a scenario's trace.
type Judge = fn(&mut Outcome);

/// Scenario `name`'s canonical name, length (microseconds), script and judge.
fn script(name: &str, seed: u64) -> Option<(&'static str, u64, Vec<Event>, Judge)> {
    Some(match name {
        "cruise" => ("cruise", 7_500_000, cruise_events(), judge_cruise),
        "heartbeat-loss" => (
            "heartbeat-loss",
            5_000_000,
            heartbeat_loss_events(),
            judge_heartbeat_loss,
        ),
        "esc-silent" => (
            "esc-silent",
            4_500_000,
            esc_silent_events(),
            judge_esc_silent,
        ),
        "over-temperature" => (
            "over-temperature",
            4_500_000,
            over_temperature_events(),
            judge_over_temperature,
        ),
        "bus-off" => ("bus-off", 7_000_000, bus_off_events(), judge_bus_off),
        "link-flood" => ("link-flood", 3_500_000, flood_events(seed), judge_flood),
        "stuck-current" => (
            "stuck-current",
            4_500_000,
            stuck_current_events(),
            judge_stuck_current,
        ),
        "battery-low" => (
            "battery-low",
            9_000_000,
            battery_low_events(),
            judge_battery_low,
        ),
        _ => return None,
    })
}

/// How long scenario `name` runs, microseconds.
pub fn duration_us(name: &str) -> Option<u64> {
    script(name, 0).map(|(_, d, _, _)| d)
}

/// Runs scenario `name` on `fil` (fresh, at time 0).
pub fn run_on(name: &str, fil: &mut Fil, seed: u64) -> Result<Outcome, FilError> {
    let started = Instant::now();
    let Some((name, end_us, events, judge)) = script(name, seed) else {
        return Err(FilError::UnknownScenario {
            name: name.to_owned(),
            known: NAMES.join(", "),
        });
    };
    fil.schedule(events);
    fil.run_until(end_us)?;
    let trace = fil.take_trace();
    let mut outcome = Outcome {
        name,
        bus: trace.bus.clone(),
        figures: Vec::new(),
        checks: Vec::new(),
        wall_s: 0.0,
        trace,
    };
    judge(&mut outcome);
    outcome.check(
        "every firmware frame decodes on the onboard side",
        outcome.trace.host_decode_errors == 0,
        format!("{} undecodable", outcome.trace.host_decode_errors),
    );
    outcome.wall_s = started.elapsed().as_secs_f64();
    Ok(outcome)
}

// ---------------------------------------------------------------------------------------------
// Scripts

fn at(at_us: u64, action: Action) -> Event {
    Event { at_us, action }
}

fn send(at_us: u64, msg: impl Into<ToFirmware>) -> Event {
    at(at_us, Action::Send(msg.into()))
}

/// The drive command of every scenario: 0.2 m/s forward, 0.5 m/s^2, 5 m/s^3.
pub fn cruise_drive() -> Drive {
    Drive {
        vx_mps: CRUISE_MPS,
        vy_mps: 0.0,
        wz_radps: 0.0,
        accel_mps2: 0.5,
        jerk_mps3: 5.0,
    }
}

/// How a run starts: heartbeats on, `Hello`, then [`cruise_drive`] at `drive_at_us`.
pub fn start_events(drive_at_us: u64) -> Vec<Event> {
    vec![
        at(0, Action::Heartbeats(true)),
        send(0, Hello::new(Role::Simulator)),
        send(drive_at_us, cruise_drive()),
    ]
}

fn cruise_events() -> Vec<Event> {
    let mut e = start_events(DRIVE_AT_US);
    e.push(send(6_000_000, Stop { immediate: false }));
    e
}

/// When the heartbeat stops in `heartbeat-loss` (at a heartbeat time, before it is sent).
const HEARTBEAT_OFF_US: u64 = 3_001_000;
/// When faults are injected in the fault scenarios.
const FAULT_AT_US: u64 = 3_000_000;

fn heartbeat_loss_events() -> Vec<Event> {
    let mut e = start_events(DRIVE_AT_US);
    e.push(at(HEARTBEAT_OFF_US, Action::Heartbeats(false)));
    e
}

fn esc_silent_events() -> Vec<Event> {
    let mut e = start_events(DRIVE_AT_US);
    e.push(at(
        FAULT_AT_US,
        Action::Fault {
            esc_id: 3,
            fault: EscFault::Silent,
        },
    ));
    e
}

fn over_temperature_events() -> Vec<Event> {
    let mut e = start_events(DRIVE_AT_US);
    e.push(at(
        FAULT_AT_US,
        Action::Fault {
            esc_id: 2,
            fault: EscFault::OverTemperature(95.0),
        },
    ));
    e.push(send(3_500_000, ClearFaults {}));
    e.push(send(3_600_000, cruise_drive()));
    e
}

/// The stuck current of `stuck-current`, A (above the firmware's 15 A over-current limit).
const STUCK_A: f32 = 18.0;

fn stuck_current_events() -> Vec<Event> {
    let mut e = start_events(DRIVE_AT_US);
    e.push(at(
        FAULT_AT_US,
        Action::Fault {
            esc_id: 1,
            fault: EscFault::StuckCurrent(STUCK_A),
        },
    ));
    e
}

/// When the pack sags to 16 V for 150 ms (a hard acceleration on a tired pack), microseconds.
const SAG_AT_US: u64 = 2_000_000;
/// When the pack's open-circuit voltage falls for good, microseconds.
const FLAT_AT_US: u64 = FAULT_AT_US;
/// When the onboard stand-in tries to drive again, microseconds.
const RETRY_AT_US: u64 = 7_500_000;

fn battery_low_events() -> Vec<Event> {
    let mut e = start_events(DRIVE_AT_US);
    e.push(at(SAG_AT_US, Action::BatteryOpenCircuit(16.0)));
    e.push(at(SAG_AT_US + 150_000, Action::BatteryOpenCircuit(24.0)));
    e.push(at(FLAT_AT_US, Action::BatteryOpenCircuit(19.2)));
    e.push(send(RETRY_AT_US, cruise_drive()));
    e
}

const BUS_OFF_US: u64 = 20_000;
const CLEAR_AT_US: u64 = 4_500_000;
const REDRIVE_AT_US: u64 = 4_600_000;

fn bus_off_events() -> Vec<Event> {
    let mut e = start_events(DRIVE_AT_US);
    e.push(at(
        FAULT_AT_US,
        Action::BusOff {
            duration_us: BUS_OFF_US,
        },
    ));
    e.push(send(CLEAR_AT_US, ClearFaults {}));
    e.push(send(REDRIVE_AT_US, cruise_drive()));
    e
}

/// The flood runs from 100 ms to 3.4 s; the drive command comes at 1 s.
const FLOOD_DRIVE_US: u64 = 1_000_000;

fn flood_events(seed: u64) -> Vec<Event> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0xF100D);
    let mut e = start_events(FLOOD_DRIVE_US);
    let good_drive = encode_frame(&ToFirmware::Drive(cruise_drive()), 7);
    for (k, t) in (100_000..3_400_000).step_by(5_000).enumerate() {
        let bytes = match k % 4 {
            // Random garbage (no delimiter inside, one at the end: bursts land between frames).
            0 => {
                let n = rng.random_range(1..400);
                let mut b: Vec<u8> = (0..n).map(|_| rng.random_range(1..=255u8)).collect();
                b.push(0);
                b
            }
            // A drive frame with one bit flipped: bad CRC (or bad COBS).
            1 => {
                let mut b = good_drive.clone();
                let i = rng.random_range(0..b.len() - 1);
                let bit = 1u8 << rng.random_range(0..8);
                b[i] ^= bit;
                if b[i] == 0 {
                    b[i] = 0xFF;
                }
                b
            }
            // A drive frame with a valid CRC but a truncated payload: Rejected(Malformed).
            2 => raw_frame(protocol::ids::DRIVE, &[0x01, 0x02]),
            // An id the firmware does not accept: Rejected(UnknownMessage).
            _ => raw_frame(0x7777, &[]),
        };
        e.push(at(t, Action::RawBytes(bytes)));
    }
    e
}

fn encode_frame(msg: &ToFirmware, seq: u16) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME_LEN];
    msg.encode_frame(seq, Flags::NONE, &mut buf)
        .map(|n| buf[..n].to_vec())
        .unwrap_or_default()
}

fn raw_frame(msg_id: u16, payload: &[u8]) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME_LEN];
    protocol::frame::encode_raw(Header::new(msg_id, 0xBEEF, Flags::NONE), payload, &mut buf)
        .map(|n| buf[..n].to_vec())
        .unwrap_or_default()
}

// ---------------------------------------------------------------------------------------------
// Metrics (pure functions of the trace)

/// Mean and standard deviation of the true forward speed over `[from_us, to_us)`.
pub fn speed_stats(trace: &Trace, from_us: u64, to_us: u64) -> (f64, f64) {
    let v: Vec<f64> = trace
        .truth
        .samples
        .iter()
        .filter(|s| (from_us..to_us).contains(&s.stamp_us))
        .map(|s| f64::from(s.vx_mps))
        .collect();
    if v.is_empty() {
        return (0.0, 0.0);
    }
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n;
    (mean, var.sqrt())
}

/// The first time at or after `from_us` from which every command frame on the bus is all zeros
/// until the end of the run.
pub fn currents_zero_from(trace: &Trace, from_us: u64) -> Option<u64> {
    let mut since = None;
    for &(t, c) in trace.commands.iter().filter(|(t, _)| *t >= from_us) {
        if c == [0; 4] {
            since.get_or_insert(t);
        } else {
            since = None;
        }
    }
    since
}

/// The first time at or after `from_us` from which the robot's true speed stays below 1 mm/s
/// (and its yaw rate below 0.005 rad/s) until the end.
pub fn at_rest_from(trace: &Trace, from_us: u64) -> Option<u64> {
    let mut since = None;
    for s in trace.truth.samples.iter().filter(|s| s.stamp_us >= from_us) {
        if s.vx_mps.hypot(s.vy_mps) < 1e-3 && s.wz_radps.abs() < 5e-3 {
            since.get_or_insert(s.stamp_us);
        } else {
            since = None;
        }
    }
    since
}

/// The first status report at or after `from_us` satisfying `pred`.
pub fn first_status(
    trace: &Trace,
    from_us: u64,
    pred: impl Fn(&protocol::mcu::Status) -> bool,
) -> Option<(u64, protocol::mcu::Status)> {
    trace
        .statuses()
        .find(|(t, s)| *t >= from_us && pred(s))
        .map(|(t, s)| (t, *s))
}

/// Odometry against truth at the last odometry report: (position error m, yaw error rad, true
/// distance travelled m).
pub fn odometry_error(trace: &Trace) -> Option<(f64, f64, f64)> {
    let (_, odo) = trace.odometry().last()?;
    let truth = trace.truth.at(odo.stamp_us)?;
    let dx = f64::from(odo.x_m) - truth.x_m;
    let dy = f64::from(odo.y_m) - truth.y_m;
    let dyaw = f64::from(odo.yaw_rad) - truth.yaw_rad;
    Some((dx.hypot(dy), dyaw, truth.x_m.hypot(truth.y_m)))
}

fn ms(us: u64) -> f64 {
    us as f64 / 1000.0
}

fn wheel_of(trace: &Trace, esc_id: u8) -> Option<usize> {
    trace
        .statuses()
        .next()
        .and_then(|(_, s)| s.esc.iter().position(|e| e.esc_id == esc_id))
}

fn judge_cruise_phase(o: &mut Outcome, to_us: u64) {
    let (mean, std) = speed_stats(&o.trace, CRUISE_FROM_US, to_us);
    let ripple = if mean > 0.0 {
        std / mean
    } else {
        f64::INFINITY
    };
    o.figure_push("cruise mean true speed", mean, "m/s");
    o.figure_push("cruise velocity ripple (std/mean)", ripple * 100.0, "%");
    o.check(
        "cruise speed within 2 % of 0.2 m/s",
        (mean - f64::from(CRUISE_MPS)).abs() < 0.02 * f64::from(CRUISE_MPS),
        format!("{mean:.4} m/s"),
    );
    let cruising = first_status(&o.trace, CRUISE_FROM_US, |s| s.mode == DriveMode::Cruising);
    o.check(
        "firmware reports Cruising once the ramp is over",
        cruising.is_some_and(|(t, _)| t < CRUISE_FROM_US + 200_000),
        format!("{:?}", cruising.map(|(t, _)| ms(t))),
    );
    o.check(
        "velocity ripple under 1 %",
        ripple < 0.01,
        format!("{:.3} %", ripple * 100.0),
    );
}

fn judge_cruise(o: &mut Outcome) {
    judge_cruise_phase(o, 6_000_000);
    if let Some((pos, yaw, dist)) = odometry_error(&o.trace) {
        o.figure_push("distance travelled (truth)", dist, "m");
        o.figure_push("odometry position error at the end", pos * 1000.0, "mm");
        o.figure_push(
            "odometry error / distance",
            pos / dist.max(1e-9) * 100.0,
            "%",
        );
        o.figure_push("odometry yaw error at the end", yaw.to_degrees(), "deg");
        o.check(
            "odometry error under 2 % of the distance (wheel creep only)",
            pos < 0.02 * dist,
            format!("{:.1} mm over {dist:.3} m", pos * 1000.0),
        );
    } else {
        o.check("odometry reports received", false, "none");
    }
    let rest = at_rest_from(&o.trace, 6_000_000);
    o.check(
        "at rest after the stop",
        rest.is_some(),
        format!("{:?} ms", rest.map(ms)),
    );
    let odo_count = o
        .trace
        .odometry()
        .filter(|(t, _)| (1_000_000..2_000_000).contains(t))
        .count();
    o.figure_push("odometry reports per second", odo_count as f64, "1/s");
    o.check(
        "odometry at 100 Hz",
        (99..=101).contains(&odo_count),
        format!("{odo_count} in 1 s"),
    );
}

fn judge_heartbeat_loss(o: &mut Outcome) {
    let last_hb = o
        .trace
        .heartbeats_sent
        .iter()
        .copied()
        .filter(|t| *t < HEARTBEAT_OFF_US)
        .max()
        .unwrap_or(0);
    o.figure_push("last heartbeat", ms(last_hb), "ms");
    let lost = first_status(&o.trace, last_hb, |s| {
        s.interlocks.contains(Interlocks::HEARTBEAT_LOST)
    });
    let zero = currents_zero_from(&o.trace, last_hb);
    let rest = at_rest_from(&o.trace, last_hb);
    if let Some((t, _)) = lost {
        o.figure_push(
            "HEARTBEAT_LOST reported after last heartbeat",
            ms(t - last_hb),
            "ms",
        );
    }
    if let Some(t) = zero {
        o.figure_push(
            "all four currents zero after last heartbeat",
            ms(t - last_hb),
            "ms",
        );
    }
    if let Some(t) = rest {
        o.figure_push("robot at rest after last heartbeat", ms(t - last_hb), "ms");
    }
    o.check(
        "HEARTBEAT_LOST reported within timeout + 5 ms",
        lost.is_some_and(|(t, _)| t - last_hb <= 105_000),
        format!("{:?}", lost.map(|(t, _)| ms(t - last_hb))),
    );
    o.check(
        "all currents zero within 1.5 s",
        zero.is_some_and(|t| t - last_hb <= 1_500_000),
        format!("{:?}", zero.map(|t| ms(t - last_hb))),
    );
    o.check(
        "robot at rest within 1 s and stays",
        rest.is_some_and(|t| t - last_hb <= 1_000_000),
        format!("{:?}", rest.map(|t| ms(t - last_hb))),
    );
}

fn judge_esc_fault(
    o: &mut Outcome,
    esc_id: u8,
    fault: EscFaults,
    interlock: Interlocks,
    max_latency_us: u64,
    expect_rest: bool,
) {
    judge_cruise_phase(o, FAULT_AT_US);
    let wheel = wheel_of(&o.trace, esc_id);
    let latched = first_status(&o.trace, FAULT_AT_US, |s| {
        wheel.is_some_and(|w| s.esc[w].faults.contains(fault))
    });
    if let Some((t, s)) = &latched {
        o.figure_push("fault reported after its cause", ms(t - FAULT_AT_US), "ms");
        let named: Vec<u8> = s
            .esc
            .iter()
            .filter(|e| e.faults.contains(fault))
            .map(|e| e.esc_id)
            .collect();
        o.check(
            format!("fault names ESC {esc_id} and only it"),
            named == [esc_id],
            format!("faulted ESCs {named:?}"),
        );
        o.check(
            format!("interlock {interlock} set, mode Faulted"),
            s.interlocks.contains(interlock) && s.mode == DriveMode::Faulted,
            format!("{} / {}", s.interlocks, s.mode),
        );
    }
    o.check(
        format!("fault latched within {} ms", ms(max_latency_us)),
        latched.is_some_and(|(t, _)| t - FAULT_AT_US <= max_latency_us),
        format!("{:?}", latched.map(|(t, _)| ms(t - FAULT_AT_US))),
    );
    let zero = currents_zero_from(&o.trace, FAULT_AT_US);
    if let Some(t) = zero {
        o.figure_push(
            "zero currents on the bus after the cause",
            ms(t - FAULT_AT_US),
            "ms",
        );
    }
    o.check(
        "zero currents on the bus in the step the fault latches, and after",
        zero.zip(latched).is_some_and(|(z, (l, _))| z <= l),
        format!("zero from {:?} ms", zero.map(ms)),
    );
    if !expect_rest {
        return;
    }
    let rest = at_rest_from(&o.trace, FAULT_AT_US);
    o.check(
        "robot comes to rest (coasting) and stays",
        rest.is_some(),
        format!("{:?}", rest.map(|t| ms(t - FAULT_AT_US))),
    );
    if let Some(t) = rest {
        o.figure_push("robot at rest after the cause", ms(t - FAULT_AT_US), "ms");
    }
}

fn judge_esc_silent(o: &mut Outcome) {
    // The ESC's last frame goes out in the tick the fault is injected; the firmware's timeout
    // (10 ms) counts from that frame.
    judge_esc_fault(
        o,
        3,
        EscFaults::MISSING,
        Interlocks::ESC_FEEDBACK_MISSING,
        10_000,
        true,
    );
}

fn judge_stuck_current(o: &mut Outcome) {
    // over_current_time_us (3 ms) after the current first reads above the limit, plus a step.
    judge_esc_fault(
        o,
        1,
        EscFaults::OVER_CURRENT,
        Interlocks::ESC_OVER_CURRENT,
        5_000,
        false,
    );
    // Commanding zero cannot stop a stuck ESC; opening the motor contactor cuts its power.
    judge_contactor_opened(o, 1, EscFaults::OVER_CURRENT);
    let rest = at_rest_from(&o.trace, FAULT_AT_US);
    o.check(
        "robot at rest within 1.5 s of the fault and stays (no stuck wheel pushing)",
        rest.is_some_and(|t| t - FAULT_AT_US <= 1_500_000),
        format!("{:?}", rest.map(|t| ms(t - FAULT_AT_US))),
    );
    let (Some(a), Some(b)) = (
        o.trace.truth.at(FAULT_AT_US),
        o.trace.truth.at(FAULT_AT_US + 1_500_000),
    ) else {
        return;
    };
    o.figure_push(
        "travel in the 1.5 s after the fault",
        (b.x_m - a.x_m).hypot(b.y_m - a.y_m),
        "m",
    );
    o.figure_push(
        "yaw turned after the fault",
        (b.yaw_rad - a.yaw_rad).to_degrees(),
        "deg",
    );
    o.figure_push(
        "speed 1.5 s after the fault",
        f64::from(b.vx_mps.hypot(b.vy_mps)),
        "m/s",
    );
}

fn judge_over_temperature(o: &mut Outcome) {
    judge_esc_fault(
        o,
        2,
        EscFaults::OVER_TEMPERATURE,
        Interlocks::ESC_OVER_TEMPERATURE,
        2_000,
        true,
    );
    judge_contactor_opened(o, 2, EscFaults::OVER_TEMPERATURE);
    // With the contactor open the hot ESC has no power and is silent, so ClearFaults restarts it
    // as never seen; once power returns, its first report (still 95 degC) latches the fault again.
    let relatched = first_status(&o.trace, 3_500_000, |s| {
        wheel_of(&o.trace, 2).is_some_and(|w| s.esc[w].faults.contains(EscFaults::OVER_TEMPERATURE))
            && s.mode == DriveMode::Faulted
    });
    o.check(
        "after ClearFaults the hot motor latches the fault again",
        relatched.is_some(),
        format!("{:?}", relatched.map(|(t, _)| ms(t))),
    );
    let rejections: Vec<(u16, RejectReason)> = o
        .trace
        .rejections()
        .filter(|(t, _)| *t >= 3_500_000)
        .map(|(_, r)| (r.msg_id, r.reason))
        .collect();
    o.check(
        "Drive refused while the motor is hot",
        rejections.iter().any(|(id, _)| *id == protocol::ids::DRIVE),
        format!("{rejections:?}"),
    );
    let moved = o
        .trace
        .commands
        .iter()
        .any(|(t, c)| *t > 3_600_000 && *c != [0; 4]);
    o.check("no current after the refused drive", !moved, "");
}

/// The motor contactor opens (cutting the ESCs' power) no later than the step the fault of
/// `esc_id` is first reported latched.
fn judge_contactor_opened(o: &mut Outcome, esc_id: u8, fault: EscFaults) {
    let wheel = wheel_of(&o.trace, esc_id);
    let latched = first_status(&o.trace, FAULT_AT_US, |s| {
        wheel.is_some_and(|w| s.esc[w].faults.contains(fault))
    })
    .map(|(t, _)| t);
    let opened = o
        .trace
        .contactor
        .iter()
        .find(|(t, closed)| *t >= FAULT_AT_US && !closed)
        .map(|(t, _)| *t);
    if let Some(t) = opened {
        o.figure_push(
            "motor contactor opened after the cause",
            ms(t - FAULT_AT_US),
            "ms",
        );
    }
    o.check(
        "motor contactor opened by the time the fault is reported",
        opened.zip(latched).is_some_and(|(c, l)| c <= l),
        format!(
            "opened {:?} ms, reported {:?} ms",
            opened.map(ms),
            latched.map(ms)
        ),
    );
}

fn judge_battery_low(o: &mut Outcome) {
    judge_cruise_phase(o, SAG_AT_US);
    let healthy = first_status(&o.trace, CRUISE_FROM_US, |s| s.battery_mv > 0);
    if let Some((_, s)) = healthy {
        o.figure_push(
            "battery reported at cruise",
            f64::from(s.battery_mv) / 1e3,
            "V",
        );
    }
    let early = first_status(&o.trace, 0, |s| {
        s.interlocks.contains(Interlocks::BATTERY_LOW)
    })
    .filter(|(t, _)| *t < FLAT_AT_US);
    o.check(
        "a 150 ms sag to 16 V does not trip BATTERY_LOW",
        early.is_none(),
        format!("{:?}", early.map(|(t, _)| ms(t))),
    );
    let low = first_status(&o.trace, FLAT_AT_US, |s| {
        s.interlocks.contains(Interlocks::BATTERY_LOW)
    });
    if let Some((t, s)) = low {
        o.figure_push(
            "BATTERY_LOW reported after the drop",
            ms(t - FLAT_AT_US),
            "ms",
        );
        o.figure_push(
            "battery reported with BATTERY_LOW",
            f64::from(s.battery_mv) / 1e3,
            "V",
        );
    }
    o.check(
        "BATTERY_LOW reported within 2.5 s of the drop",
        low.is_some_and(|(t, _)| t - FLAT_AT_US <= 2_500_000),
        format!("{:?}", low.map(|(t, _)| ms(t - FLAT_AT_US))),
    );
    let from = low.map_or(FLAT_AT_US, |(t, _)| t);
    let rest = at_rest_from(&o.trace, from);
    if let Some(t) = rest {
        o.figure_push("robot at rest after BATTERY_LOW", ms(t - from), "ms");
    }
    o.check(
        "robot at rest within 1 s of BATTERY_LOW and stays",
        rest.is_some_and(|t| t - from <= 1_000_000),
        format!("{:?}", rest.map(|t| ms(t - from))),
    );
    let refused = o
        .trace
        .rejections()
        .find(|(t, r)| *t >= RETRY_AT_US && r.msg_id == protocol::ids::DRIVE)
        .map(|(_, r)| (r.reason, r.field.as_str().to_owned()));
    o.check(
        "a new drive is refused naming BATTERY_LOW",
        refused
            .as_ref()
            .is_some_and(|(r, f)| *r == RejectReason::Interlocked && f.contains("BATTERY_LOW")),
        format!("{refused:?}"),
    );
    let moved = o
        .trace
        .commands
        .iter()
        .any(|(t, c)| *t > RETRY_AT_US && *c != [0; 4]);
    o.check("no current after the refused drive", !moved, "");
}

fn judge_bus_off(o: &mut Outcome) {
    judge_cruise_phase(o, FAULT_AT_US);
    let reported = first_status(&o.trace, FAULT_AT_US, |s| {
        s.interlocks.contains(Interlocks::CAN_BUS_OFF)
    });
    o.check(
        "CAN_BUS_OFF reported, bus-off counted once",
        reported.is_some_and(|(_, s)| s.bus_off_count == 1 && s.mode == DriveMode::Faulted),
        format!(
            "{:?}",
            reported.map(|(t, s)| (ms(t), s.bus_off_count, s.mode))
        ),
    );
    // The ESCs hold their last command while the firmware cannot send: how long?
    let first_zero = o
        .trace
        .commands
        .iter()
        .find(|(t, c)| *t >= FAULT_AT_US && *c == [0; 4])
        .map(|(t, _)| *t);
    if let Some(t) = first_zero {
        o.figure_push("ESCs held the last command for", ms(t - FAULT_AT_US), "ms");
    }
    o.check(
        "zero currents on the bus right after recovery (disturbance + 1.4 ms + 1 step)",
        first_zero.is_some_and(|t| t - FAULT_AT_US <= BUS_OFF_US + 3_000),
        format!("{:?}", first_zero.map(|t| ms(t - FAULT_AT_US))),
    );
    o.check(
        "robot at rest before the faults are cleared",
        at_rest_window(&o.trace, FAULT_AT_US, CLEAR_AT_US),
        "",
    );
    let cleared = o
        .trace
        .rejections()
        .all(|(_, r)| r.msg_id != protocol::ids::CLEAR_FAULTS && r.msg_id != protocol::ids::DRIVE);
    o.check(
        "ClearFaults and the new Drive accepted after recovery",
        cleared,
        "",
    );
    let (mean, _) = speed_stats(&o.trace, REDRIVE_AT_US + 1_000_000, 7_000_000);
    o.figure_push("speed after recovery and a new drive", mean, "m/s");
    o.check(
        "driving again at 0.2 m/s after recovery",
        (mean - f64::from(CRUISE_MPS)).abs() < 0.004,
        format!("{mean:.4} m/s"),
    );
}

/// Whether the robot is at rest at the end of `[from_us, to_us)`.
fn at_rest_window(trace: &Trace, from_us: u64, to_us: u64) -> bool {
    let window: Vec<_> = trace
        .truth
        .samples
        .iter()
        .filter(|s| (from_us..to_us).contains(&s.stamp_us))
        .collect();
    window
        .last()
        .is_some_and(|s| s.vx_mps.hypot(s.vy_mps) < 1e-3)
}

fn judge_flood(o: &mut Outcome) {
    let moved_idle = o
        .trace
        .commands
        .iter()
        .any(|(t, c)| *t < FLOOD_DRIVE_US && *c != [0; 4]);
    let x_idle = o
        .trace
        .truth
        .at(FLOOD_DRIVE_US)
        .map_or(f64::INFINITY, |s| s.x_m.hypot(s.y_m));
    o.check(
        "nothing moves during the flood before the drive command",
        !moved_idle && x_idle < 1e-4,
        format!(
            "nonzero current: {moved_idle}, displacement {:.3} mm",
            x_idle * 1000.0
        ),
    );
    let last = o.trace.statuses().last().map(|(_, s)| *s);
    let link_errors = last.map_or(0, |s| s.link_errors);
    let rejected = last.map_or(0, |s| s.rejected_count);
    o.figure_push("link errors reported", f64::from(link_errors), "frames");
    o.figure_push("rejections reported", f64::from(rejected), "frames");
    o.check(
        "link errors counted and reported",
        link_errors > 100,
        format!("{link_errors}"),
    );
    let malformed = o
        .trace
        .rejections()
        .filter(|(_, r)| r.reason == RejectReason::Malformed)
        .count();
    let unknown = o
        .trace
        .rejections()
        .filter(|(_, r)| r.reason == RejectReason::UnknownMessage)
        .count();
    o.check(
        "malformed and unknown frames rejected by name",
        malformed > 100 && unknown > 100,
        format!("{malformed} Malformed, {unknown} UnknownMessage"),
    );
    let hb_lost = first_status(&o.trace, FLOOD_DRIVE_US + 100_000, |s| {
        s.interlocks.contains(Interlocks::HEARTBEAT_LOST)
    });
    o.check(
        "heartbeats get through the flood (no HEARTBEAT_LOST while cruising)",
        hb_lost.is_none(),
        format!("{:?}", hb_lost.map(|(t, _)| ms(t))),
    );
    let (mean, std) = speed_stats(&o.trace, 2_000_000, 3_400_000);
    o.figure_push("cruise speed under the flood", mean, "m/s");
    o.check(
        "cruise at 0.2 m/s with ripple under 1 % under the flood",
        (mean - f64::from(CRUISE_MPS)).abs() < 0.004 && std / mean < 0.01,
        format!("{mean:.4} m/s, ripple {:.3} %", std / mean * 100.0),
    );
}
