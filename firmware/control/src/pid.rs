//! Wheel-speed PID: wheel speed error (rad/s, output shaft) in, motor current (A) out.
//!
//! Parallel form `u = kp e + ki integral(e) + kd d(measurement)/dt` with:
//! - derivative on the measurement (no kick when the setpoint steps), low-pass filtered;
//! - anti-windup by conditional integration: the integrator only moves when the output is not
//!   saturated, or when the error would pull it out of saturation, and it is itself clamped to
//!   `integral_limit_a`;
//! - the output clamped to `output_limit_a` (the configured current limit, at most the C620's 20 A).
//!
//! `dt` is an input (the controller's measured step), never read from a clock.

/// PID gains and limits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PidGains {
    /// Proportional gain, A per rad/s.
    pub kp: f32,
    /// Integral gain, A per rad (per rad/s per second).
    pub ki: f32,
    /// Derivative gain, A per rad/s^2.
    pub kd: f32,
    /// Derivative low-pass time constant, seconds (0 = unfiltered).
    pub kd_filter_s: f32,
    /// Largest magnitude of the integral term, amperes.
    pub integral_limit_a: f32,
    /// Largest magnitude of the output, amperes.
    pub output_limit_a: f32,
}

/// State of one PID loop.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Pid {
    integral_a: f32,
    last_measured: Option<f32>,
    derivative: f32,
}

impl Pid {
    /// A loop at rest.
    pub const fn new() -> Self {
        Self {
            integral_a: 0.0,
            last_measured: None,
            derivative: 0.0,
        }
    }

    /// Forgets all state (after a stop or a fault, so no stale integral drives the wheel later).
    pub fn reset(&mut self) {
        *self = Self::new();
    }

    /// The integral term, amperes (for tests and telemetry).
    pub fn integral_a(&self) -> f32 {
        self.integral_a
    }

    /// One update. Returns the current command in amperes, within `+-gains.output_limit_a`.
    /// Non-finite inputs or `dt_s <= 0` give zero output and reset the loop.
    pub fn update(&mut self, gains: &PidGains, setpoint: f32, measured: f32, dt_s: f32) -> f32 {
        if !(setpoint.is_finite() && measured.is_finite() && dt_s.is_finite() && dt_s > 0.0) {
            self.reset();
            return 0.0;
        }
        let limit = gains.output_limit_a.abs();
        let error = setpoint - measured;

        let raw_derivative = self
            .last_measured
            .map_or(0.0, |last| -(measured - last) / dt_s);
        self.last_measured = Some(measured);
        let alpha = if gains.kd_filter_s > 0.0 {
            dt_s / (gains.kd_filter_s + dt_s)
        } else {
            1.0
        };
        self.derivative += alpha * (raw_derivative - self.derivative);

        let p = gains.kp * error;
        let d = gains.kd * self.derivative;
        let unsaturated = p + self.integral_a + d;
        let saturated_high = unsaturated >= limit && error > 0.0;
        let saturated_low = unsaturated <= -limit && error < 0.0;
        if !(saturated_high || saturated_low) {
            let i_limit = gains.integral_limit_a.abs().min(limit);
            self.integral_a = (self.integral_a + gains.ki * error * dt_s).clamp(-i_limit, i_limit);
        }
        (p + self.integral_a + d).clamp(-limit, limit)
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

    const GAINS: PidGains = PidGains {
        kp: 0.5,
        ki: 10.0,
        kd: 0.0,
        kd_filter_s: 0.0,
        integral_limit_a: 5.0,
        output_limit_a: 10.0,
    };

    #[test]
    fn proportional_and_integral_terms() {
        let mut pid = Pid::new();
        // First step: p = 0.5 * 2 = 1 A, i = 10 * 2 * 0.001 = 0.02 A.
        let u = pid.update(&GAINS, 2.0, 0.0, 0.001);
        assert!((u - 1.02).abs() < 1e-6, "{u}");
        assert!((pid.integral_a() - 0.02).abs() < 1e-6);
    }

    #[test]
    fn integrator_does_not_wind_up_in_saturation() {
        let mut pid = Pid::new();
        // A huge error saturates the output: the integral must not grow.
        for _ in 0..1000 {
            let u = pid.update(&GAINS, 100.0, 0.0, 0.001);
            assert_eq!(u, 10.0);
        }
        assert_eq!(pid.integral_a(), 0.0);
        // Error reverses: the output leaves saturation at once, with no stored integral to unwind.
        let u = pid.update(&GAINS, 0.0, 1.0, 0.001);
        assert!(u < 0.0, "{u}");
    }

    #[test]
    fn integral_is_clamped() {
        let mut pid = Pid::new();
        let g = PidGains { kp: 0.0, ..GAINS };
        for _ in 0..100_000 {
            pid.update(&g, 1.0, 0.0, 0.001);
        }
        assert_eq!(pid.integral_a(), 5.0);
    }

    #[test]
    fn bad_inputs_give_zero_and_reset() {
        let mut pid = Pid::new();
        pid.update(&GAINS, 1.0, 0.0, 0.001);
        assert_eq!(pid.update(&GAINS, f32::NAN, 0.0, 0.001), 0.0);
        assert_eq!(pid.integral_a(), 0.0);
        assert_eq!(pid.update(&GAINS, 1.0, 0.0, 0.0), 0.0);
        assert_eq!(pid.update(&GAINS, 1.0, f32::INFINITY, 0.001), 0.0);
    }

    #[test]
    fn derivative_acts_on_measurement_only() {
        let g = PidGains {
            kp: 0.0,
            ki: 0.0,
            kd: 0.01,
            ..GAINS
        };
        let mut pid = Pid::new();
        assert_eq!(pid.update(&g, 0.0, 0.0, 0.001), 0.0);
        // A setpoint step gives no derivative kick.
        assert_eq!(pid.update(&g, 50.0, 0.0, 0.001), 0.0);
        // Measurement rising at 1000 rad/s^2 gives -10 A of damping.
        let u = pid.update(&g, 50.0, 1.0, 0.001);
        assert!((u + 10.0).abs() < 1e-3, "{u}");
    }

    proptest! {
        #[test]
        fn output_always_within_limit(
            steps in proptest::collection::vec((-1e6f32..1e6, -1e6f32..1e6, 0.0f32..0.1), 1..200),
            limit in 0.0f32..20.0,
        ) {
            let g = PidGains { output_limit_a: limit, kd: 0.001, kd_filter_s: 0.002, ..GAINS };
            let mut pid = Pid::new();
            for (sp, m, dt) in steps {
                let u = pid.update(&g, sp, m, dt);
                prop_assert!(u.is_finite() && u.abs() <= limit, "{} > {}", u, limit);
            }
        }
    }
}
