//! The held-out protocol's bench (issue 30): every run of `hil-sim/evaluation.toml` through the
//! offline pipeline and the angle calculator, against the geometry's true angles, as one table
//! per set.
//!
//! Run: `cargo run --release -p hil-sim --example evaluate -- [--set tuning|held-out|both]
//! [--protocol FILE] [--jobs N] [--only TEXT] [--oracle] [--detail] [--save-clouds DIR |
//! --from-clouds DIR] [--camera none|cloud|fused|both]` (defaults: both sets,
//! `hil-sim/evaluation.toml`, two worker threads; `--only` keeps the runs whose `vehicle/world/seed`
//! contains TEXT; `--oracle` replaces the pipeline by the true poses: every simulated return
//! placed with the exact pose of its firing, one centroid per 5 mm voxel as the pipeline's output,
//! the true path as the scan's path, so the tables show the calculator alone on the same runs;
//! `--detail` adds, per run, each witness and its uncertainty budget against the truth's witness,
//! the fitted axles against the true tyre and, for the pipeline, the trajectory's largest errors;
//! `--save-clouds` keeps each run's cloud, path and trajectory error, and `--from-clouds` runs the
//! calculator alone on them, in seconds instead of the pipeline's minutes; `--camera` adds the
//! simulated D435's points to the cloud (the default, as on the robot), its odometry to the fusion,
//! both, or neither).
//!
//! Per run (all seeded; the same command prints the same tables): the protocol's template
//! scenario with the run's vehicle, world and seed, the robot starting 1 m ahead of the vehicle's
//! front and driving to 1 m behind its rear; the simulated VLP-16 packets decoded by
//! `vlp16::FrameAssembler`; wheel odometry at 100 Hz with the template's wheel errors; the
//! pipeline with its default settings: laser + wheel, the D435's points where the lidar does not
//! see (the camera at a quarter of its resolution, see [`CAMERA_SCALE`]); the built
//! cloud moved into the vehicle frame by the true start pose (on the hall's floor) with the
//! estimated trajectory as the scan's path; `angles::compute_angles` with its default
//! settings; `hil_sim::truth::true_angles` (49 CFR zone, flexible parts included). Nothing is
//! tuned here: every setting is the crate's default.
//!
//! Output: per set, a row per run with the true angles, the three errors (measured - true,
//! degrees; `-` where the calculator gave none), the mean and largest |error| of the run, how many
//! of its angles lie within 0.5 degree, and, for a run with a missing angle, the calculator's
//! reason; then the set's summary (per angle: mean and largest |error|, within 0.5 degree, how
//! often the true value lies within the calculator's expanded uncertainty U, the median U;
//! runs with every angle within 0.5 degree; runs without angles). Timing goes to stderr only.

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::Instant;

use angles::{AnglesConfig, compute_angles};
use anyhow::{Context as _, bail};
use hil_sim::geometry::Isometry;
use hil_sim::scenario::Scenario;
use hil_sim::trajectory::Trajectory;
use hil_sim::truth::{TruthOptions, true_angles};
use hil_sim::vehicle::Vehicle;
use hil_sim::vlp16::Vlp16Config;
use pipeline::geom::{Pose, rpy_of};
use pipeline::{BuiltCloud, DepthImage, LidarFrame, Pipeline, PipelineConfig, WheelOdometry};
use serde::Deserialize;

/// The protocol file.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Protocol {
    template: PathBuf,
    tuning: Vec<Group>,
    held_out: Vec<Group>,
}

/// A cross product of vehicles, worlds and seeds.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Group {
    vehicles: Vec<PathBuf>,
    worlds: Vec<String>,
    seeds: Vec<u64>,
}

/// One run of the protocol.
#[derive(Clone)]
struct Entry {
    vehicle: PathBuf,
    /// `None`: the empty world.
    world: Option<PathBuf>,
    seed: u64,
}

impl Entry {
    fn vehicle_name(&self) -> String {
        stem(&self.vehicle)
    }

    fn world_name(&self) -> String {
        self.world
            .as_ref()
            .map_or_else(|| "empty".to_owned(), |w| stem(w))
    }
}

fn stem(p: &Path) -> String {
    p.file_stem()
        .map_or_else(String::new, |s| s.to_string_lossy().into_owned())
}

/// What one run gave.
struct Outcome {
    /// True approach, breakover, departure, degrees.
    truth_deg: [f64; 3],
    /// Measured - true, degrees (`None`: no angle).
    error_deg: [Option<f64>; 3],
    /// The calculator's expanded uncertainty U (k = 2), degrees.
    u_deg: [Option<f64>; 3],
    /// Why angles are missing (the calculator's error or which angle it did not find).
    missing: Option<String>,
    cpu_s: f64,
    frames: usize,
    /// With `--detail`: the witnesses against the truth's, and the trajectory's largest errors.
    detail: Vec<String>,
}

fn entries(dir: &Path, groups: &[Group]) -> Vec<Entry> {
    let mut out = Vec::new();
    for g in groups {
        for v in &g.vehicles {
            for w in &g.worlds {
                for &seed in &g.seeds {
                    out.push(Entry {
                        vehicle: dir.join(v),
                        world: (w != "empty").then(|| dir.join(w)),
                        seed,
                    });
                }
            }
        }
    }
    out
}

/// The simulator's transform as the pipeline's pose (both are `passangle_geom::Pose`).
fn pose_of(iso: &Isometry) -> Pose {
    *iso
}

/// The scenario of one run: the template with the run's vehicle, world and seed, the robot from
/// 1 m ahead of the vehicle's front to 1 m behind its rear.
fn scenario_of(
    template_path: &Path,
    template: &Scenario,
    entry: &Entry,
) -> anyhow::Result<Scenario> {
    let vehicle = Vehicle::load(&entry.vehicle)?;
    let mut file = template.file.clone();
    file.vehicle.clone_from(&entry.vehicle);
    file.world.clone_from(&entry.world);
    file.hall = None;
    file.seed = entry.seed;
    file.duration_s = None;
    file.robot.start_x_m = vehicle.front_x_m() + 1.0;
    file.robot.distance_m = vehicle.front_x_m() - vehicle.rear_x_m() + 2.0;
    Ok(Scenario::from_parts(template_path, file, vehicle)?)
}

/// The decoder settings a range calibration gives for the run's sensor (see `--calibrate`), and
/// a line on how its offsets compare with the simulated biases.
fn calibrated_decoder(
    template: &Scenario,
    entry: &Entry,
) -> anyhow::Result<(vlp16::DecoderConfig, String)> {
    // The calibration recording with the run's sensor (the template's VLP-16 and the run's
    // seed, so its range biases) and vehicle, on the tripod of the shipped scenario.
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("scenarios/field/lidar-calibration-tripod-hall-a.toml");
    let recording = Scenario::load(&path)?;
    let mut file = recording.file.clone();
    file.lidar = Vlp16Config {
        mount_xyz_m: file.lidar.mount_xyz_m,
        mount_rpy_deg: file.lidar.mount_rpy_deg,
        ..template.file.lidar.clone()
    };
    file.seed = entry.seed;
    file.vehicle.clone_from(&entry.vehicle);
    let vehicle = Vehicle::load(&entry.vehicle)?;
    file.robot.start_x_m = vehicle.front_x_m() + 1.0;
    let scenario = Scenario::from_parts(&path, file, vehicle)?;
    let scene = scenario.scene();
    let config = vlp16::DecoderConfig::default();
    let points: Vec<vlp16::Point> = scenario
        .decoded_vlp16_frames(&scene, &config)
        .into_iter()
        .flat_map(|f| f.points)
        .collect();
    let cal = vlp16::calibration::estimate_range_offsets(&points, &config)
        .context("range calibration")?;
    let motion = scenario.motion();
    let truth = hil_sim::vlp16::Vlp16Sim::new(
        &scene,
        &motion,
        scenario.lidar_config(),
        scenario.lidar_seed(),
    )
    .range_bias_m();
    let errors: Vec<String> = (0..16)
        .map(|l| match cal.standard_error_m[l] {
            Some(se) => format!(
                "{l}: {:+.1}+-{:.1}",
                1e3 * (cal.offsets_m[l] - truth[l]),
                1e3 * se
            ),
            None => format!("{l}: -"),
        })
        .collect();
    let rms_bias = (truth.iter().map(|b| b * b).sum::<f64>() / 16.0).sqrt();
    let line = format!(
        "range calibration: planes {}, residual sigma {:.1} mm, simulated biases RMS {:.1} mm; offset - bias per laser, mm: {}",
        cal.planes
            .iter()
            .map(|p| format!(
                "[n {:+.2} {:+.2} {:+.2} d {:.2} m, {} returns, sigma {:.1} mm]",
                p.normal[0],
                p.normal[1],
                p.normal[2],
                p.distance_m,
                p.returns,
                1e3 * p.residual_sigma_m
            ))
            .collect::<Vec<_>>()
            .join(" "),
        1e3 * cal.residual_sigma_m,
        1e3 * rms_bias,
        errors.join(", ")
    );
    let offsets = std::array::from_fn(|l| cal.offsets_m[l] as f32);
    Ok((
        vlp16::DecoderConfig {
            range_offsets_m: offsets,
            ..config
        },
        line,
    ))
}

/// The wheels' distance scale a calibration drive gives for the run's robot (see
/// `--calibrate`): the drive of `scenarios/field/wheel-calibration-hall-a.toml` with the
/// template's sensor and wheel settings and the run's seed (so its wheel errors), the lidar
/// decoded with `decoder` (the run's range calibration); and a line on how it compares with the
/// simulated error.
fn calibrated_wheel_scale(
    template: &Scenario,
    entry: &Entry,
    decoder: &vlp16::DecoderConfig,
) -> anyhow::Result<(f64, String)> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("scenarios/field/wheel-calibration-hall-a.toml");
    let drive = Scenario::load(&path)?;
    let mut file = drive.file.clone();
    file.lidar = template.file.lidar.clone();
    file.wheel_odometry = template.file.wheel_odometry;
    file.seed = entry.seed;
    let scenario = Scenario::from_parts(&path, file, drive.vehicle.clone())?;
    let scene = scenario.scene();
    let lidar = scenario.decoded_lidar_frames_with(&scene, decoder);
    let wheel = scenario.wheel_odometry(0.0);
    let mut mounts = pipeline::config::MountConfig::default();
    set_lidar_mount(&mut mounts, &scenario);
    let cal = onboard::wheel_calibration::calibrate_wheels(&lidar, &wheel, &mounts)
        .context("wheel calibration")?;
    let (scale_error, _) = hil_sim::wheel_odometry::constant_errors(
        &scenario.file.wheel_odometry,
        scenario.wheel_seed(),
    );
    let line = format!(
        "wheel calibration: walls' travel {:.4} m +- {:.1} mm ({} walls), wheels {:.4} m, scale {:.5} +- {:.5}; simulated error {:+.2} % (true scale {:.4})",
        cal.travel.distance_m,
        1e3 * cal.travel.standard_error_m,
        cal.travel.walls.len(),
        cal.wheel_distance_m,
        cal.scale,
        cal.standard_error,
        100.0 * scale_error,
        1.0 / (1.0 + scale_error)
    );
    Ok((cal.scale, line))
}

/// The scenario's VLP-16 mount in the pipeline's terms.
fn set_lidar_mount(mounts: &mut pipeline::config::MountConfig, scenario: &Scenario) {
    let lidar_mount = pose_of(&scenario.file.lidar.robot_from_lidar());
    mounts.lidar_xyz_m = lidar_mount.translation.into();
    mounts.lidar_rpy_rad = rpy_of(&lidar_mount.rotation).into();
}

/// CPU time of this thread, seconds (`/proc/thread-self/schedstat`).
fn thread_cpu_s() -> f64 {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|t| t.split_whitespace().next()?.parse::<u64>().ok())
        .map_or(0.0, |ns| ns as f64 * 1e-9)
}

/// What the pipeline takes from the D435 (`--camera`).
#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum Camera {
    /// Nothing: lidar + wheels.
    None,
    /// Its points in the output cloud (`visual.add-to-cloud`, the product's default).
    Cloud,
    /// Its visual odometry in the fusion (`fusion.use-visual`).
    Fused,
    /// Both.
    Both,
}

impl Camera {
    /// The saved clouds' file-name suffix.
    fn suffix(self) -> &'static str {
        match self {
            Self::None => "-no-camera",
            Self::Cloud => "",
            Self::Fused => "-camera-fused",
            Self::Both => "-camera-both",
        }
    }
}

/// The camera's image scale in the evaluation: a quarter of the D435's 848 x 480, read with a
/// pixel stride of a quarter of the pipeline's default, so the pipeline samples the same rays as
/// at full resolution while the simulator renders a sixteenth of them (per-pixel noise and the
/// stereo bands are then modelled on the coarse pixels: an approximation).
const CAMERA_SCALE: f64 = 0.25;

/// The pipeline on lidar frames, depth frames and wheel odometry in arrival order (a lidar frame
/// is available after its 0.1 s sweep, a depth frame at its exposure), with the default settings,
/// the scenario's mounts and what `camera` asks of the D435.
fn run_pipeline(
    scenario: &Scenario,
    lidar: &[LidarFrame],
    depth: &[DepthImage],
    wheel: &[WheelOdometry],
    camera: Camera,
) -> anyhow::Result<BuiltCloud> {
    let mut config = PipelineConfig::default();
    config.visual.enabled = camera != Camera::None;
    config.visual.add_to_cloud = matches!(camera, Camera::Cloud | Camera::Both);
    config.fusion.use_visual = matches!(camera, Camera::Fused | Camera::Both);
    config.visual.pixel_stride =
        ((config.visual.pixel_stride as f64 * CAMERA_SCALE).round() as usize).max(1);
    set_lidar_mount(&mut config.mounts, scenario);
    let camera_mount = pose_of(&scenario.file.depth.robot_from_camera());
    config.mounts.camera_xyz_m = camera_mount.translation.into();
    config.mounts.camera_rpy_rad = rpy_of(&camera_mount.rotation).into();
    let mut pipeline = Pipeline::new(config).context("pipeline settings")?;
    for e in hil_sim::feed::arrival_order(lidar, depth, wheel) {
        e.push_to(&mut pipeline).context("simulated input")?;
    }
    Ok(pipeline.finish())
}

/// The oracle's cloud and path (vehicle frame): every return of the run placed with the true
/// pose of its firing (the decoder's maths on the reported range), reduced to one centroid per
/// 5 mm voxel, and the lidar's true positions every 0.1 s.
fn oracle_cloud(
    scenario: &Scenario,
    scene: &hil_sim::world::Scene,
    range_offsets_m: &[f32; 16],
) -> (Vec<[f64; 3]>, Vec<[f64; 3]>, usize) {
    use hil_sim::vlp16::{ELEVATION_DEG, VERTICAL_OFFSET_MM, Vlp16Sim};
    let motion = scenario.motion();
    let sim = Vlp16Sim::new(
        scene,
        &motion,
        scenario.lidar_config(),
        scenario.lidar_seed(),
    );
    let packets = Vlp16Sim::<hil_sim::trajectory::StraightRun>::packets_in(scenario.duration_s);
    let mut cells: std::collections::BTreeMap<[i64; 3], ([f64; 3], u32)> =
        std::collections::BTreeMap::new();
    for k in 0..packets {
        sim.data_packet_with_truth(k, |f| {
            if f.distance_raw == 0 {
                return;
            }
            let laser = f.channel % 16;
            let (sin_w, cos_w) = ELEVATION_DEG[laser].to_radians().sin_cos();
            let (sin_a, cos_a) = sim.azimuth_at(f.time_s).sin_cos();
            let r = f64::from(f.distance_raw) * 0.002 - f64::from(range_offsets_m[laser]);
            let p = hil_sim::geometry::Vec3::new(
                r * cos_w * sin_a,
                r * cos_w * cos_a,
                r * sin_w + VERTICAL_OFFSET_MM[laser] / 1000.0,
            );
            let w = f.world_from_lidar.apply(p);
            let key = [w.x, w.y, w.z].map(|v| (v / 0.005).floor() as i64);
            let e = cells.entry(key).or_insert(([0.0; 3], 0));
            e.0[0] += w.x;
            e.0[1] += w.y;
            e.0[2] += w.z;
            e.1 += 1;
        });
    }
    let cloud = cells
        .into_values()
        .map(|(s, n)| s.map(|v| v / f64::from(n)))
        .collect();
    let steps = (scenario.duration_s / 0.1) as u32;
    let lidar = scenario.file.lidar.robot_from_lidar().translation;
    let path = (0..=steps)
        .map(|i| {
            let p = motion
                .pose_at(f64::from(i) * 0.1)
                .to_isometry()
                .apply(lidar);
            [p.x, p.y, p.z]
        })
        .collect();
    (cloud, path, packets as usize)
}

fn run(
    template_path: &Path,
    template: &Scenario,
    entry: &Entry,
    args: &Args,
) -> anyhow::Result<Outcome> {
    let oracle = args.oracle;
    let scenario = scenario_of(template_path, template, entry)?;
    let truth = true_angles(&scenario.vehicle, &TruthOptions::default());
    let truth_deg = [
        truth.approach.angle_rad,
        truth.breakover.angle_rad,
        truth.departure.angle_rad,
    ]
    .map(f64::to_degrees);
    let scene = scenario.scene();
    let mut detail = Vec::new();
    // With `--from-clouds` the calibration is in the saved clouds (`-calibrated` names).
    let (decoder, wheel_scale) = if args.calibrate && args.from_clouds.is_none() {
        let (config, line) = calibrated_decoder(template, entry)?;
        detail.push(line);
        let (scale, line) = calibrated_wheel_scale(template, entry, &config)?;
        detail.push(line);
        (config, scale)
    } else {
        (vlp16::DecoderConfig::default(), 1.0)
    };
    let (cloud, path, frames, cpu_s, x_sigma_per_m) = if let Some(dir) = &args.from_clouds {
        let (cloud, path, x_sigma_per_m) = load_cloud(dir, entry, args)?;
        (cloud, path, 0, 0.0, x_sigma_per_m)
    } else if oracle {
        let (cloud, path, packets) = oracle_cloud(&scenario, &scene, &decoder.range_offsets_m);
        (cloud, path, packets, 0.0, 0.0)
    } else {
        pipeline_cloud(
            &scenario,
            &scene,
            (&decoder, wheel_scale),
            args.camera,
            &mut detail,
        )?
    };
    if let Some(dir) = &args.save_clouds {
        save_cloud(dir, entry, args, (&cloud, &path, x_sigma_per_m))?;
    }
    let config = AnglesConfig {
        scan_path_in_cloud: path.into_iter().map(Into::into).collect(),
        trajectory_x_sigma_per_m: x_sigma_per_m,
        range_accuracy_m: Some(vlp16::RANGE_ACCURACY_M),
        scanner_view: Some(angles::ScannerView::VLP16),
        ..AnglesConfig::default()
    };
    let (error_deg, u_deg, missing) = match compute_angles(
        &cloud.iter().map(|&p| p.into()).collect::<Vec<_>>(),
        &config,
    ) {
        Ok(r) => {
            let names = ["approach", "breakover", "departure"];
            detail.extend(witness_detail(&r, &truth, &scenario.vehicle));
            let measured = [&r.approach, &r.breakover, &r.departure]
                .map(|a| a.as_ref().map(|a| a.angle_rad.to_degrees()));
            let absent: Vec<&str> = (0..3)
                .filter(|&k| measured[k].is_none())
                .map(|k| names[k])
                .collect();
            let missing = (!absent.is_empty()).then(|| {
                let reasons: Vec<String> = r
                    .not_measured
                    .iter()
                    .map(|n| format!("{} not measured: {}", n.quantity.name(), n.reason))
                    .collect();
                reasons.join("; ")
            });
            (
                [0, 1, 2].map(|k| measured[k].map(|m| m - truth_deg[k])),
                [&r.approach, &r.breakover, &r.departure]
                    .map(|a| a.as_ref().map(|a| a.uncertainty.expanded.to_degrees())),
                missing,
            )
        }
        Err(e) => ([None; 3], [None; 3], Some(e.to_string())),
    };
    Ok(Outcome {
        truth_deg,
        error_deg,
        u_deg,
        missing,
        cpu_s,
        frames,
        detail,
    })
}

/// The pipeline's cloud and path of a run (vehicle frame: the estimated trajectory placed at the
/// true first pose), its frames, CPU seconds and stated x error per metre; the trajectory's and
/// the wheel scale's detail lines go to `detail`.
#[allow(clippy::type_complexity)]
fn pipeline_cloud(
    scenario: &Scenario,
    scene: &hil_sim::world::Scene,
    (decoder, wheel_scale): (&vlp16::DecoderConfig, f64),
    camera: Camera,
    detail: &mut Vec<String>,
) -> anyhow::Result<(Vec<[f64; 3]>, Vec<[f64; 3]>, usize, f64, f64)> {
    let lidar = scenario.decoded_lidar_frames_with(scene, decoder);
    let wheel: Vec<WheelOdometry> = scenario
        .wheel_odometry(0.2)
        .into_iter()
        .map(|w| w.scaled(wheel_scale))
        .collect();
    // Every third frame of the 30 Hz stream, as the service records it (`camera.record-every`).
    let depth = if camera == Camera::None {
        Vec::new()
    } else {
        scenario.depth_images(scene, CAMERA_SCALE, 3)
    };
    let cpu0 = thread_cpu_s();
    let built = run_pipeline(scenario, &lidar, &depth, &wheel, camera)?;
    let cpu_s = thread_cpu_s() - cpu0;
    let Some(first) = built.trajectory.first() else {
        bail!("the pipeline built no trajectory");
    };
    let motion = scenario.motion();
    let t0 = pose_of(&motion.pose_at(first.stamp_s).to_isometry());
    let cloud: Vec<[f64; 3]> = built
        .points_in_world
        .iter()
        .map(|&p| t0.apply(p).into())
        .collect();
    let lidar_mount = pose_of(&scenario.file.lidar.robot_from_lidar());
    let path = built
        .lidar_path(lidar_mount.translation)
        .into_iter()
        .map(|p| t0.apply(p).into())
        .collect();
    detail.push(trajectory_errors(&built, &t0, &motion));
    let (scale_error, _) = hil_sim::wheel_odometry::constant_errors(
        &scenario.file.wheel_odometry,
        scenario.wheel_seed(),
    );
    let (measured, se) = built.stats.wheel_scale_estimate;
    detail.push(format!(
        "wheel scale: simulated error {:+.2} % (laser / wheel {:.4}), measured {measured:.4} +- {se:.4} from {} long baselines, applied {:.4}",
        100.0 * scale_error,
        1.0 / (1.0 + scale_error),
        built.stats.scale_measurements,
        built.stats.wheel_scale
    ));
    let x_sigma_per_m = built.x_sigma_per_m(&PipelineConfig::default().fusion);
    Ok((cloud, path, lidar.len(), cpu_s, x_sigma_per_m))
}

/// The file stem of a run's saved cloud.
fn cloud_stem(entry: &Entry, args: &Args) -> String {
    format!(
        "{}-{}-{}{}{}",
        entry.vehicle_name(),
        entry.world_name(),
        entry.seed,
        if args.oracle {
            "-oracle"
        } else {
            args.camera.suffix()
        },
        if args.calibrate { "-calibrated" } else { "" }
    )
}

/// `--save-clouds`: the cloud as binary PLY, the path as XYZ text (one `x y z` line per pose), and the
/// trajectory's stated error along x per metre in `.x-sigma`.
fn save_cloud(
    dir: &Path,
    entry: &Entry,
    args: &Args,
    (cloud, path, x_sigma_per_m): (&[[f64; 3]], &[[f64; 3]], f64),
) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| dir.display().to_string())?;
    let stem = cloud_stem(entry, args);
    let sigma = dir.join(format!("{stem}.x-sigma"));
    std::fs::write(&sigma, format!("{x_sigma_per_m:e}\n"))
        .with_context(|| sigma.display().to_string())?;
    let ply = dir.join(format!("{stem}.ply"));
    let file = std::fs::File::create(&ply).with_context(|| ply.display().to_string())?;
    cloud_io::write_ply(
        std::io::BufWriter::new(file),
        &cloud_io::Cloud {
            points_m: cloud.to_vec(),
        },
        cloud_io::PlyEncoding::BinaryLittleEndian,
    )
    .with_context(|| ply.display().to_string())?;
    let xyz = dir.join(format!("{stem}.path.xyz"));
    let file = std::fs::File::create(&xyz).with_context(|| xyz.display().to_string())?;
    cloud_io::write_xyz(
        std::io::BufWriter::new(file),
        &cloud_io::Cloud {
            points_m: path.to_vec(),
        },
    )
    .with_context(|| xyz.display().to_string())?;
    Ok(())
}

/// `--from-clouds`: a run's cloud, path and trajectory error as `--save-clouds` wrote them.
type Saved = (Vec<[f64; 3]>, Vec<[f64; 3]>, f64);

fn load_cloud(dir: &Path, entry: &Entry, args: &Args) -> anyhow::Result<Saved> {
    let stem = cloud_stem(entry, args);
    let ply = dir.join(format!("{stem}.ply"));
    let (cloud, _) = cloud_io::read_cloud(&ply).with_context(|| ply.display().to_string())?;
    let xyz = dir.join(format!("{stem}.path.xyz"));
    let (path, _) = cloud_io::read_cloud(&xyz).with_context(|| xyz.display().to_string())?;
    let sigma = dir.join(format!("{stem}.x-sigma"));
    let x_sigma_per_m = std::fs::read_to_string(&sigma)
        .with_context(|| sigma.display().to_string())?
        .trim()
        .parse()
        .with_context(|| sigma.display().to_string())?;
    Ok((cloud.points_m, path.points_m, x_sigma_per_m))
}

/// `--detail`: each angle's witness and uncertainty budget against the truth's witness, the axles
/// against the true tyre, the wheelbase and the ground.
fn witness_detail(
    r: &angles::AnglesResult,
    truth: &hil_sim::truth::TrueAngles,
    vehicle: &Vehicle,
) -> Vec<String> {
    let mut out = Vec::new();
    let names = ["approach", "breakover", "departure"];
    let true_witness = [&truth.approach, &truth.breakover, &truth.departure];
    for (k, f) in [&r.approach, &r.breakover, &r.departure].iter().enumerate() {
        let shown = true_witness[k].witness.as_ref().map_or_else(
            || "none".to_owned(),
            |w| format!("x {:+.3} z {:.3} ({})", w.x_m, w.z_m, w.source),
        );
        let found = f.as_ref().map_or_else(
            || "none".to_owned(),
            |f| {
                let w = f.witness_in_cloud;
                let u = &f.uncertainty;
                format!(
                    "x {:+.3} z {:.3} support {}, U {:.2} deg (u: height {:.2}, position {:.2}, radius {:.2}, axle {:.2}, ground {:.2}, trajectory {:.2}, end reach {:.2})",
                    w[0],
                    w[2],
                    f.support,
                    u.expanded.to_degrees(),
                    u.witness_height.to_degrees(),
                    u.witness_position.to_degrees(),
                    u.tyre_radius.to_degrees(),
                    u.axle_position.to_degrees(),
                    u.ground.to_degrees(),
                    u.trajectory.to_degrees(),
                    u.end_reach.to_degrees()
                )
            },
        );
        out.push(format!("{}: witness {found}; true {shown}", names[k]));
    }
    let tyre = &vehicle.tyre;
    for (name, a) in [("front", &r.front_axle), ("rear", &r.rear_axle)] {
        out.push(format!(
            "{name} axle: x {:+.3}, loaded radius {:.3} (true {:.3}), free radius {:.3} (true {:.3})",
            a.x_m,
            a.loaded_radius_m,
            tyre.radius_m,
            a.free_radius_m,
            tyre.tread_radius()
        ));
    }
    out.push(format!(
        "wheelbase {:.3} (true {:.3}); ground sigma {:.1} mm, tilt {:.2} deg",
        r.wheelbase_m,
        vehicle.wheelbase_m,
        r.ground.noise_sigma_m * 1e3,
        r.ground.tilt_rad.to_degrees()
    ));
    out
}

/// The trajectory's largest errors against the truth (vehicle frame): x, y, z (cm) and pitch,
/// roll (degrees).
fn trajectory_errors(built: &BuiltCloud, t0: &Pose, motion: &impl Trajectory) -> String {
    let mut worst = [0.0_f64; 5];
    let mut worst_frame = String::new();
    let mut tilted = 0;
    for tp in &built.trajectory {
        let est = t0.compose(&tp.world_from_robot);
        let truth = pose_of(&motion.pose_at(tp.stamp_s).to_isometry());
        let (e, t) = (rpy_of(&est.rotation), rpy_of(&truth.rotation));
        let errs = [
            100.0 * (est.translation[0] - truth.translation[0]),
            100.0 * (est.translation[1] - truth.translation[1]),
            100.0 * (est.translation[2] - truth.translation[2]),
            (e[1] - t[1]).to_degrees(),
            (e[0] - t[0]).to_degrees(),
        ];
        if errs[3].abs().max(errs[4].abs()) > 0.5 {
            tilted += 1;
        }
        if errs[3].abs() > worst[3].abs() {
            worst_frame = format!(
                "t {:.1} s, chosen {:?}, laser degenerate {:?}, refinement rejected {:?}",
                tp.stamp_s, tp.chosen, tp.laser_degenerate, tp.refine_rejected
            );
        }
        for (w, x) in worst.iter_mut().zip(errs) {
            if x.abs() > w.abs() {
                *w = x;
            }
        }
    }
    format!(
        "trajectory worst: x {:+.1} cm, y {:+.1} cm, z {:+.1} cm, pitch {:+.2} deg, roll {:+.2} deg; {tilted} of {} frames off by more than 0.5 deg in pitch or roll ({} without ground); worst pitch at {worst_frame}",
        worst[0],
        worst[1],
        worst[2],
        worst[3],
        worst[4],
        built.trajectory.len(),
        built.stats.frames_without_ground
    )
}

fn fmt_err(e: Option<f64>) -> String {
    e.map_or_else(|| "-".to_owned(), |v| format!("{v:+.2}"))
}

// One table and its summary, printed in order.
#[allow(clippy::too_many_lines)]
fn print_set(name: &str, entries: &[Entry], outcomes: &[anyhow::Result<Outcome>]) {
    println!("## {name} set: {} runs\n", entries.len());
    println!(
        "| vehicle | world | seed | true a / b / d deg | approach err | breakover err | departure err | mean abs | max abs | within 0.5 | missing |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    let mut per_angle: [Vec<f64>; 3] = [Vec::new(), Vec::new(), Vec::new()];
    // Per angle: (|error|, U) of every measured angle.
    let mut with_u: [Vec<(f64, f64)>; 3] = [Vec::new(), Vec::new(), Vec::new()];
    let (mut runs_all_ok, mut runs_without, mut angles_total) = (0, Vec::new(), 0);
    for (e, o) in entries.iter().zip(outcomes) {
        let (v, w) = (e.vehicle_name(), e.world_name());
        match o {
            Err(err) => {
                println!(
                    "| {v} | {w} | {} | - | - | - | - | - | - | 0/3 | run failed: {err:#} |",
                    e.seed
                );
                runs_without.push(format!("{v}/{w}/{}: run failed: {err:#}", e.seed));
                angles_total += 3;
            }
            Ok(o) => {
                let found: Vec<f64> = o.error_deg.iter().flatten().map(|x| x.abs()).collect();
                for (k, err) in o.error_deg.iter().enumerate() {
                    if let Some(x) = err {
                        per_angle[k].push(x.abs());
                        if let Some(u) = o.u_deg[k] {
                            with_u[k].push((x.abs(), u));
                        }
                    }
                }
                angles_total += 3;
                let within = found.iter().filter(|x| **x <= 0.5).count();
                if within == 3 {
                    runs_all_ok += 1;
                }
                let (mean, max) = if found.is_empty() {
                    ("-".to_owned(), "-".to_owned())
                } else {
                    (
                        format!("{:.2}", found.iter().sum::<f64>() / found.len() as f64),
                        format!("{:.2}", found.iter().fold(0.0_f64, |m, x| m.max(*x))),
                    )
                };
                if let Some(why) = &o.missing {
                    runs_without.push(format!("{v}/{w}/{}: {why}", e.seed));
                }
                println!(
                    "| {v} | {w} | {} | {:.2} / {:.2} / {:.2} | {} | {} | {} | {mean} | {max} | {within}/3 | {} |",
                    e.seed,
                    o.truth_deg[0],
                    o.truth_deg[1],
                    o.truth_deg[2],
                    fmt_err(o.error_deg[0]),
                    fmt_err(o.error_deg[1]),
                    fmt_err(o.error_deg[2]),
                    o.missing.as_deref().unwrap_or(""),
                );
            }
        }
    }
    println!("\n| {name} | approach | breakover | departure |");
    println!("|---|---|---|---|");
    let stat = |f: &dyn Fn(&[f64]) -> String| -> String {
        per_angle
            .iter()
            .map(|v| f(v))
            .collect::<Vec<_>>()
            .join(" | ")
    };
    println!(
        "| angles found | {} |",
        stat(&|v| format!("{} of {}", v.len(), entries.len()))
    );
    println!(
        "| mean abs error deg | {} |",
        stat(&|v| if v.is_empty() {
            "-".to_owned()
        } else {
            format!("{:.2}", v.iter().sum::<f64>() / v.len() as f64)
        })
    );
    println!(
        "| max abs error deg | {} |",
        stat(&|v| if v.is_empty() {
            "-".to_owned()
        } else {
            format!("{:.2}", v.iter().fold(0.0_f64, |m, x| m.max(*x)))
        })
    );
    println!(
        "| within 0.5 deg | {} |",
        stat(&|v| format!(
            "{} of {}",
            v.iter().filter(|x| **x <= 0.5).count(),
            entries.len()
        ))
    );
    let covered = |v: &[(f64, f64)]| v.iter().filter(|(e, u)| e <= u).count();
    let median_u = |v: &[(f64, f64)]| {
        let mut us: Vec<f64> = v.iter().map(|(_, u)| *u).collect();
        us.sort_by(f64::total_cmp);
        us.get(us.len() / 2)
            .map_or_else(|| "-".to_owned(), |u| format!("{u:.2}"))
    };
    println!(
        "| true value within +-U | {} |",
        with_u
            .iter()
            .map(|v| format!("{} of {}", covered(v), v.len()))
            .collect::<Vec<_>>()
            .join(" | ")
    );
    println!(
        "| median U deg | {} |",
        with_u
            .iter()
            .map(|v| median_u(v))
            .collect::<Vec<_>>()
            .join(" | ")
    );
    let all_u: Vec<(f64, f64)> = with_u.iter().flatten().copied().collect();
    println!(
        "\n{name}: the true value lies within +-U (k = 2) for {} of {} measured angles ({:.0} %), median U {} deg",
        covered(&all_u),
        all_u.len(),
        100.0 * covered(&all_u) as f64 / all_u.len().max(1) as f64,
        median_u(&all_u)
    );
    let within_all: usize = per_angle
        .iter()
        .map(|v| v.iter().filter(|x| **x <= 0.5).count())
        .sum();
    println!(
        "\n{name}: {within_all} of {angles_total} angles within 0.5 degree; {runs_all_ok} of {} runs with all three within 0.5 degree; {} runs without all angles",
        entries.len(),
        runs_without.len()
    );
    for r in &runs_without {
        println!("- {r}");
    }
    println!();
}

/// `--detail`'s lines of every run.
fn print_detail(list: &[Entry], outcomes: &[anyhow::Result<Outcome>]) {
    for (e, o) in list.iter().zip(outcomes) {
        if let Ok(o) = o {
            println!("{}/{}/{}:", e.vehicle_name(), e.world_name(), e.seed);
            for line in &o.detail {
                println!("  {line}");
            }
        }
    }
    println!();
}

/// The held-out protocol's bench (see the module docs).
#[derive(clap::Parser)]
struct Args {
    /// Which set: tuning, held-out or both.
    #[arg(long, default_value = "both")]
    set: String,
    /// The protocol file.
    #[arg(long)]
    protocol: Option<PathBuf>,
    /// Worker threads (each run is single-threaded and seeded, so the tables do not depend on it).
    #[arg(long, default_value_t = 2)]
    jobs: usize,
    /// Only runs whose `vehicle/world/seed` contains this (`van`, `hall-a`, `suv_unibody/hall-a/1`).
    #[arg(long)]
    only: Option<String>,
    /// The calculator alone: true poses instead of the pipeline.
    #[arg(long)]
    oracle: bool,
    /// After each table, every run's witnesses against the truth's and, for the pipeline, the
    /// trajectory's largest errors.
    #[arg(long)]
    detail: bool,
    /// Write each run's cloud (vehicle frame) as `DIR/VEHICLE-WORLD-SEED[SUFFIX].ply` (suffix
    /// `-oracle`, or `-no-camera`, `-camera-fused`, `-camera-both` for a `--camera` other than
    /// the default; then `-calibrated` with `--calibrate`) and its scan path as `.path.xyz`
    /// beside it, for `passangle angles` and a look by eye.
    #[arg(long, value_name = "DIR")]
    save_clouds: Option<PathBuf>,
    /// Read each run's cloud, path and trajectory error from DIR, as `--save-clouds` wrote them,
    /// instead of simulating and running the pipeline: the calculator alone on the same clouds
    /// (no trajectory detail, no CPU figures).
    #[arg(long, value_name = "DIR", conflicts_with = "save_clouds")]
    from_clouds: Option<PathBuf>,
    /// What the pipeline takes from the simulated D435: nothing, its points in the cloud (the
    /// product's default), its odometry in the fusion, or both.
    #[arg(long, value_enum, default_value = "cloud")]
    camera: Camera,
    /// Calibrate the simulated VLP-16's per-laser range offsets before each run, as the
    /// operator's manual describes (`passangle lidar --calibrate`): a 2 s recording with the
    /// sensor raised to 1.5 m in hall A (`scenarios/field/lidar-calibration-tripod-hall-a.toml`)
    /// with the run's sensor seed (so its range biases), its offsets estimated by
    /// `vlp16::calibration` and applied by the decoder (and by the oracle's placement).
    #[arg(long)]
    calibrate: bool,
}

/// What the tables measure.
fn print_header(args: &Args, shown: &str) {
    if args.oracle {
        println!(
            "Protocol {shown}, oracle: lidar returns placed with the true poses (5 mm voxel centroids), angle calculator at its defaults; errors are measured - true, degrees.\n"
        );
    } else {
        let sources = match args.camera {
            Camera::None => "lidar + wheel odometry",
            Camera::Cloud => "lidar + wheel odometry, D435 points where the lidar does not see",
            Camera::Fused => "lidar + wheel + D435 visual odometry",
            Camera::Both => {
                "lidar + wheel + D435 visual odometry, D435 points where the lidar does not see"
            }
        };
        println!(
            "Protocol {shown}: {sources}, pipeline and angle calculator at their defaults otherwise; errors are measured - true, degrees.\n"
        );
    }
}

fn main() -> anyhow::Result<()> {
    let args = <Args as clap::Parser>::parse();
    let shown = args.protocol.as_ref().map_or_else(
        || "hil-sim/evaluation.toml".to_owned(),
        |p| p.display().to_string(),
    );
    // Absolute, so that the vehicle and world paths it gives each run do not resolve again
    // against the template's directory (a relative `--protocol evaluation.toml` found no worlds).
    let protocol_path = std::path::absolute(
        args.protocol
            .clone()
            .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("evaluation.toml")),
    )
    .context("the protocol's path")?;
    let text = std::fs::read_to_string(&protocol_path)
        .with_context(|| protocol_path.display().to_string())?;
    let protocol: Protocol =
        toml::from_str(&text).with_context(|| protocol_path.display().to_string())?;
    let dir = protocol_path.parent().unwrap_or(Path::new("."));
    let template_path = dir.join(&protocol.template);
    let template = Scenario::load(&template_path)?;
    let sets: Vec<(&str, &[Group])> = match args.set.as_str() {
        "tuning" => vec![("tuning", &protocol.tuning)],
        "held-out" => vec![("held-out", &protocol.held_out)],
        "both" => vec![
            ("tuning", &protocol.tuning),
            ("held-out", &protocol.held_out),
        ],
        other => bail!("--set must be tuning, held-out or both, not {other:?}"),
    };
    print_header(&args, &shown);
    for (name, groups) in sets {
        let mut list = entries(dir, groups);
        if let Some(o) = &args.only {
            list.retain(|e| {
                format!("{}/{}/{}", e.vehicle_name(), e.world_name(), e.seed).contains(o.as_str())
            });
        }
        let results: Mutex<Vec<Option<anyhow::Result<Outcome>>>> =
            Mutex::new((0..list.len()).map(|_| None).collect());
        let next = Mutex::new(0usize);
        let started = Instant::now();
        std::thread::scope(|s| {
            for _ in 0..args.jobs.max(1) {
                s.spawn(|| {
                    loop {
                        let i = {
                            let mut n = next.lock().expect("not poisoned");
                            let i = *n;
                            *n += 1;
                            i
                        };
                        let Some(entry) = list.get(i) else { break };
                        let t = Instant::now();
                        let r = run(&template_path, &template, entry, &args);
                        match &r {
                            Ok(o) => eprintln!(
                                "{name} {}/{}/{}: {} frames, pipeline {:.1} ms CPU per frame, run {:.1} s",
                                entry.vehicle_name(),
                                entry.world_name(),
                                entry.seed,
                                o.frames,
                                o.cpu_s * 1e3 / o.frames.max(1) as f64,
                                t.elapsed().as_secs_f64()
                            ),
                            Err(e) => eprintln!(
                                "{name} {}/{}/{}: {e:#}",
                                entry.vehicle_name(),
                                entry.world_name(),
                                entry.seed
                            ),
                        }
                        results.lock().expect("not poisoned")[i] = Some(r);
                    }
                });
            }
        });
        eprintln!(
            "{name}: {} runs in {:.0} s",
            list.len(),
            started.elapsed().as_secs_f64()
        );
        let outcomes: Vec<anyhow::Result<Outcome>> = results
            .into_inner()
            .expect("not poisoned")
            .into_iter()
            .map(|r| r.unwrap_or_else(|| Err(anyhow::anyhow!("not run"))))
            .collect();
        print_set(name, &list, &outcomes);
        if args.detail {
            print_detail(&list, &outcomes);
        }
    }
    Ok(())
}
