//! A simple C620 + M3508 + wheel plant for host tests and the bench (approximate by design).
//!
//! Per wheel, at the output shaft: `J dw/dt = kt i - b w - tc sign(w) + disturbance`, with the
//! ESC's current loop as a first-order lag of `current_tau_s` on the commanded current. The four
//! wheels are independent (the chassis coupling through the rollers is not modelled), and the
//! reflected inertia lumps a quarter of the robot's mass at the wheel radius. The ESC reports what
//! a C620 reports: the rotor angle quantised to 8192 counts, the rotor speed in whole rpm (plus a
//! seeded measurement noise), the actual current and the temperature.

use control::odometry::wheel_radps_to_rpm;
use protocol::esc::{EscFeedback, M3508_GEAR_RATIO, raw_to_amps};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Plant parameters.
#[derive(Debug, Clone, Copy)]
pub struct PlantParams {
    /// Output torque per amp, N m / A (M3508: 0.3).
    pub kt_nm_per_a: f32,
    /// Reflected inertia at the output shaft, kg m^2.
    pub inertia_kgm2: f32,
    /// Viscous friction, N m s / rad.
    pub viscous_nms: f32,
    /// Coulomb friction, N m.
    pub coulomb_nm: f32,
    /// ESC current-loop time constant, s.
    pub current_tau_s: f32,
    /// Standard deviation of a white load-torque disturbance, N m (floor roughness, roller bumps).
    pub disturbance_nm: f32,
    /// Standard deviation of the ESC's speed reading noise, rotor rpm.
    pub speed_noise_rpm: f32,
}

impl Default for PlantParams {
    fn default() -> Self {
        // 8 kg robot, 0.038 m wheels: 2 kg * 0.038^2 = 0.0029 kg m^2, plus the rotor reflected
        // through the 19.2:1 gearbox (about 0.004 kg m^2).
        Self {
            kt_nm_per_a: 0.3,
            inertia_kgm2: 0.007,
            viscous_nms: 0.002,
            coulomb_nm: 0.05,
            current_tau_s: 0.001,
            disturbance_nm: 0.05,
            speed_noise_rpm: 8.0,
        }
    }
}

/// One simulated wheel with its ESC.
#[derive(Debug, Clone, Copy, Default)]
pub struct MotorState {
    /// Output shaft speed, rad/s (motor positive direction).
    pub speed_radps: f32,
    /// Output shaft angle, rad (continuous).
    pub angle_rad: f64,
    /// Actual current, A.
    pub current_a: f32,
    /// Reported temperature, C.
    pub temperature_c: u8,
    /// Wheel blocked (stall test).
    pub locked: bool,
}

/// Four wheels, indexed by ESC slot (id - 1).
pub struct Plant {
    pub params: PlantParams,
    pub motors: [MotorState; 4],
    rng: ChaCha8Rng,
}

impl Plant {
    pub fn new(params: PlantParams, seed: u64) -> Self {
        let motor = MotorState {
            temperature_c: 35,
            ..MotorState::default()
        };
        Self {
            params,
            motors: [motor; 4],
            rng: ChaCha8Rng::seed_from_u64(seed),
        }
    }

    fn gauss(&mut self) -> f32 {
        // Sum of 4 uniforms, scaled to unit variance: cheap and seeded.
        let s: f32 = (0..4).map(|_| self.rng.random::<f32>() - 0.5).sum();
        s * 3.0f32.sqrt()
    }

    /// Advances `dt_s` with the raw commanded currents (per ESC slot).
    pub fn advance(&mut self, currents_raw: [i16; 4], dt_s: f32) {
        let p = self.params;
        for (slot, current_raw) in currents_raw.into_iter().enumerate() {
            let disturbance = p.disturbance_nm * self.gauss();
            let m = &mut self.motors[slot];
            let commanded = raw_to_amps(current_raw);
            m.current_a += (commanded - m.current_a) * (dt_s / (p.current_tau_s + dt_s));
            if m.locked {
                m.speed_radps = 0.0;
                continue;
            }
            let drive = p.kt_nm_per_a * m.current_a + disturbance;
            let friction = p.viscous_nms * m.speed_radps;
            let mut accel = (drive - friction) / p.inertia_kgm2;
            // Coulomb friction: opposes motion, or holds the wheel when the drive cannot beat it.
            if m.speed_radps.abs() < 1e-3 && drive.abs() <= p.coulomb_nm {
                m.speed_radps = 0.0;
                accel = 0.0;
            } else {
                let sign = if m.speed_radps.abs() >= 1e-3 {
                    m.speed_radps.signum()
                } else {
                    drive.signum()
                };
                accel -= sign * p.coulomb_nm / p.inertia_kgm2;
            }
            m.speed_radps += accel * dt_s;
            m.angle_rad += f64::from(m.speed_radps * dt_s);
        }
    }

    /// What ESC `slot` reports now.
    pub fn feedback(&mut self, slot: usize) -> EscFeedback {
        let noise = self.params.speed_noise_rpm * self.gauss();
        let m = &self.motors[slot];
        let rotor_turns = m.angle_rad * f64::from(M3508_GEAR_RATIO) / core::f64::consts::TAU;
        let angle_raw = (rotor_turns.rem_euclid(1.0) * 8192.0).floor() as u16 % 8192;
        let rpm = (wheel_radps_to_rpm(m.speed_radps) + noise).round();
        EscFeedback {
            angle_raw,
            speed_rpm: rpm.clamp(-32767.0, 32767.0) as i16,
            current_raw: protocol::esc::amps_to_raw(m.current_a),
            temperature_c: m.temperature_c,
        }
    }
}
