//! DJI C620 ESC + M3508 motor models (docs/architecture.md section 7), one per wheel.
//!
//! What one [`Esc`] does, per simulated millisecond:
//! - holds the last current command it received in a 0x200/0x1FF frame (a real C620 does too: the
//!   firmware must itself command zero on a fault);
//! - follows it with a first-order current loop (`current_tau_s`) and turns it into output-shaft
//!   torque `kt_nm_per_a * I` (0.3 N m/A for the M3508 behind its 3591/187 gearbox);
//! - heats the motor by `I^2 R` through a single thermal mass to ambient
//!   (`C dT/dt = I^2 R - (T - T_amb) / R_th`);
//! - reports what a C620 reports, every 1 ms: the rotor angle quantised to 0..8191, the rotor speed
//!   in whole rpm (plus seeded noise), the actual current in raw units and the temperature in whole
//!   degrees.
//!
//! The wheel's speed and angle come from the chassis model ([`crate::robot`]), which owns the
//! mechanics; the ESC only turns currents into torques and states into frames.
//!
//! Faults ([`EscFault`]) are injected by the scenario: an ESC that stops answering, a current stuck
//! at a value whatever the command, and an over-temperature (the motor's temperature forced up).
//!
//! Approximations, on purpose: the current loop is ideal apart from its lag and the +-20 A clamp
//! (no back-EMF voltage limit: at 0.2 m/s the M3508 runs at about 5 % of its no-load speed), and
//! the thermal model is one lump with textbook-order constants, not a measured curve.

use protocol::esc::{self, EscFeedback};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::can_bus::CanFrame;

/// Parameters of one C620 + M3508 pair.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EscParams {
    /// Output-shaft torque per amp, N m/A (M3508 with its gearbox: 0.3).
    pub kt_nm_per_a: f32,
    /// Time constant of the C620's current loop, s.
    pub current_tau_s: f32,
    /// Winding resistance (phase to phase), ohm: M3508 0.194.
    pub winding_resistance_ohm: f32,
    /// Heat capacity of the motor, J/K (about 0.36 kg of copper and steel).
    pub heat_capacity_j_per_k: f32,
    /// Thermal resistance motor to ambient, K/W.
    pub thermal_resistance_k_per_w: f32,
    /// Ambient and starting temperature, degrees C.
    pub ambient_c: f32,
    /// Standard deviation of the reported rotor speed, rpm (the C620's speed estimate is noisy).
    pub speed_noise_rpm: f32,
}

impl Default for EscParams {
    fn default() -> Self {
        Self {
            kt_nm_per_a: 0.3,
            current_tau_s: 0.001,
            winding_resistance_ohm: 0.194,
            heat_capacity_j_per_k: 180.0,
            thermal_resistance_k_per_w: 2.0,
            ambient_c: 25.0,
            speed_noise_rpm: 3.0,
        }
    }
}

/// A fault injected into one ESC.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum EscFault {
    /// The ESC stops sending feedback (it still obeys commands, as a C620 with a broken feedback
    /// path would).
    Silent,
    /// The ESC's current is stuck at this value, A, whatever it is commanded.
    StuckCurrent(f32),
    /// The motor's temperature is forced to this value, degrees C (e.g. a blocked fan).
    OverTemperature(f32),
}

/// One simulated C620 with its M3508.
#[derive(Debug, Clone)]
pub struct Esc {
    /// ESC id (1..=8): its feedback goes out as 0x200 + id.
    pub esc_id: u8,
    params: EscParams,
    commanded_a: f32,
    current_a: f32,
    temperature_c: f32,
    faults: Vec<EscFault>,
    /// Motor power through the robot's contactor ([`Esc::set_powered`]).
    powered: bool,
    rng: ChaCha8Rng,
}

impl Esc {
    /// An ESC at rest at ambient temperature; `seed` drives its measurement noise.
    pub fn new(esc_id: u8, params: EscParams, seed: u64) -> Self {
        Self {
            esc_id,
            params,
            commanded_a: 0.0,
            current_a: 0.0,
            temperature_c: params.ambient_c,
            faults: Vec::new(),
            powered: true,
            rng: ChaCha8Rng::seed_from_u64(seed ^ u64::from(esc_id).wrapping_mul(0x9E37_79B9)),
        }
    }

    /// Injects a fault (faults accumulate; [`Esc::clear_faults`] removes them).
    pub fn inject(&mut self, fault: EscFault) {
        self.faults.push(fault);
    }

    /// Removes every injected fault (the motor keeps its temperature and cools normally).
    pub fn clear_faults(&mut self) {
        self.faults.clear();
    }

    /// Switches the ESC's power (the robot's motor contactor). Without power the ESC drives no
    /// current (the motor coasts), sends no feedback and ignores commands; when power returns it
    /// starts as after a reset, commanded zero. Injected faults stay: a stuck output stage is
    /// stuck again when powered, and a hot motor stays hot and cools at its own rate.
    pub fn set_powered(&mut self, on: bool) {
        if on && !self.powered {
            self.commanded_a = 0.0;
        }
        self.powered = on;
    }

    /// Whether the ESC has power.
    pub fn is_powered(&self) -> bool {
        self.powered
    }

    /// Whether the ESC answers on the bus.
    pub fn is_silent(&self) -> bool {
        !self.powered || self.faults.contains(&EscFault::Silent)
    }

    /// Applies a command frame if it addresses this ESC (0x200 for ids 1-4, 0x1FF for 5-8);
    /// returns whether it did. Malformed command frames are ignored, as a C620 ignores them.
    pub fn on_frame(&mut self, frame: &CanFrame) -> bool {
        if !self.powered {
            return false;
        }
        let Ok((id, currents)) = esc::parse_command_frame(frame) else {
            return false;
        };
        match esc::command_slot(self.esc_id) {
            Some((cmd_id, slot)) if cmd_id == id => {
                self.commanded_a = esc::raw_to_amps(currents[slot]);
                true
            }
            _ => false,
        }
    }

    /// The current the ESC was last commanded, A.
    pub fn commanded_a(&self) -> f32 {
        self.commanded_a
    }

    /// The actual motor current, A.
    pub fn current_a(&self) -> f32 {
        self.current_a
    }

    /// Motor temperature, degrees C.
    pub fn temperature_c(&self) -> f32 {
        self.temperature_c
    }

    /// Output-shaft torque in the motor's positive direction, N m.
    pub fn torque_nm(&self) -> f32 {
        self.params.kt_nm_per_a * self.current_a
    }

    /// Advances the current loop and the thermal model by `dt_s`.
    pub fn advance(&mut self, dt_s: f32) {
        let p = &self.params;
        let stuck = self.faults.iter().find_map(|f| match f {
            EscFault::StuckCurrent(a) => Some(*a),
            _ => None,
        });
        let target = stuck
            .unwrap_or(self.commanded_a)
            .clamp(-esc::CURRENT_MAX_A, esc::CURRENT_MAX_A);
        if !self.powered {
            self.current_a = 0.0;
        } else if stuck.is_some() {
            self.current_a = target;
        } else {
            self.current_a += (target - self.current_a) * (dt_s / (p.current_tau_s + dt_s));
        }
        let heat_w = self.current_a * self.current_a * p.winding_resistance_ohm;
        let loss_w = (self.temperature_c - p.ambient_c) / p.thermal_resistance_k_per_w;
        self.temperature_c += (heat_w - loss_w) * dt_s / p.heat_capacity_j_per_k;
        if let Some(forced) = self.faults.iter().find_map(|f| match f {
            EscFault::OverTemperature(t) => Some(*t),
            _ => None,
        }) {
            self.temperature_c = self.temperature_c.max(forced);
        }
    }

    /// The feedback frame for a motor whose output shaft is at `shaft_angle_rad` turning at
    /// `shaft_radps` (both in the motor's positive direction), or `None` when the ESC is silent.
    pub fn feedback(&mut self, shaft_angle_rad: f64, shaft_radps: f32) -> Option<CanFrame> {
        if self.is_silent() {
            return None;
        }
        let fb = self.feedback_values(shaft_angle_rad, shaft_radps);
        esc::feedback_frame(self.esc_id, &fb).ok()
    }

    fn feedback_values(&mut self, shaft_angle_rad: f64, shaft_radps: f32) -> EscFeedback {
        let gear = f64::from(esc::M3508_GEAR_RATIO);
        let rotor_turns = shaft_angle_rad * gear / std::f64::consts::TAU;
        let counts = f64::from(esc::ENCODER_COUNTS);
        let angle_raw =
            ((rotor_turns.rem_euclid(1.0) * counts).floor() as u16) % esc::ENCODER_COUNTS;
        let rotor_rpm = shaft_radps * esc::M3508_GEAR_RATIO * 60.0 / std::f32::consts::TAU;
        let noise = self.params.speed_noise_rpm * gauss(&mut self.rng);
        EscFeedback {
            angle_raw,
            speed_rpm: (rotor_rpm + noise).round().clamp(-32767.0, 32767.0) as i16,
            current_raw: esc::amps_to_raw(self.current_a),
            temperature_c: self.temperature_c.round().clamp(0.0, 255.0) as u8,
        }
    }
}

/// A zero-mean, unit-variance sample (sum of four uniforms): cheap, seeded, bounded.
pub(crate) fn gauss(rng: &mut ChaCha8Rng) -> f32 {
    let s: f32 = (0..4).map(|_| rng.random::<f32>() - 0.5).sum();
    s * 3.0f32.sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quiet() -> EscParams {
        EscParams {
            speed_noise_rpm: 0.0,
            ..EscParams::default()
        }
    }

    #[test]
    fn holds_last_command_and_follows_it_with_a_lag() {
        let mut e = Esc::new(2, quiet(), 1);
        let cmd: CanFrame = esc::command_frame(0x200, [0, 8192, 0, 0]).unwrap();
        assert!(e.on_frame(&cmd));
        e.advance(0.001);
        assert!((e.current_a() - 5.0).abs() < 0.01, "{}", e.current_a());
        for _ in 0..20 {
            e.advance(0.001);
        }
        assert!((e.current_a() - 10.0).abs() < 0.01);
        assert!((e.torque_nm() - 3.0).abs() < 0.01);
        // A frame for ids 5-8 does not touch ESC 2.
        let other: CanFrame = esc::command_frame(0x1FF, [0; 4]).unwrap();
        assert!(!e.on_frame(&other));
        assert!((e.commanded_a() - 10.0).abs() < 1e-3);
    }

    #[test]
    fn feedback_quantises_angle_and_reports_rotor_rpm() {
        let mut e = Esc::new(1, quiet(), 1);
        // Half a rotor turn: shaft angle = pi / gear.
        let shaft = std::f64::consts::PI / f64::from(esc::M3508_GEAR_RATIO);
        let f = e.feedback(shaft, 1.0).unwrap();
        let (id, fb) = esc::parse_feedback_frame(&f).unwrap();
        assert_eq!(id, 1);
        assert!(
            fb.angle_raw == 4095 || fb.angle_raw == 4096,
            "{}",
            fb.angle_raw
        );
        // 1 rad/s at the shaft = 183.4 rpm at the rotor.
        assert_eq!(fb.speed_rpm, 183);
        assert_eq!(fb.temperature_c, 25);
    }

    #[test]
    fn heats_with_i_squared_r() {
        let mut e = Esc::new(1, quiet(), 1);
        e.inject(EscFault::StuckCurrent(10.0));
        for _ in 0..60_000 {
            e.advance(0.001);
        }
        // 19.4 W into 180 J/K for 60 s, minus the loss to ambient: about +6 K.
        let rise = e.temperature_c() - 25.0;
        assert!(rise > 5.0 && rise < 6.5, "{rise}");
    }

    #[test]
    fn faults_silence_stick_and_overheat() {
        let mut e = Esc::new(3, quiet(), 1);
        e.inject(EscFault::Silent);
        assert!(e.feedback(0.0, 0.0).is_none());
        e.clear_faults();
        e.inject(EscFault::StuckCurrent(-4.0));
        let cmd: CanFrame = esc::command_frame(0x200, [0; 4]).unwrap();
        e.on_frame(&cmd);
        e.advance(0.001);
        assert!((e.current_a() + 4.0).abs() < 1e-6);
        e.inject(EscFault::OverTemperature(95.0));
        e.advance(0.001);
        let (_, fb) = esc::parse_feedback_frame(&e.feedback(0.0, 0.0).unwrap()).unwrap();
        assert_eq!(fb.temperature_c, 95);
    }

    #[test]
    fn without_power_a_stuck_esc_drives_nothing_and_is_silent() {
        let mut e = Esc::new(1, quiet(), 1);
        e.inject(EscFault::StuckCurrent(18.0));
        e.advance(0.001);
        assert!((e.current_a() - 18.0).abs() < 1e-6);
        e.set_powered(false);
        e.advance(0.001);
        assert!(e.current_a().abs() < 1e-9);
        assert!(e.feedback(0.0, 0.0).is_none());
        let cmd: CanFrame = esc::command_frame(0x200, [1000, 0, 0, 0]).unwrap();
        assert!(!e.on_frame(&cmd), "an unpowered ESC ignores commands");
        // Power back: commanded zero, but the stuck output stage is stuck again.
        e.set_powered(true);
        assert!(e.commanded_a().abs() < 1e-9);
        e.advance(0.001);
        assert!((e.current_a() - 18.0).abs() < 1e-6);
        assert!(e.feedback(0.0, 0.0).is_some());
    }
}
