//! The simulated Intel RealSense D435 depth stream: Z16 frames (u16 millimetres, 0 = invalid) from
//! a pinhole model, rendered by casting one ray per pixel through the [`Scene`].
//!
//! # Model
//! - Intrinsics: at 848x480 the default is fx = fy = 426.0 px, cx = 424.0, cy = 240.0 px (typical
//!   of D435 units, about 89 x 59 degrees; each real unit differs a little and reports its own
//!   calibration). Other resolutions scale the defaults with the width; every value can be set.
//! - Pixel `(u, v)` looks along `((u - cx) / fx, (v - cy) / fy, 1)` in the optical frame (x right,
//!   y down, z forward); its depth is the hit's z in that frame (not the range along the ray).
//! - Mount: `robot_from_camera` from `mount_xyz_m` (default: the robot's front face, 7 cm up) and
//!   `mount_pitch_up_deg` (default 20 degrees up) / `mount_yaw_deg`.
//! - Noise: stereo depth noise grows with the square of the distance: sigma = k z^2 with
//!   k = subpixel / (f B) = 0.08 / (426 px * 0.050 m) = 0.0038 per metre by default (3.8 mm at 1 m).
//! - Invalid (0): depth below `min_depth_m` (0.17 m) or above `max_depth_m`, no hit, surfaces seen at
//!   grazing incidence (cosine below `min_cos_incidence`: stereo matching fails there), and random
//!   dropouts with probability `invalid_probability`.
//! - Depth is rounded to the 1 mm depth unit. The shutter is global: one pose per frame, at the
//!   frame's timestamp `index / fps`.
//!
//! - Field effects, each off by default: the stereo geometry (`stereo_baseline_m`: the left-edge
//!   band where the right imager sees nothing, `u < fx B / z`, and the occlusion shadow where a
//!   nearer surface hides the point from the right imager), holes on dark tyre rubber
//!   (`dark_invalid_probability`) and on bare-metal parts seen near their normal
//!   (`specular_invalid_probability`). The minimum depth and the noise coefficient are the keys
//!   above; Intel's model (D400 tuning white paper) gives RMS = z^2 subpixel / (f B), 0.38 % at
//!   1 m for subpixel 0.08 and 0.47 % for 0.1.
//!
//! Frame `i` draws from `ChaCha8Rng::seed_from_u64(seed)` on stream `i`: a pure function of
//! (scenario, seed, i).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::geometry::{Isometry, Rot3, Vec3, rot_from_rpy};
use crate::trajectory::Trajectory;
use crate::world::{Scene, SurfaceKind};

/// Default focal length at 848 px width, pixels.
pub const DEFAULT_FOCAL_PX_AT_848: f64 = 426.0;

/// Camera settings (the scenario's `[depth]` table; every key optional).
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct D435Config {
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Frame rate, frames per second.
    pub fps: f64,
    /// Focal lengths and principal point, pixels; `None` = the defaults scaled to `width`.
    pub fx_px: Option<f64>,
    /// See `fx_px`.
    pub fy_px: Option<f64>,
    /// See `fx_px`.
    pub cx_px: Option<f64>,
    /// See `fx_px`.
    pub cy_px: Option<f64>,
    /// Camera optical centre in the robot frame, metres.
    pub mount_xyz_m: [f64; 3],
    /// Upward pitch of the optical axis, degrees.
    pub mount_pitch_up_deg: f64,
    /// Yaw of the optical axis from the robot's +x, degrees (positive to the left).
    pub mount_yaw_deg: f64,
    /// Nearest valid depth, metres.
    pub min_depth_m: f64,
    /// Farthest valid depth, metres.
    pub max_depth_m: f64,
    /// Noise coefficient k in sigma = k z^2, 1/m.
    pub noise_k_per_m: f64,
    /// Pixels seeing a surface with |cos incidence| below this are invalid.
    pub min_cos_incidence: f64,
    /// Probability that a valid pixel drops out.
    pub invalid_probability: f64,
    /// Camera clock at simulation time 0, microseconds.
    pub clock_offset_us: u64,
    /// Stereo baseline, metres (the D435's is 0.050); 0 (the default): no stereo geometry. When
    /// set, the right imager sits this far along the optical x axis and a pixel is invalid where
    /// the right imager cannot see its point: outside the right image (the invalid band on the
    /// left edge, `u < fx B / z`) or behind a nearer surface (the occlusion shadow beside depth
    /// edges).
    pub stereo_baseline_m: f64,
    /// Probability that a pixel on a tyre (dark rubber absorbs the projector's pattern) is
    /// invalid; 0 (the default): none.
    pub dark_invalid_probability: f64,
    /// Probability that a pixel on a bare-metal part seen within [`SPECULAR_MAX_ANGLE_DEG`] of
    /// its normal (a specular highlight) is invalid; 0 (the default): none.
    pub specular_invalid_probability: f64,
}

/// Within this angle of a part's normal, a bare-metal part mirrors the projector (specular hole).
pub const SPECULAR_MAX_ANGLE_DEG: f64 = 18.0;

impl Default for D435Config {
    fn default() -> Self {
        Self {
            width: 848,
            height: 480,
            fps: 30.0,
            fx_px: None,
            fy_px: None,
            cx_px: None,
            cy_px: None,
            mount_xyz_m: [0.19, 0.0, 0.07],
            mount_pitch_up_deg: 20.0,
            mount_yaw_deg: 0.0,
            min_depth_m: 0.17,
            max_depth_m: 10.0,
            noise_k_per_m: 0.0038,
            min_cos_incidence: 0.1,
            invalid_probability: 0.005,
            clock_offset_us: 0,
            stereo_baseline_m: 0.0,
            dark_invalid_probability: 0.0,
            specular_invalid_probability: 0.0,
        }
    }
}

/// Pinhole intrinsics, pixels.
#[derive(Clone, Copy, Debug, Serialize, PartialEq)]
pub struct Intrinsics {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// Focal length x, pixels.
    pub fx_px: f64,
    /// Focal length y, pixels.
    pub fy_px: f64,
    /// Principal point x, pixels.
    pub cx_px: f64,
    /// Principal point y, pixels.
    pub cy_px: f64,
}

impl D435Config {
    /// Check every field; on failure `(field, reason)` named as in the scenario file.
    pub fn validate(&self) -> Result<(), (String, String)> {
        let bad = |f: &str, r: &str| Err((format!("depth.{f}"), r.to_owned()));
        if self.width == 0 || self.height == 0 || self.width > 4096 || self.height > 4096 {
            return bad("width", "width and height must lie in 1..=4096");
        }
        if !(self.fps > 0.0 && self.fps <= 300.0) {
            return bad("fps", "must lie in (0, 300]");
        }
        for (name, v) in [("fx_px", self.fx_px), ("fy_px", self.fy_px)] {
            if v.is_some_and(|f| !(f.is_finite() && f > 0.0)) {
                return bad(name, "must be a positive number");
            }
        }
        if !(self.min_depth_m > 0.0
            && self.min_depth_m < self.max_depth_m
            && self.max_depth_m <= 65.0)
        {
            return bad(
                "min_depth_m",
                "need 0 < min_depth_m < max_depth_m <= 65 m (u16 millimetres)",
            );
        }
        if !(self.noise_k_per_m >= 0.0 && (0.0..=1.0).contains(&self.min_cos_incidence)) {
            return bad(
                "noise_k_per_m",
                "noise_k_per_m must be >= 0 and min_cos_incidence in 0..=1",
            );
        }
        if !(0.0..=1.0).contains(&self.invalid_probability) {
            return bad("invalid_probability", "must lie in 0..=1");
        }
        if !(0.0..=0.5).contains(&self.stereo_baseline_m) {
            return bad("stereo_baseline_m", "must lie in 0..=0.5 m");
        }
        for (name, v) in [
            ("dark_invalid_probability", self.dark_invalid_probability),
            (
                "specular_invalid_probability",
                self.specular_invalid_probability,
            ),
        ] {
            if !(0.0..=1.0).contains(&v) {
                return bad(name, "must lie in 0..=1");
            }
        }
        if self
            .mount_xyz_m
            .iter()
            .chain([&self.mount_pitch_up_deg, &self.mount_yaw_deg])
            .any(|v| !v.is_finite())
        {
            return bad("mount_xyz_m", "mount values must be finite");
        }
        Ok(())
    }

    /// The intrinsics, defaults filled in.
    pub fn intrinsics(&self) -> Intrinsics {
        let scale = f64::from(self.width) / 848.0;
        Intrinsics {
            width: self.width,
            height: self.height,
            fx_px: self.fx_px.unwrap_or(DEFAULT_FOCAL_PX_AT_848 * scale),
            fy_px: self.fy_px.unwrap_or(DEFAULT_FOCAL_PX_AT_848 * scale),
            cx_px: self.cx_px.unwrap_or(f64::from(self.width) / 2.0),
            cy_px: self.cy_px.unwrap_or(f64::from(self.height) / 2.0),
        }
    }

    /// The same camera with its image scaled by `q` (0.25: a quarter of the width and height),
    /// the intrinsics scaled with it, so a pixel sees what a `1/q` by `1/q` block of the full image
    /// sees at its centre. The simulator renders fewer rays; the noise and stereo models stay per
    /// pixel, so the scaled image is an approximation of a stride through the full one.
    #[must_use]
    pub fn scaled(&self, q: f64) -> Self {
        let k = self.intrinsics();
        Self {
            width: (f64::from(k.width) * q).round() as u32,
            height: (f64::from(k.height) * q).round() as u32,
            fx_px: Some(k.fx_px * q),
            fy_px: Some(k.fy_px * q),
            cx_px: Some(k.cx_px * q),
            cy_px: Some(k.cy_px * q),
            ..self.clone()
        }
    }

    /// `robot_from_camera` for the optical frame (x right, y down, z forward).
    pub fn robot_from_camera(&self) -> Isometry {
        // Optical axes in a level, forward-looking robot frame: z -> +x, x -> -y, y -> -z.
        let optical = Rot3::new(0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, -1.0, 0.0);
        let [x, y, z] = self.mount_xyz_m;
        Isometry {
            rotation: rot_from_rpy(
                0.0,
                -self.mount_pitch_up_deg.to_radians(),
                self.mount_yaw_deg.to_radians(),
            ) * optical,
            translation: Vec3::new(x, y, z),
        }
    }
}

/// One Z16 depth frame.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Z16Frame {
    /// Frame number from 0.
    pub index: u64,
    /// Camera clock at exposure, microseconds.
    pub stamp_us: u64,
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// Row-major depth, millimetres; 0 = invalid.
    pub depth_mm: Vec<u16>,
}

impl Z16Frame {
    /// The frame as raw Z16 bytes (little-endian u16, row-major), as a camera delivers it.
    pub fn to_z16_bytes(&self) -> Vec<u8> {
        self.depth_mm.iter().flat_map(|d| d.to_le_bytes()).collect()
    }
}

/// The simulated camera looking at `scene` from a robot moving along `trajectory`.
pub struct D435Sim<'a, T: Trajectory> {
    scene: &'a Scene,
    trajectory: &'a T,
    config: D435Config,
    intrinsics: Intrinsics,
    robot_from_camera: Isometry,
    seed: u64,
}

impl<'a, T: Trajectory> D435Sim<'a, T> {
    /// A camera; `config` must have passed [`D435Config::validate`].
    pub fn new(scene: &'a Scene, trajectory: &'a T, config: D435Config, seed: u64) -> Self {
        Self {
            scene,
            trajectory,
            intrinsics: config.intrinsics(),
            robot_from_camera: config.robot_from_camera(),
            config,
            seed,
        }
    }

    /// Simulation time of frame `index`, seconds.
    pub fn frame_time_s(&self, index: u64) -> f64 {
        index as f64 / self.config.fps
    }

    /// Number of frames exposed within `duration_s`.
    pub fn frames_in(&self, duration_s: f64) -> u64 {
        (duration_s * self.config.fps).ceil().max(0.0) as u64
    }

    /// `world_from_camera` at frame `index`.
    pub fn world_from_camera(&self, index: u64) -> Isometry {
        self.trajectory
            .pose_at(self.frame_time_s(index))
            .to_isometry()
            .compose(&self.robot_from_camera)
    }

    /// Render frame `index`.
    pub fn frame(&self, index: u64) -> Z16Frame {
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        rng.set_stream(index);
        let world_from_camera = self.world_from_camera(index);
        let origin = world_from_camera.translation;
        let k = &self.intrinsics;
        let c = &self.config;
        let mut depth_mm = Vec::with_capacity((k.width * k.height) as usize);
        for v in 0..k.height {
            for u in 0..k.width {
                let ray_cam = Vec3::new(
                    (f64::from(u) - k.cx_px) / k.fx_px,
                    (f64::from(v) - k.cy_px) / k.fy_px,
                    1.0,
                );
                let inv_norm = 1.0 / ray_cam.norm();
                let dir = world_from_camera.apply_vector(ray_cam * inv_norm);
                let (u_drop, noise) = (rng.random::<f64>(), gaussian(&mut rng));
                let value = self
                    .scene
                    .cast(origin, dir, c.max_depth_m / inv_norm + 1.0)
                    .map_or(0, |hit| {
                        let z = hit.range_m * inv_norm;
                        let z_noisy = z + noise * c.noise_k_per_m * z * z;
                        let cos_incidence = -hit.normal.dot(&dir);
                        let grazing = cos_incidence < c.min_cos_incidence;
                        if grazing
                            || u_drop < c.invalid_probability
                            || z_noisy < c.min_depth_m
                            || z_noisy > c.max_depth_m
                            || self.field_invalid(
                                &mut rng,
                                u,
                                z,
                                origin + dir * hit.range_m,
                                &hit,
                                cos_incidence,
                                &world_from_camera,
                            )
                        {
                            0
                        } else {
                            (z_noisy * 1000.0).round() as u16
                        }
                    });
                depth_mm.push(value);
            }
        }
        Z16Frame {
            index,
            stamp_us: c.clock_offset_us + (self.frame_time_s(index) * 1e6).round() as u64,
            width: k.width,
            height: k.height,
            depth_mm,
        }
    }
}

impl<T: Trajectory> D435Sim<'_, T> {
    /// The field effects (each only when its key is set, drawing only then): the stereo
    /// geometry's invalid band and occlusion shadow, holes on dark rubber and specular metal.
    #[allow(clippy::too_many_arguments)]
    fn field_invalid(
        &self,
        rng: &mut ChaCha8Rng,
        u: u32,
        z: f64,
        point: Vec3,
        hit: &crate::world::Hit,
        cos_incidence: f64,
        world_from_camera: &Isometry,
    ) -> bool {
        let c = &self.config;
        let b = c.stereo_baseline_m;
        if b > 0.0 {
            if f64::from(u) < self.intrinsics.fx_px * b / z {
                return true;
            }
            let right = world_from_camera.apply(Vec3::new(b, 0.0, 0.0));
            let to_point = point - right;
            let dist = to_point.norm();
            if self
                .scene
                .cast(right, to_point * (1.0 / dist), dist - 0.005)
                .is_some()
            {
                return true;
            }
        }
        let p = match hit.surface.kind {
            SurfaceKind::Tyre => c.dark_invalid_probability,
            SurfaceKind::Part if cos_incidence >= SPECULAR_MAX_ANGLE_DEG.to_radians().cos() => {
                c.specular_invalid_probability
            }
            _ => 0.0,
        };
        p > 0.0 && rng.random::<f64>() < p
    }
}

/// A standard normal draw (Box-Muller).
pub(crate) fn gaussian(rng: &mut ChaCha8Rng) -> f64 {
    let bits: u64 = rng.random();
    let u1 = ((bits >> 32) as f64 + 0.5) / 4_294_967_296.0;
    let u2 = ((bits & 0xffff_ffff) as f64) / 4_294_967_296.0;
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Normalized, Pose};
    use crate::trajectory::SampledTrajectory;
    use crate::vehicle::tests::test_sedan;

    fn parked_at(x: f64) -> SampledTrajectory {
        let pose = Pose {
            position_m: Vec3::new(x, 0.0, 0.0),
            ..Pose::default()
        };
        SampledTrajectory::new(vec![(0.0, pose, 0.0)]).expect("one sample")
    }

    fn small() -> D435Config {
        D435Config {
            width: 212,
            height: 120,
            ..D435Config::default()
        }
    }

    #[test]
    fn default_mount_looks_forward_and_up() {
        let m = D435Config::default().robot_from_camera();
        let axis = m.apply_vector(Vec3::new(0.0, 0.0, 1.0));
        assert!((axis.z - 20f64.to_radians().sin()).abs() < 1e-12 && axis.x > 0.9);
        let right = m.apply_vector(Vec3::new(1.0, 0.0, 0.0));
        assert!((right - Vec3::new(0.0, -1.0, 0.0)).norm() < 1e-12);
        let k = small().intrinsics();
        assert!((k.fx_px - 106.5).abs() < 1e-12 && (k.cx_px - 106.0).abs() < 1e-12);
    }

    #[test]
    fn noiseless_pixels_back_project_onto_the_scene() {
        let scene = Scene::from_vehicle(&test_sedan());
        let traj = parked_at(-0.6);
        let cfg = D435Config {
            noise_k_per_m: 0.0,
            invalid_probability: 0.0,
            ..small()
        };
        let cam = D435Sim::new(&scene, &traj, cfg.clone(), 3);
        let f = cam.frame(0);
        let k = cfg.intrinsics();
        let world_from_camera = cam.world_from_camera(0);
        let mut valid = 0;
        for v in 0..k.height {
            for u in 0..k.width {
                let d = f.depth_mm[(v * k.width + u) as usize];
                if d == 0 {
                    continue;
                }
                valid += 1;
                let z = f64::from(d) / 1000.0;
                let p_cam = Vec3::new(
                    (f64::from(u) - k.cx_px) / k.fx_px * z,
                    (f64::from(v) - k.cy_px) / k.fy_px * z,
                    z,
                );
                let p = world_from_camera.apply(p_cam);
                let ray = (p - world_from_camera.translation).normalized();
                let hit = scene
                    .cast(world_from_camera.translation, ray, 20.0)
                    .expect("pixel saw something");
                // Rounding to 1 mm of depth moves the point at most 0.5 mm * (range / depth) along the ray.
                let dist = scene.distance_to_surface(hit.surface, p);
                assert!(
                    dist < 0.0006 * (p - world_from_camera.translation).norm() / z + 1e-6,
                    "pixel ({u},{v}) {dist}"
                );
            }
        }
        assert!(valid > k.width * k.height / 2, "{valid}");
        // The camera under the floor, pitched up, sees the floor (0.14-0.15 m) right above it.
        let top = f.depth_mm[(k.width / 2) as usize];
        assert!(top > 0);
    }

    #[test]
    fn noise_grows_with_the_square_of_depth_and_frames_are_reproducible() {
        let scene = Scene::from_vehicle(&test_sedan());
        let traj = parked_at(3.0); // in front of the car: floor far away, ground near
        let cfg = D435Config {
            invalid_probability: 0.0,
            noise_k_per_m: 0.01,
            ..small()
        };
        let a = D435Sim::new(&scene, &traj, cfg.clone(), 5);
        let clean = D435Sim::new(
            &scene,
            &traj,
            D435Config {
                noise_k_per_m: 0.0,
                ..cfg.clone()
            },
            5,
        )
        .frame(0);
        let noisy = a.frame(0);
        assert_eq!(noisy, D435Sim::new(&scene, &traj, cfg.clone(), 5).frame(0));
        assert_ne!(noisy, D435Sim::new(&scene, &traj, cfg, 6).frame(0));
        // Residuals normalised by k z^2 have unit spread (up to the 1 mm rounding).
        let (mut n, mut sum2) = (0.0, 0.0);
        for (c, z) in clean.depth_mm.iter().zip(&noisy.depth_mm) {
            if *c > 300 && *z > 0 {
                let zc = f64::from(*c) / 1000.0;
                let r = (f64::from(*z) - f64::from(*c)) / 1000.0 / (0.01 * zc * zc);
                n += 1.0;
                sum2 += r * r;
            }
        }
        let rms = (sum2 / n).sqrt();
        assert!(n > 1000.0 && (rms - 1.0).abs() < 0.15, "n {n} rms {rms}");
    }

    #[test]
    fn too_near_is_invalid() {
        let scene = Scene::from_vehicle(&test_sedan());
        let traj = parked_at(-1.4);
        // Pitched straight up, 6 cm under the 0.14 m floor: depth 0.07 m < 0.17 m -> all centre pixels 0.
        let cfg = D435Config {
            mount_pitch_up_deg: 90.0,
            mount_xyz_m: [0.0, 0.0, 0.08],
            invalid_probability: 0.0,
            ..small()
        };
        let f = D435Sim::new(&scene, &traj, cfg, 1).frame(0);
        assert_eq!(f.depth_mm[(60 * 212 + 106) as usize], 0);
        assert_eq!(f.to_z16_bytes().len(), 212 * 120 * 2);
    }

    /// Frame 0 of a camera parked at `x` facing the vehicle's rear (the front tyres ahead).
    fn facing_rear(cfg: &D435Config, x: f64) -> (Z16Frame, Isometry) {
        let scene = Scene::from_vehicle(&test_sedan());
        let pose = Pose {
            position_m: Vec3::new(x, 0.0, 0.0),
            yaw_rad: std::f64::consts::PI,
            ..Pose::default()
        };
        let traj = SampledTrajectory::new(vec![(0.0, pose, 0.0)]).expect("one sample");
        let cam = D435Sim::new(&scene, &traj, cfg.clone(), 3);
        (cam.frame(0), cam.world_from_camera(0))
    }

    #[test]
    fn the_stereo_geometry_blanks_the_left_band_and_the_occlusion_shadow() {
        let clean = D435Config {
            noise_k_per_m: 0.0,
            invalid_probability: 0.0,
            ..small()
        };
        let stereo = D435Config {
            stereo_baseline_m: 0.05,
            ..clean.clone()
        };
        let k = clean.intrinsics();
        let (a, _) = facing_rear(&clean, 1.3);
        let (b, _) = facing_rear(&stereo, 1.3);
        let (mut band, mut shadow) = (0, 0);
        for v in 0..k.height {
            for u in 0..k.width {
                let i = (v * k.width + u) as usize;
                let (da, db) = (a.depth_mm[i], b.depth_mm[i]);
                if db != 0 {
                    // Valid stereo pixels are the same as without stereo, right of the band.
                    assert_eq!(da, db);
                    let z = f64::from(db) / 1000.0;
                    assert!(f64::from(u) >= k.fx_px * 0.05 / z, "({u},{v}) z {z}");
                } else if da != 0 {
                    let z = f64::from(da) / 1000.0;
                    if f64::from(u) < k.fx_px * 0.05 / z {
                        band += 1;
                    } else {
                        shadow += 1;
                    }
                }
            }
        }
        assert!(band > 50, "left band {band} pixels");
        assert!(shadow > 5, "occlusion shadow {shadow} pixels");
    }

    #[test]
    fn dark_rubber_leaves_holes_only_on_tyres() {
        let clean = D435Config {
            noise_k_per_m: 0.0,
            invalid_probability: 0.0,
            ..small()
        };
        let dark = D435Config {
            dark_invalid_probability: 1.0,
            ..clean.clone()
        };
        let k = clean.intrinsics();
        let (a, world_from_camera) = facing_rear(&clean, 1.3);
        let (b, _) = facing_rear(&dark, 1.3);
        let scene = Scene::from_vehicle(&test_sedan());
        let mut holes = 0;
        for v in 0..k.height {
            for u in 0..k.width {
                let i = (v * k.width + u) as usize;
                if a.depth_mm[i] == 0 || b.depth_mm[i] != 0 {
                    assert_eq!(a.depth_mm[i], b.depth_mm[i], "({u},{v})");
                    continue;
                }
                holes += 1;
                let ray = world_from_camera
                    .apply_vector(Vec3::new(
                        (f64::from(u) - k.cx_px) / k.fx_px,
                        (f64::from(v) - k.cy_px) / k.fy_px,
                        1.0,
                    ))
                    .normalized();
                let hit = scene
                    .cast(world_from_camera.translation, ray, 20.0)
                    .expect("a surface");
                assert_eq!(hit.surface.kind, SurfaceKind::Tyre, "({u},{v})");
            }
        }
        assert!(holes > 20, "{holes} tyre pixels");
    }
}
