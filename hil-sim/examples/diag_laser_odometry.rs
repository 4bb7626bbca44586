//! Diagnostic of the scan-to-scan laser odometry (`pipeline::laser_odometry`) in
//! isolation, on simulator runs with ground truth: every lidar frame is deskewed with the TRUE
//! velocity, its features are extracted exactly as the pipeline does, and it is registered against
//! the previous frame from a prior; the registered increment is compared per component with the
//! true increment. No fusion, no map, no feedback: what is left is the registration's own error.
//!
//! Run: `cargo run --release -p hil-sim --example diag_laser_odometry -- SCENARIO [--duration-s S]
//! [--from-s S] [--prior truth|zero|wheel] [--frames] [--explain [--dump GROUP [--dump-every K]]]
//! [--no-corners] [--no-planes] [--mixed-planes] [--stride K] [--straight-deskew] [--map [--free]]
//! [--config FILE]`
//! (SCENARIO: a file stem under `hil-sim/scenarios`, e.g. `sedan-pass`).
//! `--frames` prints one line per frame; the summary gives the mean (bias) and RMS of the error per
//! component `[rx, ry, rz, tx, ty, tz]` in mrad and mm per frame, the summed x error over the run
//! against the distance travelled, and how often each component was degenerate. `--explain` groups
//! the step-2 residuals at the TRUE pose by feature kind, normal axis and position and prints which
//! groups pull x (`--dump GROUP` prints every 20th frame's residuals of groups starting so,
//! `--dump-every K` every K-th), then the plane residuals' pull by the fit's tilt and by |r|.
//! `--no-corners` / `--no-planes` leave a feature kind out of step 2; `--mixed-planes` tags the
//! ground like any other plane point (as without `GROUND_TAG_BIT`). `--stride K`
//! registers against the frame K back (the slip meter's baseline); `--straight-deskew` deskews
//! without the rotation (as the pipeline's wheel deskew does). `--map` registers each frame
//! against the scan-to-map refinement's feature map built from the earlier frames at their TRUE
//! poses (`register_joint`, no wheel prior); `--free` drops the degeneracy test there, so the
//! directions the map hardly determines show where it pulls; `--config FILE` takes the pipeline
//! settings from a `[pipeline]`-like TOML file.
//!
//! What it showed (sedan-pass, 12 s, truth prior): plane residuals of underbody points whose
//! "plane" was fitted through underbody and ground points together had normals along x and pulled
//! every increment towards zero motion: x bias -2.87 mm per 30 mm frame (-9.7 %); with the classes
//! kept apart -0.02 mm (-0.07 %).
//!
//! Also: corners alone read 3.5-4 % short scan-to-scan on the off-roader and the
//! sedan, planes alone 0.2 % at the slip baseline (`--stride 10 --no-corners`); and the map
//! refinement left free (`--map --free`) pulls every frame back along x, by 4 (sedan) to 66
//! (off-roader) mm on average from the true pose, through plane and corner fits with normals
//! along x on the parts behind and ahead of the robot (`--explain`: residuals of 2-7 cm at the
//! true pose; on the off-roader the strongest are corners on the differentials, whose grazing
//! line moves around them with the viewpoint). The pipeline's wheel prior holds x against that
//! pull; what gets through is the x drifting short.
//! (Those figures are Huber alone, now `--config` with `[laser] max-residual-m = 1e9`; the
//! truncated kernel's defaults leave 45 mm on the off-roader, a flat 3 cm cutoff 5 mm.)

use std::path::PathBuf;

use anyhow::Context;

use hil_sim::geometry::Isometry;
use hil_sim::scenario::Scenario;
use hil_sim::trajectory::Trajectory;
use hil_sim::world::Scene;
use pipeline::config::PipelineConfig;
use pipeline::deskew::{self, Velocity};
use pipeline::features::{self, RingPoint};
use pipeline::geom::{Pose, V3};
use pipeline::ground;
use pipeline::laser_odometry::{
    FeatureTarget, GROUND_TAG_BIT, Scan, register_two_step, residuals_at,
};
use pipeline::map::FeatureMap;
use pipeline::registration::{JointProblem, register_joint};
use pipeline::{Candidates, LidarFrame, step1_planes, tagged_index};

/// The simulator's transform as the pipeline's pose (both are `passangle_geom::Pose`).
fn pose_of(iso: &Isometry) -> Pose {
    *iso
}

struct Prepared {
    stamp_s: f64,
    step1_planes: Vec<V3>,
    planes: Vec<V3>,
    corners: Vec<V3>,
    target: FeatureTarget,
    /// The tagged candidates, for the map.
    candidates: Candidates,
}

/// The pipeline's steps 1-4 for one frame, deskewed with `velocity`.
fn prepare(
    ground_bit: u32,
    frame: &LidarFrame,
    index: u64,
    robot_from_lidar: &Pose,
    velocity: Velocity,
    config: &PipelineConfig,
) -> Prepared {
    let mut points = Vec::new();
    let mut times = Vec::new();
    let mut ranges = Vec::new();
    for p in &frame.points {
        let l = V3::from(p.xyz_in_lidar_m.map(f64::from));
        points.push(robot_from_lidar.apply(l));
        times.push(f64::from(p.time_offset_s));
        ranges.push(l.norm());
    }
    deskew::deskew(&mut points, &times, velocity, &config.deskew);
    let split = ground::segment_ground(
        &points,
        robot_from_lidar.translation[2],
        &config.ground,
        index,
    );
    let ring_points: Vec<RingPoint> = (0..points.len())
        .map(|i| RingPoint {
            p: points[i],
            range_m: ranges[i],
            azimuth_rad: f64::from(frame.points[i].azimuth_rad),
            ring: frame.points[i].ring,
            is_ground: split.as_ref().is_some_and(|s| s.is_ground[i]),
        })
        .collect();
    let feats = features::extract(&ring_points, &config.features);
    let step1_planes = step1_planes(&feats, config.laser.ground_sample_voxel_m);
    let mut candidates = Candidates::of(&feats, index);
    for (_, t) in &mut candidates.planes[candidates.above_ground..] {
        *t = (*t & !GROUND_TAG_BIT) | ground_bit;
    }
    let voxel = config.laser.max_correspondence_m;
    Prepared {
        stamp_s: frame.stamp_s,
        step1_planes,
        target: FeatureTarget {
            corners: tagged_index(candidates.corners.clone(), voxel),
            planes: tagged_index(candidates.planes.clone(), voxel),
        },
        planes: feats.planes,
        corners: feats.corners,
        candidates,
    }
}

/// Laser odometry against the truth on a simulated pass (see the module docs).
// Command-line switches, not a state machine.
#[allow(clippy::struct_excessive_bools)]
#[derive(clap::Parser)]
struct Args {
    /// Scenario name under hil-sim/scenarios.
    #[arg(default_value = "sedan-pass")]
    name: String,
    /// Simulated seconds instead of the scenario's.
    #[arg(long)]
    duration_s: Option<f64>,
    /// Evaluate (and explain) only the frames from this time on; earlier ones are still prepared.
    #[arg(long, default_value_t = 0.0)]
    from_s: f64,
    /// The registration's prior: truth, zero or wheel.
    #[arg(long, default_value = "truth")]
    prior: String,
    /// Print every frame.
    #[arg(long)]
    frames: bool,
    /// Leave corner features out of step 2.
    #[arg(long)]
    no_corners: bool,
    /// Leave plane features out of step 2.
    #[arg(long)]
    no_planes: bool,
    /// The pipeline settings, a TOML table like the service's `[pipeline]`.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Explain the pull on x per residual group.
    #[arg(long)]
    explain: bool,
    /// Print residuals of the groups starting with this.
    #[arg(long)]
    dump: Option<String>,
    /// With `--dump`: every K-th frame.
    #[arg(long, default_value_t = 20)]
    dump_every: usize,
    /// Deskew with the true linear velocity only.
    #[arg(long)]
    straight_deskew: bool,
    /// Register each frame against the one K frames back.
    #[arg(long, default_value_t = 1)]
    stride: usize,
    /// Register against the feature map built at the true poses.
    #[arg(long)]
    map: bool,
    /// With `--map`: no degeneracy test.
    #[arg(long)]
    free: bool,
    /// Tag the ground like any other plane point.
    #[arg(long)]
    mixed_planes: bool,
}

// The per-frame loop and the summary are one straight script.
#[allow(clippy::too_many_lines)]
fn main() -> anyhow::Result<()> {
    let args = <Args as clap::Parser>::parse();
    let name = args.name.clone();
    let duration_s = args.duration_s;
    let from_s = args.from_s;
    let prior_mode = args.prior.clone();
    let per_frame = args.frames;
    let no_corners = args.no_corners;
    let no_planes = args.no_planes;
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("scenarios")
        .join(format!("{name}.toml"));
    let base = Scenario::load(&path)?;
    let mut file = base.file.clone();
    if let Some(d) = duration_s {
        file.duration_s = Some(d);
    }
    let scenario = Scenario::from_parts(&path, file, base.vehicle.clone())?;
    let scene = Scene::from_vehicle(&scenario.vehicle);
    let frames = scenario.decoded_lidar_frames(&scene);
    // `--config FILE`: the pipeline settings, a TOML table like the service's `[pipeline]`.
    let mut config = match &args.config {
        Some(path) => {
            let text = std::fs::read_to_string(path).with_context(|| path.display().to_string())?;
            PipelineConfig::from_toml(&text).with_context(|| path.display().to_string())?
        }
        None => PipelineConfig::default(),
    };
    let robot_from_lidar = pose_of(&scenario.file.lidar.robot_from_lidar());
    config.mounts.lidar_xyz_m = robot_from_lidar.translation.into();
    let truth = |t: f64| pose_of(&scenario.run.pose_at(t).to_isometry());
    let true_increment = |a: f64, b: f64| truth(a).inverse().compose(&truth(b));
    let velocity_at = |t: f64| {
        let inc = true_increment(t, t + 0.01).to_increment();
        Velocity {
            linear_mps: V3::new(inc[3] / 0.01, inc[4] / 0.01, inc[5] / 0.01),
            angular_radps: V3::new(inc[0] / 0.01, inc[1] / 0.01, inc[2] / 0.01),
        }
    };
    let mut sum = [0.0; 6];
    let mut sum_sq = [0.0; 6];
    let mut degenerate = [0usize; 6];
    let mut n = 0usize;
    // Sum of estimated and true x, and the count, over the frames where x was determined.
    let mut x_determined = (0.0, 0.0, 0usize);
    let mut travelled_m = 0.0;
    let explain = args.explain;
    let dump = args.dump.clone();
    // Pull on x at the true pose, per group: sum of e_x * r (positive pushes the estimate back).
    let mut pull: std::collections::BTreeMap<String, (f64, usize)> =
        std::collections::BTreeMap::default();
    // The plane residuals' pull again, by how far the fit's normal is from the nearest axis and
    // by |r| (a fit through two surfaces at a depth step has a tilted normal and residuals of
    // millimetres to centimetres at the true pose: decision record 018).
    let mut by_tilt = [(0.0, 0usize); 2];
    let mut by_size = [(0.0, 0usize); 5];
    // `--dump-every K`: with `--dump`, every K-th frame (default 20).
    let dump_every: usize = args.dump_every.max(1);
    // `--stride K`: register each frame against the one K frames back (the slip meter's long
    // baseline is 10-17 frames).
    // `--straight-deskew`: deskew with the true linear velocity only, no rotation (what the
    // pipeline's wheel-velocity deskew can do: the vibration's rotation stays in the scan).
    let straight_deskew = args.straight_deskew;
    let stride: usize = args.stride;
    let mut history: std::collections::VecDeque<Prepared> = std::collections::VecDeque::new();
    // `--map`: register each frame against the pipeline's feature map built from every earlier
    // frame at its TRUE pose (the scan-to-map refinement, `register_joint`, no wheel prior),
    // starting from the TRUE pose (or the `--prior`); the error is the refined pose's against the
    // truth, in the robot frame, per frame (it does not accumulate here; in the pipeline the next
    // frame starts from it).
    let mut map = args.map.then(|| {
        FeatureMap::new(
            config.map.feature_voxel_m,
            config.map.points_per_voxel,
            config.map.min_point_spacing_m,
        )
    });
    // `--free`: the map solve without the degeneracy test (no direction held at the prior), to
    // see where the map alone pulls.
    let mut map_laser = config.laser.clone();
    if args.free {
        map_laser.degeneracy_eigen_min = 0.0;
        map_laser.degeneracy_rotation_eigen_min_m2 = 0.0;
    }
    let t0 = frames.first().map_or(0.0, |f| f.stamp_s);
    let world_truth = |t: f64| truth(t0).inverse().compose(&truth(t));
    for (i, frame) in frames.iter().enumerate() {
        let current = prepare(
            if args.mixed_planes { 0 } else { GROUND_TAG_BIT },
            frame,
            i as u64,
            &robot_from_lidar,
            if straight_deskew {
                let v = velocity_at(frame.stamp_s + 0.05);
                Velocity {
                    linear_mps: v.linear_mps,
                    angular_radps: V3::zeros(),
                }
            } else {
                velocity_at(frame.stamp_s + 0.05)
            },
            &config,
        );
        if history.len() == stride.max(1)
            && frame.stamp_s >= from_s
            && let Some(prev) = history.front()
        {
            let truth_inc = true_increment(prev.stamp_s, current.stamp_s);
            let prior = match prior_mode.as_str() {
                "zero" => Pose::IDENTITY,
                "wheel" => {
                    let d = scenario.run.wheel_distance_at(current.stamp_s)
                        - scenario.run.wheel_distance_at(prev.stamp_s);
                    Pose::from_xyz_rpy([d, 0.0, 0.0], [0.0; 3])
                }
                _ => truth_inc,
            };
            // In map mode the target is the map and the poses are world poses.
            let prev_world = world_truth(prev.stamp_s);
            let (target, truth_pose, prior) = match &map {
                Some(m) => (
                    m.target(),
                    world_truth(current.stamp_s),
                    prev_world.compose(&prior),
                ),
                None => (&prev.target, truth_inc, prior),
            };
            if explain {
                for r in residuals_at(
                    target,
                    &current.planes,
                    &current.corners,
                    &truth_pose,
                    config.laser.max_correspondence_m,
                ) {
                    let axis = (0..3)
                        .max_by(|&a, &b| r.direction[a].abs().total_cmp(&r.direction[b].abs()))
                        .unwrap_or(0);
                    let key = format!(
                        "{} n~{} x{:+.1} z{:.2}",
                        if r.corner { "corner" } else { "plane " },
                        ["x", "y", "z"][axis],
                        (r.source[0] * 2.0).round() / 2.0,
                        (r.source[2] * 10.0).round() / 10.0
                    );
                    if dump.as_ref().is_some_and(|d| key.starts_with(d.as_str()))
                        && i % dump_every == 0
                    {
                        println!(
                            "frame {i} {key} src {:.3?} at {:.3?} dir {:.3?} r {:+.4} anchor {:.3?}",
                            r.source,
                            truth_pose.apply(r.source),
                            r.direction,
                            r.residual_m,
                            r.anchor
                        );
                    }
                    let g = r.direction[0] * r.residual_m.clamp(-0.05, 0.05);
                    let e = pull.entry(key).or_default();
                    e.0 += g;
                    e.1 += 1;
                    if !r.corner {
                        // cos 18 degrees: within 18 degrees of an axis.
                        let tilted = r.direction[axis].abs() < 0.95;
                        let size = [0.002, 0.005, 0.01, 0.03]
                            .iter()
                            .take_while(|&&edge| r.residual_m.abs() >= edge)
                            .count();
                        for bucket in [&mut by_tilt[usize::from(tilted)], &mut by_size[size]] {
                            bucket.0 += g;
                            bucket.1 += 1;
                        }
                    }
                }
            }
            let corners: &[V3] = if no_corners { &[] } else { &current.corners };
            let reg = if map.is_some() {
                // As the pipeline: levelled by the floor, x, y and yaw from the plane features
                // and corners; else all six, with the ground sample. The floor's roll, pitch and
                // height are here the prior's: the truth's with `--prior truth`, the previous
                // frame's true ones with `zero` and `wheel`.
                let first = if no_planes { current.planes.len() } else { 0 };
                let scan = Scan {
                    step1_planes: &current.step1_planes[first..],
                    step2_planes: current.planes.len() - first,
                    corners,
                };
                let ((planes, corners), active) = scan.for_refinement(config.map.level_with_ground);
                register_joint(&JointProblem {
                    target,
                    planes,
                    corners,
                    prior,
                    prior_information: None,
                    active,
                    iterations: config.map.iterations,
                    config: &map_laser,
                })
            } else {
                let scan = Scan {
                    step1_planes: &current.step1_planes,
                    step2_planes: if no_planes { 0 } else { current.planes.len() },
                    corners,
                };
                register_two_step(target, scan, prior, &config.laser)
            };
            // Map mode: the refined pose's error in the robot frame, as an increment from the
            // truth; the "true motion" is the frame's true increment.
            let (est, tru) = if map.is_some() {
                let e = truth_pose.inverse().compose(&reg.pose).to_increment();
                let t = truth_inc.to_increment();
                (std::array::from_fn(|k| t[k] + e[k]), t)
            } else {
                (reg.pose.to_increment(), truth_inc.to_increment())
            };
            let err: [f64; 6] = std::array::from_fn(|k| est[k] - tru[k]);
            for k in 0..6 {
                sum[k] += err[k];
                sum_sq[k] += err[k] * err[k];
                degenerate[k] += usize::from(reg.degenerate[k]);
            }
            travelled_m += tru[3];
            if !reg.degenerate[3] {
                x_determined.0 += est[3];
                x_determined.1 += tru[3];
                x_determined.2 += 1;
            }
            n += 1;
            if per_frame {
                println!(
                    "{i:4} t {:.2} true x {:+.4} est x {:+.4} err mm/mrad [{}] deg {:?} n {} rms {:.4} planes {} corners {}",
                    current.stamp_s,
                    tru[3],
                    est[3],
                    err.map(|e| format!("{:+6.2}", e * 1e3)).join(" "),
                    reg.degenerate.map(u8::from),
                    reg.residuals,
                    reg.rms_m,
                    current.planes.len(),
                    current.corners.len()
                );
            }
        }
        if let Some(m) = &mut map {
            m.add(
                &world_truth(current.stamp_s),
                current.candidates.map_planes(config.map.level_with_ground),
                &current.candidates.corners,
            );
        }
        history.push_back(current);
        if history.len() > stride.max(1) {
            history.pop_front();
        }
    }
    if explain {
        let mut v: Vec<_> = pull.into_iter().collect();
        v.sort_by(|a, b| b.1.0.abs().total_cmp(&a.1.0.abs()));
        for (k, (g, count)) in v.iter().take(30) {
            println!("{k:32} pull {g:+.4} m over {count} residuals");
        }
        let [(g0, n0), (g1, n1)] = by_tilt;
        println!(
            "planes by normal: within 18 deg of an axis pull {g0:+.4} m over {n0}, tilted more {g1:+.4} m over {n1}"
        );
        let labels = ["< 2 mm", "2-5 mm", "5-10 mm", "1-3 cm", ">= 3 cm"];
        let sizes: Vec<String> = labels
            .iter()
            .zip(by_size)
            .map(|(l, (g, c))| format!("{l} {g:+.4} ({c})"))
            .collect();
        println!("planes by |r|: {}", sizes.join(", "));
    }
    let nf = n.max(1) as f64;
    println!("{name}: {n} increments, prior {prior_mode}, travelled {travelled_m:.3} m");
    println!(
        "bias  mm|mrad per frame [rx ry rz tx ty tz]: {}",
        sum.map(|s| format!("{:+.3}", s / nf * 1e3)).join(" ")
    );
    println!(
        "rms   mm|mrad per frame                    : {}",
        sum_sq
            .map(|s| format!("{:.3}", (s / nf).sqrt() * 1e3))
            .join(" ")
    );
    println!("degenerate frames per component: {degenerate:?}");
    println!(
        "summed x error {:+.4} m = {:+.2} % of the distance",
        sum[3],
        100.0 * sum[3] / travelled_m.abs().max(1e-9)
    );
    println!(
        "x determined in {} frames: estimated / true distance there {:.4}",
        x_determined.2,
        x_determined.0 / x_determined.1
    );
    Ok(())
}
