//! Step 3, motion compensation (paper section 3.2, eq. 1).
//!
//! A VLP-16 sweep takes 0.1 s; at 0.3 m/s the robot moves 3 cm meanwhile, the size of the error
//! budget. Every point carries its firing time `t` since the frame's first firing; it is moved into
//! the robot frame at the frame's start, assuming the robot's velocity is constant over the sweep:
//!
//! - straight motion (eq. 1): `p_start = p_t + v * t`, where `v` is the robot-frame velocity
//!   from wheel odometry. The paper writes it with the travel direction `A` and the scan angle
//!   `theta / omega_r` (= `t`); with `v = |v| (cos A, sin A)` the two forms are identical. The
//!   paper's empirical scale factor alpha is 1 here: the wheels' speed is taken as it is, since a
//!   slip of a few per cent moves a point by about a millimetre over the 0.1 s sweep (3 % of
//!   3 cm), far below the lidar's range noise.
//! - general constant twist (the fallback when the yaw rate is not negligible):
//!   `p_start = exp(w t) p_t + v t` (first order in `t` for the translation, exact rotation).

use super::config::DeskewConfig;
use super::geom::{V3, exp_so3};

/// The robot's velocity over a sweep, robot frame.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Velocity {
    /// Linear velocity, m/s.
    pub linear_mps: V3,
    /// Angular velocity, rad/s.
    pub angular_radps: V3,
}

/// Which model [`deskew`] used.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DeskewModel {
    /// Nothing done (disabled).
    None,
    /// Eq. 1, straight constant-velocity motion.
    Straight,
    /// Constant twist.
    Twist,
}

/// Move each point (robot frame at its own firing time `times_s[i]` after the frame start) into the
/// robot frame at the frame start, in place.
pub fn deskew(
    points_in_robot: &mut [V3],
    times_s: &[f64],
    velocity: Velocity,
    config: &DeskewConfig,
) -> DeskewModel {
    if !config.enabled {
        return DeskewModel::None;
    }
    let v = velocity.linear_mps;
    if velocity.angular_radps.norm() <= config.straight_max_yaw_rate_radps {
        for (p, &t) in points_in_robot.iter_mut().zip(times_s) {
            *p += v * t;
        }
        DeskewModel::Straight
    } else {
        for (p, &t) in points_in_robot.iter_mut().zip(times_s) {
            let r = exp_so3(velocity.angular_radps * t);
            *p = r * *p + v * t;
        }
        DeskewModel::Twist
    }
}

#[cfg(test)]
mod tests {
    use super::super::geom::Pose;
    use super::*;

    /// A fixed world point seen from a robot moving with a constant twist comes back to the same
    /// start-frame coordinates whatever its firing time.
    #[test]
    fn static_point_is_restored_for_both_models() {
        let world_point = V3::new(2.0, 0.5, 0.3);
        for velocity in [
            Velocity {
                linear_mps: V3::new(0.3, 0.0, 0.0),
                angular_radps: V3::zeros(),
            },
            Velocity {
                linear_mps: V3::new(0.3, 0.05, 0.0),
                angular_radps: V3::new(0.0, 0.0, 0.4),
            },
        ] {
            let times: Vec<f64> = (0..10).map(|i| f64::from(i) * 0.01).collect();
            let mut points: Vec<V3> = times
                .iter()
                .map(|&t| {
                    // start_from_t = (exp(w t), v t) to first order, exact for w = 0.
                    let start_from_t = Pose {
                        rotation: exp_so3(velocity.angular_radps * t),
                        translation: velocity.linear_mps * t,
                    };
                    start_from_t.inverse().apply(world_point)
                })
                .collect();
            let model = deskew(&mut points, &times, velocity, &DeskewConfig::default());
            for p in &points {
                assert!(
                    (*p - world_point).norm_squared() < 1e-20,
                    "{model:?}: {p:?}"
                );
            }
        }
    }

    #[test]
    fn disabled_does_nothing() {
        let mut points = vec![V3::new(1.0, 0.0, 0.0)];
        let c = DeskewConfig {
            enabled: false,
            ..DeskewConfig::default()
        };
        let v = Velocity {
            linear_mps: V3::new(1.0, 0.0, 0.0),
            angular_radps: V3::zeros(),
        };
        assert_eq!(deskew(&mut points, &[0.1], v, &c), DeskewModel::None);
        assert_eq!(points, vec![V3::new(1.0, 0.0, 0.0)]);
    }
}
