//! Evidence for the point-cloud pipeline (`pipeline`, issue 7) on simulator runs with
//! ground truth: trajectory error, cloud error, angles against the geometry's truth, and time per
//! lidar frame, for the configurations of the paper's Figure 14 ablation.
//!
//! Run: `cargo run --release -p hil-sim --example bench_pipeline -- [SEEDS] [--ablation | --peer]
//! [--no-depth] [--only NAME] [--duration-s S] [--no-refine] [--eigen-min E] [--export DIR]
//! [--save-clouds DIR] [--config FILE] [--wheel-noise]`
//! (defaults: 10 seeds, laser + wheel, the pipeline's defaults and the full configuration; `--config FILE` starts every
//! variant from the pipeline settings in FILE, a TOML table like the service's `[pipeline]`). `--ablation` adds wheel only,
//! laser only, laser + visual, without ground removal and without outlier removal, on the first
//! seed of every scenario. `--peer` runs exactly the two configurations of the KISS-ICP
//! comparison, laser only and laser + wheel (no depth). `--export DIR` writes each run's lidar
//! frames, the true poses and our estimated trajectories for the peer run
//! (`bench/pipeline_peer.sh`; layout at [`export_frames`]). `--save-clouds DIR` writes the
//! cloud the angle figures were computed from, with the true angles and the trajectory, for
//! re-running the angle calculator without the pipeline (layout at [`save_cloud`]; reader:
//! `cargo run --release -p onboard --example accuracy_angles -- saved DIR`).
//!
//! Inputs per run (all from `hil_sim`, all seeded): the VLP-16 packets decoded by
//! `vlp16::FrameAssembler`, the D435 depth frames (every 3rd, i.e. 10 Hz), and wheel
//! odometry at 100 Hz from the scenario's wheel distance (which includes the scenario's slip: the
//! wheels overestimate the distance exactly as a slipping robot's would) with the scenario's
//! `[wheel_odometry]` errors (`hil_sim::wheel_odometry`; none in the shipped scenarios, so exact
//! but for the slip; `--wheel-noise` applies `WheelNoise::TYPICAL_MECANUM`, an assumption, where
//! a scenario sets none). Stamps are simulation time (the sensor clocks of the shipped scenarios
//! have zero offset).
//!
//! Figures:
//! - ATE: RMS over frames of the translation error of `world_from_robot` against the truth (both
//!   relative to the first frame), metres; drift: final translation error / distance travelled.
//! - cloud error: distance of each built point to the nearest true surface (ground, tyres, body
//!   prisms, parts): median and 95th percentile, metres.
//! - angles: `angles::compute_angles` on the built cloud (moved into the vehicle frame by
//!   the true start pose, with the estimated trajectory as the scan's path, as the robot would
//!   give it) against `hil_sim::truth::true_angles`, degrees. The closing table gives per
//!   scenario the angle errors' mean and sample standard deviation over the seeds and the ATE's
//!   mean and largest (of laser + visual + wheel, else laser + wheel), then how many angles meet
//!   issue 7's target (sd < 0.15 degree).
//! - time: wall time of `Pipeline` calls per lidar frame (decode and simulation excluded), ms,
//!   and the thread's CPU time over the same calls (`/proc/thread-self/schedstat`; the pipeline
//!   is single-threaded), which other processes' load on a shared machine does not inflate.

use std::fmt::Write as _;

use anyhow::Context as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use angles::{AnglesConfig, compute_angles};
use cloud_io::{Cloud, PlyEncoding, write_ply};
use hil_sim::geometry::{Isometry, Vec3};
use hil_sim::scenario::Scenario;
use hil_sim::trajectory::Trajectory;
use hil_sim::truth::{TruthOptions, true_angles};
use hil_sim::wheel_odometry::WheelNoise;
use hil_sim::world::Scene;
use pipeline::geom::{Pose, rpy_of};
use pipeline::{BuiltCloud, DepthImage, LidarFrame, Pipeline, PipelineConfig, WheelOdometry};

/// One configuration of the ablation.
struct Variant {
    name: &'static str,
    config: PipelineConfig,
    depth: bool,
}

/// Which configurations a seed runs.
#[derive(Clone, Copy, PartialEq)]
enum Mode {
    /// Laser + wheel, the pipeline's defaults (the camera's points added) and laser + visual + wheel.
    Default,
    /// All of the Figure 14 ablation.
    Ablation,
    /// Laser only and laser + wheel: the KISS-ICP comparison.
    Peer,
}

/// The configurations of `mode`. Without `depth`, the two "no ..." rows of the ablation leave
/// their stage out of laser + wheel instead of the full configuration (and say so in the name).
fn variants(mode: Mode, depth: bool, base: &PipelineConfig) -> Vec<Variant> {
    // "defaults": the pipeline as the robot runs it, laser + wheel with the camera's points where
    // the lidar is blind (decision record 037), its odometry not fused.
    let defaults = base.clone();
    // "laser+visual+wheel": the camera fused and its points in the cloud (the fusion is off in
    // the pipeline's defaults), as the ablation table measures it.
    let mut full = base.clone();
    full.fusion.use_visual = true;
    full.visual.add_to_cloud = true;
    let mut wheel_only = full.clone();
    wheel_only.fusion.use_laser = false;
    wheel_only.fusion.use_visual = false;
    wheel_only.map.refine = false;
    let mut laser = full.clone();
    laser.fusion.use_wheel = false;
    laser.fusion.use_visual = false;
    laser.visual.enabled = false;
    let mut laser_wheel = full.clone();
    laser_wheel.fusion.use_visual = false;
    laser_wheel.visual.enabled = false;
    let mut laser_visual = full.clone();
    laser_visual.fusion.use_wheel = false;
    let base = if depth { &full } else { &laser_wheel };
    let mut no_ground = base.clone();
    no_ground.ground.enabled = false;
    let mut no_outliers = base.clone();
    no_outliers.features.outlier_removal = false;
    let v = |name, config, depth| Variant {
        name,
        config,
        depth,
    };
    match mode {
        Mode::Default => vec![
            v("laser+wheel", laser_wheel, false),
            v("defaults", defaults, true),
            v("laser+visual+wheel", full, true),
        ],
        Mode::Peer => vec![
            v("laser only", laser, false),
            v("laser+wheel", laser_wheel, false),
        ],
        Mode::Ablation => vec![
            v("wheel only (baseline)", wheel_only, false),
            v("laser only", laser, false),
            v("laser+wheel", laser_wheel, false),
            v("laser+visual", laser_visual, true),
            v("laser+visual+wheel", full, true),
            v(
                if depth {
                    "no ground removal"
                } else {
                    "no ground removal (laser+wheel)"
                },
                no_ground,
                depth,
            ),
            v(
                if depth {
                    "no outlier removal"
                } else {
                    "no outlier removal (laser+wheel)"
                },
                no_outliers,
                depth,
            ),
        ],
    }
}

/// The simulator's transform as the pipeline's pose (both are `passangle_geom::Pose`).
fn pose_of(iso: &Isometry) -> Pose {
    *iso
}

/// The pipeline's mounts from the scenario's sensor configs.
fn mounts_from(scenario: &Scenario, config: &mut PipelineConfig) {
    let lidar = pose_of(&scenario.file.lidar.robot_from_lidar());
    let camera = pose_of(&scenario.file.depth.robot_from_camera());
    config.mounts.lidar_xyz_m = lidar.translation.into();
    config.mounts.lidar_rpy_rad = rpy_of(&lidar.rotation).into();
    config.mounts.camera_xyz_m = camera.translation.into();
    config.mounts.camera_rpy_rad = rpy_of(&camera.rotation).into();
}

/// CPU time this thread has run, seconds, from the kernel's scheduler statistics
/// (`/proc/thread-self/schedstat`, first field in nanoseconds); `None` where that file is
/// missing. On a shared machine it is the figure that other processes' load does not inflate.
fn thread_cpu_s() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    let ns: u64 = text.split_whitespace().next()?.parse().ok()?;
    Some(ns as f64 * 1e-9)
}

/// Time the pipeline took: wall clock and, where the kernel reports it, this thread's CPU time.
struct Timing {
    wall_s: f64,
    cpu_s: Option<f64>,
}

/// Feed everything in time order; returns the result and the time the pipeline's calls took.
fn run_pipeline(
    config: PipelineConfig,
    lidar: &[LidarFrame],
    depth: &[DepthImage],
    wheel: &[WheelOdometry],
) -> (BuiltCloud, Timing) {
    let events = hil_sim::feed::arrival_order(lidar, depth, wheel);
    let start = Instant::now();
    let cpu_start = thread_cpu_s();
    let mut pipeline = Pipeline::new(config).expect("valid config");
    for e in events {
        e.push_to(&mut pipeline)
            .expect("simulated input is well-formed");
    }
    let built = pipeline.finish();
    let timing = Timing {
        wall_s: start.elapsed().as_secs_f64(),
        cpu_s: cpu_start.zip(thread_cpu_s()).map(|(a, b)| b - a),
    };
    (built, timing)
}

/// The estimated robot positions, moved into the vehicle frame like the cloud (by the true start
/// pose `t0`): the scan's path for the angle calculator's coverage check.
/// The lidar's path (its optical centre along the trajectory) in the vehicle frame.
fn path_in_vehicle(scenario: &Scenario, built: &BuiltCloud, t0: &Pose) -> Vec<[f64; 3]> {
    let lidar = pose_of(&scenario.file.lidar.robot_from_lidar());
    built
        .lidar_path(lidar.translation)
        .into_iter()
        .map(|p| t0.apply(p).into())
        .collect()
}

/// Distance from `p` (vehicle frame) to the nearest true surface (the hall's too, if any).
fn surface_distance(scene: &Scene, p: [f64; 3]) -> f64 {
    scene.distance_to_nearest(Vec3::new(p[0], p[1], p[2]))
}

fn percentile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}

struct Figures {
    ate_m: f64,
    drift_per_m: f64,
    cloud_median_m: f64,
    cloud_p95_m: f64,
    angle_error_deg: [f64; 3],
    ms_per_frame: f64,
    cpu_ms_per_frame: f64,
    points: usize,
}

fn evaluate(scenario: &Scenario, scene: &Scene, built: &BuiltCloud, time: &Timing) -> Figures {
    let motion = scenario.motion();
    let truth = |t: f64| pose_of(&motion.pose_at(t).to_isometry());
    let t0 = truth(built.trajectory[0].stamp_s);
    let mut sq = 0.0;
    let mut final_err = 0.0;
    let mut max_rpy_err = [0.0_f64; 3];
    let mut max_xyz_err = [0.0_f64; 3];
    for tp in &built.trajectory {
        let rel = t0.inverse().compose(&truth(tp.stamp_s));
        let r = rel.inverse().compose(&tp.world_from_robot).rpy();
        for k in 0..3 {
            max_rpy_err[k] = max_rpy_err[k].max(r[k].abs().to_degrees());
            max_xyz_err[k] =
                max_xyz_err[k].max((tp.world_from_robot.translation[k] - rel.translation[k]).abs());
        }
        let d: Vec<f64> = (0..3)
            .map(|k| tp.world_from_robot.translation[k] - rel.translation[k])
            .collect();
        final_err = d.iter().map(|v| v * v).sum::<f64>().sqrt();
        sq += final_err * final_err;
    }
    eprintln!(
        "max |error| roll/pitch/yaw deg {max_rpy_err:.3?}, x/y/z m {max_xyz_err:.4?}; wheel scale {:.4}, yaw bias {:+.3} deg/s ({} yaw measurements)",
        built.stats.wheel_scale,
        built.stats.wheel_yaw_bias_radps.to_degrees(),
        built.stats.yaw_measurements
    );
    let n = built.trajectory.len() as f64;
    let last = built.trajectory.last().map_or(0.0, |l| l.stamp_s);
    let t_last = t0.inverse().compose(&truth(last)).translation;
    let travelled = t_last.iter().map(|v| v * v).sum::<f64>().sqrt();
    let in_vehicle: Vec<[f64; 3]> = built
        .points_in_world
        .iter()
        .map(|&p| t0.apply(p).into())
        .collect();
    let mut dist: Vec<f64> = in_vehicle
        .iter()
        .step_by(7)
        .map(|&p| surface_distance(scene, p))
        .collect();
    dist.sort_by(f64::total_cmp);
    let true_a = true_angles(&scenario.vehicle, &TruthOptions::default());
    let t = [
        true_a.approach.angle_rad,
        true_a.breakover.angle_rad,
        true_a.departure.angle_rad,
    ];
    let config = AnglesConfig {
        scan_path_in_cloud: path_in_vehicle(scenario, built, &t0)
            .into_iter()
            .map(Into::into)
            .collect(),
        range_accuracy_m: Some(vlp16::RANGE_ACCURACY_M),
        scanner_view: Some(angles::ScannerView::VLP16),
        ..AnglesConfig::default()
    };
    let angle_error_deg = match compute_angles(
        &in_vehicle.iter().map(|&p| p.into()).collect::<Vec<_>>(),
        &config,
    ) {
        Ok(r) => {
            let m = [&r.approach, &r.breakover, &r.departure]
                .map(|a| a.as_ref().map_or(f64::NAN, |a| a.angle_rad));
            [0, 1, 2].map(|k| (m[k] - t[k]).to_degrees())
        }
        Err(e) => {
            eprintln!("angle calculator failed: {e}");
            [f64::NAN; 3]
        }
    };
    Figures {
        ate_m: (sq / n).sqrt(),
        drift_per_m: final_err / travelled.max(1e-9),
        cloud_median_m: percentile(&dist, 0.5),
        cloud_p95_m: percentile(&dist, 0.95),
        angle_error_deg,
        ms_per_frame: time.wall_s * 1e3 / n,
        cpu_ms_per_frame: time.cpu_s.map_or(f64::NAN, |s| s * 1e3 / n),
        points: built.points_in_world.len(),
    }
}

/// A pose as one line of 12 numbers, KITTI style: the rotation's rows, each followed by that
/// row's translation (`r00 r01 r02 tx r10 r11 r12 ty r20 r21 r22 tz`).
fn kitti_row(p: &Pose) -> String {
    let (r, t) = (&p.rotation, &p.translation);
    (0..3)
        .map(|i| format!("{} {} {} {}", r[(i, 0)], r[(i, 1)], r[(i, 2)], t[i]))
        .collect::<Vec<_>>()
        .join(" ")
}

/// Export of one run for the peer (`bench/pipeline_peer.py`), under `DIR/NAME/`:
/// - `frames/NNNNNN.bin`: per point `x y z t` as little-endian f32, x y z in the VLP-16's own
///   sensor frame (manual convention: x right, y forward at azimuth 0, z up), metres, exactly as
///   decoded (not deskewed); t = firing time after the frame's first firing, seconds. KITTI's
///   `.bin` layout with the time in the intensity column.
/// - `robot_from_lidar.txt`: the mount, one KITTI row.
/// - `truth.txt`: per frame `start_s end_s` (first and last firing, simulation time) then the
///   true `vehicle_from_robot` at `start_s` and at `end_s` (two KITTI rows, 24 numbers).
/// - `check.txt`: the convention check. Every 97th point of the first, middle and last frame,
///   moved into the vehicle frame by the exact true pose at its firing time and the mount:
///   `frame point x y z`. Its header gives the median distance of these points to the true
///   surfaces: range noise (millimetres) only if the frames, the mount and the truth agree. The
///   peer script maps the same points from the files and must land on them.
///
/// The peer needs both instants: our poses are for the frame start, KISS-ICP deskews each frame
/// to its last point and so reports the sensor pose at the frame end.
fn export_frames(
    dir: &Path,
    name: &str,
    scenario: &Scenario,
    scene: &Scene,
    frames: &[LidarFrame],
) -> anyhow::Result<()> {
    let root = dir.join(name);
    std::fs::create_dir_all(root.join("frames"))?;
    let motion = scenario.motion();
    let robot_at = |t: f64| pose_of(&motion.pose_at(t).to_isometry());
    let mut truth = String::from(
        "# start_s end_s vehicle_from_robot(start_s) vehicle_from_robot(end_s), KITTI rows\n",
    );
    for (i, f) in frames.iter().enumerate() {
        let mut bytes = Vec::with_capacity(f.points.len() * 16);
        let mut last_s = 0.0_f64;
        for p in &f.points {
            for v in p.xyz_in_lidar_m {
                bytes.extend_from_slice(&v.to_le_bytes());
            }
            bytes.extend_from_slice(&p.time_offset_s.to_le_bytes());
            last_s = last_s.max(f64::from(p.time_offset_s));
        }
        std::fs::write(root.join("frames").join(format!("{i:06}.bin")), bytes)?;
        let end_s = f.stamp_s + last_s;
        writeln!(
            truth,
            "{} {} {} {}",
            f.stamp_s,
            end_s,
            kitti_row(&robot_at(f.stamp_s)),
            kitti_row(&robot_at(end_s))
        )?;
    }
    std::fs::write(root.join("truth.txt"), truth)?;
    let mount = pose_of(&scenario.file.lidar.robot_from_lidar());
    std::fs::write(
        root.join("robot_from_lidar.txt"),
        format!("{}\n", kitti_row(&mount)),
    )?;
    let mut samples = Vec::new();
    for i in [0, frames.len() / 2, frames.len() - 1] {
        let f = &frames[i];
        for (j, p) in f.points.iter().enumerate().step_by(97) {
            let world_from_lidar = robot_at(f.stamp_s + f64::from(p.time_offset_s)).compose(&mount);
            samples.push((
                i,
                j,
                world_from_lidar.apply(pipeline::geom::V3::from(p.xyz_in_lidar_m.map(f64::from))),
            ));
        }
    }
    let mut distances: Vec<f64> = samples
        .iter()
        .map(|&(_, _, v)| surface_distance(scene, v.into()))
        .collect();
    distances.sort_by(f64::total_cmp);
    let median_mm = percentile(&distances, 0.5) * 1e3;
    eprintln!(
        "{name}: export check: median distance of true-posed points to the surfaces {median_mm:.1} mm"
    );
    let mut check = format!(
        "# frame point x y z (vehicle frame, exact truth); median distance to the true surfaces {median_mm:.2} mm\n"
    );
    for (i, j, v) in samples {
        writeln!(check, "{i} {j} {} {} {}", v[0], v[1], v[2])?;
    }
    std::fs::write(root.join("check.txt"), check)?;
    // Our variants append their lines to it; a re-export starts it afresh.
    std::fs::write(
        root.join("ours.tsv"),
        "# variant slug ate_m drift_per_m ms_per_frame cpu_ms_per_frame frames\n",
    )?;
    Ok(())
}

/// Our estimate of one variant beside the export: `DIR/NAME/ours-SLUG.txt` (per frame the stamp,
/// then `world_from_robot` as a KITTI row) and a line in `DIR/NAME/ours.tsv` (variant, the bench's
/// own ATE m, drift per metre, ms per frame, frames) so the peer script can check that it
/// recomputes our figures exactly from the files.
fn export_trajectory(
    dir: &Path,
    name: &str,
    variant: &str,
    built: &BuiltCloud,
    figures: &Figures,
) -> anyhow::Result<()> {
    let root = dir.join(name);
    let slug: String = variant
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    let mut text = String::new();
    for tp in &built.trajectory {
        writeln!(text, "{} {}", tp.stamp_s, kitti_row(&tp.world_from_robot))?;
    }
    std::fs::write(root.join(format!("ours-{slug}.txt")), text)?;
    let line = format!(
        "{variant}\t{slug}\t{}\t{}\t{}\t{}\t{}\n",
        figures.ate_m,
        figures.drift_per_m,
        figures.ms_per_frame,
        figures.cpu_ms_per_frame,
        built.trajectory.len()
    );
    let tsv = root.join("ours.tsv");
    let mut all = std::fs::read_to_string(&tsv)?;
    all.push_str(&line);
    std::fs::write(tsv, all)?;
    Ok(())
}

/// The cloud the angle figures come from, for the angle calculator alone
/// (`onboard/examples/accuracy_angles.rs`, mode `saved`), under `DIR/`:
/// - `NAME-SEED-SLUG.ply`: the built cloud in the vehicle frame (moved by the true start pose,
///   exactly what `evaluate` gives the calculator), binary PLY, doubles.
/// - `NAME-SEED-SLUG.truth`: one line `approach breakover departure`, the true angles in degrees
///   (`nan` where the geometry has none).
/// - `NAME-SEED-SLUG.path`: the scan's path as the calculator got it (estimated robot positions
///   in the vehicle frame), `x y z` per line.
/// - `NAME-SEED-SLUG.traj.tsv`: per frame the stamp, the estimated `x y z roll pitch yaw` of
///   `world_from_robot` and the true one (both relative to the first frame; metres, degrees), so a
///   spread can be traced to a pose error; then, per component (roll pitch yaw x y z), the
///   fused source's initial (`L`aser, `V`isual, `W`heel, `R`eference, `Z`ero), and 1/0 for the
///   laser's degenerate components and the components the refinement left at the prediction.
fn save_cloud(
    dir: &Path,
    run: &str,
    variant: &str,
    scenario: &Scenario,
    built: &BuiltCloud,
) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir)?;
    let slug: String = variant
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    let stem = dir.join(format!("{run}-{slug}"));
    let motion = scenario.motion();
    let truth = |t: f64| pose_of(&motion.pose_at(t).to_isometry());
    let t0 = truth(built.trajectory.first().map_or(0.0, |t| t.stamp_s));
    let cloud = Cloud {
        points_m: built
            .points_in_world
            .iter()
            .map(|&p| t0.apply(p).into())
            .collect(),
    };
    let file = std::fs::File::create(stem.with_extension("ply"))?;
    write_ply(
        std::io::BufWriter::new(file),
        &cloud,
        PlyEncoding::BinaryLittleEndian,
    )?;
    let a = true_angles(&scenario.vehicle, &TruthOptions::default());
    std::fs::write(
        stem.with_extension("truth"),
        format!(
            "{} {} {}\n",
            a.approach.angle_rad.to_degrees(),
            a.breakover.angle_rad.to_degrees(),
            a.departure.angle_rad.to_degrees()
        ),
    )?;
    let mut text = String::from(
        "# stamp_s est_x_m est_y_m est_z_m est_roll_deg est_pitch_deg est_yaw_deg true_x_m true_y_m true_z_m true_roll_deg true_pitch_deg true_yaw_deg sources laser_degenerate refine_rejected\n",
    );
    let six = |p: &Pose| {
        let r = p.rpy().map(f64::to_degrees);
        format!(
            "{} {} {} {} {} {}",
            p.translation[0], p.translation[1], p.translation[2], r[0], r[1], r[2]
        )
    };
    for tp in &built.trajectory {
        let rel = t0.inverse().compose(&truth(tp.stamp_s));
        // Per component roll pitch yaw x y z: the fused source's initial (Laser, Visual,
        // Wheel, Reference, Zero) and 1/0 flags.
        let sources: String = tp
            .chosen
            .iter()
            .map(|s| format!("{s:?}").remove(0))
            .collect();
        let flags =
            |f: &[bool; 6]| -> String { f.iter().map(|&b| if b { '1' } else { '0' }).collect() };
        writeln!(
            text,
            "{} {} {} {sources} {} {}",
            tp.stamp_s,
            six(&tp.world_from_robot),
            six(&rel),
            flags(&tp.laser_degenerate),
            flags(&tp.refine_rejected),
        )?;
    }
    std::fs::write(stem.with_extension("traj.tsv"), text)?;
    let mut path = String::new();
    for p in path_in_vehicle(scenario, built, &t0) {
        writeln!(path, "{} {} {}", p[0], p[1], p[2])?;
    }
    std::fs::write(stem.with_extension("path"), path)?;
    Ok(())
}

/// The pipeline's evidence on simulated passes (see the module docs).
// Command-line switches, not a state machine.
#[allow(clippy::struct_excessive_bools)]
#[derive(clap::Parser)]
struct Args {
    /// Seeds per scenario.
    #[arg(default_value_t = 10)]
    seeds: u64,
    /// Add the ablation's variants on the first seed of every scenario.
    #[arg(long, conflicts_with = "peer")]
    ablation: bool,
    /// Run exactly the KISS-ICP comparison's two configurations.
    #[arg(long)]
    peer: bool,
    /// Write each run's frames, true poses and trajectories for the peer here.
    #[arg(long = "export")]
    export_dir: Option<PathBuf>,
    /// Write each run's cloud with its true angles and path here.
    #[arg(long = "save-clouds")]
    save_dir: Option<PathBuf>,
    /// Only scenarios whose path contains this.
    #[arg(long)]
    only: Option<String>,
    /// Simulated seconds per run instead of the scenario's.
    #[arg(long)]
    duration_s: Option<f64>,
    /// Leave the D435 out.
    #[arg(long)]
    no_depth: bool,
    /// Apply the assumed mecanum wheel errors where a scenario sets none.
    #[arg(long)]
    wheel_noise: bool,
    /// Turn the scan-to-map refinement off.
    #[arg(long)]
    no_refine: bool,
    /// Override `laser.degeneracy-eigen-min`.
    #[arg(long)]
    eigen_min: Option<f64>,
    /// A `[pipeline]`-style TOML table (kebab-case keys, the service's) that replaces the
    /// defaults every variant starts from.
    #[arg(long)]
    config: Option<PathBuf>,
}

// The two tables are one straight script.
#[allow(clippy::too_many_lines)]
fn main() -> anyhow::Result<()> {
    let Args {
        seeds,
        ablation,
        peer,
        export_dir,
        save_dir,
        only,
        duration_s,
        no_depth,
        wheel_noise,
        no_refine,
        eigen_min,
        config,
    } = <Args as clap::Parser>::parse();
    let mode = match (ablation, peer) {
        (true, _) => Mode::Ablation,
        (false, true) => Mode::Peer,
        (false, false) => Mode::Default,
    };
    let base_config = match &config {
        Some(path) => {
            let text = std::fs::read_to_string(path).with_context(|| path.display().to_string())?;
            PipelineConfig::from_toml(&text).with_context(|| path.display().to_string())?
        }
        None => PipelineConfig::default(),
    };
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenarios");
    let mut paths: Vec<PathBuf> = std::fs::read_dir(&dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .filter(|p| {
            only.as_ref()
                .is_none_or(|o| p.to_string_lossy().contains(o.as_str()))
        })
        .collect();
    paths.sort();
    println!(
        "| scenario | seed | variant | ATE m | drift %/m | cloud median mm | cloud p95 mm | approach err deg | breakover err deg | departure err deg | ms/frame | cpu ms/frame | points |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    // Per scenario: the angle errors and the ATE of each seed (the statistics variant).
    let mut per_vehicle: Vec<(String, Vec<[f64; 3]>, Vec<f64>)> = Vec::new();
    for path in &paths {
        let base = Scenario::load(path)?;
        let name = path
            .file_stem()
            .map_or_else(String::new, |s| s.to_string_lossy().into_owned());
        let mut errors = Vec::new();
        let mut ates_m = Vec::new();
        for seed in 1..=seeds {
            let mut file = base.file.clone();
            file.seed = seed;
            if let Some(d) = duration_s {
                file.duration_s = Some(d);
            }
            if wheel_noise && file.wheel_odometry.is_exact() {
                // `--wheel-noise`: the assumed mecanum errors where the scenario sets none.
                file.wheel_odometry = WheelNoise::TYPICAL_MECANUM;
            }
            let scenario = Scenario::from_parts(path, file, base.vehicle.clone())?;
            let scene = scenario.scene();
            let lidar = scenario.decoded_lidar_frames(&scene);
            if let Some(dir) = &export_dir {
                export_frames(dir, &format!("{name}-{seed}"), &scenario, &scene, &lidar)?;
            }
            let wheel = scenario.wheel_odometry(0.2);
            let mode = if mode == Mode::Ablation && seed > 1 {
                Mode::Default
            } else {
                mode
            };
            let mut vs = variants(mode, !no_depth, &base_config);
            if no_depth {
                vs.retain(|v| !v.depth);
            }
            let depth = if vs.iter().any(|v| v.depth) {
                scenario.depth_images(&scene, 1.0, 3)
            } else {
                Vec::new()
            };
            // Angle statistics: the full configuration, else laser + wheel.
            let stats_of = if vs.iter().any(|v| v.name == "laser+visual+wheel") {
                "laser+visual+wheel"
            } else {
                "laser+wheel"
            };
            for v in vs {
                let mut config = v.config;
                mounts_from(&scenario, &mut config);
                if let Some(e) = eigen_min {
                    config.laser.degeneracy_eigen_min = e;
                }
                if no_refine {
                    config.map.refine = false;
                }
                let d: &[DepthImage] = if v.depth { &depth } else { &[] };
                let (built, time) = run_pipeline(config, &lidar, d, &wheel);
                let f = evaluate(&scenario, &scene, &built, &time);
                if let Some(dir) = &export_dir {
                    export_trajectory(dir, &format!("{name}-{seed}"), v.name, &built, &f)?;
                }
                if v.name == stats_of {
                    errors.push(f.angle_error_deg);
                    ates_m.push(f.ate_m);
                    if let Some(dir) = &save_dir {
                        save_cloud(dir, &format!("{name}-{seed}"), v.name, &scenario, &built)?;
                    }
                }
                println!(
                    "| {name} | {seed} | {} | {:.4} | {:.2} | {:.1} | {:.1} | {:+.2} | {:+.2} | {:+.2} | {:.1} | {:.1} | {} |",
                    v.name,
                    f.ate_m,
                    f.drift_per_m * 100.0,
                    f.cloud_median_m * 1e3,
                    f.cloud_p95_m * 1e3,
                    f.angle_error_deg[0],
                    f.angle_error_deg[1],
                    f.angle_error_deg[2],
                    f.ms_per_frame,
                    f.cpu_ms_per_frame,
                    f.points
                );
            }
        }
        per_vehicle.push((name, errors, ates_m));
    }
    println!();
    println!(
        "| scenario | runs | approach mean / sd deg | breakover mean / sd deg | departure mean / sd deg | ATE mean (max) mm |"
    );
    println!("|---|---|---|---|---|---|");
    // Issue 7's target: a standard deviation under 0.15 degree on every angle.
    let (mut under_target, mut angles) = (0, 0);
    for (name, errors, ates_m) in &per_vehicle {
        // Per angle: the cell and the sample standard deviation (needs two values).
        let stats = |k: usize| -> (String, Option<f64>) {
            let v: Vec<f64> = errors
                .iter()
                .map(|e| e[k])
                .filter(|x| x.is_finite())
                .collect();
            let n = v.len() as f64;
            let mean = v.iter().sum::<f64>() / n;
            let sd = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
            match v.len() {
                0 => ("no angle (0 ok)".to_owned(), None),
                1 => (format!("{mean:+.2} / - (1 ok)"), None),
                k => (format!("{mean:+.2} / {sd:.2} ({k} ok)"), Some(sd)),
            }
        };
        let [(a0, sd0), (a1, sd1), (a2, sd2)] = [stats(0), stats(1), stats(2)];
        for sd in [sd0, sd1, sd2].into_iter().flatten() {
            angles += 1;
            under_target += usize::from(sd < 0.15);
        }
        let ate_mm = ates_m.iter().sum::<f64>() / ates_m.len().max(1) as f64 * 1e3;
        let ate_max_mm = ates_m.iter().fold(0.0_f64, |m, &a| m.max(a)) * 1e3;
        println!(
            "| {name} | {} | {a0} | {a1} | {a2} | {ate_mm:.1} ({ate_max_mm:.1}) |",
            errors.len(),
        );
    }
    if angles > 0 {
        println!("\nsd < 0.15 degree on {under_target} of {angles} angles");
    }
    Ok(())
}
