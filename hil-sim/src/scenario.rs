//! Scenarios: which vehicle, how the robot drives under it, the sensors' settings and the seed.
//!
//! # Format (TOML, unknown keys rejected; angles in degrees at this user boundary)
//! ```toml
//! vehicle = "../vehicles/sedan.toml"  # relative to this scenario file
//! seed = 42                           # every random stream derives from it
//! duration_s = 25.0                   # optional; default: the time to drive robot.distance_m
//!
//! [robot]
//! start_x_m = 2.0            # start of the robot origin in the vehicle frame (ahead of the bumper)
//! lateral_offset_m = 0.0     # start y: offset from the vehicle's centre line
//! heading_deg = 180.0        # direction of travel; 180 drives toward the vehicle's rear
//! yaw_misalignment_deg = 0.0 # body yaw relative to the direction of travel
//! speed_mps = 0.3            # cruise speed commanded to the wheels
//! accel_mps2 = 0.0           # 0: cruising from t = 0
//! distance_m = 7.5           # wheel distance of the run (sets the default duration)
//! slip = 0.0                 # true distance = (1 - slip) * wheel distance
//! height_m = 0.16            # robot top; the run is rejected if the vehicle hangs lower
//! still_s = 0.0              # standing still before the start (and after the stop)
//! stop = false               # brake to a stop after distance_m (at accel_mps2)
//!
//! [vibration]
//! pitch_sigma_deg = 0.1      # RMS of the pitch oscillation
//! roll_sigma_deg = 0.1
//!
//! [lidar]                    # crate::vlp16::Vlp16Config, every key optional
//! rpm = 600
//! start_azimuth_deg = 90.0   # head azimuth at t = 0; absent: drawn from the seed
//!
//! [depth]                    # crate::d435::D435Config, every key optional
//! fps = 30
//!
//! [wheel_odometry]           # crate::wheel_odometry::WheelNoise, every key optional; default exact
//! scale_sigma = 0.01         # relative scale error (Gauss-Markov), on top of `slip`
//! scale_tau_s = 1.0
//! lateral_sigma_mps = 0.003
//! lateral_tau_s = 0.5
//! yaw_rate_bias_sigma_degps = 0.1   # a constant per run, drawn from the seed
//! yaw_rate_sigma_degps = 0.2
//! yaw_rate_tau_s = 0.3
//! ```
//!
//! # Seeds
//! `seed` feeds independent streams: vibration = `derive_seed(seed, 1)`, lidar = `derive_seed(seed, 2)`,
//! depth = `derive_seed(seed, 3)`, wheel odometry = `derive_seed(seed, 4)`, the lidar head's
//! starting azimuth (unless the file sets it) = `derive_seed(seed, 6)`, the vehicle's placement =
//! `derive_seed(seed, 7)`, the hall's placement (walls, pillar phase, other vehicles, tilt
//! direction, floor waves) = `derive_seed(seed, 8)`; changing one sensor's settings never
//! changes another's noise.
//!
//! ```toml
//! [placement]                # the parked vehicle against the path; default none
//! yaw_max_deg = 3.0          # uniform in +-3 degrees about the vehicle's centre
//! lateral_max_m = 0.1        # uniform in +-0.1 m
//!
//! [hall]                     # crate::world::HallSpec; default: an empty, flat world
//! walls_m = [7.0, 8.0, 6.5, 9.0]   # front, rear, left, right walls from the vehicle's centre
//! ```

use std::path::{Path, PathBuf};
use std::sync::Arc;

use serde::Deserialize;

use crate::d435::D435Config;
use crate::geometry::Vec3;
use crate::trajectory::{StraightRun, Vibration};
use crate::vehicle::{Vehicle, VehicleError};
use crate::vlp16::Vlp16Config;
use crate::wheel_odometry::WheelNoise;
use crate::world::{Hall, HallSpec, OnFloor, Scene, SurfaceKind};

/// The scenario file as written.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ScenarioFile {
    /// Vehicle file, relative to the scenario file.
    pub vehicle: PathBuf,
    /// Master seed.
    pub seed: u64,
    /// Length of the simulated recording, seconds.
    #[serde(default)]
    pub duration_s: Option<f64>,
    /// The robot's run.
    pub robot: RobotRun,
    /// Pitch/roll vibration.
    #[serde(default)]
    pub vibration: VibrationSpec,
    /// VLP-16 settings.
    #[serde(default)]
    pub lidar: Vlp16Config,
    /// D435 settings.
    #[serde(default)]
    pub depth: D435Config,
    /// Wheel odometry's error model (default: exact wheels but for `robot.slip`).
    #[serde(default)]
    pub wheel_odometry: WheelNoise,
    /// Seeded placement of the vehicle against the robot's path (default: none).
    #[serde(default)]
    pub placement: Placement,
    /// The hall around the vehicle, written inline (default: none, an empty flat world).
    #[serde(default)]
    pub hall: Option<HallSpec>,
    /// A world file holding a hall (its keys at the top level), relative to this file; an
    /// alternative to `[hall]`.
    #[serde(default)]
    pub world: Option<PathBuf>,
}

/// The `[placement]` table: how far the parked vehicle may sit off the robot's path, drawn per
/// seed (stream `derive_seed(seed, 7)`): a yaw uniform in +-`yaw_max_deg` about the vehicle's
/// centre and a lateral offset uniform in +-`lateral_max_m`, both added to the `[robot]` run.
#[derive(Clone, Debug, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Placement {
    /// Largest yaw of the vehicle against the path, degrees.
    #[serde(default)]
    pub yaw_max_deg: f64,
    /// Largest lateral offset of the path from the vehicle's centre line, metres.
    #[serde(default)]
    pub lateral_max_m: f64,
}

/// The `[robot]` table.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RobotRun {
    /// Start x of the robot origin, vehicle frame, metres.
    pub start_x_m: f64,
    /// Start y, metres.
    #[serde(default)]
    pub lateral_offset_m: f64,
    /// Direction of travel, degrees from the vehicle's +x.
    #[serde(default = "default_heading")]
    pub heading_deg: f64,
    /// Body yaw relative to the direction of travel, degrees.
    #[serde(default)]
    pub yaw_misalignment_deg: f64,
    /// Cruise speed, m/s.
    pub speed_mps: f64,
    /// Acceleration from rest, m/s^2 (0: cruising from the start).
    #[serde(default)]
    pub accel_mps2: f64,
    /// Wheel distance of the run, metres.
    pub distance_m: f64,
    /// Longitudinal slip ratio.
    #[serde(default)]
    pub slip: f64,
    /// Height of the robot's top (the lidar's top), metres; the run is rejected if the vehicle
    /// hangs lower anywhere over the robot's footprint.
    #[serde(default = "default_robot_height")]
    pub height_m: f64,
    /// Seconds standing still before the start (and after the stop, with `stop`).
    #[serde(default)]
    pub still_s: f64,
    /// Brake to a stop after `distance_m` (at `accel_mps2`) and stand still for `still_s`: a
    /// drive between two parked captures, as the wheels' calibration takes it.
    #[serde(default)]
    pub stop: bool,
}

fn default_robot_height() -> f64 {
    DEFAULT_ROBOT_HEIGHT_M
}

/// Default robot height: 88 mm chassis plus the VLP-16 on top, about 0.16 m (the paper's system
/// needs a chassis higher than 160 mm).
pub const DEFAULT_ROBOT_HEIGHT_M: f64 = 0.16;

/// Half the robot's width (295 mm) and length (384 mm), metres.
const ROBOT_HALF_WIDTH_M: f64 = 0.1475;
const ROBOT_HALF_LENGTH_M: f64 = 0.192;

fn default_heading() -> f64 {
    180.0
}

/// The `[vibration]` table.
#[derive(Clone, Debug, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct VibrationSpec {
    /// RMS pitch, degrees.
    #[serde(default)]
    pub pitch_sigma_deg: f64,
    /// RMS roll, degrees.
    #[serde(default)]
    pub roll_sigma_deg: f64,
}

/// A loaded, validated scenario.
#[derive(Clone, Debug, PartialEq)]
pub struct Scenario {
    /// Where the scenario came from.
    pub path: PathBuf,
    /// The file's content.
    pub file: ScenarioFile,
    /// The vehicle.
    pub vehicle: Vehicle,
    /// The robot's motion.
    pub run: StraightRun,
    /// Recording length, seconds.
    pub duration_s: f64,
    /// The hall, built for this seed (`None`: an empty flat world).
    pub hall: Option<Arc<Hall>>,
}

/// Why a scenario was rejected.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    /// The file could not be read.
    #[error("cannot read scenario file {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The IO error.
        source: std::io::Error,
    },
    /// The TOML did not parse or match the format.
    #[error("scenario file {path}: {message}")]
    Toml {
        /// The file.
        path: PathBuf,
        /// toml's message with line and column.
        message: String,
    },
    /// A field has an impossible value.
    #[error("scenario file {path}: field `{field}`: {reason}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// The field.
        field: String,
        /// What is wrong.
        reason: String,
    },
    /// The referenced vehicle is invalid.
    #[error("scenario file {path}: {source}")]
    Vehicle {
        /// The scenario file.
        path: PathBuf,
        /// The vehicle's error.
        source: VehicleError,
    },
}

/// Mix a master seed and a stream tag into an independent seed (splitmix64 finaliser).
pub fn derive_seed(seed: u64, tag: u64) -> u64 {
    let mut z = seed ^ tag.wrapping_mul(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

impl Scenario {
    /// The run's lidar frames as the onboard pipeline takes them: the simulated VLP-16 packets
    /// decoded by `vlp16::FrameAssembler` with its default settings, complete frames only,
    /// stamped in simulation time (the sensor clock minus the scenario's clock offset). For
    /// benches and diagnostics that feed `pipeline` directly.
    pub fn decoded_lidar_frames(&self, scene: &Scene) -> Vec<pipeline::LidarFrame> {
        self.decoded_lidar_frames_with(scene, &vlp16::DecoderConfig::default())
    }

    /// [`Self::decoded_lidar_frames`] with the decoder's settings given (a range calibration).
    pub fn decoded_lidar_frames_with(
        &self,
        scene: &Scene,
        config: &vlp16::DecoderConfig,
    ) -> Vec<pipeline::LidarFrame> {
        let offset_s = self.file.lidar.clock_offset_us as f64 * 1e-6;
        self.decoded_vlp16_frames(scene, config)
            .iter()
            .map(|f| onboard::frames::lidar_frame(f, f.start_sensor_us * 1e-6 - offset_s))
            .collect()
    }

    /// The run's complete VLP-16 frames as `vlp16::FrameAssembler` decodes the simulated packets
    /// with `config` (sensor frame, sensor clock); none when `config` is invalid.
    pub fn decoded_vlp16_frames(
        &self,
        scene: &Scene,
        config: &vlp16::DecoderConfig,
    ) -> Vec<vlp16::Frame> {
        use vlp16::FrameAssembler;

        use crate::vlp16::{Datagram, Vlp16Sim};
        let motion = self.motion();
        let sim = Vlp16Sim::new(scene, &motion, self.lidar_config(), self.lidar_seed());
        let Ok(mut assembler) = FrameAssembler::new(*config) else {
            return Vec::new();
        };
        let mut frames = Vec::new();
        let take = |a: &mut FrameAssembler, frames: &mut Vec<vlp16::Frame>| {
            while let Some(f) = a.pop_frame() {
                if f.is_complete() {
                    frames.push(f);
                }
            }
        };
        for d in sim.datagrams(self.duration_s) {
            match d {
                Datagram::Data { send_s, payload } => {
                    let _ = assembler.push_data(&payload[..], (send_s * 1e9) as u64);
                }
                Datagram::Position { payload, .. } => {
                    let _ = assembler.push_position(&payload[..]);
                }
            }
            take(&mut assembler, &mut frames);
        }
        assembler.finish();
        take(&mut assembler, &mut frames);
        frames
    }

    /// The run's depth frames as the onboard pipeline takes them: every `every`-th frame of the
    /// scenario's D435, its image scaled by `q` ([`D435Config::scaled`]), stamped at exposure in
    /// simulation time, depth in millimetres. For benches and diagnostics that feed `pipeline`
    /// directly.
    pub fn depth_images(&self, scene: &Scene, q: f64, every: usize) -> Vec<pipeline::DepthImage> {
        let config = self.file.depth.scaled(q);
        let k = config.intrinsics();
        let motion = self.motion();
        let sim = crate::d435::D435Sim::new(scene, &motion, config, self.depth_seed());
        (0..sim.frames_in(self.duration_s))
            .step_by(every.max(1))
            .map(|i| {
                let f = sim.frame(i);
                pipeline::DepthImage {
                    stamp_s: sim.frame_time_s(i),
                    width: f.width as usize,
                    height: f.height as usize,
                    intrinsics_px: [k.fx_px, k.fy_px, k.cx_px, k.cy_px],
                    depth_scale_m: 0.001,
                    depth: f.depth_mm,
                }
            })
            .collect()
    }

    /// Read a scenario and its vehicle.
    pub fn load(path: &Path) -> Result<Self, ScenarioError> {
        let text = std::fs::read_to_string(path).map_err(|source| ScenarioError::Io {
            path: path.to_owned(),
            source,
        })?;
        let file: ScenarioFile = toml::from_str(&text).map_err(|e| ScenarioError::Toml {
            path: path.to_owned(),
            message: e.to_string(),
        })?;
        let vehicle_path = path.parent().unwrap_or(Path::new(".")).join(&file.vehicle);
        let vehicle = Vehicle::load(&vehicle_path).map_err(|source| ScenarioError::Vehicle {
            path: path.to_owned(),
            source,
        })?;
        Self::from_parts(path, file, vehicle)
    }

    /// Validate a parsed scenario against its vehicle.
    pub fn from_parts(
        path: &Path,
        file: ScenarioFile,
        vehicle: Vehicle,
    ) -> Result<Self, ScenarioError> {
        let invalid = |(field, reason): (String, String)| ScenarioError::Invalid {
            path: path.to_owned(),
            field,
            reason,
        };
        validate_run(&file).map_err(invalid)?;
        let p = &file.placement;
        if !((0.0..=10.0).contains(&p.yaw_max_deg) && (0.0..=0.5).contains(&p.lateral_max_m)) {
            return Err(invalid((
                "placement".to_owned(),
                "yaw_max_deg must lie in 0..=10 and lateral_max_m in 0..=0.5".to_owned(),
            )));
        }
        file.lidar.validate().map_err(invalid)?;
        file.depth.validate().map_err(invalid)?;
        file.wheel_odometry.validate().map_err(invalid)?;
        let r = &file.robot;
        let (yaw_off, lateral_off) = placement_draw(&file);
        // The vehicle yawed by `yaw_off` about its centre is the path turned by `-yaw_off`
        // about that centre, in the vehicle frame.
        let pivot = Vec3::new(-vehicle.wheelbase_m / 2.0, 0.0, 0.0);
        let (s_y, c_y) = (-yaw_off).sin_cos();
        let rel = Vec3::new(r.start_x_m, r.lateral_offset_m + lateral_off, 0.0) - pivot;
        let start = pivot + Vec3::new(c_y * rel.x - s_y * rel.y, s_y * rel.x + c_y * rel.y, 0.0);
        let run = StraightRun {
            start_m: start,
            heading_rad: r.heading_deg.to_radians() - yaw_off,
            yaw_misalignment_rad: r.yaw_misalignment_deg.to_radians(),
            speed_mps: r.speed_mps,
            accel_mps2: r.accel_mps2,
            slip: r.slip,
            vibration: Vibration::new(
                file.vibration.pitch_sigma_deg.to_radians(),
                file.vibration.roll_sigma_deg.to_radians(),
                derive_seed(file.seed, 1),
            ),
            still_s: r.still_s,
            stop_after_m: r.stop.then_some(r.distance_m),
        };
        let duration_s = file
            .duration_s
            .unwrap_or_else(|| run.time_for_wheel_distance(r.distance_m));
        check_clearance(&vehicle, &run, r.distance_m * (1.0 - r.slip), r.height_m)
            .map_err(|reason| invalid(("robot".to_owned(), reason)))?;
        let dir = path.parent().unwrap_or(Path::new("."));
        let spec = match (&file.hall, &file.world) {
            (Some(_), Some(_)) => {
                return Err(invalid((
                    "world".to_owned(),
                    "give either [hall] or world, not both".to_owned(),
                )));
            }
            (Some(spec), None) => Some((spec.clone(), dir.to_owned())),
            (None, Some(w)) => {
                let world_path = dir.join(w);
                let spec = load_world(&world_path)
                    .map_err(|reason| invalid(("world".to_owned(), reason)))?;
                Some((
                    spec,
                    world_path.parent().unwrap_or(Path::new(".")).to_owned(),
                ))
            }
            (None, None) => None,
        };
        let hall = match spec {
            Some((spec, base)) => Some(Arc::new(
                Hall::build(&spec, &vehicle, &base, derive_seed(file.seed, 8)).map_err(invalid)?,
            )),
            None => None,
        };
        Ok(Self {
            path: path.to_owned(),
            file,
            vehicle,
            run,
            duration_s,
            hall,
        })
    }

    /// The scene the sensors see: the vehicle, inside the hall if there is one.
    pub fn scene(&self) -> Scene {
        Scene::from_vehicle(&self.vehicle).with_hall(self.hall.clone())
    }

    /// The robot's true motion: the straight run, on the hall's floor if there is one (the floor's
    /// undulation moves the robot's height, pitch and roll).
    pub fn motion(&self) -> OnFloor<'_, StraightRun> {
        OnFloor {
            inner: &self.run,
            floor: self.hall.as_deref().map(|h| &h.floor),
        }
    }

    /// The VLP-16's settings with the head's starting azimuth resolved: the file's
    /// `start_azimuth_deg`, else drawn uniformly from the seed (so the seeds of a bench sample
    /// the rotation's phase against the robot's travel, as real passes do).
    pub fn lidar_config(&self) -> Vlp16Config {
        let mut c = self.file.lidar.clone();
        if c.start_azimuth_deg.is_none() {
            let u = (derive_seed(self.file.seed, 6) >> 11) as f64 / (1u64 << 53) as f64;
            c.start_azimuth_deg = Some(360.0 * u);
        }
        c
    }

    /// Seed of the VLP-16's noise.
    pub fn lidar_seed(&self) -> u64 {
        derive_seed(self.file.seed, 2)
    }

    /// Seed of the D435's noise.
    pub fn depth_seed(&self) -> u64 {
        derive_seed(self.file.seed, 3)
    }

    /// Seed of the wheel odometry's errors.
    pub fn wheel_seed(&self) -> u64 {
        derive_seed(self.file.seed, 4)
    }

    /// The wheel odometry the firmware would report over the run (and `extra_s` beyond it) at
    /// 100 Hz, with the scenario's `[wheel_odometry]` errors, stamped in simulation time.
    pub fn wheel_odometry(&self, extra_s: f64) -> Vec<pipeline::WheelOdometry> {
        crate::wheel_odometry::simulate(
            &self.run,
            &self.file.wheel_odometry,
            self.wheel_seed(),
            self.duration_s + extra_s,
            100.0,
        )
    }
}

/// Cast vertical rays over the robot's footprint along the whole run (every 2 cm along, 5 across,
/// with the footprint's half length added at both ends): the vehicle must be higher than `height_m`
/// everywhere, or the robot would hit it. Returns what would be hit and where.
fn check_clearance(
    vehicle: &Vehicle,
    run: &StraightRun,
    distance_m: f64,
    height_m: f64,
) -> Result<(), String> {
    let scene = Scene::from_vehicle(vehicle);
    let (sin_h, cos_h) = run.heading_rad.sin_cos();
    let steps = ((distance_m + 2.0 * ROBOT_HALF_LENGTH_M) / 0.02).ceil() as usize;
    for k in 0..=steps {
        let along = -ROBOT_HALF_LENGTH_M + k as f64 * 0.02;
        for j in -2..=2 {
            let across = f64::from(j) / 2.0 * ROBOT_HALF_WIDTH_M;
            let origin = run.start_m
                + Vec3::new(
                    along * cos_h - across * sin_h,
                    along * sin_h + across * cos_h,
                    0.001,
                );
            if let Some(hit) = scene.cast(origin, Vec3::new(0.0, 0.0, 1.0), height_m) {
                let what = match hit.surface.kind {
                    SurfaceKind::Part => vehicle
                        .parts
                        .get(usize::from(hit.surface.index))
                        .map_or("a part", |p| p.name())
                        .to_owned(),
                    SurfaceKind::Body => vehicle
                        .body_prisms()
                        .get(usize::from(hit.surface.index))
                        .map_or_else(|| "the body".to_owned(), |b| b.0.clone()),
                    SurfaceKind::Tyre => "a tyre".to_owned(),
                    SurfaceKind::Ground => "the ground".to_owned(),
                    SurfaceKind::Structure | SurfaceKind::OtherVehicle => "the hall".to_owned(),
                };
                return Err(format!(
                    "the robot ({height_m} m tall) would hit {what} at x = {:.3} m, y = {:.3} m (only {:.3} m above the ground)",
                    origin.x,
                    origin.y,
                    hit.range_m + 0.001
                ));
            }
        }
    }
    Ok(())
}

/// Read a world file: a hall's keys ([`HallSpec`]) at the top level.
pub fn load_world(path: &Path) -> Result<HallSpec, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("cannot read world file {}: {e}", path.display()))?;
    toml::from_str(&text).map_err(|e| format!("world file {}: {e}", path.display()))
}

/// The placement's yaw (radians) and lateral offset (metres) for this seed.
fn placement_draw(file: &ScenarioFile) -> (f64, f64) {
    use rand::{Rng, SeedableRng};
    let p = &file.placement;
    if p.yaw_max_deg == 0.0 && p.lateral_max_m == 0.0 {
        return (0.0, 0.0);
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(derive_seed(file.seed, 7));
    let u: f64 = rng.random_range(-1.0..=1.0);
    let v: f64 = rng.random_range(-1.0..=1.0);
    (u * p.yaw_max_deg.to_radians(), v * p.lateral_max_m)
}

fn validate_run(file: &ScenarioFile) -> Result<(), (String, String)> {
    let bad = |f: &str, r: &str| Err((f.to_owned(), r.to_owned()));
    let r = &file.robot;
    let finite = [
        r.start_x_m,
        r.lateral_offset_m,
        r.heading_deg,
        r.yaw_misalignment_deg,
        r.accel_mps2,
    ];
    if finite.iter().any(|v| !v.is_finite()) {
        return bad(
            "robot",
            "start_x_m, lateral_offset_m, heading_deg, yaw_misalignment_deg and accel_mps2 must be finite",
        );
    }
    if !(r.speed_mps > 0.0 && r.speed_mps <= 3.0) {
        return bad("robot.speed_mps", "must lie in (0, 3] m/s");
    }
    if !(r.distance_m > 0.0 && r.distance_m.is_finite()) {
        return bad("robot.distance_m", "must be a positive number");
    }
    if !(r.height_m > 0.0 && r.height_m <= 1.0) {
        return bad("robot.height_m", "must lie in (0, 1] m");
    }
    if !(0.0..1.0).contains(&r.slip) {
        return bad("robot.slip", "must lie in [0, 1)");
    }
    if !(0.0..=60.0).contains(&r.still_s) {
        return bad("robot.still_s", "must lie in [0, 60] s");
    }
    if r.yaw_misalignment_deg.abs() > 45.0 {
        return bad("robot.yaw_misalignment_deg", "must lie within +-45 degrees");
    }
    let v = &file.vibration;
    if !(v.pitch_sigma_deg >= 0.0
        && v.pitch_sigma_deg <= 10.0
        && v.roll_sigma_deg >= 0.0
        && v.roll_sigma_deg <= 10.0)
    {
        return bad(
            "vibration",
            "pitch_sigma_deg and roll_sigma_deg must lie in 0..=10",
        );
    }
    if let Some(d) = file.duration_s
        && !(d > 0.0 && d <= 3600.0)
    {
        return bad("duration_s", "must lie in (0, 3600] s");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vehicle::tests::test_sedan;

    const SCENARIO: &str = r#"
vehicle = "sedan.toml"
seed = 7
[robot]
start_x_m = 2.0
lateral_offset_m = 0.1
yaw_misalignment_deg = 1.0
speed_mps = 0.3
distance_m = 6.0
slip = 0.02
height_m = 0.12
[vibration]
pitch_sigma_deg = 0.1
[lidar]
rpm = 1200
[depth]
fps = 15
"#;

    fn parse(text: &str) -> Result<Scenario, ScenarioError> {
        let file: ScenarioFile = toml::from_str(text).map_err(|e| ScenarioError::Toml {
            path: "s.toml".into(),
            message: e.to_string(),
        })?;
        Scenario::from_parts(Path::new("s.toml"), file, test_sedan())
    }

    #[test]
    fn scenario_parses_with_defaults_and_derived_seeds() {
        let s = parse(SCENARIO).expect("valid");
        assert!((s.duration_s - 20.0).abs() < 1e-12);
        assert!((s.file.lidar.rpm - 1200.0).abs() < 1e-12);
        assert!(
            (s.file.lidar.range_noise_sigma_m - 0.015).abs() < 1e-12,
            "default kept"
        );
        assert!((s.run.heading_rad - std::f64::consts::PI).abs() < 1e-12);
        assert_ne!(s.lidar_seed(), s.depth_seed());
    }

    #[test]
    fn the_lidar_phase_is_drawn_per_seed_unless_the_file_sets_it() {
        let phase = |text: &str, seed: u64| {
            let mut s = parse(text).expect("valid");
            s.file.seed = seed;
            s.lidar_config().start_azimuth_deg.expect("resolved")
        };
        let drawn: Vec<f64> = (1..=10).map(|seed| phase(SCENARIO, seed)).collect();
        assert!(drawn.iter().all(|a| (0.0..360.0).contains(a)), "{drawn:?}");
        assert_eq!(drawn[2].to_bits(), phase(SCENARIO, 3).to_bits(), "seeded");
        // Ten draws spread over the circle (not one phase for every seed).
        let (lo, hi) = drawn
            .iter()
            .fold((f64::MAX, f64::MIN), |(l, h), a| (l.min(*a), h.max(*a)));
        assert!(hi - lo > 180.0, "{drawn:?}");
        let fixed = SCENARIO.replace("rpm = 1200", "rpm = 1200\nstart_azimuth_deg = 90.0");
        assert!((phase(&fixed, 1) - 90.0).abs() < 1e-12);
        assert!((phase(&fixed, 2) - 90.0).abs() < 1e-12);
        let e = parse(&SCENARIO.replace("rpm = 1200", "rpm = 1200\nstart_azimuth_deg = nan"))
            .expect_err("not finite")
            .to_string();
        assert!(e.contains("lidar.start_azimuth_deg"), "{e}");
    }

    #[test]
    fn a_run_under_parts_lower_than_the_robot_is_rejected_with_the_part_named() {
        let e = parse(&SCENARIO.replace("height_m = 0.12", "height_m = 0.35"))
            .expect_err("robot too tall")
            .to_string();
        assert!(
            e.contains("field `robot`") && e.contains("would hit"),
            "{e}"
        );
        // The test sedan's floor is 0.14 m high: the default 0.16 m robot does not fit either.
        let e = parse(&SCENARIO.replace("height_m = 0.12", ""))
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(e.contains("between axles") || e.contains("overhang"), "{e}");
    }

    #[test]
    fn errors_name_the_field() {
        let e = parse(&SCENARIO.replace("slip = 0.02", "slip = 1.5"))
            .expect_err("bad slip")
            .to_string();
        assert!(e.contains("robot.slip"), "{e}");
        let e = parse(&SCENARIO.replace("rpm = 1200", "rpm = 2000"))
            .expect_err("bad rpm")
            .to_string();
        assert!(e.contains("lidar.rpm"), "{e}");
        let e = parse(&SCENARIO.replace("fps = 15", "fps = 15\nexposure = 3"))
            .expect_err("unknown key")
            .to_string();
        assert!(e.contains("exposure") && e.contains("line"), "{e}");
        let e = parse(&format!("{SCENARIO}[wheel_odometry]\nscale_sigma = -0.1\n"))
            .expect_err("negative sigma")
            .to_string();
        assert!(e.contains("wheel_odometry.scale_sigma"), "{e}");
        let e = parse(&format!("{SCENARIO}[wheel_odometry]\nyaw_rate_tau_s = 0\n"))
            .expect_err("zero tau")
            .to_string();
        assert!(e.contains("wheel_odometry.yaw_rate_tau_s"), "{e}");
    }

    #[test]
    fn wheel_odometry_is_exact_by_default_and_noisy_when_asked() {
        let exact = parse(SCENARIO).expect("valid");
        assert!(exact.file.wheel_odometry.is_exact());
        let noisy = parse(&format!(
            "{SCENARIO}[wheel_odometry]\nyaw_rate_bias_sigma_degps = 0.1\nyaw_rate_sigma_degps = 0.2\n"
        ))
        .expect("valid");
        let (a, b) = (exact.wheel_odometry(0.0), noisy.wheel_odometry(0.0));
        assert_eq!(a.len(), b.len());
        assert!(a.iter().all(|w| w.yaw_rad == 0.0));
        assert!(b.last().is_some_and(|w| w.yaw_rad != 0.0));
        // The wheel stream has its own seed: the lidar's and the depth's are untouched.
        assert_eq!(exact.lidar_seed(), noisy.lidar_seed());
        assert_ne!(noisy.wheel_seed(), noisy.lidar_seed());
    }
}
