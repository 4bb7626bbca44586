//! Setpoint profile: moves a velocity setpoint toward a target with limited acceleration and,
//! optionally, limited jerk (an S-curve), then holds the target exactly (the constant cruise speed
//! the lidar motion model assumes).
//!
//! One [`Ramp`] per axis (vx, vy, wz); the axes are independent (each reaches its own target in its
//! own time), which is exact for the straight runs this robot makes and approximate for combined
//! motions.
//!
//! Jerk-limited law, per step of `dt`: with `dv = target - v`, the acceleration from which ramping
//! down to zero at jerk `j` lands exactly on the target is `a* = sign(dv) sqrt(2 j |dv|)`; the
//! acceleration moves toward `clamp(a*, -amax, amax)` by at most `j dt`, then `v += a dt`. A step
//! that would cross the target lands on it with `a = 0`, so the profile never overshoots. With
//! `jerk = None` (trapezoid) the acceleration jumps straight to `+-amax`.

/// Acceleration and jerk limits of one axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Largest acceleration magnitude, units/s^2 (> 0).
    pub accel: f32,
    /// Largest jerk magnitude, units/s^3 (> 0), or `None` for a trapezoid (unlimited jerk).
    pub jerk: Option<f32>,
}

/// State of one axis' setpoint.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Ramp {
    velocity: f32,
    accel: f32,
}

impl Ramp {
    /// A ramp at rest.
    pub const fn new() -> Self {
        Self {
            velocity: 0.0,
            accel: 0.0,
        }
    }

    /// Current setpoint velocity.
    pub fn velocity(&self) -> f32 {
        self.velocity
    }

    /// Current setpoint acceleration.
    pub fn accel(&self) -> f32 {
        self.accel
    }

    /// Whether the ramp sits at rest exactly (velocity and acceleration zero).
    pub fn is_at_rest(&self) -> bool {
        self.velocity == 0.0 && self.accel == 0.0
    }

    /// Whether the ramp has landed on `target` (it lands exactly, by construction of `step`).
    #[allow(clippy::float_cmp)]
    pub fn is_settled_at(&self, target: f32) -> bool {
        self.velocity == target && self.accel == 0.0
    }

    /// Jumps to rest (used when a fault zeroes the currents: the setpoint must not resume from
    /// where it was).
    pub fn reset(&mut self) {
        *self = Self::new();
    }

    /// Advances the setpoint by `dt_s` toward `target` and returns the new setpoint velocity.
    /// Non-finite or non-positive limits, targets or steps leave the state unchanged.
    pub fn step(&mut self, target: f32, limits: &Limits, dt_s: f32) -> f32 {
        let jerk_ok = limits.jerk.is_none_or(|j| j.is_finite() && j > 0.0);
        let inputs_ok = target.is_finite() && dt_s.is_finite() && dt_s > 0.0;
        if !(inputs_ok && limits.accel.is_finite() && limits.accel > 0.0 && jerk_ok) {
            return self.velocity;
        }
        let dv = target - self.velocity;
        let desired_accel = match limits.jerk {
            Some(jerk) => (libm::sqrtf(2.0 * jerk * dv.abs())).copysign(dv),
            None => limits.accel.copysign(dv),
        }
        .clamp(-limits.accel, limits.accel);
        self.accel = match limits.jerk {
            Some(jerk) => {
                let max_change = jerk * dt_s;
                self.accel + (desired_accel - self.accel).clamp(-max_change, max_change)
            }
            None => desired_accel,
        };
        let next = self.velocity + self.accel * dt_s;
        if dv == 0.0 || (target - next) * dv <= 0.0 {
            // Reached or crossed the target this step: land on it.
            self.velocity = target;
            self.accel = 0.0;
        } else {
            self.velocity = next;
        }
        self.velocity
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

    const DT: f32 = 0.001;

    fn run(ramp: &mut Ramp, target: f32, limits: &Limits, steps: usize) -> ([f32; 2], f32) {
        // Returns (max |accel|, max |jerk| seen), final velocity.
        let mut max_a = 0.0f32;
        let mut max_j = 0.0f32;
        let mut last_a = ramp.accel();
        for _ in 0..steps {
            ramp.step(target, limits, DT);
            max_a = max_a.max(ramp.accel().abs());
            max_j = max_j.max((ramp.accel() - last_a).abs() / DT);
            last_a = ramp.accel();
        }
        ([max_a, max_j], ramp.velocity())
    }

    #[test]
    fn trapezoid_reaches_target_in_expected_time() {
        let limits = Limits {
            accel: 0.5,
            jerk: None,
        };
        let mut ramp = Ramp::new();
        // 0.3 m/s at 0.5 m/s^2 takes 0.6 s = 600 steps.
        let mut steps = 0;
        while ramp.step(0.3, &limits, DT) < 0.3 {
            steps += 1;
            assert!(steps < 10_000);
        }
        assert!((599..=601).contains(&steps), "{steps}");
        assert_eq!(ramp.accel(), 0.0);
    }

    #[test]
    fn s_curve_respects_limits_and_never_overshoots() {
        let limits = Limits {
            accel: 0.5,
            jerk: Some(2.0),
        };
        let mut ramp = Ramp::new();
        let mut peak = 0.0f32;
        let mut last_a = 0.0f32;
        for _ in 0..5000 {
            let v = ramp.step(0.3, &limits, DT);
            peak = peak.max(v);
            assert!(ramp.accel().abs() <= 0.5 + 1e-6);
            // The last step may drop the acceleration to zero when landing on the target.
            if v < 0.3 {
                assert!((ramp.accel() - last_a).abs() <= 2.0 * DT + 1e-6);
            }
            last_a = ramp.accel();
        }
        assert_eq!(ramp.velocity(), 0.3);
        assert!(peak <= 0.3, "overshoot to {peak}");
    }

    #[test]
    fn s_curve_is_slower_than_trapezoid() {
        let trap = Limits {
            accel: 0.5,
            jerk: None,
        };
        let s = Limits {
            accel: 0.5,
            jerk: Some(2.0),
        };
        let count = |limits: &Limits| {
            let mut r = Ramp::new();
            (0..10_000)
                .take_while(|_| r.step(0.3, limits, DT) < 0.3)
                .count()
        };
        let (t, c) = (count(&trap), count(&s));
        // S-curve with a = 0.5, j = 2: the accel phases take a/j = 0.25 s each: about 0.85 s total.
        assert!(
            c > t && (800..=900).contains(&c),
            "trapezoid {t}, s-curve {c}"
        );
    }

    #[test]
    fn ramps_down_to_zero_from_cruise() {
        let limits = Limits {
            accel: 1.0,
            jerk: Some(10.0),
        };
        let mut ramp = Ramp::new();
        let _ = run(&mut ramp, -0.4, &limits, 2000);
        assert_eq!(ramp.velocity(), -0.4);
        let ([max_a, _], v) = run(&mut ramp, 0.0, &limits, 2000);
        assert_eq!(v, 0.0);
        assert!(ramp.is_at_rest());
        assert!(max_a <= 1.0 + 1e-6);
    }

    #[test]
    fn bad_limits_hold_state() {
        let mut ramp = Ramp::new();
        assert_eq!(
            ramp.step(
                1.0,
                &Limits {
                    accel: 0.0,
                    jerk: None
                },
                DT
            ),
            0.0
        );
        assert_eq!(
            ramp.step(
                1.0,
                &Limits {
                    accel: 1.0,
                    jerk: Some(f32::NAN)
                },
                DT
            ),
            0.0
        );
        assert_eq!(
            ramp.step(
                f32::NAN,
                &Limits {
                    accel: 1.0,
                    jerk: None
                },
                DT
            ),
            0.0
        );
    }

    proptest! {
        #[test]
        fn converges_without_overshoot(
            start in -1.0f32..1.0, target in -1.0f32..1.0,
            accel in 0.2f32..3.0, jerk in proptest::option::of(1.0f32..50.0),
        ) {
            let limits = Limits { accel, jerk };
            let mut ramp = Ramp::new();
            // Settle on `start` first.
            let _ = run(&mut ramp, start, &limits, 20_000);
            prop_assert_eq!(ramp.velocity(), start);
            let (lo, hi) = if start <= target { (start, target) } else { (target, start) };
            let mut max_a = 0.0f32;
            for _ in 0..20_000 {
                let v = ramp.step(target, &limits, DT);
                prop_assert!(v >= lo - 1e-6 && v <= hi + 1e-6, "v {} outside [{}, {}]", v, lo, hi);
                max_a = max_a.max(ramp.accel().abs());
            }
            prop_assert_eq!(ramp.velocity(), target);
            prop_assert!(max_a <= accel * (1.0 + 1e-5));
        }
    }
}
