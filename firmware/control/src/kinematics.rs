//! Mecanum kinematics for the standard X configuration (45-degree rollers, rollers of the four
//! wheels forming an X seen from above).
//!
//! Body frame: x forward, y left, z up, yaw counter-clockwise. `k = lx + ly`, where `lx` is half
//! the wheelbase and `ly` half the track. Wheel speeds are output-shaft angular speeds in rad/s,
//! positive when the wheel rolls the robot forward, in the order [`Wheel::ALL`] (FL, FR, RL, RR):
//!
//! ```text
//! inverse:  w_FL = (vx - vy - k wz) / r      forward:  vx = r/4   ( w_FL + w_FR + w_RL + w_RR)
//!           w_FR = (vx + vy + k wz) / r                vy = r/4   (-w_FL + w_FR + w_RL - w_RR)
//!           w_RL = (vx + vy - k wz) / r                wz = r/(4k)(-w_FL + w_FR - w_RL + w_RR)
//!           w_RR = (vx - vy + k wz) / r
//! ```
//!
//! (notes/domain.md B6). Forward kinematics is the least-squares inverse of the over-determined
//! 4-wheel system, so a wheel-speed set that no rigid twist produces (slip) is projected onto the
//! nearest twist. Which ESC drives which wheel, and in which direction, is [`crate::config::WheelMap`].

/// A wheel position on the chassis. The discriminant is the index into wheel arrays.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Wheel {
    /// Front left.
    FrontLeft = 0,
    /// Front right.
    FrontRight = 1,
    /// Rear left.
    RearLeft = 2,
    /// Rear right.
    RearRight = 3,
}

impl Wheel {
    /// All wheels in array order.
    pub const ALL: [Self; 4] = [
        Self::FrontLeft,
        Self::FrontRight,
        Self::RearLeft,
        Self::RearRight,
    ];

    /// Short name for logs and docs.
    pub fn name(self) -> &'static str {
        match self {
            Self::FrontLeft => "FL",
            Self::FrontRight => "FR",
            Self::RearLeft => "RL",
            Self::RearRight => "RR",
        }
    }
}

/// Chassis geometry.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Geometry {
    /// Half the wheelbase (centre to axle, along x), metres.
    pub half_wheelbase_m: f32,
    /// Half the track (centre to wheel contact, along y), metres.
    pub half_track_m: f32,
    /// Mecanum wheel radius (roller envelope), metres.
    pub wheel_radius_m: f32,
}

impl Geometry {
    /// `k = lx + ly`, metres.
    pub fn k_m(&self) -> f32 {
        self.half_wheelbase_m + self.half_track_m
    }
}

/// A planar body twist in the body frame.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Twist {
    /// Forward speed, m/s.
    pub vx_mps: f32,
    /// Leftward speed, m/s.
    pub vy_mps: f32,
    /// Yaw rate (counter-clockwise), rad/s.
    pub wz_radps: f32,
}

impl Twist {
    /// A twist from its three components.
    pub const fn new(vx_mps: f32, vy_mps: f32, wz_radps: f32) -> Self {
        Self {
            vx_mps,
            vy_mps,
            wz_radps,
        }
    }

    /// The zero twist.
    pub const ZERO: Self = Self::new(0.0, 0.0, 0.0);
}

/// Inverse kinematics: wheel speeds (rad/s, FL, FR, RL, RR) that produce `twist`.
pub fn inverse(geometry: &Geometry, twist: Twist) -> [f32; 4] {
    let Twist {
        vx_mps: vx,
        vy_mps: vy,
        wz_radps: wz,
    } = twist;
    let kw = geometry.k_m() * wz;
    let r = geometry.wheel_radius_m;
    [
        (vx - vy - kw) / r,
        (vx + vy + kw) / r,
        (vx + vy - kw) / r,
        (vx - vy + kw) / r,
    ]
}

/// Forward kinematics: the least-squares body twist of wheel speeds (rad/s, FL, FR, RL, RR).
/// Also maps wheel angle increments (rad) to body displacement increments (m, m, rad).
pub fn forward(geometry: &Geometry, wheel_radps: [f32; 4]) -> Twist {
    let [fl, fr, rl, rr] = wheel_radps;
    let r4 = geometry.wheel_radius_m / 4.0;
    Twist {
        vx_mps: r4 * (fl + fr + rl + rr),
        vy_mps: r4 * (-fl + fr + rl - rr),
        wz_radps: r4 / geometry.k_m() * (-fl + fr - rl + rr),
    }
}

/// Scales a wheel-speed set down uniformly so that no wheel exceeds `max_radps`, keeping the
/// twist's direction (what DJI's chassis task does). Returns the set unchanged when within limits.
pub fn limit_wheel_speeds(wheel_radps: [f32; 4], max_radps: f32) -> [f32; 4] {
    let peak = wheel_radps.iter().fold(0.0f32, |m, w| m.max(w.abs()));
    if peak <= max_radps || peak <= 0.0 {
        return wheel_radps;
    }
    let scale = max_radps / peak;
    wheel_radps.map(|w| w * scale)
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

    const G: Geometry = Geometry {
        half_wheelbase_m: 0.12,
        half_track_m: 0.13,
        wheel_radius_m: 0.04,
    };

    fn close(a: f32, b: f32) -> bool {
        (a - b).abs() <= 1e-4 * (1.0 + a.abs().max(b.abs()))
    }

    #[test]
    fn known_vectors() {
        // Pure forward at 0.4 m/s: every wheel at v / r = 10 rad/s.
        assert_eq!(inverse(&G, Twist::new(0.4, 0.0, 0.0)), [10.0; 4]);
        // Pure left strafe at 0.4 m/s: FL and RR backwards, FR and RL forwards.
        let w = inverse(&G, Twist::new(0.0, 0.4, 0.0));
        assert!(close(w[0], -10.0) && close(w[1], 10.0) && close(w[2], 10.0) && close(w[3], -10.0));
        // Pure CCW rotation at 1 rad/s: k = 0.25 m, rim speed 0.25 m/s, 6.25 rad/s; left side back.
        let w = inverse(&G, Twist::new(0.0, 0.0, 1.0));
        assert!(close(w[0], -6.25) && close(w[1], 6.25) && close(w[2], -6.25) && close(w[3], 6.25));
    }

    #[test]
    fn forward_of_known_wheel_sets() {
        let t = forward(&G, [10.0, 10.0, 10.0, 10.0]);
        assert!(close(t.vx_mps, 0.4) && close(t.vy_mps, 0.0) && close(t.wz_radps, 0.0));
        // Only the front-left wheel turns: a quarter of its rim speed forward, a quarter right,
        // and clockwise yaw.
        let t = forward(&G, [4.0, 0.0, 0.0, 0.0]);
        assert!(close(t.vx_mps, 0.04) && close(t.vy_mps, -0.04) && close(t.wz_radps, -0.16));
    }

    #[test]
    fn limit_keeps_direction() {
        let w = limit_wheel_speeds([20.0, -40.0, 10.0, 0.0], 20.0);
        assert_eq!(w, [10.0, -20.0, 5.0, 0.0]);
        assert_eq!(
            limit_wheel_speeds([1.0, 2.0, 3.0, 4.0], 20.0),
            [1.0, 2.0, 3.0, 4.0]
        );
    }

    proptest! {
        #[test]
        fn inverse_then_forward_is_identity(
            vx in -2.0f32..2.0, vy in -2.0f32..2.0, wz in -4.0f32..4.0,
            lx in 0.05f32..0.5, ly in 0.05f32..0.5, r in 0.02f32..0.1,
        ) {
            let g = Geometry { half_wheelbase_m: lx, half_track_m: ly, wheel_radius_m: r };
            let t = forward(&g, inverse(&g, Twist::new(vx, vy, wz)));
            prop_assert!(close(t.vx_mps, vx), "vx {} vs {}", t.vx_mps, vx);
            prop_assert!(close(t.vy_mps, vy), "vy {} vs {}", t.vy_mps, vy);
            prop_assert!(close(t.wz_radps, wz), "wz {} vs {}", t.wz_radps, wz);
        }

        /// Forward kinematics is a projection: applying IK after FK to an arbitrary (slipping)
        /// wheel set and then FK again gives the same twist.
        #[test]
        fn forward_is_a_projection(w in proptest::array::uniform4(-50.0f32..50.0)) {
            let t1 = forward(&G, w);
            let t2 = forward(&G, inverse(&G, t1));
            prop_assert!(close(t1.vx_mps, t2.vx_mps) && close(t1.vy_mps, t2.vy_mps));
            prop_assert!(close(t1.wz_radps, t2.wz_radps));
        }

        #[test]
        fn limited_wheels_stay_in_bounds(w in proptest::array::uniform4(-100.0f32..100.0), max in 1.0f32..60.0) {
            let l = limit_wheel_speeds(w, max);
            for (a, b) in l.iter().zip(w) {
                prop_assert!(a.abs() <= max * (1.0 + 1e-6));
                prop_assert!(a * b >= 0.0, "sign kept");
            }
        }
    }
}
