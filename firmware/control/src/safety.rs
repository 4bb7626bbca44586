//! Safety monitors: per-ESC fault detection, heartbeat supervision, CAN bus state, and the named
//! interlocks that block motion.
//!
//! | condition | detected when | action (by [`crate::machine::Machine`]) | interlock | cleared by |
//! |---|---|---|---|---|
//! | ESC feedback missing | a seen ESC is silent for `feedback_timeout_us` (10 ms) | zero currents at once, latch | `ESC_FEEDBACK_MISSING` | `ClearFaults` with fresh feedback |
//! | over-temperature | `temperature_c >= over_temperature_c` | zero currents at once, latch | `ESC_OVER_TEMPERATURE` | `ClearFaults` once 10 C below |
//! | over-current | `abs(measured current) > over_current_a` for `over_current_time_us` | zero currents at once, latch | `ESC_OVER_CURRENT` | `ClearFaults` |
//! | stall | `abs(current) >= stall_current_a`, `abs(wheel) < stall_speed_radps` for `stall_time_us` | zero currents at once, latch | `ESC_STALLED` | `ClearFaults` |
//! | not following | `abs(measured current - commanded current) > NOT_FOLLOWING_A` for `NOT_FOLLOWING_TIME_US` | zero currents at once, latch | `ESC_NOT_FOLLOWING` | `ClearFaults` |
//! | CAN bus-off | the shell reports bus-off | zero currents, ask the shell to recover the bus, latch | `CAN_BUS_OFF` | `ClearFaults` with the bus back |
//! | heartbeat lost | no heartbeat for `heartbeat_timeout_us` (100 ms) | ramp to zero, drop the drive command, latch | `HEARTBEAT_LOST` | heartbeats again, then a new drive command |
//! | no host | no `Hello` since boot | block starts | `NO_HOST` | `Hello` |
//! | stop requested | `Stop` received | ramp to zero (or zero at once if `immediate`) | `STOP_REQUESTED` | a new drive command |
//! | battery low | filtered supply voltage below `battery.cutoff_mv` (19.8 V; see [`crate::battery`]) | ramp to zero, refuse drives | `BATTERY_LOW` | voltage back above cutoff + hysteresis, then a new drive command |
//!
//! The interlocks and per-ESC fault bits are the MCU link's wire types ([`Interlocks`],
//! [`EscFaults`]), each bit with a name. ESC faults are also reported per wheel with the ESC id.
//! "At once" means in the same 1 ms step that detects the condition.

use protocol::esc::EscFeedback;

use crate::config::Config;

/// Fault bits of one ESC and the named interlocks are the wire types of the MCU link, so what
/// the machine latches is exactly what the onboard computer reads, names included.
pub use protocol::mcu::{EscFaults, Interlocks};

/// Interlocks that zero the currents at once and stay latched until `ClearFaults`.
pub const HARD_INTERLOCKS: Interlocks = Interlocks(
    Interlocks::ESC_FEEDBACK_MISSING.0
        | Interlocks::ESC_OVER_TEMPERATURE.0
        | Interlocks::ESC_OVER_CURRENT.0
        | Interlocks::ESC_STALLED.0
        | Interlocks::ESC_NOT_FOLLOWING.0
        | Interlocks::CAN_BUS_OFF.0,
);

/// The interlock bits that stand for a set of ESC faults.
pub fn interlocks_of(faults: EscFaults) -> Interlocks {
    let mut i = Interlocks::EMPTY;
    for (fault, interlock) in [
        (EscFaults::MISSING, Interlocks::ESC_FEEDBACK_MISSING),
        (
            EscFaults::OVER_TEMPERATURE,
            Interlocks::ESC_OVER_TEMPERATURE,
        ),
        (EscFaults::OVER_CURRENT, Interlocks::ESC_OVER_CURRENT),
        (EscFaults::STALLED, Interlocks::ESC_STALLED),
        (EscFaults::NOT_FOLLOWING, Interlocks::ESC_NOT_FOLLOWING),
    ] {
        if faults.contains(fault) {
            i.insert(interlock);
        }
    }
    i
}

/// State of the CAN controller as the shell reads it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum BusState {
    /// Error-active: normal.
    #[default]
    Active,
    /// Error-passive (many errors; still sending).
    Passive,
    /// Bus-off: the controller no longer sends or receives.
    BusOff,
}

/// An ESC whose torque current stays further than this from the commanded current, for
/// [`NOT_FOLLOWING_TIME_US`], does not obey its command, A: a stuck current loop or a shorted
/// output stage can push the robot with a current below the over-current and stall limits, and
/// the speed loops of the other wheels cannot hold it (in the simulator, an ESC stuck at 6 A
/// turned the stopped robot in a slow circle). The C620's current loop settles within a few
/// milliseconds (the simulator's model: 1 ms time constant), so a healthy ESC is never 3 A off
/// for 100 ms at the robot's speeds, where the back EMF leaves ample voltage headroom. An
/// assumption about the real C620, to confirm on the bench with `control_step_max_us`-style
/// logging of command and feedback.
pub const NOT_FOLLOWING_A: f32 = 3.0;

/// How long the current must stay off its command, us ([`NOT_FOLLOWING_A`]).
pub const NOT_FOLLOWING_TIME_US: u64 = 100_000;

/// Hysteresis for clearing an over-temperature fault, degrees Celsius.
const TEMPERATURE_HYSTERESIS_C: u8 = 10;

/// Supervision of one ESC.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EscMonitor {
    last_seen_us: Option<u64>,
    last: EscFeedback,
    faults: EscFaults,
    over_current_since_us: Option<u64>,
    stall_since_us: Option<u64>,
    not_following_since_us: Option<u64>,
    /// Restarted with an over-temperature latched: its first report must be below the clearing
    /// temperature (limit minus the hysteresis), or the fault latches again.
    recheck_cool: bool,
}

impl EscMonitor {
    /// A monitor that has seen nothing.
    pub const fn new() -> Self {
        Self {
            last_seen_us: None,
            last: EscFeedback {
                angle_raw: 0,
                speed_rpm: 0,
                current_raw: 0,
                temperature_c: 0,
            },
            faults: EscFaults::EMPTY,
            over_current_since_us: None,
            stall_since_us: None,
            not_following_since_us: None,
            recheck_cool: false,
        }
    }

    /// A monitor that has seen nothing, for an ESC that may have been unpowered (see
    /// `Machine::clear_faults`): an over-temperature latched before keeps its hysteresis, so the
    /// first report must be cool enough to clear it.
    #[must_use]
    pub fn restarted(&self) -> Self {
        Self {
            recheck_cool: self.recheck_cool || self.faults.contains(EscFaults::OVER_TEMPERATURE),
            ..Self::new()
        }
    }

    /// Latched faults.
    pub fn faults(&self) -> EscFaults {
        self.faults
    }

    /// Whether this ESC has ever reported.
    pub fn seen(&self) -> bool {
        self.last_seen_us.is_some()
    }

    /// The last feedback frame.
    pub fn last(&self) -> &EscFeedback {
        &self.last
    }

    /// Records one feedback frame and checks temperature, current and stall. `wheel_radps` is the
    /// wheel speed the frame stands for.
    pub fn on_feedback(
        &mut self,
        config: &Config,
        fb: &EscFeedback,
        wheel_radps: f32,
        now_us: u64,
    ) {
        self.last_seen_us = Some(now_us);
        self.last = *fb;
        let limit = if self.recheck_cool {
            config
                .over_temperature_c
                .saturating_sub(TEMPERATURE_HYSTERESIS_C)
        } else {
            config.over_temperature_c
        };
        self.recheck_cool = false;
        if fb.temperature_c >= limit {
            self.faults.insert(EscFaults::OVER_TEMPERATURE);
        }
        let current_a = libm::fabsf(protocol::esc::raw_to_amps(fb.current_raw));
        if held(
            &mut self.over_current_since_us,
            current_a > config.over_current_a,
            now_us,
        )
        .is_some_and(|since| now_us - since >= config.over_current_time_us)
        {
            self.faults.insert(EscFaults::OVER_CURRENT);
        }
        let stalled = current_a >= config.stall_current_a
            && libm::fabsf(wheel_radps) < config.stall_speed_radps;
        if held(&mut self.stall_since_us, stalled, now_us)
            .is_some_and(|since| now_us - since >= config.stall_time_us)
        {
            self.faults.insert(EscFaults::STALLED);
        }
    }

    /// Checks that the last feedback's torque current follows `command_a`, the current commanded
    /// in the step before that frame ([`NOT_FOLLOWING_A`]).
    pub fn check_following(&mut self, command_a: f32, now_us: u64) {
        let current_a = protocol::esc::raw_to_amps(self.last.current_raw);
        let off = libm::fabsf(current_a - command_a) > NOT_FOLLOWING_A;
        if held(&mut self.not_following_since_us, off, now_us)
            .is_some_and(|since| now_us - since >= NOT_FOLLOWING_TIME_US)
        {
            self.faults.insert(EscFaults::NOT_FOLLOWING);
        }
    }

    /// Whether this ESC reported within the feedback timeout before `now_us`.
    pub fn fresh(&self, config: &Config, now_us: u64) -> bool {
        self.last_seen_us
            .is_some_and(|t| now_us.saturating_sub(t) < config.feedback_timeout_us)
    }

    /// Checks the feedback timeout at `now_us`.
    pub fn check_timeout(&mut self, config: &Config, now_us: u64) {
        if self
            .last_seen_us
            .is_some_and(|t| now_us.saturating_sub(t) >= config.feedback_timeout_us)
        {
            self.faults.insert(EscFaults::MISSING);
        }
    }

    /// Clears the faults whose condition is gone; returns what stays latched.
    pub fn clear(&mut self, config: &Config, now_us: u64) -> EscFaults {
        let fresh = self.fresh(config, now_us);
        let mut keep = EscFaults::EMPTY;
        if self.faults.contains(EscFaults::MISSING) && !fresh {
            keep.insert(EscFaults::MISSING);
        }
        let cool = config
            .over_temperature_c
            .saturating_sub(TEMPERATURE_HYSTERESIS_C);
        if self.faults.contains(EscFaults::OVER_TEMPERATURE)
            && (!fresh || self.last.temperature_c >= cool)
        {
            keep.insert(EscFaults::OVER_TEMPERATURE);
        }
        self.faults = keep;
        self.over_current_since_us = None;
        self.stall_since_us = None;
        self.not_following_since_us = None;
        keep
    }
}

/// Tracks since when `condition` has held; returns that start time while it holds.
fn held(since: &mut Option<u64>, condition: bool, now_us: u64) -> Option<u64> {
    if condition {
        Some(*since.get_or_insert(now_us))
    } else {
        *since = None;
        None
    }
}

// Tests compare exact values on purpose (the code under test lands on them exactly) and build
// synthetic encoder counts with plain casts.
#[cfg(test)]
#[allow(
    clippy::float_cmp,
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss
)]
mod tests {
    use super::*;

    fn fb(current_raw: i16, speed_rpm: i16, temperature_c: u8) -> EscFeedback {
        EscFeedback {
            angle_raw: 0,
            speed_rpm,
            current_raw,
            temperature_c,
        }
    }

    #[test]
    fn esc_faults_map_to_named_interlocks() {
        let f = EscFaults::STALLED.union(EscFaults::MISSING);
        let i = interlocks_of(f);
        assert_eq!(
            i,
            Interlocks::ESC_FEEDBACK_MISSING.union(Interlocks::ESC_STALLED)
        );
        assert_eq!(
            i.names().collect::<heapless::Vec<_, 4>>().as_slice(),
            ["ESC_FEEDBACK_MISSING", "ESC_STALLED"]
        );
        assert!(HARD_INTERLOCKS.contains(i));
        assert!(!HARD_INTERLOCKS.contains(Interlocks::HEARTBEAT_LOST));
    }

    #[test]
    fn a_restarted_hot_esc_must_report_cool_before_it_counts_as_healthy() {
        let c = Config::default();
        let hot = c.over_temperature_c;
        let mut m = EscMonitor::new();
        m.on_feedback(&c, &fb(0, 0, hot), 0.0, 0);
        assert_eq!(m.faults(), EscFaults::OVER_TEMPERATURE);
        // Restarted (its supply was cut): seen by nobody, but the hysteresis is kept.
        let mut r = m.restarted();
        assert!(!r.seen() && r.faults().is_empty());
        r.on_feedback(&c, &fb(0, 0, hot - 5), 0.0, 1_000);
        assert_eq!(
            r.faults(),
            EscFaults::OVER_TEMPERATURE,
            "5 C below is not cool"
        );
        let mut r = m.restarted();
        r.on_feedback(&c, &fb(0, 0, hot - 11), 0.0, 1_000);
        assert!(r.faults().is_empty());
        // Only the first report is held to the clearing temperature.
        r.on_feedback(&c, &fb(0, 0, hot - 5), 0.0, 2_000);
        assert!(r.faults().is_empty());
        // A cool ESC restarts without the recheck.
        let mut cool = EscMonitor::new().restarted();
        cool.on_feedback(&c, &fb(0, 0, hot - 5), 0.0, 0);
        assert!(cool.faults().is_empty());
    }

    #[test]
    fn timeout_latches_and_clears_only_with_fresh_feedback() {
        let c = Config::default();
        let mut m = EscMonitor::new();
        m.check_timeout(&c, 1_000_000);
        assert!(
            m.faults().is_empty(),
            "never-seen ESCs are offline, not timed out"
        );
        m.on_feedback(&c, &fb(0, 0, 30), 0.0, 0);
        m.check_timeout(&c, 9_999);
        assert!(m.faults().is_empty());
        m.check_timeout(&c, 10_000);
        assert_eq!(m.faults(), EscFaults::MISSING);
        assert_eq!(m.clear(&c, 20_000), EscFaults::MISSING);
        m.on_feedback(&c, &fb(0, 0, 30), 0.0, 20_000);
        assert!(m.clear(&c, 20_500).is_empty());
    }

    #[test]
    fn over_temperature_with_hysteresis() {
        let c = Config::default();
        let mut m = EscMonitor::new();
        m.on_feedback(&c, &fb(0, 0, 79), 0.0, 0);
        assert!(m.faults().is_empty());
        m.on_feedback(&c, &fb(0, 0, 80), 0.0, 1000);
        assert_eq!(m.faults(), EscFaults::OVER_TEMPERATURE);
        m.on_feedback(&c, &fb(0, 0, 75), 0.0, 2000);
        assert_eq!(m.clear(&c, 2000), EscFaults::OVER_TEMPERATURE);
        m.on_feedback(&c, &fb(0, 0, 69), 0.0, 3000);
        assert!(m.clear(&c, 3000).is_empty());
    }

    #[test]
    fn a_current_off_its_command_latches_after_100_ms() {
        let c = Config::default();
        let six = protocol::esc::amps_to_raw(6.0);
        let mut m = EscMonitor::new();
        // Following: 6 A measured for 6 A commanded, and a 2 A lag, for a second.
        for t in (0..1_000_000).step_by(1_000) {
            m.on_feedback(&c, &fb(six, 3000, 30), 20.0, t);
            m.check_following(if t % 2_000 == 0 { 6.0 } else { 4.0 }, t);
        }
        assert!(m.faults().is_empty());
        // Stuck at 6 A with zero commanded: latched at 100 ms, not before.
        let t0 = 1_000_000;
        for t in (t0..t0 + 100_000).step_by(1_000) {
            m.on_feedback(&c, &fb(six, 0, 30), 0.0, t);
            m.check_following(0.0, t);
        }
        assert!(m.faults().is_empty(), "99 ms off");
        m.on_feedback(&c, &fb(six, 0, 30), 0.0, t0 + 100_000);
        m.check_following(0.0, t0 + 100_000);
        assert_eq!(m.faults(), EscFaults::NOT_FOLLOWING);
        assert_eq!(interlocks_of(m.faults()), Interlocks::ESC_NOT_FOLLOWING);
        assert!(HARD_INTERLOCKS.contains(Interlocks::ESC_NOT_FOLLOWING));
    }

    #[test]
    fn over_current_needs_to_last() {
        let c = Config::default(); // 15 A for 3 ms
        let raw = protocol::esc::amps_to_raw(16.0);
        let mut m = EscMonitor::new();
        m.on_feedback(&c, &fb(raw, 5000, 30), 30.0, 0);
        m.on_feedback(&c, &fb(raw, 5000, 30), 30.0, 2000);
        assert!(m.faults().is_empty());
        m.on_feedback(&c, &fb(0, 5000, 30), 30.0, 2500);
        m.on_feedback(&c, &fb(-raw, 5000, 30), 30.0, 3000);
        m.on_feedback(&c, &fb(-raw, 5000, 30), 30.0, 5999);
        assert!(m.faults().is_empty(), "the spike at 0-2 ms was interrupted");
        m.on_feedback(&c, &fb(-raw, 5000, 30), 30.0, 6000);
        assert_eq!(m.faults(), EscFaults::OVER_CURRENT);
    }

    #[test]
    fn stall_needs_current_without_motion() {
        let c = Config::default(); // 7 A, 0.3 rad/s, 400 ms
        let raw = protocol::esc::amps_to_raw(8.0);
        let mut m = EscMonitor::new();
        for t in (0..=400_000).step_by(1000) {
            m.on_feedback(&c, &fb(raw, 2000, 30), 10.0, t);
        }
        assert!(m.faults().is_empty(), "turning wheel is not stalled");
        for t in (400_000..800_000).step_by(1000) {
            m.on_feedback(&c, &fb(raw, 0, 30), 0.0, t);
        }
        assert!(m.faults().is_empty());
        m.on_feedback(&c, &fb(raw, 0, 30), 0.0, 800_000);
        assert_eq!(m.faults(), EscFaults::STALLED);
    }
}
