//! The measurement run state machine (pure: time and observations in, actions out).
//!
//! ```text
//!  Idle --start--> Checks --sensors, firmware, interlocks ok--> Driving --distance reached--> Stopping
//!                    |                                            |                            |
//!                    +--timeout: Failed                           +--abort / handheld silent--> Stopping (then Aborted)
//!                                                                                              |
//!  Idle <-- Done <-- Processing <----------------------- firmware at rest ---------------------+
//! ```
//!
//! - A start while a run is active is refused (`Busy`); bad parameters are refused naming the field.
//! - An abort, or the handheld going silent while the robot moves (configurable), stops the robot
//!   *first*: the [`Action::Motion`] stop is the first action returned.
//! - Progress goes out at a fixed period (2 Hz by default) and on every phase change.
//! - The shell executes the actions (MCU intent, recorder, pipeline, radio) and feeds back
//!   [`Observations`] on every [`RunMachine::tick`] and the processing outcome with
//!   [`RunMachine::processing_finished`].

use protocol::common::LogLevel;
use protocol::mcu::Interlocks;
use protocol::radio::{Phase, Progress, RefuseReason, StartMeasurement};

use link::mcu::MotionIntent;

/// Period of the handheld's heartbeats on the radio, us (the radio link core's).
pub const HANDHELD_BEAT_US: u64 = link::reliable::LinkConfig::RADIO.heartbeat_period_us;

/// Limits and timeouts of a run. All times in microseconds.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields, default)]
pub struct RunConfig {
    /// Largest accepted drive speed, m/s.
    pub max_speed_mps: f32,
    /// Largest accepted drive distance, m.
    pub max_distance_m: f32,
    /// How long the pre-run checks may wait for sensors and firmware, us.
    pub checks_timeout_us: u64,
    /// How long the robot may take to come to rest after a stop, us.
    pub stop_timeout_us: u64,
    /// Stop the robot when this many of the handheld's heartbeats in a row are missing while it
    /// moves (0: never). The handheld beats every 200 ms ([`HANDHELD_BEAT_US`]); the default 12
    /// (2.4 s) rides out a radio that loses 30 % of the frames and corrupts 10 %: twelve lost in a
    /// row there has p = 0.37^12 per beat, at most one false stop in 500 one-minute runs, fewer
    /// because every frame of the session counts as a beat.
    pub handheld_missed_beats: u32,
    /// Progress period, us (2 Hz).
    pub progress_period_us: u64,
    /// Extra time over `distance / speed` before a drive counts as stuck, us.
    pub drive_margin_us: u64,
    /// The checks refuse to drive below this battery voltage, mV (0: no check). Default 21 V,
    /// 3.5 V per cell of a 6S pack: a run of 15 m and back needs a pack above its knee. The
    /// firmware's own cutoff (19.8 V, filtered) stops a robot whose pack sags below it mid-run.
    /// A firmware that does not measure the battery reports 0, and the check is skipped.
    pub min_battery_mv: u16,
    /// The robot stands still, recorded, for at least this long before it drives (the checks
    /// last at least this long) and, without moving, after it has come to rest (before
    /// processing), us: every
    /// run's recording begins and ends with a parked capture, between which `passangle wheels`
    /// measures the wheels' distance scale against the walls (docs/operator/run.md,
    /// "Calibrating the wheels' distance"). Default 1 s (ten lidar frames); below
    /// `checks-timeout-us`.
    pub parked_us: u64,
}

impl Default for RunConfig {
    fn default() -> Self {
        Self {
            max_speed_mps: 0.5,
            max_distance_m: 15.0,
            checks_timeout_us: 5_000_000,
            stop_timeout_us: 5_000_000,
            handheld_missed_beats: 12,
            progress_period_us: 500_000,
            drive_margin_us: 10_000_000,
            min_battery_mv: 21_000,
            parked_us: 1_000_000,
        }
    }
}

/// What the shell observed since the last tick (independent health flags, hence the bools).
#[allow(clippy::struct_excessive_bools)]
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Observations {
    /// Lidar packets arrive.
    pub lidar_ok: bool,
    /// Depth frames arrive.
    pub camera_ok: bool,
    /// The firmware said hello and reports status.
    pub firmware_ok: bool,
    /// Interlocks the firmware reports.
    pub interlocks: Interlocks,
    /// The firmware reports the wheels at rest.
    pub at_rest: bool,
    /// Latest odometry position (odometry frame), m.
    pub odometry_xy_m: Option<[f32; 2]>,
    /// Microseconds since the handheld was last heard (`None`: never).
    pub handheld_silent_us: Option<u64>,
    /// Lidar frames recorded in this run.
    pub lidar_frames: u32,
    /// Battery voltage the firmware reports, mV (0: not measured).
    pub battery_mv: u16,
}

/// How a run ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Outcome {
    /// Measured; the result is ready.
    Completed,
    /// Stopped by the operator or by a lost handheld.
    Aborted(String),
    /// Failed (checks, stop timeout, processing error).
    Failed(String),
}

/// What the shell must do, in order.
#[derive(Debug, Clone, PartialEq)]
pub enum Action {
    /// Refuse a start.
    Refuse {
        /// Seq of the start.
        seq: u16,
        /// Why.
        reason: RefuseReason,
        /// Detail (field or check).
        detail: String,
    },
    /// Open the run's recording.
    BeginRecording {
        /// The run.
        run_id: u32,
        /// Its parameters.
        params: StartMeasurement,
    },
    /// Change the MCU session's intent.
    Motion(MotionIntent),
    /// Build the cloud and compute the angles from the recorded run.
    StartProcessing {
        /// The run.
        run_id: u32,
        /// Distance actually driven, m.
        travelled_m: f32,
        /// The drive ended before the requested distance.
        short_run: bool,
    },
    /// Stop processing (an abort during processing).
    CancelProcessing {
        /// The run.
        run_id: u32,
    },
    /// Close the recording with this outcome.
    FinishRecording {
        /// The run.
        run_id: u32,
        /// Outcome.
        outcome: Outcome,
    },
    /// Send progress to the handheld.
    Progress(Progress),
    /// Log locally and to the handheld.
    Log {
        /// Severity.
        level: LogLevel,
        /// Text.
        text: String,
    },
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum AfterStop {
    Process { short_run: bool },
    Abort,
}

#[derive(Debug, Clone, PartialEq)]
enum State {
    Idle,
    Checks {
        since_us: u64,
    },
    Driving {
        since_us: u64,
        start_xy_m: Option<[f32; 2]>,
    },
    Stopping {
        since_us: u64,
        then: AfterStop,
        reason: String,
        /// Since when the robot has been at rest (`None`: not yet).
        rest_since_us: Option<u64>,
    },
    Processing,
}

#[derive(Debug, Clone)]
struct Active {
    run_id: u32,
    params: StartMeasurement,
    travelled_m: f32,
}

/// The run state machine. See the module docs.
#[derive(Debug, Clone)]
pub struct RunMachine {
    config: RunConfig,
    state: State,
    active: Option<Active>,
    next_run_id: u32,
    last_run_id: u32,
    last_phase: Phase,
    next_progress_us: u64,
    lidar_frames: u32,
}

/// Interlocks a new drive command clears by itself (a stop or a lost heartbeat just asks for a new
/// start); every other one blocks the checks.
const CLEARED_BY_DRIVE: Interlocks = Interlocks::STOP_REQUESTED.union(Interlocks::HEARTBEAT_LOST);

impl RunMachine {
    /// A machine whose next run gets `next_run_id` (the recorder's next free number).
    pub fn new(config: RunConfig, next_run_id: u32) -> Self {
        Self {
            config,
            state: State::Idle,
            active: None,
            next_run_id: next_run_id.max(1),
            last_run_id: 0,
            last_phase: Phase::Idle,
            next_progress_us: 0,
            lidar_frames: 0,
        }
    }

    /// The current phase (the last run's final phase while idle after it, until the next start).
    pub fn phase(&self) -> Phase {
        match self.state {
            State::Idle => self.last_phase,
            State::Checks { .. } => Phase::Checks,
            State::Driving { .. } => Phase::Driving,
            State::Stopping { .. } => Phase::Stopping,
            State::Processing => Phase::Processing,
        }
    }

    /// Whether a run is active.
    pub fn is_active(&self) -> bool {
        self.state != State::Idle
    }

    /// The active or last run id (0: none yet).
    pub fn run_id(&self) -> u32 {
        self.active.as_ref().map_or(self.last_run_id, |a| a.run_id)
    }

    /// Whether the robot may be moving under this machine's command.
    pub fn robot_may_move(&self) -> bool {
        matches!(self.state, State::Driving { .. } | State::Stopping { .. })
    }

    /// An authenticated start arrived.
    pub fn start(&mut self, now_us: u64, params: StartMeasurement, seq: u16) -> Vec<Action> {
        if self.is_active() {
            return vec![Action::Refuse {
                seq,
                reason: RefuseReason::Busy,
                detail: format!("run {} is active", self.run_id()),
            }];
        }
        if let Err(detail) = self.validate(&params) {
            return vec![Action::Refuse {
                seq,
                reason: RefuseReason::InvalidParameter,
                detail,
            }];
        }
        let run_id = self.next_run_id;
        self.next_run_id = self.next_run_id.wrapping_add(1).max(1);
        self.active = Some(Active {
            run_id,
            params: params.clone(),
            travelled_m: 0.0,
        });
        self.lidar_frames = 0;
        self.state = State::Checks { since_us: now_us };
        let mut out = vec![
            Action::BeginRecording { run_id, params },
            Action::Log {
                level: LogLevel::Info,
                text: format!("run {run_id}: checks"),
            },
        ];
        self.progress_now(now_us, &mut out);
        out
    }

    fn validate(&self, p: &StartMeasurement) -> Result<(), String> {
        let c = &self.config;
        if !(p.speed_mps.is_finite() && p.speed_mps > 0.0 && p.speed_mps <= c.max_speed_mps) {
            return Err(format!(
                "speed_mps {} not in (0, {}]",
                p.speed_mps, c.max_speed_mps
            ));
        }
        if !(p.distance_m.is_finite() && p.distance_m > 0.0 && p.distance_m <= c.max_distance_m) {
            return Err(format!(
                "distance_m {} not in (0, {}]",
                p.distance_m, c.max_distance_m
            ));
        }
        Ok(())
    }

    /// An abort arrived (`run_id` 0: whatever runs). Stops the robot first.
    pub fn abort(&mut self, now_us: u64, run_id: u32) -> Vec<Action> {
        let Some(active) = &self.active else {
            // Nothing runs: still make sure the robot stands still.
            return vec![Action::Motion(MotionIntent::Stop)];
        };
        if run_id != 0 && run_id != active.run_id {
            return vec![Action::Motion(MotionIntent::Stop)];
        }
        self.abort_with(now_us, "aborted by the operator".to_owned())
    }

    /// The firmware refused a drive command of the active run (`why`: its reason and field, as
    /// the firmware sent them). Stops the robot and ends the run as aborted, naming the refusal,
    /// so that it is not mistaken for the operator's abort.
    pub fn drive_refused(&mut self, now_us: u64, why: &str) -> Vec<Action> {
        self.abort_with(now_us, format!("the firmware refused to drive: {why}"))
    }

    fn abort_with(&mut self, now_us: u64, reason: String) -> Vec<Action> {
        let mut out = vec![Action::Motion(MotionIntent::Stop)];
        match self.state.clone() {
            State::Idle => {}
            State::Checks { .. } => self.end(now_us, Outcome::Aborted(reason), &mut out),
            State::Driving { .. } => {
                self.state = State::Stopping {
                    since_us: now_us,
                    then: AfterStop::Abort,
                    reason,
                    rest_since_us: None,
                };
                self.progress_now(now_us, &mut out);
            }
            State::Stopping {
                since_us,
                rest_since_us,
                ..
            } => {
                self.state = State::Stopping {
                    since_us,
                    then: AfterStop::Abort,
                    reason,
                    rest_since_us,
                };
            }
            State::Processing => {
                let run_id = self.run_id();
                out.push(Action::CancelProcessing { run_id });
                self.end(now_us, Outcome::Aborted(reason), &mut out);
            }
        }
        out
    }

    /// Processing of the active run ended (`Err`: why it failed).
    pub fn processing_finished(
        &mut self,
        now_us: u64,
        run_id: u32,
        outcome: Result<(), String>,
    ) -> Vec<Action> {
        let mut out = Vec::new();
        if self.state != State::Processing || self.run_id() != run_id {
            return out;
        }
        let outcome = match outcome {
            Ok(()) => Outcome::Completed,
            Err(e) => Outcome::Failed(format!("processing failed: {e}")),
        };
        self.end(now_us, outcome, &mut out);
        out
    }

    /// Time passes: checks, distance, timeouts, handheld silence, progress.
    pub fn tick(&mut self, now_us: u64, obs: &Observations) -> Vec<Action> {
        let mut out = Vec::new();
        self.lidar_frames = obs.lidar_frames;
        let c = self.config;
        if self.robot_may_move() || matches!(self.state, State::Checks { .. }) {
            let silent = obs.handheld_silent_us.unwrap_or(u64::MAX);
            let timeout_us = u64::from(c.handheld_missed_beats) * HANDHELD_BEAT_US;
            if timeout_us > 0
                && silent > timeout_us
                && !matches!(
                    self.state,
                    State::Stopping {
                        then: AfterStop::Abort,
                        ..
                    }
                )
            {
                out.extend(self.abort_with(
                    now_us,
                    format!(
                        "handheld silent for more than {} ms ({} heartbeats missed)",
                        timeout_us / 1000,
                        c.handheld_missed_beats
                    ),
                ));
                return out;
            }
        }
        match self.state.clone() {
            State::Idle | State::Processing => {}
            State::Checks { since_us } => self.tick_checks(now_us, since_us, obs, &mut out),
            State::Driving {
                since_us,
                start_xy_m,
            } => self.tick_driving(now_us, since_us, start_xy_m, obs, &mut out),
            State::Stopping {
                since_us,
                then,
                reason,
                rest_since_us,
            } => {
                // Since when the robot has been at rest; moving again starts it over.
                let rest_since = obs.at_rest.then(|| rest_since_us.unwrap_or(now_us));
                if let State::Stopping { rest_since_us, .. } = &mut self.state {
                    *rest_since_us = rest_since;
                }
                match rest_since {
                    // A run to process stays recorded while parked for `parked-us`; an aborted
                    // one ends at once.
                    Some(rest_us)
                        if now_us.saturating_sub(rest_us) >= c.parked_us
                            || matches!(then, AfterStop::Abort) =>
                    {
                        self.after_stop(now_us, then, reason, &mut out);
                    }
                    None if now_us.saturating_sub(since_us) > c.stop_timeout_us => {
                        out.insert(0, Action::Motion(MotionIntent::StopNow));
                        let reason = format!(
                            "robot not at rest {} ms after stop; {reason}",
                            c.stop_timeout_us / 1000
                        );
                        self.end(now_us, Outcome::Failed(reason), &mut out);
                    }
                    _ => {}
                }
            }
        }
        if self.is_active() && now_us >= self.next_progress_us {
            self.progress_now(now_us, &mut out);
        }
        out
    }

    fn tick_checks(
        &mut self,
        now_us: u64,
        since_us: u64,
        obs: &Observations,
        out: &mut Vec<Action>,
    ) {
        let mut blocking = obs.interlocks;
        blocking.remove(CLEARED_BY_DRIVE);
        let mut missing = Vec::new();
        if !obs.lidar_ok {
            missing.push("lidar".to_owned());
        }
        if !obs.camera_ok {
            missing.push("camera".to_owned());
        }
        if !obs.firmware_ok {
            missing.push("firmware".to_owned());
        } else if !blocking.is_empty() {
            missing.push(format!("interlocks {blocking}"));
        }
        let min_mv = self.config.min_battery_mv;
        if obs.firmware_ok && obs.battery_mv != 0 && obs.battery_mv < min_mv {
            missing.push(format!(
                "battery {:.1} V below {:.1} V",
                f64::from(obs.battery_mv) / 1e3,
                f64::from(min_mv) / 1e3
            ));
        }
        if missing.is_empty() {
            // Parked and recorded for `parked-us` first.
            if now_us.saturating_sub(since_us) < self.config.parked_us {
                return;
            }
            let Some(a) = &self.active else { return };
            let vx_mps = a.params.speed_mps;
            self.state = State::Driving {
                since_us: now_us,
                start_xy_m: obs.odometry_xy_m,
            };
            out.push(Action::Motion(MotionIntent::Drive { vx_mps }));
            out.push(Action::Log {
                level: LogLevel::Info,
                text: format!("run {}: driving at {vx_mps} m/s", a.run_id),
            });
            self.progress_now(now_us, out);
        } else if now_us.saturating_sub(since_us) > self.config.checks_timeout_us {
            let reason = format!("checks failed: {}", missing.join(", "));
            self.end(now_us, Outcome::Failed(reason), out);
        }
    }

    fn tick_driving(
        &mut self,
        now_us: u64,
        since_us: u64,
        start_xy_m: Option<[f32; 2]>,
        obs: &Observations,
        out: &mut Vec<Action>,
    ) {
        let start = start_xy_m.or(obs.odometry_xy_m);
        if start_xy_m.is_none() && start.is_some() {
            self.state = State::Driving {
                since_us,
                start_xy_m: start,
            };
        }
        let travelled = match (start, obs.odometry_xy_m) {
            (Some(a), Some(b)) => (b[0] - a[0]).hypot(b[1] - a[1]),
            _ => 0.0,
        };
        let Some(active) = &mut self.active else {
            return;
        };
        active.travelled_m = travelled;
        let p = &active.params;
        let budget_us =
            (f64::from(p.distance_m / p.speed_mps) * 1e6) as u64 + self.config.drive_margin_us;
        let (then, reason) = if travelled >= p.distance_m {
            (
                AfterStop::Process { short_run: false },
                "distance reached".to_owned(),
            )
        } else if now_us.saturating_sub(since_us) > budget_us {
            (
                AfterStop::Process { short_run: true },
                format!(
                    "drive took too long: {travelled:.2} m of {} m",
                    p.distance_m
                ),
            )
        } else {
            return;
        };
        out.push(Action::Motion(MotionIntent::Stop));
        out.push(Action::Log {
            level: LogLevel::Info,
            text: format!("run {}: stopping, {reason}", active.run_id),
        });
        self.state = State::Stopping {
            since_us: now_us,
            then,
            reason,
            rest_since_us: None,
        };
        self.progress_now(now_us, out);
    }

    fn after_stop(&mut self, now_us: u64, then: AfterStop, reason: String, out: &mut Vec<Action>) {
        match then {
            AfterStop::Process { short_run } => {
                let (run_id, travelled_m) = self
                    .active
                    .as_ref()
                    .map_or((0, 0.0), |a| (a.run_id, a.travelled_m));
                self.state = State::Processing;
                out.push(Action::StartProcessing {
                    run_id,
                    travelled_m,
                    short_run,
                });
                self.progress_now(now_us, out);
            }
            AfterStop::Abort => self.end(now_us, Outcome::Aborted(reason), out),
        }
    }

    fn end(&mut self, now_us: u64, outcome: Outcome, out: &mut Vec<Action>) {
        let Some(active) = self.active.take() else {
            return;
        };
        let (phase, level, text) = match &outcome {
            Outcome::Completed => (Phase::Done, LogLevel::Info, "done".to_owned()),
            Outcome::Aborted(r) => (Phase::Aborted, LogLevel::Warn, format!("aborted: {r}")),
            Outcome::Failed(r) => (Phase::Failed, LogLevel::Error, format!("failed: {r}")),
        };
        out.push(Action::Log {
            level,
            text: format!("run {}: {text}", active.run_id),
        });
        out.push(Action::FinishRecording {
            run_id: active.run_id,
            outcome,
        });
        out.push(Action::Progress(Progress {
            run_id: active.run_id,
            phase,
            percent: 100,
            travelled_m: active.travelled_m,
            lidar_frames: self.lidar_frames,
        }));
        self.last_run_id = active.run_id;
        self.last_phase = phase;
        self.state = State::Idle;
        self.next_progress_us = now_us + self.config.progress_period_us;
    }

    fn progress_now(&mut self, now_us: u64, out: &mut Vec<Action>) {
        let Some(a) = &self.active else { return };
        let percent = match self.state {
            State::Driving { .. } => {
                (a.travelled_m / a.params.distance_m * 100.0).clamp(0.0, 100.0) as u8
            }
            State::Stopping { .. } | State::Processing => 100,
            _ => 0,
        };
        out.push(Action::Progress(Progress {
            run_id: a.run_id,
            phase: self.phase(),
            percent,
            travelled_m: a.travelled_m,
            lidar_frames: self.lidar_frames,
        }));
        self.next_progress_us = now_us + self.config.progress_period_us;
    }
}

#[cfg(test)]
mod tests {
    use protocol::bounded::Text;
    use protocol::radio::Zone;

    use super::*;

    fn params(speed: f32, distance: f32) -> StartMeasurement {
        StartMeasurement {
            vehicle_id: Text::truncated("V"),
            speed_mps: speed,
            distance_m: distance,
            zone: Zone::Tyre,
            lab: protocol::radio::LabRef::NONE,
        }
    }

    fn healthy() -> Observations {
        Observations {
            lidar_ok: true,
            camera_ok: true,
            firmware_ok: true,
            interlocks: Interlocks::STOP_REQUESTED,
            at_rest: true,
            odometry_xy_m: Some([1.0, 0.0]),
            handheld_silent_us: Some(100_000),
            lidar_frames: 0,
            battery_mv: 23_900,
        }
    }

    /// The default limits without the parked captures, so that a test drives on its first tick.
    fn unparked() -> RunConfig {
        RunConfig {
            parked_us: 0,
            ..RunConfig::default()
        }
    }

    #[test]
    fn the_robot_stays_parked_and_recorded_before_the_drive_and_after_the_stop() {
        let mut m = RunMachine::new(RunConfig::default(), 3);
        m.start(0, params(0.2, 0.5), 1);
        let mut obs = healthy();
        m.tick(500_000, &obs);
        assert_eq!(m.phase(), Phase::Checks, "parked for 1 s first");
        assert!(!m.robot_may_move());
        let acts = m.tick(1_000_000, &obs);
        assert_eq!(m.phase(), Phase::Driving);
        assert!(motions(&acts).contains(&MotionIntent::Drive { vx_mps: 0.2 }));
        obs.at_rest = false;
        obs.odometry_xy_m = Some([1.6, 0.0]);
        m.tick(3_600_000, &obs);
        assert_eq!(m.phase(), Phase::Stopping);
        obs.at_rest = true;
        for now in [3_700_000, 4_200_000, 4_690_000] {
            let acts = m.tick(now, &obs);
            assert_eq!(m.phase(), Phase::Stopping, "at {now} us: {acts:?}");
        }
        // Nudged at 4.69 s: the parked second starts over when it is at rest again.
        obs.at_rest = false;
        m.tick(4_695_000, &obs);
        obs.at_rest = true;
        m.tick(4_700_000, &obs);
        m.tick(5_690_000, &obs);
        assert_eq!(m.phase(), Phase::Stopping);
        // At rest since 4.7 s: processing starts 1 s later, not before.
        let acts = m.tick(5_700_000, &obs);
        assert!(
            acts.iter()
                .any(|a| matches!(a, Action::StartProcessing { run_id: 3, .. })),
            "{acts:?}"
        );
    }

    fn motions(actions: &[Action]) -> Vec<MotionIntent> {
        actions
            .iter()
            .filter_map(|a| match a {
                Action::Motion(m) => Some(*m),
                _ => None,
            })
            .collect()
    }

    fn phases(actions: &[Action]) -> Vec<Phase> {
        actions
            .iter()
            .filter_map(|a| match a {
                Action::Progress(p) => Some(p.phase),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn full_run_goes_through_every_phase_with_progress_at_2_hz() {
        let mut m = RunMachine::new(RunConfig::default(), 7);
        let mut all = m.start(0, params(0.2, 1.0), 1);
        assert!(matches!(all[0], Action::BeginRecording { run_id: 7, .. }));
        let mut obs = healthy();
        let mut progress_times = Vec::new();
        let mut now = 0;
        while now < 20_000_000 && m.is_active() {
            now += 10_000;
            if m.robot_may_move() && m.phase() == Phase::Driving {
                obs.at_rest = false;
                obs.odometry_xy_m = Some([1.0 + 0.2 * (now as f32 * 1e-6 - 0.01), 0.0]);
            }
            if m.phase() == Phase::Stopping {
                obs.at_rest = true;
            }
            let acts = m.tick(now, &obs);
            if acts.iter().any(|a| matches!(a, Action::Progress(_))) {
                progress_times.push(now);
            }
            if let Some(Action::StartProcessing {
                run_id,
                short_run,
                travelled_m,
            }) = acts
                .iter()
                .find(|a| matches!(a, Action::StartProcessing { .. }))
            {
                assert_eq!(*run_id, 7);
                assert!(!short_run);
                assert!(*travelled_m >= 1.0);
                all.extend(acts.clone());
                all.extend(m.processing_finished(now, 7, Ok(())));
                break;
            }
            all.extend(acts);
        }
        assert_eq!(
            motions(&all),
            vec![MotionIntent::Drive { vx_mps: 0.2 }, MotionIntent::Stop]
        );
        let ph = phases(&all);
        for want in [
            Phase::Checks,
            Phase::Driving,
            Phase::Stopping,
            Phase::Processing,
            Phase::Done,
        ] {
            assert!(ph.contains(&want), "{want:?} in {ph:?}");
        }
        let gaps: Vec<u64> = progress_times.windows(2).map(|w| w[1] - w[0]).collect();
        assert!(gaps.iter().all(|&g| g <= 500_000), "{gaps:?}");
        assert!(all.iter().any(|a| matches!(
            a,
            Action::FinishRecording {
                run_id: 7,
                outcome: Outcome::Completed
            }
        )));
        assert!(!m.is_active());
        assert_eq!(m.phase(), Phase::Done);
    }

    #[test]
    fn busy_and_bad_parameters_are_refused_naming_the_field() {
        let mut m = RunMachine::new(unparked(), 1);
        let a = m.start(0, params(2.0, 1.0), 5);
        assert!(
            matches!(&a[0], Action::Refuse { seq: 5, reason: RefuseReason::InvalidParameter, detail } if detail.contains("speed_mps"))
        );
        let a = m.start(0, params(0.2, f32::NAN), 6);
        assert!(
            matches!(&a[0], Action::Refuse { reason: RefuseReason::InvalidParameter, detail, .. } if detail.contains("distance_m"))
        );
        assert!(!m.is_active());
        m.start(0, params(0.2, 1.0), 7);
        let a = m.start(10, params(0.2, 1.0), 8);
        assert!(matches!(
            &a[0],
            Action::Refuse {
                seq: 8,
                reason: RefuseReason::Busy,
                ..
            }
        ));
    }

    /// A machine driving its run since 10 ms, and its observations (robot moving).
    fn driving() -> (RunMachine, Observations) {
        let mut m = RunMachine::new(unparked(), 1);
        m.start(0, params(0.2, 5.0), 1);
        let mut obs = healthy();
        m.tick(10_000, &obs);
        assert_eq!(m.phase(), Phase::Driving);
        obs.at_rest = false;
        (m, obs)
    }

    #[test]
    fn abort_while_driving_stops_first_then_ends_aborted() {
        let (mut m, mut obs) = driving();
        let a = m.abort(20_000, 0);
        assert_eq!(
            a[0],
            Action::Motion(MotionIntent::Stop),
            "stop is the first action"
        );
        assert_eq!(m.phase(), Phase::Stopping);
        assert!(
            m.tick(30_000, &obs)
                .iter()
                .all(|a| !matches!(a, Action::FinishRecording { .. }))
        );
        obs.at_rest = true;
        let a = m.tick(40_000, &obs);
        assert!(a.iter().any(|a| matches!(
            a,
            Action::FinishRecording {
                outcome: Outcome::Aborted(_),
                ..
            }
        )));
        assert_eq!(m.phase(), Phase::Aborted);
    }

    #[test]
    fn a_refused_drive_stops_and_names_the_firmware_not_the_operator() {
        let (mut m, mut obs) = driving();
        let a = m.drive_refused(20_000, "Interlocked esc_feedback");
        assert_eq!(a[0], Action::Motion(MotionIntent::Stop));
        obs.at_rest = true;
        let a = m.tick(40_000, &obs);
        assert!(
            a.iter().any(|a| matches!(
                a,
                Action::FinishRecording { outcome: Outcome::Aborted(r), .. }
                    if r == "the firmware refused to drive: Interlocked esc_feedback"
            )),
            "{a:?}"
        );
        // With no run active it still makes sure the robot stands still.
        assert_eq!(
            m.drive_refused(50_000, "OutOfRange vx_mps"),
            vec![Action::Motion(MotionIntent::Stop)]
        );
    }

    #[test]
    fn handheld_silence_while_driving_stops_the_robot() {
        let mut m = RunMachine::new(unparked(), 1);
        m.start(0, params(0.2, 5.0), 1);
        let mut obs = healthy();
        m.tick(10_000, &obs);
        obs.at_rest = false;
        obs.handheld_silent_us = Some(12 * HANDHELD_BEAT_US + 1);
        let a = m.tick(20_000, &obs);
        assert_eq!(a[0], Action::Motion(MotionIntent::Stop));
        obs.at_rest = true;
        let a = m.tick(30_000, &obs);
        assert!(a.iter().any(|a| matches!(
            a,
            Action::FinishRecording { outcome: Outcome::Aborted(r), .. } if r.contains("handheld silent")
        )));
    }

    #[test]
    fn failed_checks_name_what_is_missing_and_never_drive() {
        let mut m = RunMachine::new(unparked(), 1);
        m.start(0, params(0.2, 5.0), 1);
        let mut obs = healthy();
        obs.camera_ok = false;
        obs.interlocks = Interlocks::ESC_OVER_TEMPERATURE;
        let mut all = Vec::new();
        for t in 1..=60 {
            all.extend(m.tick(t * 100_000, &obs));
        }
        assert!(motions(&all).is_empty(), "never drove: {all:?}");
        assert!(all.iter().any(|a| matches!(
            a,
            Action::FinishRecording { outcome: Outcome::Failed(r), .. }
                if r.contains("camera") && r.contains("ESC_OVER_TEMPERATURE")
        )));
    }

    #[test]
    fn a_low_battery_fails_the_checks_by_voltage_and_never_drives() {
        let mut m = RunMachine::new(unparked(), 1);
        m.start(0, params(0.2, 5.0), 1);
        let mut obs = healthy();
        obs.battery_mv = 20_400;
        let mut all = Vec::new();
        for t in 1..=60 {
            all.extend(m.tick(t * 100_000, &obs));
        }
        assert!(motions(&all).is_empty(), "never drove: {all:?}");
        assert!(all.iter().any(|a| matches!(
            a,
            Action::FinishRecording { outcome: Outcome::Failed(r), .. }
                if r.contains("battery 20.4 V below 21.0 V")
        )));
        // Unmeasured (0) is not "low": the firmware's own cutoff still protects the pack.
        let mut m = RunMachine::new(unparked(), 1);
        m.start(0, params(0.2, 5.0), 1);
        obs.battery_mv = 0;
        let a = m.tick(100_000, &obs);
        assert!(!motions(&a).is_empty(), "{a:?}");
    }

    #[test]
    fn stop_timeout_zeroes_currents_and_fails() {
        let mut m = RunMachine::new(unparked(), 1);
        m.start(0, params(0.2, 5.0), 1);
        let mut obs = healthy();
        m.tick(10_000, &obs);
        obs.at_rest = false;
        m.abort(20_000, 1);
        let a = m.tick(6_000_000, &obs);
        assert_eq!(a[0], Action::Motion(MotionIntent::StopNow));
        assert_eq!(m.phase(), Phase::Failed);
    }
}
