//! Safety monitors: per-ESC fault detection, heartbeat supervision, CAN bus state, and the named
//! interlocks that block motion.
//!
//! | condition | detected when | action (by [`crate::Controller`]) | cleared by |
//! |---|---|---|---|
//! | ESC feedback missing | a seen ESC is silent for `feedback_timeout_us` (10 ms) | zero currents at once, latch | `ClearFaults` with fresh feedback |
//! | over-temperature | `temperature_c >= over_temperature_c` | zero currents at once, latch | `ClearFaults` once 10 C below |
//! | over-current | `|measured current| > over_current_a` for `over_current_time_us` | zero currents at once, latch | `ClearFaults` |
//! | stall | `|current| >= stall_current_a` and `|wheel| < stall_speed_radps` for `stall_time_us` | zero currents at once, latch | `ClearFaults` |
//! | CAN bus-off | the shell reports bus-off | zero currents, ask the shell to recover the bus, latch | `ClearFaults` with the bus back |
//! | heartbeat lost | no heartbeat for `heartbeat_timeout_us` (100 ms) while moving | ramp to zero, drop the drive command, latch | the next accepted drive command |
//!
//! Each latched condition is an [`Interlocks`] bit with a name; ESC faults also carry the ESC id in
//! [`EscFaults`] per ESC. "At once" means in the same 1 ms step that detects the condition.

use protocol::esc::EscFeedback;

use crate::config::Config;

/// Fault bits of one ESC (latched until cleared).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct EscFaults(pub u8);

impl EscFaults {
    /// No feedback frame for the feedback timeout.
    pub const FEEDBACK_TIMEOUT: Self = Self(1 << 0);
    /// Motor temperature at or above the limit.
    pub const OVER_TEMPERATURE: Self = Self(1 << 1);
    /// Measured current above the over-current limit.
    pub const OVER_CURRENT: Self = Self(1 << 2);
    /// High current with the wheel not turning.
    pub const STALL: Self = Self(1 << 3);
    /// Every bit with its name, for reports.
    pub const NAMED: [(Self, &'static str); 4] = [
        (Self::FEEDBACK_TIMEOUT, "feedback-timeout"),
        (Self::OVER_TEMPERATURE, "over-temperature"),
        (Self::OVER_CURRENT, "over-current"),
        (Self::STALL, "stall"),
    ];

    /// Whether no bit is set.
    pub const fn is_empty(self) -> bool {
        self.0 == 0
    }
    /// Whether every bit of `other` is set.
    pub const fn contains(self, other: Self) -> bool {
        self.0 & other.0 == other.0
    }
    /// Sets the bits of `other`.
    pub fn insert(&mut self, other: Self) {
        self.0 |= other.0;
    }
    /// Names of the set bits.
    pub fn names(self) -> impl Iterator<Item = &'static str> {
        Self::NAMED
            .into_iter()
            .filter(move |(b, _)| self.contains(*b))
            .map(|(_, n)| n)
    }
}

/// Conditions that currently block motion, each with a name (a bit set).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Interlocks(pub u16);

impl Interlocks {
    /// No heartbeat from the onboard computer within the timeout (live, not latched).
    pub const HEARTBEAT_MISSING: Self = Self(1 << 0);
    /// The heartbeat was lost while moving; latched until the next accepted drive command.
    pub const HEARTBEAT_LOST: Self = Self(1 << 1);
    /// An ESC has never reported (live).
    pub const ESC_OFFLINE: Self = Self(1 << 2);
    /// An ESC fault is latched (see the per-ESC [`EscFaults`]).
    pub const ESC_FAULT: Self = Self(1 << 3);
    /// The CAN bus went bus-off; latched until cleared with the bus back.
    pub const CAN_BUS_OFF: Self = Self(1 << 4);
    /// Every bit with its name, for reports.
    pub const NAMED: [(Self, &'static str); 5] = [
        (Self::HEARTBEAT_MISSING, "heartbeat-missing"),
        (Self::HEARTBEAT_LOST, "heartbeat-lost"),
        (Self::ESC_OFFLINE, "esc-offline"),
        (Self::ESC_FAULT, "esc-fault"),
        (Self::CAN_BUS_OFF, "can-bus-off"),
    ];
    /// Interlocks that zero the currents at once (the rest ramp down or only block a start).
    pub const HARD: Self = Self(Self::ESC_OFFLINE.0 | Self::ESC_FAULT.0 | Self::CAN_BUS_OFF.0);

    /// Whether no bit is set.
    pub const fn is_empty(self) -> bool {
        self.0 == 0
    }
    /// Whether every bit of `other` is set.
    pub const fn contains(self, other: Self) -> bool {
        self.0 & other.0 == other.0
    }
    /// Whether any bit of `other` is set.
    pub const fn intersects(self, other: Self) -> bool {
        self.0 & other.0 != 0
    }
    /// Sets the bits of `other`.
    pub fn insert(&mut self, other: Self) {
        self.0 |= other.0;
    }
    /// Clears the bits of `other`.
    pub fn remove(&mut self, other: Self) {
        self.0 &= !other.0;
    }
    /// Names of the set bits.
    pub fn names(self) -> impl Iterator<Item = &'static str> {
        Self::NAMED
            .into_iter()
            .filter(move |(b, _)| self.contains(*b))
            .map(|(_, n)| n)
    }
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
            faults: EscFaults(0),
            over_current_since_us: None,
            stall_since_us: None,
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
        if fb.temperature_c >= config.over_temperature_c {
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
            self.faults.insert(EscFaults::STALL);
        }
    }

    /// Checks the feedback timeout at `now_us`.
    pub fn check_timeout(&mut self, config: &Config, now_us: u64) {
        if self
            .last_seen_us
            .is_some_and(|t| now_us.saturating_sub(t) >= config.feedback_timeout_us)
        {
            self.faults.insert(EscFaults::FEEDBACK_TIMEOUT);
        }
    }

    /// Clears the faults whose condition is gone; returns what stays latched.
    pub fn clear(&mut self, config: &Config, now_us: u64) -> EscFaults {
        let fresh = self
            .last_seen_us
            .is_some_and(|t| now_us.saturating_sub(t) < config.feedback_timeout_us);
        let mut keep = EscFaults::default();
        if self.faults.contains(EscFaults::FEEDBACK_TIMEOUT) && !fresh {
            keep.insert(EscFaults::FEEDBACK_TIMEOUT);
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
    fn names() {
        let i = Interlocks(Interlocks::HEARTBEAT_LOST.0 | Interlocks::CAN_BUS_OFF.0);
        let mut it = i.names();
        assert_eq!(it.next(), Some("heartbeat-lost"));
        assert_eq!(it.next(), Some("can-bus-off"));
        assert_eq!(it.next(), None);
        let f = EscFaults(EscFaults::STALL.0 | EscFaults::FEEDBACK_TIMEOUT.0);
        assert_eq!(
            f.names().collect::<heapless::Vec<_, 4>>().as_slice(),
            ["feedback-timeout", "stall"]
        );
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
        assert_eq!(m.faults(), EscFaults::FEEDBACK_TIMEOUT);
        assert_eq!(m.clear(&c, 20_000), EscFaults::FEEDBACK_TIMEOUT);
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
        assert_eq!(m.faults(), EscFaults::STALL);
    }
}
