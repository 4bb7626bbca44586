//! Firmware configuration: geometry, wheel map, PID gains, limits and safety thresholds.
//!
//! [`Config::default`] is the build-time configuration; the onboard computer may replace parts of
//! it at run time over the MCU link (`SetConfig`), and every replacement goes through
//! [`Config::validate`] first, so the controller never runs on a configuration that fails it.
//! The geometry defaults are nominal values for the 295 x 384 mm chassis: measure and set them.

use crate::battery::BatteryConfig;
use crate::kinematics::{Geometry, Wheel};
use crate::pid::PidGains;
use protocol::mcu::McuConfig;

/// Which ESC drives which wheel, and in which direction.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WheelMap {
    /// C620 ESC id (1..=4, distinct) of each wheel, in [`Wheel::ALL`] order (FL, FR, RL, RR).
    pub esc_id: [u8; 4],
    /// +1 when a positive rotor speed rolls that wheel forward, -1 when it rolls it backward (the
    /// right-side motors are mirrored, so usually `[1, -1, 1, -1]`).
    pub sign: [i8; 4],
}

impl WheelMap {
    /// The wheel (array index) driven by `esc_id`, if any.
    pub fn wheel_of_esc(&self, esc_id: u8) -> Option<usize> {
        self.esc_id.iter().position(|&id| id == esc_id)
    }

    /// `sign` of wheel `wheel` as f32 (+1.0 for a bad index, which `validate` rules out).
    pub fn sign_f(&self, wheel: usize) -> f32 {
        match self.sign.get(wheel) {
            Some(-1) => -1.0,
            _ => 1.0,
        }
    }
}

/// Everything the controller is tuned by.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Config {
    /// Chassis geometry.
    pub geometry: Geometry,
    /// ESC ids and directions.
    pub wheels: WheelMap,
    /// Wheel-speed loop gains; `output_limit_a` is the current limit (<= 20 A).
    pub pid: PidGains,
    /// Largest accepted |vx| and |vy| in a drive command, m/s.
    pub max_speed_mps: f32,
    /// Largest accepted |wz| in a drive command, rad/s.
    pub max_yaw_rate_radps: f32,
    /// Largest accepted ramp acceleration, m/s^2 (yaw uses this divided by k).
    pub max_accel_mps2: f32,
    /// Largest accepted ramp jerk, m/s^3.
    pub max_jerk_mps3: f32,
    /// Largest wheel speed, rad/s (output shaft): setpoints are scaled down to it.
    pub max_wheel_radps: f32,
    /// Deceleration used when the heartbeat is lost, m/s^2.
    pub stop_accel_mps2: f32,
    /// Jerk used when the heartbeat is lost, m/s^3.
    pub stop_jerk_mps3: f32,
    /// After a ramp to zero, the wheels are held at zero speed this long, then the currents go to 0.
    pub hold_after_stop_us: u64,
    /// Heartbeat timeout, microseconds (default 100 ms).
    pub heartbeat_timeout_us: u64,
    /// ESC feedback timeout, microseconds (default 10 ms).
    pub feedback_timeout_us: u64,
    /// Motor temperature at or above which the ESC is faulted, degrees Celsius.
    pub over_temperature_c: u8,
    /// Measured |current| above which, held for `over_current_time_us`, the ESC is faulted, A.
    pub over_current_a: f32,
    /// How long the over-current must last, microseconds (filters single noisy readings).
    pub over_current_time_us: u64,
    /// A motor is stalled when |measured current| >= this ...
    pub stall_current_a: f32,
    /// ... while its |wheel speed| < this (rad/s) ...
    pub stall_speed_radps: f32,
    /// ... for this long, microseconds.
    pub stall_time_us: u64,
    /// Odometry report period, microseconds (default 10 ms = 100 Hz).
    pub odometry_period_us: u64,
    /// Status report period, microseconds (status is also sent at once when faults change).
    pub status_period_us: u64,
    /// Battery under-voltage supervision (built in, not on the MCU link).
    pub battery: BatteryConfig,
}

impl Default for Config {
    fn default() -> Self {
        Self {
            geometry: Geometry {
                half_wheelbase_m: 0.12,
                half_track_m: 0.115,
                wheel_radius_m: 0.038,
            },
            wheels: WheelMap {
                esc_id: [1, 2, 3, 4],
                sign: [1, -1, 1, -1],
            },
            pid: PidGains {
                kp: 2.0,
                ki: 20.0,
                kd: 0.0,
                kd_filter_s: 0.002,
                integral_limit_a: 6.0,
                output_limit_a: 10.0,
            },
            max_speed_mps: 1.0,
            max_yaw_rate_radps: 2.0,
            max_accel_mps2: 2.0,
            max_jerk_mps3: 40.0,
            max_wheel_radps: 45.0,
            stop_accel_mps2: 1.0,
            stop_jerk_mps3: 10.0,
            hold_after_stop_us: 500_000,
            heartbeat_timeout_us: 100_000,
            feedback_timeout_us: 10_000,
            over_temperature_c: 80,
            over_current_a: 15.0,
            over_current_time_us: 3_000,
            stall_current_a: 7.0,
            stall_speed_radps: 0.3,
            stall_time_us: 400_000,
            odometry_period_us: 10_000,
            status_period_us: 100_000,
            battery: BatteryConfig::default(),
        }
    }
}

/// The first configuration field that failed validation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ConfigError {
    /// A length, gain or limit is not finite or not in its range; the field is named.
    OutOfRange(&'static str),
    /// ESC ids must be 1..=4 and distinct (they share the 0x200 command frame).
    BadEscIds,
    /// Wheel signs must be +1 or -1.
    BadSigns,
}

impl core::fmt::Display for ConfigError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::OutOfRange(field) => write!(f, "config field `{field}` is out of range"),
            Self::BadEscIds => {
                f.write_str("config `wheels.esc_id` must be 4 distinct ids in 1..=4")
            }
            Self::BadSigns => f.write_str("config `wheels.sign` entries must be +1 or -1"),
        }
    }
}

fn check(ok: bool, field: &'static str) -> Result<(), ConfigError> {
    if ok {
        Ok(())
    } else {
        Err(ConfigError::OutOfRange(field))
    }
}

fn in_range(x: f32, lo: f32, hi: f32) -> bool {
    x.is_finite() && x >= lo && x <= hi
}

impl Config {
    /// Checks every field; returns the first that is wrong.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let g = &self.geometry;
        check(
            in_range(g.half_wheelbase_m, 0.01, 2.0),
            "geometry.half_wheelbase_m",
        )?;
        check(in_range(g.half_track_m, 0.01, 2.0), "geometry.half_track_m")?;
        check(
            in_range(g.wheel_radius_m, 0.005, 0.5),
            "geometry.wheel_radius_m",
        )?;
        let mut seen = [false; 4];
        for id in self.wheels.esc_id {
            let slot = usize::from(id).wrapping_sub(1);
            match seen.get_mut(slot) {
                Some(s) if !*s => *s = true,
                _ => return Err(ConfigError::BadEscIds),
            }
        }
        if self.wheels.sign.iter().any(|s| *s != 1 && *s != -1) {
            return Err(ConfigError::BadSigns);
        }
        let p = &self.pid;
        check(in_range(p.kp, 0.0, 1000.0), "pid.kp")?;
        check(in_range(p.ki, 0.0, 100_000.0), "pid.ki")?;
        check(in_range(p.kd, 0.0, 100.0), "pid.kd")?;
        check(in_range(p.kd_filter_s, 0.0, 1.0), "pid.kd_filter_s")?;
        check(
            in_range(p.integral_limit_a, 0.0, protocol::esc::CURRENT_MAX_A),
            "pid.integral_limit_a",
        )?;
        check(
            in_range(p.output_limit_a, 0.0, protocol::esc::CURRENT_MAX_A),
            "pid.output_limit_a",
        )?;
        check(in_range(self.max_speed_mps, 0.0, 5.0), "max_speed_mps")?;
        check(
            in_range(self.max_yaw_rate_radps, 0.0, 20.0),
            "max_yaw_rate_radps",
        )?;
        check(in_range(self.max_accel_mps2, 0.01, 20.0), "max_accel_mps2")?;
        check(in_range(self.max_jerk_mps3, 0.1, 1000.0), "max_jerk_mps3")?;
        check(
            in_range(self.max_wheel_radps, 0.1, 100.0),
            "max_wheel_radps",
        )?;
        check(
            in_range(self.stop_accel_mps2, 0.01, 20.0),
            "stop_accel_mps2",
        )?;
        check(in_range(self.stop_jerk_mps3, 0.1, 1000.0), "stop_jerk_mps3")?;
        check(self.hold_after_stop_us <= 10_000_000, "hold_after_stop_us")?;
        check(
            (10_000..=2_000_000).contains(&self.heartbeat_timeout_us),
            "heartbeat_timeout_us",
        )?;
        check(
            (2_000..=100_000).contains(&self.feedback_timeout_us),
            "feedback_timeout_us",
        )?;
        check(
            (40..=125).contains(&self.over_temperature_c),
            "over_temperature_c",
        )?;
        check(
            in_range(self.over_current_a, 1.0, protocol::esc::CURRENT_MAX_A),
            "over_current_a",
        )?;
        check(
            self.over_current_time_us <= 1_000_000,
            "over_current_time_us",
        )?;
        check(
            in_range(self.stall_current_a, 0.5, protocol::esc::CURRENT_MAX_A),
            "stall_current_a",
        )?;
        check(
            in_range(self.stall_speed_radps, 0.0, 10.0),
            "stall_speed_radps",
        )?;
        check(
            (10_000..=10_000_000).contains(&self.stall_time_us),
            "stall_time_us",
        )?;
        check(
            (1_000..=1_000_000).contains(&self.odometry_period_us),
            "odometry_period_us",
        )?;
        check(
            (10_000..=10_000_000).contains(&self.status_period_us),
            "status_period_us",
        )?;
        let b = &self.battery;
        check(b.hysteresis_mv <= 5_000, "battery.hysteresis_mv")?;
        check(
            (10_000..=10_000_000).contains(&b.filter_time_us),
            "battery.filter_time_us",
        )?;
        Ok(())
    }

    /// The ESC id of `wheel`.
    pub fn esc_of(&self, wheel: Wheel) -> u8 {
        self.wheels.esc_id[wheel as usize]
    }
}

// Tests compare exact values on purpose (the code under test lands on them exactly) and build
// synthetic encoder counts with plain casts.
impl Config {
    /// This configuration with the fields the MCU link can set replaced by `mcu`'s (the rest keep
    /// their values). Validate the result before using it.
    #[must_use]
    pub fn with_mcu(&self, mcu: &McuConfig) -> Self {
        let ms = |v: u16| u64::from(v) * 1000;
        Self {
            geometry: Geometry {
                half_wheelbase_m: mcu.half_length_m,
                half_track_m: mcu.half_width_m,
                wheel_radius_m: mcu.wheel_radius_m,
            },
            wheels: WheelMap {
                esc_id: mcu.esc_ids,
                sign: mcu.wheel_signs,
            },
            pid: PidGains {
                kp: mcu.speed_kp,
                ki: mcu.speed_ki,
                kd: mcu.speed_kd,
                output_limit_a: mcu.current_limit_a,
                ..self.pid
            },
            max_speed_mps: mcu.max_speed_mps,
            max_accel_mps2: mcu.max_accel_mps2,
            heartbeat_timeout_us: ms(mcu.heartbeat_timeout_ms),
            feedback_timeout_us: ms(mcu.feedback_timeout_ms),
            odometry_period_us: ms(mcu.odometry_period_ms),
            over_temperature_c: mcu.over_temperature_c,
            over_current_a: mcu.over_current_a,
            stall_time_us: ms(mcu.stall_timeout_ms),
            ..*self
        }
    }

    /// The MCU-link view of this configuration (times rounded down to whole milliseconds).
    pub fn to_mcu(&self) -> McuConfig {
        let ms = |us: u64| u16::try_from(us / 1000).unwrap_or(u16::MAX);
        McuConfig {
            wheel_radius_m: self.geometry.wheel_radius_m,
            half_length_m: self.geometry.half_wheelbase_m,
            half_width_m: self.geometry.half_track_m,
            esc_ids: self.wheels.esc_id,
            wheel_signs: self.wheels.sign,
            current_limit_a: self.pid.output_limit_a,
            speed_kp: self.pid.kp,
            speed_ki: self.pid.ki,
            speed_kd: self.pid.kd,
            max_speed_mps: self.max_speed_mps,
            max_accel_mps2: self.max_accel_mps2,
            heartbeat_timeout_ms: ms(self.heartbeat_timeout_us),
            feedback_timeout_ms: ms(self.feedback_timeout_us),
            odometry_period_ms: ms(self.odometry_period_us),
            over_temperature_c: self.over_temperature_c,
            over_current_a: self.over_current_a,
            stall_timeout_ms: ms(self.stall_time_us),
        }
    }
}

impl ConfigError {
    /// The name of the wrong field as `McuConfig` spells it (for `Rejected.field`).
    pub fn mcu_field(&self) -> &'static str {
        match self {
            Self::BadEscIds => "esc_ids",
            Self::BadSigns => "wheel_signs",
            Self::OutOfRange(field) => match *field {
                "geometry.wheel_radius_m" => "wheel_radius_m",
                "geometry.half_wheelbase_m" => "half_length_m",
                "geometry.half_track_m" => "half_width_m",
                "pid.output_limit_a" => "current_limit_a",
                "pid.kp" => "speed_kp",
                "pid.ki" => "speed_ki",
                "pid.kd" => "speed_kd",
                "heartbeat_timeout_us" => "heartbeat_timeout_ms",
                "feedback_timeout_us" => "feedback_timeout_ms",
                "odometry_period_us" => "odometry_period_ms",
                "stall_time_us" => "stall_timeout_ms",
                other => other,
            },
        }
    }
}

#[cfg(test)]
#[allow(
    clippy::float_cmp,
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss
)]
mod tests {
    use super::*;

    #[test]
    fn default_is_valid() {
        assert_eq!(Config::default().validate(), Ok(()));
    }

    #[test]
    fn each_bad_field_is_named() {
        let mut c = Config::default();
        c.geometry.wheel_radius_m = f32::NAN;
        assert_eq!(
            c.validate(),
            Err(ConfigError::OutOfRange("geometry.wheel_radius_m"))
        );
        let mut c = Config::default();
        c.pid.output_limit_a = 25.0;
        assert_eq!(
            c.validate(),
            Err(ConfigError::OutOfRange("pid.output_limit_a"))
        );
        let c = Config {
            heartbeat_timeout_us: 0,
            ..Config::default()
        };
        assert_eq!(
            c.validate(),
            Err(ConfigError::OutOfRange("heartbeat_timeout_us"))
        );
        let mut c = Config::default();
        c.wheels.esc_id = [1, 2, 2, 4];
        assert_eq!(c.validate(), Err(ConfigError::BadEscIds));
        c.wheels.esc_id = [1, 2, 3, 5];
        assert_eq!(c.validate(), Err(ConfigError::BadEscIds));
        c.wheels.esc_id = [0, 2, 3, 4];
        assert_eq!(c.validate(), Err(ConfigError::BadEscIds));
        let mut c = Config::default();
        c.wheels.sign = [1, 0, 1, -1];
        assert_eq!(c.validate(), Err(ConfigError::BadSigns));
    }

    #[test]
    fn mcu_round_trip_and_field_names() {
        let c = Config::default();
        assert_eq!(c.with_mcu(&c.to_mcu()), c);
        let mut m = c.to_mcu();
        m.half_length_m = -1.0;
        let err = c.with_mcu(&m).validate().unwrap_err();
        assert_eq!(err.mcu_field(), "half_length_m");
        let mut m = c.to_mcu();
        m.esc_ids = [5, 6, 7, 8];
        assert_eq!(
            c.with_mcu(&m).validate().unwrap_err().mcu_field(),
            "esc_ids"
        );
        let mut m = c.to_mcu();
        m.heartbeat_timeout_ms = 5;
        assert_eq!(
            c.with_mcu(&m).validate().unwrap_err().mcu_field(),
            "heartbeat_timeout_ms"
        );
        let mut m = c.to_mcu();
        m.stall_timeout_ms = 250;
        m.current_limit_a = 8.0;
        let c2 = c.with_mcu(&m);
        assert_eq!((c2.stall_time_us, c2.pid.output_limit_a), (250_000, 8.0));
        assert_eq!(c2.validate(), Ok(()));
    }

    #[test]
    fn wheel_lookup() {
        let c = Config {
            wheels: WheelMap {
                esc_id: [2, 1, 4, 3],
                sign: [1, -1, 1, -1],
            },
            ..Config::default()
        };
        assert_eq!(c.wheels.wheel_of_esc(1), Some(1));
        assert_eq!(c.wheels.wheel_of_esc(3), Some(3));
        assert_eq!(c.wheels.wheel_of_esc(5), None);
        assert_eq!(c.esc_of(Wheel::FrontLeft), 2);
        assert_eq!(c.wheels.sign_f(1), -1.0);
    }
}
