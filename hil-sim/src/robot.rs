//! The mecanum robot's mechanics: four wheels driven by the ESC models, a rigid chassis on flat
//! ground, and its pose over time, which is the ground truth for the firmware's odometry (and,
//! through [`PoseHistory`], the trajectory the VLP-16 and D435 models can be driven along).
//!
//! Model (planar, body frame x forward, y left, z up; wheels FL, FR, RL, RR):
//! - Wheel `i` spins at `w_i` (output shaft, rad/s, positive rolling the robot forward):
//!   `J_w dw_i/dt = s_i tau_i - r F_i - b w_i - tc tanh(w_i / w_c)`, where `tau_i` is the ESC's
//!   torque in the motor's direction and `s_i` the mounting sign (`-1` on the mirrored right side).
//! - Mecanum contact: with ideal 45-degree rollers wheel `i` rolls without slip when
//!   `r w_i = g_i . (vx, vy, k wz)` with `g = (1,-1,-1), (1,1,1), (1,1,-1), (1,-1,1)` (the rows of
//!   `control::kinematics::inverse`). The difference is the slip speed `u_i`; the ground pushes
//!   back with `F_i = clamp(c u_i, +-mu N_i)` (a stiff linear slip law saturating at Coulomb
//!   friction). `c` (`slip_stiffness_n_per_mps`) sets how much the wheels creep under load, `mu`
//!   when they spin out; both are the "configurable slip".
//! - Chassis: by virtual work, the contact forces act on the body as
//!   `(Fx, Fy, Mz) = sum_i F_i (g_i0, g_i1, k g_i2)`; plus rolling resistance `c_rr m g` against
//!   the velocity. `m dv/dt = F - m w x v`, `I_z dwz/dt = Mz`.
//! - Integration: semi-implicit Euler with `substeps` per millisecond (the slip law is stiff).
//!
//! Approximations: no load transfer between wheels, no roller gaps, flat ground; tanh-smoothed
//! Coulomb friction in the gearbox. Good enough for velocity ripple, odometry drift from creep and
//! the fault scenarios; not a tyre model.

use std::fmt::Write as _;

use control::kinematics::Geometry;

use crate::geometry::{Pose, Vec3};
use crate::trajectory::{SampledTrajectory, TrajectoryError};

/// Standard gravity, m/s^2.
const G_MPS2: f32 = 9.81;

/// Rows of the mecanum relation (see the module docs), order FL, FR, RL, RR.
const ROWS: [[f32; 3]; 4] = [
    [1.0, -1.0, -1.0],
    [1.0, 1.0, 1.0],
    [1.0, 1.0, -1.0],
    [1.0, -1.0, 1.0],
];

/// Mechanical parameters of the robot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobotParams {
    /// Chassis geometry (same meaning as the firmware's).
    pub geometry: Geometry,
    /// Mass with sensors, kg.
    pub mass_kg: f32,
    /// Yaw inertia, kg m^2.
    pub yaw_inertia_kgm2: f32,
    /// Inertia of one wheel with its gearbox and the rotor reflected through it, kg m^2.
    pub wheel_inertia_kgm2: f32,
    /// Viscous friction in each drive train, N m s/rad.
    pub viscous_nms: f32,
    /// Coulomb friction in each drive train, N m.
    pub coulomb_nm: f32,
    /// Rolling resistance coefficient (force / weight).
    pub rolling_resistance: f32,
    /// Slip stiffness per wheel, N per m/s of slip speed.
    pub slip_stiffness_n_per_mps: f32,
    /// Friction coefficient wheel/ground (traction limit = mu * m g / 4 per wheel).
    pub friction_coefficient: f32,
    /// Mounting sign per wheel: +1 when positive motor torque rolls it forward.
    pub wheel_signs: [i8; 4],
    /// ESC id per wheel (FL, FR, RL, RR).
    pub esc_ids: [u8; 4],
    /// Integration substeps per millisecond.
    pub substeps: u32,
}

impl Default for RobotParams {
    fn default() -> Self {
        Self {
            geometry: Geometry {
                half_wheelbase_m: 0.12,
                half_track_m: 0.115,
                wheel_radius_m: 0.038,
            },
            mass_kg: 8.0,
            // A 0.38 x 0.3 m box of 8 kg: m (a^2 + b^2) / 12.
            yaw_inertia_kgm2: 0.16,
            // Rotor 1.6e-5 kg m^2 * 19.2^2 plus the wheel.
            wheel_inertia_kgm2: 0.006,
            viscous_nms: 0.002,
            coulomb_nm: 0.05,
            rolling_resistance: 0.02,
            slip_stiffness_n_per_mps: 800.0,
            friction_coefficient: 0.6,
            wheel_signs: [1, -1, 1, -1],
            esc_ids: [1, 2, 3, 4],
            substeps: 10,
        }
    }
}

/// The robot's planar pose and twist at one instant (world frame = odometry frame at start).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PoseSample {
    /// Simulation time, microseconds (the firmware's MCU clock in the simulator).
    pub stamp_us: u64,
    /// Position, m.
    pub x_m: f64,
    /// Position, m.
    pub y_m: f64,
    /// Heading, rad (unwrapped).
    pub yaw_rad: f64,
    /// Body velocity, m/s (robot frame).
    pub vx_mps: f32,
    /// Body velocity, m/s (robot frame).
    pub vy_mps: f32,
    /// Yaw rate, rad/s.
    pub wz_radps: f32,
    /// Forward distance the wheel encoders report, m: `r` times the mean wheel angle (the
    /// forward-kinematics x increment). Exceeds the true distance by the wheels' creep.
    pub wheel_distance_m: f64,
}

/// The robot's poses over a run, one per simulated millisecond: the ground truth for odometry and
/// the input trajectory for the sensor models.
#[derive(Debug, Clone, Default)]
pub struct PoseHistory {
    /// Samples in time order.
    pub samples: Vec<PoseSample>,
}

impl PoseHistory {
    /// The pose at `stamp_us`, linearly interpolated (clamped to the recorded span).
    pub fn at(&self, stamp_us: u64) -> Option<PoseSample> {
        let s = &self.samples;
        let idx = s.partition_point(|p| p.stamp_us <= stamp_us);
        match (idx.checked_sub(1).and_then(|i| s.get(i)), s.get(idx)) {
            (Some(a), Some(b)) => {
                let f = (stamp_us - a.stamp_us) as f64 / (b.stamp_us - a.stamp_us).max(1) as f64;
                let lerp = |x: f64, y: f64| x + (y - x) * f;
                let lerpf = |x: f32, y: f32| x + (y - x) * f as f32;
                Some(PoseSample {
                    stamp_us,
                    x_m: lerp(a.x_m, b.x_m),
                    y_m: lerp(a.y_m, b.y_m),
                    yaw_rad: lerp(a.yaw_rad, b.yaw_rad),
                    vx_mps: lerpf(a.vx_mps, b.vx_mps),
                    vy_mps: lerpf(a.vy_mps, b.vy_mps),
                    wz_radps: lerpf(a.wz_radps, b.wz_radps),
                    wheel_distance_m: lerp(a.wheel_distance_m, b.wheel_distance_m),
                })
            }
            (Some(a), None) => Some(*a),
            (None, Some(b)) => Some(*b),
            (None, None) => None,
        }
    }

    /// The history as a [`SampledTrajectory`] for the VLP-16 and D435 models: the odometry
    /// frame (the robot's pose at time 0) is placed at `world_from_start` in the world (vehicle)
    /// frame. Planar: the start pose's roll and pitch are kept, yaw and position compose.
    pub fn to_trajectory(
        &self,
        world_from_start: &Pose,
    ) -> Result<SampledTrajectory, TrajectoryError> {
        let (sin, cos) = world_from_start.yaw_rad.sin_cos();
        let p0 = world_from_start.position_m;
        let samples = self
            .samples
            .iter()
            .map(|s| {
                let pose = Pose {
                    position_m: Vec3::new(
                        p0.x + cos * s.x_m - sin * s.y_m,
                        p0.y + sin * s.x_m + cos * s.y_m,
                        p0.z,
                    ),
                    roll_rad: world_from_start.roll_rad,
                    pitch_rad: world_from_start.pitch_rad,
                    yaw_rad: world_from_start.yaw_rad + s.yaw_rad,
                };
                (s.stamp_us as f64 * 1e-6, pose, s.wheel_distance_m)
            })
            .collect();
        SampledTrajectory::new(samples)
    }

    /// The history as CSV (`stamp_us,x_m,y_m,yaw_rad,vx_mps,vy_mps,wz_radps,wheel_distance_m`).
    pub fn to_csv(&self) -> String {
        let mut out =
            String::from("stamp_us,x_m,y_m,yaw_rad,vx_mps,vy_mps,wz_radps,wheel_distance_m\n");
        for p in &self.samples {
            let _ = writeln!(
                out,
                "{},{:.6},{:.6},{:.6},{:.5},{:.5},{:.5},{:.6}",
                p.stamp_us,
                p.x_m,
                p.y_m,
                p.yaw_rad,
                p.vx_mps,
                p.vy_mps,
                p.wz_radps,
                p.wheel_distance_m
            );
        }
        out
    }
}

/// The robot's mechanical state.
#[derive(Debug, Clone)]
pub struct Robot {
    params: RobotParams,
    /// Wheel speeds, rad/s, wheel-forward positive (FL, FR, RL, RR).
    wheel_radps: [f32; 4],
    /// Wheel angles, rad, wheel-forward positive (continuous).
    wheel_rad: [f64; 4],
    vx_mps: f32,
    vy_mps: f32,
    wz_radps: f32,
    x_m: f64,
    y_m: f64,
    yaw_rad: f64,
    /// Extra per-wheel traction scale (1 = nominal), e.g. one wheel on a slippery patch.
    traction_scale: [f32; 4],
}

impl Robot {
    /// A robot at rest at the origin.
    pub fn new(params: RobotParams) -> Self {
        Self {
            params,
            wheel_radps: [0.0; 4],
            wheel_rad: [0.0; 4],
            vx_mps: 0.0,
            vy_mps: 0.0,
            wz_radps: 0.0,
            x_m: 0.0,
            y_m: 0.0,
            yaw_rad: 0.0,
            traction_scale: [1.0; 4],
        }
    }

    /// Parameters.
    pub fn params(&self) -> &RobotParams {
        &self.params
    }

    /// Scales one wheel's traction limit (1 = nominal; 0.1 = ice).
    pub fn set_traction_scale(&mut self, wheel: usize, scale: f32) {
        if let Some(s) = self.traction_scale.get_mut(wheel) {
            *s = scale.max(0.0);
        }
    }

    /// Wheel `wheel`'s shaft angle and speed in its motor's direction (what its encoder sees).
    pub fn motor_shaft(&self, wheel: usize) -> (f64, f32) {
        let sign = self.sign(wheel);
        (
            f64::from(sign) * self.wheel_rad[wheel],
            sign * self.wheel_radps[wheel],
        )
    }

    /// Wheel speeds, rad/s, wheel-forward positive.
    pub fn wheel_radps(&self) -> [f32; 4] {
        self.wheel_radps
    }

    fn sign(&self, wheel: usize) -> f32 {
        if self.params.wheel_signs[wheel] < 0 {
            -1.0
        } else {
            1.0
        }
    }

    /// The current pose and twist, stamped `stamp_us`.
    pub fn sample(&self, stamp_us: u64) -> PoseSample {
        PoseSample {
            stamp_us,
            x_m: self.x_m,
            y_m: self.y_m,
            yaw_rad: self.yaw_rad,
            vx_mps: self.vx_mps,
            vy_mps: self.vy_mps,
            wz_radps: self.wz_radps,
            wheel_distance_m: f64::from(self.params.geometry.wheel_radius_m)
                * self.wheel_rad.iter().sum::<f64>()
                / 4.0,
        }
    }

    /// Advances by `dt_s` with the given motor torques (N m, motor direction, per wheel).
    pub fn advance(&mut self, motor_torque_nm: [f32; 4], dt_s: f32) {
        let n = self.params.substeps.max(1);
        let h = dt_s / n as f32;
        for _ in 0..n {
            self.substep(motor_torque_nm, h);
        }
    }

    fn substep(&mut self, motor_torque_nm: [f32; 4], h: f32) {
        let p = self.params;
        let r = p.geometry.wheel_radius_m;
        let k = p.geometry.k_m();
        let body = [self.vx_mps, self.vy_mps, k * self.wz_radps];
        let traction_limit = p.friction_coefficient * p.mass_kg * G_MPS2 / 4.0;
        let mut generalized = [0.0f32; 3];
        for i in 0..4 {
            let row = ROWS[i];
            let ground_speed = row[0] * body[0] + row[1] * body[1] + row[2] * body[2];
            let slip_mps = r * self.wheel_radps[i] - ground_speed;
            let limit = traction_limit * self.traction_scale[i];
            let force_n = (p.slip_stiffness_n_per_mps * slip_mps).clamp(-limit, limit);
            let w = self.wheel_radps[i];
            let drive = self.sign(i) * motor_torque_nm[i];
            let friction = p.viscous_nms * w + p.coulomb_nm * (w / 0.05).tanh();
            let accel = (drive - r * force_n - friction) / p.wheel_inertia_kgm2;
            self.wheel_radps[i] += accel * h;
            self.wheel_rad[i] += f64::from(self.wheel_radps[i] * h);
            for (g, row_j) in generalized.iter_mut().zip(row) {
                *g += force_n * row_j;
            }
        }
        let speed = self.vx_mps.hypot(self.vy_mps);
        let rolling_n = p.rolling_resistance * p.mass_kg * G_MPS2;
        // Rolling resistance, smoothed at rest so it cannot reverse the motion.
        let rr = rolling_n * (speed / 0.005).tanh();
        let (rx, ry) = if speed > 0.0 {
            (rr * self.vx_mps / speed, rr * self.vy_mps / speed)
        } else {
            (0.0, 0.0)
        };
        let ax = (generalized[0] - rx) / p.mass_kg + self.wz_radps * self.vy_mps;
        let ay = (generalized[1] - ry) / p.mass_kg - self.wz_radps * self.vx_mps;
        let alpha = k * generalized[2] / p.yaw_inertia_kgm2;
        self.vx_mps += ax * h;
        self.vy_mps += ay * h;
        self.wz_radps += alpha * h;
        let (sin, cos) = self.yaw_rad.sin_cos();
        let (vx, vy) = (f64::from(self.vx_mps), f64::from(self.vy_mps));
        let hd = f64::from(h);
        self.x_m += (cos * vx - sin * vy) * hd;
        self.y_m += (sin * vx + cos * vy) * hd;
        self.yaw_rad += f64::from(self.wz_radps) * hd;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn equal_forward_torques_drive_straight_and_reach_a_balance() {
        let mut robot = Robot::new(RobotParams::default());
        // Motor directions: right side mirrored, so forward torque is negative there.
        let t = 0.12;
        for _ in 0..3000 {
            robot.advance([t, -t, t, -t], 0.001);
        }
        let s = robot.sample(3_000_000);
        assert!(s.vx_mps > 0.1, "{s:?}");
        assert!(s.vy_mps.abs() < 1e-4 && s.wz_radps.abs() < 1e-4, "{s:?}");
        assert!(s.y_m.abs() < 1e-4 && s.yaw_rad.abs() < 1e-4);
        // The wheels creep a little under load: rim speed slightly above ground speed.
        let rim = robot.wheel_radps()[0] * 0.038;
        assert!(
            rim > s.vx_mps && rim < s.vx_mps * 1.05,
            "rim {rim} body {}",
            s.vx_mps
        );
    }

    #[test]
    fn mecanum_pattern_moves_sideways() {
        let mut robot = Robot::new(RobotParams::default());
        // vy > 0: FL -, FR +, RL +, RR - (wheel-forward), then mounting signs.
        let t = 0.15;
        for _ in 0..2000 {
            robot.advance([-t, -t, t, t], 0.001);
        }
        let s = robot.sample(0);
        assert!(s.vy_mps > 0.05, "{s:?}");
        assert!(s.vx_mps.abs() < 1e-3 && s.wz_radps.abs() < 1e-3, "{s:?}");
    }

    #[test]
    fn coasts_to_rest_without_torque() {
        let mut robot = Robot::new(RobotParams::default());
        for _ in 0..1000 {
            robot.advance([0.15, -0.15, 0.15, -0.15], 0.001);
        }
        for _ in 0..5000 {
            robot.advance([0.0; 4], 0.001);
        }
        let s = robot.sample(0);
        assert!(s.vx_mps.abs() < 1e-3, "{s:?}");
    }

    #[test]
    fn history_becomes_a_sensor_trajectory_placed_in_the_world() {
        use crate::trajectory::Trajectory as _;
        let mut robot = Robot::new(RobotParams::default());
        let mut history = PoseHistory::default();
        for k in 0..=2000u64 {
            history.samples.push(robot.sample(k * 1000));
            robot.advance([0.12, -0.12, 0.12, -0.12], 0.001);
        }
        let start = Pose {
            position_m: Vec3::new(-3.0, 0.5, 0.0),
            roll_rad: 0.0,
            pitch_rad: 0.0,
            yaw_rad: std::f64::consts::FRAC_PI_2,
        };
        let traj = history.to_trajectory(&start).unwrap();
        let end = history.samples.last().unwrap();
        let p = traj.pose_at(2.0);
        // Forward along the robot's x = along the world's y here.
        assert!((p.position_m.x + 3.0).abs() < 1e-6, "{p:?}");
        assert!((p.position_m.y - (0.5 + end.x_m)).abs() < 1e-6, "{p:?}");
        assert!((p.yaw_rad - std::f64::consts::FRAC_PI_2).abs() < 1e-6);
        // The encoders see a little more than the true distance (creep).
        let wheel = traj.wheel_distance_at(2.0);
        assert!(
            wheel > end.x_m && wheel < end.x_m * 1.02,
            "{wheel} vs {}",
            end.x_m
        );
    }

    #[test]
    fn history_interpolates() {
        let h = PoseHistory {
            samples: vec![
                PoseSample {
                    stamp_us: 0,
                    ..PoseSample::default()
                },
                PoseSample {
                    stamp_us: 1000,
                    x_m: 1.0,
                    ..PoseSample::default()
                },
            ],
        };
        assert!((h.at(250).unwrap().x_m - 0.25).abs() < 1e-12);
        assert!((h.at(5000).unwrap().x_m - 1.0).abs() < 1e-12);
        assert!(h.to_csv().lines().count() == 3);
    }
}
