//! Simulated wheel odometry: what the firmware's forward kinematics would report while the robot
//! drives a scenario's [`StraightRun`], with a seeded error model for a mecanum chassis.
//!
//! The scenario's `slip` already makes the wheels overestimate the distance by a constant factor.
//! Real mecanum odometry is worse than a constant factor: the rollers' contact changes as they
//! turn, so the effective scale, the sideways creep and the left-right balance (the yaw rate the
//! kinematics report while driving straight) wander along the run. [`WheelNoise`] models that as
//! three first-order Gauss-Markov processes (relative scale error, lateral velocity error, yaw-rate
//! error) plus a constant yaw-rate bias drawn per run. All zero (the default) gives exact wheels
//! but for the slip, as the simulator's figures before this model assumed.
//!
//! **Approximate, and not measured on the robot.** [`WheelNoise::TYPICAL_MECANUM`] is an
//! assumption from the general experience with mecanum platforms on hard floors (a few per cent of
//! distance, a few degrees of heading over a few metres), not from this robot's data; replace it
//! with figures from a real run (drive a known straight line, compare the odometry's scale, its
//! heading and their spread) before trusting any result that depends on it.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::Deserialize;

use crate::d435::gaussian;
use crate::trajectory::{StraightRun, Trajectory};
use pipeline::WheelOdometry;

/// The wheel odometry's error model (scenario table `[wheel_odometry]`, every key optional).
#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct WheelNoise {
    /// Standard deviation of the relative scale error of the distance increments (0.01: the
    /// wheels read 1 % long or short, varying), on top of the scenario's constant slip.
    #[serde(default)]
    pub scale_sigma: f64,
    /// Correlation time of the scale error, seconds.
    #[serde(default = "default_tau")]
    pub scale_tau_s: f64,
    /// Standard deviation of the lateral (body y) velocity error, m/s.
    #[serde(default)]
    pub lateral_sigma_mps: f64,
    /// Correlation time of the lateral error, seconds.
    #[serde(default = "default_tau")]
    pub lateral_tau_s: f64,
    /// Standard deviation of the constant yaw-rate bias drawn for each run, degrees per second.
    #[serde(default)]
    pub yaw_rate_bias_sigma_degps: f64,
    /// Standard deviation of the wandering yaw-rate error, degrees per second.
    #[serde(default)]
    pub yaw_rate_sigma_degps: f64,
    /// Correlation time of the yaw-rate error, seconds.
    #[serde(default = "default_tau")]
    pub yaw_rate_tau_s: f64,
    /// A constant relative scale error per run, uniform in +- this (0.02: the wheels read up to
    /// 2 % long or short for the whole run), on top of the wandering one.
    #[serde(default)]
    pub scale_error_max: f64,
    /// A constant yaw-rate bias per run whose magnitude is uniform in `[min, max]` degrees per
    /// second, with a random sign (`[0.1, 0.3]`: a left-right imbalance of the rollers), on top
    /// of the Gaussian one.
    #[serde(default)]
    pub yaw_rate_bias_range_degps: [f64; 2],
}

fn default_tau() -> f64 {
    1.0
}

impl Default for WheelNoise {
    fn default() -> Self {
        Self::EXACT
    }
}

impl WheelNoise {
    /// Exact wheels (but for the scenario's slip).
    pub const EXACT: Self = Self {
        scale_sigma: 0.0,
        scale_tau_s: 1.0,
        lateral_sigma_mps: 0.0,
        lateral_tau_s: 1.0,
        yaw_rate_bias_sigma_degps: 0.0,
        yaw_rate_sigma_degps: 0.0,
        yaw_rate_tau_s: 1.0,
        scale_error_max: 0.0,
        yaw_rate_bias_range_degps: [0.0, 0.0],
    };

    /// An assumed mecanum chassis on a hard floor (see the module docs: not measured): scale
    /// error 1 % (1 s), lateral creep 3 mm/s (0.5 s), yaw-rate bias 0.1 deg/s per run (0.3 deg
    /// per metre at 0.3 m/s, 2-2.5 degrees over a pass) and yaw-rate wander 0.2 deg/s (0.3 s).
    pub const TYPICAL_MECANUM: Self = Self {
        scale_sigma: 0.01,
        scale_tau_s: 1.0,
        lateral_sigma_mps: 0.003,
        lateral_tau_s: 0.5,
        yaw_rate_bias_sigma_degps: 0.1,
        yaw_rate_sigma_degps: 0.2,
        yaw_rate_tau_s: 0.3,
        scale_error_max: 0.0,
        yaw_rate_bias_range_degps: [0.0, 0.0],
    };

    /// True when every error is zero.
    pub fn is_exact(&self) -> bool {
        self.scale_sigma == 0.0
            && self.lateral_sigma_mps == 0.0
            && self.yaw_rate_bias_sigma_degps == 0.0
            && self.yaw_rate_sigma_degps == 0.0
            && self.scale_error_max == 0.0
            && self.yaw_rate_bias_range_degps[1] == 0.0
    }

    /// The first invalid field and why: standard deviations finite and non-negative (at most
    /// 0.5 relative, 1 m/s, 45 deg/s), correlation times in (0, 1000] s.
    pub fn validate(&self) -> Result<(), (String, String)> {
        let sigmas = [
            ("scale_sigma", self.scale_sigma, 0.5),
            ("lateral_sigma_mps", self.lateral_sigma_mps, 1.0),
            (
                "yaw_rate_bias_sigma_degps",
                self.yaw_rate_bias_sigma_degps,
                45.0,
            ),
            ("yaw_rate_sigma_degps", self.yaw_rate_sigma_degps, 45.0),
        ];
        for (name, v, max) in sigmas {
            if !(0.0..=max).contains(&v) {
                return Err((
                    format!("wheel_odometry.{name}"),
                    format!("must lie in [0, {max}], got {v}"),
                ));
            }
        }
        if !(0.0..=0.2).contains(&self.scale_error_max) {
            return Err((
                "wheel_odometry.scale_error_max".to_owned(),
                format!("must lie in [0, 0.2], got {}", self.scale_error_max),
            ));
        }
        let [lo, hi] = self.yaw_rate_bias_range_degps;
        if !(lo >= 0.0 && lo <= hi && hi <= 45.0) {
            return Err((
                "wheel_odometry.yaw_rate_bias_range_degps".to_owned(),
                format!("need 0 <= min <= max <= 45, got [{lo}, {hi}]"),
            ));
        }
        let taus = [
            ("scale_tau_s", self.scale_tau_s),
            ("lateral_tau_s", self.lateral_tau_s),
            ("yaw_rate_tau_s", self.yaw_rate_tau_s),
        ];
        for (name, v) in taus {
            if !(v > 0.0 && v <= 1000.0) {
                return Err((
                    format!("wheel_odometry.{name}"),
                    format!("must lie in (0, 1000] s, got {v}"),
                ));
            }
        }
        Ok(())
    }
}

/// A first-order Gauss-Markov process sampled every `dt`: stationary from its first value.
struct GaussMarkov {
    value: f64,
    decay: f64,
    drive: f64,
}

impl GaussMarkov {
    fn new(sigma: f64, tau_s: f64, dt_s: f64, rng: &mut ChaCha8Rng) -> Self {
        let decay = (-dt_s / tau_s).exp();
        Self {
            value: sigma * gaussian(rng),
            decay,
            drive: sigma * (1.0 - decay * decay).sqrt(),
        }
    }

    fn step(&mut self, rng: &mut ChaCha8Rng) -> f64 {
        let v = self.value;
        self.value = self.decay * self.value + self.drive * gaussian(rng);
        v
    }
}

/// Wheel odometry at `rate_hz` over `[0, duration_s]` for `run`, with `noise` drawn from `seed`.
///
/// The exact part is the wheels' distance along the body's direction of travel (a crabbing robot's
/// body frame sees its travel at minus the yaw misalignment), yaw constant. The errors are
/// integrated on top of it: each step's body displacement is scaled by `1 + scale error`, gets
/// the lateral error, and is turned by the accumulated yaw error. With [`WheelNoise::EXACT`] the
/// output is the exact part to the bit.
pub fn simulate(
    run: &StraightRun,
    noise: &WheelNoise,
    seed: u64,
    duration_s: f64,
    rate_hz: f64,
) -> Vec<WheelOdometry> {
    let dt = 1.0 / rate_hz;
    let (s, c) = (-run.yaw_misalignment_rad).sin_cos();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (scale_const, bias_const_radps) = constant_errors(noise, seed);
    let bias_radps =
        noise.yaw_rate_bias_sigma_degps.to_radians() * gaussian(&mut rng) + bias_const_radps;
    let mut scale = GaussMarkov::new(noise.scale_sigma, noise.scale_tau_s, dt, &mut rng);
    let mut lateral = GaussMarkov::new(noise.lateral_sigma_mps, noise.lateral_tau_s, dt, &mut rng);
    let yaw_sigma = noise.yaw_rate_sigma_degps.to_radians();
    let mut yaw_rate = GaussMarkov::new(yaw_sigma, noise.yaw_rate_tau_s, dt, &mut rng);
    // Accumulated errors: position in the odometry frame, heading.
    let (mut ex, mut ey, mut eyaw) = (0.0_f64, 0.0_f64, 0.0_f64);
    let steps = (duration_s * rate_hz) as u32;
    let mut out = Vec::with_capacity(steps as usize + 1);
    for i in 0..=steps {
        let t = f64::from(i) * dt;
        let d = run.wheel_distance_at(t);
        let v = (run.wheel_distance_at(t + 0.5 * dt)
            - run.wheel_distance_at(t - 0.5 * dt).max(0.0))
            / dt;
        let (e_scale, e_lat, e_wz) = (
            scale.step(&mut rng) + scale_const,
            lateral.step(&mut rng),
            bias_radps + yaw_rate.step(&mut rng),
        );
        out.push(WheelOdometry {
            stamp_s: t,
            x_m: d * c + ex,
            y_m: d * s + ey,
            yaw_rad: eyaw,
            vx_mps: v * c * (1.0 + e_scale),
            vy_mps: v * s * (1.0 + e_scale) + e_lat,
            wz_radps: e_wz,
        });
        // The step to the next sample: the exact body displacement, its errors, turned by the
        // heading error at the step's middle.
        let step = run.wheel_distance_at(t + dt) - d;
        let (bx, by) = (step * c, step * s);
        let (nx, ny) = (bx * (1.0 + e_scale), by * (1.0 + e_scale) + e_lat * dt);
        let (sy, cy) = (eyaw + 0.5 * e_wz * dt).sin_cos();
        ex += cy * nx - sy * ny - bx;
        ey += sy * nx + cy * ny - by;
        eyaw += e_wz * dt;
    }
    out
}

/// The run's constant scale error and yaw-rate bias (rad/s) from `scale_error_max` and
/// `yaw_rate_bias_range_degps`, drawn on their own stream (`derive_seed(seed, 21)`) so that the
/// Gauss-Markov errors of a seed stay the same with or without them.
pub fn constant_errors(noise: &WheelNoise, seed: u64) -> (f64, f64) {
    use rand::Rng;
    let [lo, hi] = noise.yaw_rate_bias_range_degps;
    if noise.scale_error_max == 0.0 && hi == 0.0 {
        return (0.0, 0.0);
    }
    let mut rng = ChaCha8Rng::seed_from_u64(crate::scenario::derive_seed(seed, 21));
    let scale = noise.scale_error_max * rng.random_range(-1.0..=1.0);
    let magnitude = lo + (hi - lo) * rng.random::<f64>();
    let sign = if rng.random::<bool>() { 1.0 } else { -1.0 };
    (scale, sign * magnitude.to_radians())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Vec3;
    use crate::trajectory::Vibration;

    fn run(slip: f64, misalignment_rad: f64) -> StraightRun {
        StraightRun {
            start_m: Vec3::new(2.0, 0.0, 0.0),
            heading_rad: std::f64::consts::PI,
            yaw_misalignment_rad: misalignment_rad,
            speed_mps: 0.3,
            accel_mps2: 0.5,
            slip,
            vibration: Vibration::new(0.0, 0.0, 1),
            still_s: 0.0,
            stop_after_m: None,
        }
    }

    #[test]
    #[allow(clippy::float_cmp)] // Exact to the bit is the point: the figures before this model.
    fn exact_wheels_report_the_wheel_distance_along_the_body_travel() {
        let r = run(0.03, 0.02);
        let odo = simulate(&r, &WheelNoise::EXACT, 5, 10.0, 100.0);
        assert_eq!(odo.len(), 1001);
        for w in &odo {
            let d = r.wheel_distance_at(w.stamp_s);
            assert_eq!(w.x_m, d * (-0.02_f64).cos());
            assert_eq!(w.y_m, d * (-0.02_f64).sin());
            assert_eq!((w.yaw_rad, w.wz_radps), (0.0, 0.0));
        }
        // Cruising at 0.3 m/s of wheel speed (the slip is in the true motion, not the wheels).
        let v = odo[900].vx_mps.hypot(odo[900].vy_mps);
        assert!((v - 0.3).abs() < 1e-9, "{v}");
    }

    #[test]
    fn the_same_seed_gives_the_same_odometry_and_another_seed_another() {
        let r = run(0.0, 0.0);
        let n = WheelNoise::TYPICAL_MECANUM;
        let a = simulate(&r, &n, 1, 5.0, 100.0);
        assert_eq!(a, simulate(&r, &n, 1, 5.0, 100.0));
        assert_ne!(a, simulate(&r, &n, 2, 5.0, 100.0));
    }

    /// Sample mean and standard deviation.
    fn mean_sd(v: &[f64]) -> (f64, f64) {
        let n = v.len() as f64;
        let m = v.iter().sum::<f64>() / n;
        (
            m,
            (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt(),
        )
    }

    #[test]
    fn errors_grow_as_the_model_says() {
        // Over T = 20 s of cruise the integral of a Gauss-Markov error (sigma, tau << T) has
        // variance 2 sigma^2 tau T (less a tau/T correction); a constant bias b gives b T.
        let mut r = run(0.0, 0.0);
        r.accel_mps2 = 0.0;
        let t = 20.0;
        let only = |n: WheelNoise| -> Vec<WheelOdometry> {
            (1..=300)
                .map(|seed| *simulate(&r, &n, seed, t, 100.0).last().unwrap())
                .collect()
        };
        // Scale: the along-track error of the final position, 1 % with tau 1 s.
        let scale = only(WheelNoise {
            scale_sigma: 0.01,
            ..WheelNoise::EXACT
        });
        let along: Vec<f64> = scale.iter().map(|w| w.x_m - 0.3 * t).collect();
        let (m, sd) = mean_sd(&along);
        let want = 0.3 * 0.01 * (2.0 * 1.0 * t * (1.0 - 1.0 / t)).sqrt();
        assert!(m.abs() < 3.0 * want / 300f64.sqrt(), "mean {m}");
        assert!((sd / want - 1.0).abs() < 0.15, "sd {sd} want {want}");
        assert!(scale.iter().all(|w| w.yaw_rad == 0.0 && w.y_m == 0.0));
        // Lateral: the final y, 3 mm/s with tau 0.5 s.
        let lateral = only(WheelNoise {
            lateral_sigma_mps: 0.003,
            lateral_tau_s: 0.5,
            ..WheelNoise::EXACT
        });
        let ys: Vec<f64> = lateral.iter().map(|w| w.y_m).collect();
        let want = 0.003 * (2.0 * 0.5 * t * (1.0 - 0.5 / t)).sqrt();
        let (_, sd) = mean_sd(&ys);
        assert!((sd / want - 1.0).abs() < 0.15, "sd {sd} want {want}");
        // Yaw bias: the final heading's spread is bias_sigma * T.
        let bias = only(WheelNoise {
            yaw_rate_bias_sigma_degps: 0.1,
            ..WheelNoise::EXACT
        });
        let yaws: Vec<f64> = bias.iter().map(|w| w.yaw_rad.to_degrees()).collect();
        let (_, sd) = mean_sd(&yaws);
        assert!((sd / 2.0 - 1.0).abs() < 0.15, "sd {sd} deg, want 2");
        // A heading error turns the travel: y drifts by about the mean heading error times the
        // distance (half the final heading for a constant rate).
        for w in &bias {
            let predicted = 0.5 * w.yaw_rad * 0.3 * t;
            assert!(
                (w.y_m - predicted).abs() < 1e-3 + 0.01 * predicted.abs(),
                "{w:?}"
            );
        }
    }

    #[test]
    fn constant_errors_stay_within_their_ranges_and_shift_the_whole_run() {
        let mut r = run(0.0, 0.0);
        r.accel_mps2 = 0.0;
        let n = WheelNoise {
            scale_error_max: 0.02,
            yaw_rate_bias_range_degps: [0.1, 0.3],
            ..WheelNoise::EXACT
        };
        assert!(!n.is_exact());
        let (mut pos, mut neg) = (0, 0);
        for seed in 1..=200 {
            let (scale, bias) = constant_errors(&n, seed);
            assert!(scale.abs() <= 0.02, "{scale}");
            let b = bias.to_degrees().abs();
            assert!((0.1..=0.3).contains(&b), "{b}");
            pos += usize::from(bias > 0.0);
            neg += usize::from(bias < 0.0);
            // The final heading is the bias times the run's time; the distance along the body
            // is the wheel distance times (1 + scale), to first order.
            let odo = simulate(&r, &n, seed, 10.0, 100.0);
            let last = odo.last().expect("samples");
            assert!((last.yaw_rad - bias * 10.0).abs() < 1e-9, "{last:?}");
            let along = last.x_m.hypot(last.y_m);
            assert!((along / 3.0 - 1.0 - scale).abs() < 2e-3, "{along} {scale}");
        }
        assert!(pos > 70 && neg > 70, "signs {pos} / {neg}");
        assert_eq!(constant_errors(&WheelNoise::EXACT, 3), (0.0, 0.0));
    }
}
