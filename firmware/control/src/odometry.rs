//! Encoder odometry: rotor angle unwrapping, wheel angles, integrated pose and twist.
//!
//! The C620 reports the rotor angle as 0..=8191 per rotor turn, and the M3508 gearbox turns the
//! wheel once per 3591/187 rotor turns. At the motor's top speed (about 9 300 rpm rotor, 482 rpm at
//! the output) the rotor turns about 1 270 counts per 1 ms feedback period, under half a turn, so
//! the shortest-path rule would do at exactly 1 kHz. It fails when frames are lost (two frames at
//! top speed are 2 540 counts, three are 3 800, four are past half a turn). [`EncoderUnwrap`]
//! therefore predicts the increment from the speed the ESC reports in the same frame and the time
//! since the previous frame, and picks the number of whole turns that lands nearest that
//! prediction; this is exact as long as the speed reading times the gap errs by less than half a
//! turn (at 1 ms, a speed error under 3 800 rpm; at 10 ms, under 380 rpm).
//!
//! [`Odometry`] integrates the body displacement from wheel angle increments (forward kinematics
//! of increments, midpoint yaw), and reports the twist from the ESC speed readings, which lag less
//! than differenced angles. Wheel slip is not observable here: mecanum encoder odometry is known to
//! read 10 % or more off in lateral motion (notes/domain.md B6); the onboard fuses it with the lidar.

use crate::kinematics::{self, Geometry, Twist};

/// Encoder counts per rotor turn, as f32.
const COUNTS_F: f32 = protocol::esc::ENCODER_COUNTS as f32;

/// Unwraps one rotor's 0..8191 angle into a continuous count.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EncoderUnwrap {
    last: Option<(u16, u64)>,
    total_counts: i64,
}

impl EncoderUnwrap {
    /// An unwrapper that has seen no frame yet.
    pub const fn new() -> Self {
        Self {
            last: None,
            total_counts: 0,
        }
    }

    /// Continuous rotor count since the first frame.
    pub fn total_counts(&self) -> i64 {
        self.total_counts
    }

    /// Feeds one frame (`angle_raw` 0..=8191, the frame's own rotor speed, its arrival time on the
    /// MCU clock) and returns the increment in counts since the previous frame (0 for the first).
    /// Angles above 8191 are folded into range (the codec already rejects them). A frame with a
    /// timestamp earlier than the previous one is treated as arriving at the same time.
    pub fn update(&mut self, angle_raw: u16, speed_rpm: i16, stamp_us: u64) -> i64 {
        let counts = i64::from(protocol::esc::ENCODER_COUNTS);
        let angle = angle_raw % protocol::esc::ENCODER_COUNTS;
        let Some((last_angle, last_stamp_us)) = self.last else {
            self.last = Some((angle, stamp_us));
            return 0;
        };
        self.last = Some((angle, stamp_us));
        let dt_us = stamp_us.saturating_sub(last_stamp_us);
        let forward = (i64::from(angle) - i64::from(last_angle)).rem_euclid(counts);
        // Predicted increment: rpm * counts/turn * dt / 60 s (f32 is ample: at most a few turns).
        #[allow(clippy::cast_precision_loss)]
        let predicted = f32::from(speed_rpm) * COUNTS_F * (dt_us as f32) / 60.0e6;
        #[allow(clippy::cast_precision_loss)]
        let turns = libm::roundf((predicted - forward as f32) / COUNTS_F);
        // |turns| is bounded by |rpm| * dt / 60 s + 1; clamp so absurd gaps cannot overflow.
        #[allow(clippy::cast_possible_truncation)]
        let turns = turns.clamp(-1.0e6, 1.0e6) as i64;
        let delta = forward + turns * counts;
        self.total_counts = self.total_counts.saturating_add(delta);
        delta
    }
}

/// Rotor counts to output-shaft radians.
pub fn counts_to_wheel_rad(counts: i64) -> f32 {
    #[allow(clippy::cast_precision_loss)]
    let rotor_turns = counts as f32 / COUNTS_F;
    rotor_turns / protocol::esc::M3508_GEAR_RATIO * core::f32::consts::TAU
}

/// Rotor rpm to output-shaft rad/s.
pub fn rpm_to_wheel_radps(speed_rpm: i16) -> f32 {
    f32::from(speed_rpm) / protocol::esc::M3508_GEAR_RATIO * core::f32::consts::TAU / 60.0
}

/// Output-shaft rad/s to rotor rpm (for the stall and speed checks).
pub fn wheel_radps_to_rpm(wheel_radps: f32) -> f32 {
    wheel_radps * protocol::esc::M3508_GEAR_RATIO * 60.0 / core::f32::consts::TAU
}

/// A planar pose in the odometry frame (the body frame at start-up, or at the last reset).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Pose {
    /// x, metres.
    pub x_m: f32,
    /// y, metres.
    pub y_m: f32,
    /// Yaw, radians, wrapped to (-pi, pi].
    pub yaw_rad: f32,
}

/// Integrated wheel odometry.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Odometry {
    pose: Pose,
    twist: Twist,
    /// Wheel angle increments (rad, wheel-forward positive) not yet integrated.
    pending_rad: [f32; 4],
    /// Last wheel speeds (rad/s, wheel-forward positive).
    wheel_radps: [f32; 4],
}

impl Odometry {
    /// Odometry at the origin, at rest.
    pub const fn new() -> Self {
        Self {
            pose: Pose {
                x_m: 0.0,
                y_m: 0.0,
                yaw_rad: 0.0,
            },
            twist: Twist::ZERO,
            pending_rad: [0.0; 4],
            wheel_radps: [0.0; 4],
        }
    }

    /// Adds one wheel's angle increment (rad) and speed (rad/s), both wheel-forward positive.
    pub fn add_wheel(&mut self, wheel: usize, delta_rad: f32, speed_radps: f32) {
        if let (Some(p), Some(s)) = (
            self.pending_rad.get_mut(wheel),
            self.wheel_radps.get_mut(wheel),
        ) {
            *p += delta_rad;
            *s = speed_radps;
        }
    }

    /// Integrates the pending increments into the pose (call once per control step).
    pub fn integrate(&mut self, geometry: &Geometry) {
        let d = kinematics::forward(geometry, self.pending_rad);
        self.pending_rad = [0.0; 4];
        let mid_yaw = self.pose.yaw_rad + 0.5 * d.wz_radps;
        let (sin, cos) = (libm::sinf(mid_yaw), libm::cosf(mid_yaw));
        self.pose.x_m += cos * d.vx_mps - sin * d.vy_mps;
        self.pose.y_m += sin * d.vx_mps + cos * d.vy_mps;
        self.pose.yaw_rad = wrap_angle(self.pose.yaw_rad + d.wz_radps);
        self.twist = kinematics::forward(geometry, self.wheel_radps);
    }

    /// Current pose.
    pub fn pose(&self) -> Pose {
        self.pose
    }

    /// Current body twist (from the ESC speed readings).
    pub fn twist(&self) -> Twist {
        self.twist
    }

    /// Current wheel speeds, rad/s, wheel-forward positive (FL, FR, RL, RR).
    pub fn wheel_radps(&self) -> [f32; 4] {
        self.wheel_radps
    }
}

/// Wraps an angle to (-pi, pi].
pub fn wrap_angle(rad: f32) -> f32 {
    use core::f32::consts::{PI, TAU};
    let wrapped = rad - TAU * libm::floorf((rad + PI) / TAU);
    if wrapped <= -PI {
        wrapped + TAU
    } else {
        wrapped
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
    use proptest::prelude::*;

    /// Simulates a rotor at constant rpm sampled every `period_us`, returns the unwrapped total
    /// and the true total.
    fn spin(rpm: i16, period_us: u64, frames: u64) -> (i64, f64) {
        let mut unwrap = EncoderUnwrap::new();
        let counts_per_us = f64::from(rpm) * 8192.0 / 60.0e6;
        for k in 0..=frames {
            let t = k * period_us;
            let true_counts = counts_per_us * t as f64;
            let angle = (true_counts.floor() as i64).rem_euclid(8192) as u16;
            unwrap.update(angle, rpm, t);
        }
        (
            unwrap.total_counts(),
            counts_per_us * (frames * period_us) as f64,
        )
    }

    #[test]
    fn wraps_at_top_speed_and_beyond() {
        // M3508 top speed is about 9 300 rpm at the rotor; test to the i16 limit of the field.
        for rpm in [9300i16, -9300, 16_000, -16_000, i16::MAX, i16::MIN + 1] {
            let (got, truth) = spin(rpm, 1000, 5000);
            assert!(
                (got as f64 - truth).abs() <= 1.0,
                "rpm {rpm}: {got} vs {truth}"
            );
        }
    }

    #[test]
    fn survives_lost_frames_where_shortest_path_fails() {
        // 9 300 rpm with only every 5th frame arriving: 6 350 counts between frames, more than
        // half a turn; the shortest-path rule would read it as about -1 840.
        let (got, truth) = spin(9300, 5000, 1000);
        assert!((got as f64 - truth).abs() <= 1.0, "{got} vs {truth}");
        // 10 ms gaps: 1.9 turns per gap.
        let (got, truth) = spin(-9300, 10_000, 500);
        assert!((got as f64 - truth).abs() <= 1.0, "{got} vs {truth}");
    }

    #[test]
    fn tolerates_speed_reading_error() {
        // The reported speed is 1 000 rpm off while the rotor turns at 9 000 rpm at 1 kHz.
        let mut unwrap = EncoderUnwrap::new();
        let mut truth = 0i64;
        for k in 0..2000u64 {
            let angle = truth.rem_euclid(8192) as u16;
            unwrap.update(angle, 8000, k * 1000);
            truth += 1229; // 9 000 rpm * 8192 / 60 000 per ms
        }
        assert_eq!(unwrap.total_counts(), truth - 1229);
    }

    #[test]
    fn conversions() {
        // One output turn = 3591/187 rotor turns.
        let counts = (8192.0f64 * 3591.0 / 187.0).round() as i64;
        assert!((counts_to_wheel_rad(counts) - core::f32::consts::TAU).abs() < 1e-3);
        // 482 rpm output is about 9 256 rpm rotor.
        let w = rpm_to_wheel_radps(9256);
        assert!(
            (w - 482.0 * core::f32::consts::TAU / 60.0).abs() < 0.05,
            "{w}"
        );
        assert!((wheel_radps_to_rpm(w) - 9256.0).abs() < 0.5);
    }

    #[test]
    fn straight_line_and_turn_in_place() {
        let g = Geometry {
            half_wheelbase_m: 0.12,
            half_track_m: 0.13,
            wheel_radius_m: 0.04,
        };
        let mut odo = Odometry::new();
        // 1 m forward in 1000 steps: each wheel turns 25 rad in total.
        for _ in 0..1000 {
            for w in 0..4 {
                odo.add_wheel(w, 0.025, 10.0);
            }
            odo.integrate(&g);
        }
        let p = odo.pose();
        assert!((p.x_m - 1.0).abs() < 1e-3 && p.y_m.abs() < 1e-5 && p.yaw_rad.abs() < 1e-6);
        assert!((odo.twist().vx_mps - 0.4).abs() < 1e-5);
        // Quarter turn CCW in place: yaw pi/2, position unchanged.
        let per_step = core::f32::consts::FRAC_PI_2 * g.k_m() / g.wheel_radius_m / 1000.0;
        for _ in 0..1000 {
            for (w, s) in [(0, -1.0), (1, 1.0), (2, -1.0), (3, 1.0)] {
                odo.add_wheel(w, s * per_step, 0.0);
            }
            odo.integrate(&g);
        }
        let p = odo.pose();
        assert!(
            (p.yaw_rad - core::f32::consts::FRAC_PI_2).abs() < 1e-4,
            "{p:?}"
        );
        assert!((p.x_m - 1.0).abs() < 1e-3 && p.y_m.abs() < 1e-4);
        // Then 0.5 m "forward" in the body frame goes along +y in the odometry frame.
        for _ in 0..500 {
            for w in 0..4 {
                odo.add_wheel(w, 0.025, 10.0);
            }
            odo.integrate(&g);
        }
        let p = odo.pose();
        assert!(
            (p.x_m - 1.0).abs() < 2e-3 && (p.y_m - 0.5).abs() < 2e-3,
            "{p:?}"
        );
    }

    #[test]
    fn arc_closes_into_a_circle() {
        // Drive a full circle of radius 0.5 m at 0.25 m/s: back at the start.
        let g = Geometry {
            half_wheelbase_m: 0.12,
            half_track_m: 0.13,
            wheel_radius_m: 0.04,
        };
        let twist = Twist::new(0.25, 0.0, 0.5);
        let dt = 0.001;
        let steps = (core::f32::consts::TAU / 0.5 / dt) as usize;
        let w = kinematics::inverse(&g, twist);
        let mut odo = Odometry::new();
        for _ in 0..steps {
            for (i, wi) in w.iter().enumerate() {
                odo.add_wheel(i, wi * dt, *wi);
            }
            odo.integrate(&g);
        }
        let p = odo.pose();
        assert!(p.x_m.abs() < 5e-3 && p.y_m.abs() < 5e-3, "{p:?}");
    }

    proptest! {
        #[test]
        fn unwrap_matches_truth_at_any_speed_and_gap(
            rpm in -9500i16..9500, period_us in 500u64..4000, frames in 1u64..400,
        ) {
            let (got, truth) = spin(rpm, period_us, frames);
            prop_assert!((got as f64 - truth).abs() <= 1.0, "{} vs {}", got, truth);
        }

        #[test]
        fn unwrap_never_panics(frames in proptest::collection::vec((any::<u16>(), any::<i16>(), any::<u64>()), 0..100)) {
            let mut unwrap = EncoderUnwrap::new();
            for (a, s, t) in frames {
                let _ = unwrap.update(a, s, t);
            }
        }

        #[test]
        fn wrap_angle_in_range(a in -1000.0f32..1000.0) {
            let w = wrap_angle(a);
            prop_assert!(w > -core::f32::consts::PI - 1e-6 && w <= core::f32::consts::PI + 1e-6);
            prop_assert!(libm::fabsf(libm::sinf(w) - libm::sinf(a)) < 1e-3);
        }
    }
}
