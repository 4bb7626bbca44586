//! Whole-pipeline tests on a synthetic garage: ground, a car-like underbody box, four tyre boxes and
//! the garage walls, scanned by an analytic 16-ring lidar on a robot driving straight at 0.3 m/s.
//! (The simulator-based evidence runs live in `bench/`; these pin the orchestration.)

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::geom::{Pose, V3};
use super::*;

const SPEED_MPS: f64 = 0.3;
const AZIMUTHS: usize = 900;
const FRAME_S: f64 = 0.1;

/// Axis-aligned boxes `(min, max)` of the scene (besides the ground z = 0).
fn boxes() -> Vec<(V3, V3)> {
    vec![
        // Underbody: its lower face at 0.4 m.
        (V3::new(-0.5, -0.8, 0.4), V3::new(3.5, 0.8, 1.2)),
        // Tyres.
        (V3::new(-0.3, 0.8, 0.0), V3::new(0.3, 1.0, 0.6)),
        (V3::new(-0.3, -1.0, 0.0), V3::new(0.3, -0.8, 0.6)),
        (V3::new(2.5, 0.8, 0.0), V3::new(3.1, 1.0, 0.6)),
        (V3::new(2.5, -1.0, 0.0), V3::new(3.1, -0.8, 0.6)),
        // Garage walls.
        (V3::new(-4.0, -5.0, 0.0), V3::new(-3.8, 5.0, 3.0)),
        (V3::new(7.8, -5.0, 0.0), V3::new(8.0, 5.0, 3.0)),
        (V3::new(-4.0, 4.0, 0.0), V3::new(8.0, 4.2, 3.0)),
        (V3::new(-4.0, -4.2, 0.0), V3::new(8.0, -4.0, 3.0)),
        // A pillar and a cabinet so the walls are not the only x/y structure.
        (V3::new(5.0, 2.0, 0.0), V3::new(5.3, 2.3, 3.0)),
        (V3::new(-2.0, -3.0, 0.0), V3::new(-1.0, -2.5, 1.0)),
    ]
}

fn ray_box(o: V3, d: V3, lo: V3, hi: V3) -> Option<f64> {
    let mut t0 = 0.0_f64;
    let mut t1 = f64::INFINITY;
    for k in 0..3 {
        if d[k].abs() < 1e-12 {
            if o[k] < lo[k] || o[k] > hi[k] {
                return None;
            }
            continue;
        }
        let (a, b) = ((lo[k] - o[k]) / d[k], (hi[k] - o[k]) / d[k]);
        t0 = t0.max(a.min(b));
        t1 = t1.min(a.max(b));
    }
    (t0 <= t1 && t0 > 1e-6).then_some(t0)
}

fn cast(o: V3, d: V3) -> Option<f64> {
    let mut best = if d[2] < 0.0 {
        -o[2] / d[2]
    } else {
        f64::INFINITY
    };
    for (lo, hi) in boxes() {
        if let Some(t) = ray_box(o, d, lo, hi) {
            best = best.min(t);
        }
    }
    (best.is_finite() && best > 0.3 && best < 30.0).then_some(best)
}

/// The robot's true pose at `t_s`.
fn truth_at(t_s: f64) -> Pose {
    Pose::from_xyz_rpy([-1.5 + SPEED_MPS * t_s, 0.05, 0.0], [0.0, 0.0, 0.0])
}

/// Frame `k` of the synthetic lidar, with range noise of `sigma_m`.
fn frame(k: usize, sigma_m: f64, rng: &mut ChaCha8Rng) -> LidarFrame {
    let mounts = config::MountConfig::default();
    let robot_from_lidar = Pose::from_xyz_rpy(mounts.lidar_xyz_m, mounts.lidar_rpy_rad);
    let t0 = k as f64 * FRAME_S;
    let mut points = Vec::new();
    for step in 0..AZIMUTHS {
        let dt = step as f64 * FRAME_S / AZIMUTHS as f64;
        let world_from_lidar = truth_at(t0 + dt).compose(&robot_from_lidar);
        let az = step as f64 * std::f64::consts::TAU / AZIMUTHS as f64;
        for ring in 0..16u8 {
            let w = (-15.0 + 2.0 * f64::from(ring)).to_radians();
            let dir = V3::new(w.cos() * az.sin(), w.cos() * az.cos(), w.sin());
            let o = world_from_lidar.translation;
            let Some(r) = cast(o, world_from_lidar.apply_vector(dir)) else {
                continue;
            };
            let r = r + sigma_m * (rng.random::<f64>() + rng.random::<f64>() - 1.0) * 2.45;
            points.push(LidarPoint {
                xyz_in_lidar_m: [dir[0] * r, dir[1] * r, dir[2] * r].map(|v| v as f32),
                time_offset_s: dt as f32,
                azimuth_rad: az as f32,
                ring,
            });
        }
    }
    LidarFrame {
        stamp_s: t0,
        points,
    }
}

/// Wheel odometry at 100 Hz reporting `1 + overshoot` times the true distance (slip).
fn wheel(t_s: f64, overshoot: f64) -> WheelOdometry {
    WheelOdometry {
        stamp_s: t_s,
        x_m: SPEED_MPS * t_s * (1.0 + overshoot),
        y_m: 0.0,
        yaw_rad: 0.0,
        vx_mps: SPEED_MPS * (1.0 + overshoot),
        vy_mps: 0.0,
        wz_radps: 0.0,
    }
}

/// Run `frames` frames; returns the final position error (m) and the result.
fn run(config: PipelineConfig, frames: usize, wheel_overshoot: Option<f64>) -> (f64, BuiltCloud) {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let mut pipeline = Pipeline::new(config).unwrap();
    let mut next_wheel = 0_u32;
    for k in 0..frames {
        pipeline.push_lidar_frame(frame(k, 0.01, &mut rng)).unwrap();
        if let Some(o) = wheel_overshoot {
            while f64::from(next_wheel) * 0.01 <= (k + 1) as f64 * FRAME_S + 1e-9 {
                pipeline
                    .push_wheel_odometry(wheel(f64::from(next_wheel) * 0.01, o))
                    .unwrap();
                next_wheel += 1;
            }
        }
    }
    let built = pipeline.finish();
    let last = built.trajectory.last().unwrap();
    let truth = truth_at(0.0).inverse().compose(&truth_at(last.stamp_s));
    let err = (last.world_from_robot.translation - truth.translation).norm();
    (err, built)
}

#[test]
fn laser_and_wheel_hold_exact_wheels_and_beat_slipping_ones() {
    let frames = 30;
    // Exact wheels: the map must not pull the run far off them. Weighing the map against the
    // wheels (`map.residual-sigma-m`) so that it holds wandering wheels costs exact ones a few
    // millimetres over this 0.87 m run; the bound allows that and no more.
    let (exact_err, _) = run(PipelineConfig::default(), frames, Some(0.0));
    assert!(exact_err < 0.008, "error {exact_err} m with exact wheels");
    let (err, built) = run(PipelineConfig::default(), frames, Some(0.05));
    assert_eq!(built.trajectory.len(), frames);
    assert_eq!(built.stats.frames, frames);
    // Wheels alone would be 5 % long: 4.4 cm over the 0.87 m run. The slip is not yet
    // significant this early (`fusion.wheel-scale-min-slip`), so what the laser and the map take
    // off is all there is: 0.62 of it remained at 0.2 m voxels, 0.13 with the spaced map
    // weighted at 0.01. The 0.5 m map left 0.32, but part of that was the backward pull that
    // cost it the 7.7 mm above.
    let wheel_only_err = 0.05 * SPEED_MPS * (frames - 1) as f64 * FRAME_S;
    assert!(
        err < 0.25 * wheel_only_err,
        "error {err} m vs wheel-only {wheel_only_err} m"
    );
    assert!(built.stats.ground_points > built.stats.points_in / 4);
    assert!(built.points_in_world.len() > 10_000);
}

#[test]
fn long_baseline_slip_measurements_calibrate_slipping_wheels_and_leave_exact_ones_alone() {
    // 1.3 m: the overlapping measurements must cover a metre of travel to count as four.
    let (_, built) = run(PipelineConfig::default(), 45, Some(0.05));
    assert!(
        built.stats.scale_measurements >= fusion::MIN_SCALE_MEASUREMENTS,
        "{:?}",
        built.stats
    );
    let truth = 1.0 / 1.05;
    assert!(
        (built.stats.wheel_scale - truth).abs() < 0.01,
        "wheel scale {} vs {truth}",
        built.stats.wheel_scale
    );
    let (_, exact) = run(PipelineConfig::default(), 45, Some(0.0));
    assert!(exact.stats.scale_measurements >= fusion::MIN_SCALE_MEASUREMENTS);
    assert!(
        (exact.stats.wheel_scale - 1.0).abs() < 1e-15,
        "{:?}",
        exact.stats
    );
    for (value, key) in [
        (-0.1, "fusion.wheel-scale-baseline-m"),
        (f64::NAN, "fusion.wheel-scale-baseline-m"),
    ] {
        let mut config = PipelineConfig::default();
        config.fusion.wheel_scale_baseline_m = value;
        let e = Pipeline::new(config).unwrap_err().to_string();
        assert!(e.contains(key), "{e}");
    }
    let mut config = PipelineConfig::default();
    config.fusion.wheel_scale_min_slip = 0.5;
    let e = Pipeline::new(config).unwrap_err().to_string();
    assert!(e.contains("fusion.wheel-scale-min-slip"), "{e}");
}

/// Position error (m) of every frame of `built`'s trajectory.
fn position_errors(built: &BuiltCloud) -> Vec<f64> {
    built
        .trajectory
        .iter()
        .map(|t| {
            let truth = truth_at(0.0).inverse().compose(&truth_at(t.stamp_s));
            (t.world_from_robot.translation - truth.translation).norm()
        })
        .collect()
}

#[test]
fn slip_replay_scales_the_travel_before_the_scale_was_significant() {
    // The map weighted less against the wheels (`map.residual-sigma-m` 0.02): the frames before
    // the scale is significant then follow the slipping wheels wherever the laser does not hold
    // x, the case the replay is for. (At the default the map holds most of it itself here.)
    let mut on = PipelineConfig::default();
    on.map.residual_sigma_m = 0.02;
    let mut off = on.clone();
    off.fusion.slip_replay_s = 0.0;
    let (_, without) = run(off.clone(), 45, Some(0.05));
    let (_, with) = run(on.clone(), 45, Some(0.05));
    assert_eq!(without.stats.slip_replays, 0);
    assert_eq!(with.stats.slip_replays, 1, "{:?}", with.stats);
    // The second pass counts every frame once and ends with the same scale.
    assert_eq!(with.trajectory.len(), 45);
    assert_eq!(with.stats.frames, 45);
    assert!(
        (with.stats.wheel_scale - 1.0 / 1.05).abs() < 0.01,
        "{:?}",
        with.stats
    );
    // Before the scale was significant the first pass followed the wheels' 5 % overshoot
    // where the laser did not hold x; the replay scaled those frames too.
    let (e_without, e_with) = (position_errors(&without), position_errors(&with));
    // (ATE-like: one frame near the end jumps by about 1.5 cm in both runs.)
    let rms = |e: &[f64]| (e.iter().map(|v| v * v).sum::<f64>() / e.len() as f64).sqrt();
    assert!(
        rms(&e_with) < 0.5 * rms(&e_without),
        "RMS position error with the replay {} m, without {} m",
        rms(&e_with),
        rms(&e_without)
    );
    // Exact wheels: the scale never turns significant, nothing is replayed, and the output is
    // the same to the bit as with the replay off.
    let (_, exact) = run(on, 45, Some(0.0));
    let (_, exact_off) = run(off, 45, Some(0.0));
    assert_eq!(exact.stats.slip_replays, 0);
    assert_eq!(exact.points_in_world, exact_off.points_in_world);
    assert_eq!(position_errors(&exact), position_errors(&exact_off));
    let mut config = PipelineConfig::default();
    config.fusion.slip_replay_s = -1.0;
    let e = Pipeline::new(config).unwrap_err().to_string();
    assert!(e.contains("fusion.slip-replay-s"), "{e}");
}

/// The slipping run of [`run`] with a depth frame (the ceiling of the visual odometry tests)
/// after every lidar frame.
fn run_with_depth(config: PipelineConfig, frames: usize) -> BuiltCloud {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let m = &config.mounts;
    let robot_from_camera = Pose::from_xyz_rpy(m.camera_xyz_m, m.camera_rpy_rad);
    let mut pipeline = Pipeline::new(config).unwrap();
    let mut next_wheel = 0_u32;
    for k in 0..frames {
        pipeline.push_lidar_frame(frame(k, 0.01, &mut rng)).unwrap();
        let end_s = (k + 1) as f64 * FRAME_S;
        while f64::from(next_wheel) * 0.01 <= end_s + 1e-9 {
            pipeline
                .push_wheel_odometry(wheel(f64::from(next_wheel) * 0.01, 0.05))
                .unwrap();
            next_wheel += 1;
        }
        let camera = truth_at(end_s).compose(&robot_from_camera);
        pipeline
            .push_depth_frame(visual_odometry::tests::render(&camera, end_s))
            .unwrap();
    }
    pipeline.finish()
}

#[test]
fn slip_replay_adds_every_depth_frame_once() {
    let mut on = PipelineConfig::default();
    on.visual.add_to_cloud = true;
    let mut off = on.clone();
    off.fusion.slip_replay_s = 0.0;
    let without = run_with_depth(off, 45);
    let with = run_with_depth(on, 45);
    assert_eq!(with.stats.slip_replays, 1, "{:?}", with.stats);
    // The depth points the first pass had already put in the cloud are put in again by the
    // second pass, once: as many as without the replay (the count does not depend on the poses).
    assert!(without.stats.depth_points > 0, "{:?}", without.stats);
    assert_eq!(with.stats.depth_points, without.stats.depth_points);
    assert_eq!(with.stats.depth_frames, 45);
}

#[test]
fn laser_only_tracks_the_run() {
    let mut config = PipelineConfig::default();
    config.fusion.use_wheel = false;
    let (err, built) = run(config, 20, None);
    assert!(err < 0.03, "error {err} m; {:?}", built.stats);
}

#[test]
fn streaming_waits_for_wheel_odometry_then_finish_flushes() {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let mut pipeline = Pipeline::new(PipelineConfig::default()).unwrap();
    pipeline.push_wheel_odometry(wheel(0.0, 0.0)).unwrap();
    pipeline.push_lidar_frame(frame(0, 0.0, &mut rng)).unwrap();
    assert!(
        pipeline.trajectory().is_empty(),
        "frame 0 must wait for odometry past its end"
    );
    pipeline.push_wheel_odometry(wheel(0.1, 0.0)).unwrap();
    assert_eq!(pipeline.trajectory().len(), 1);
    pipeline.push_lidar_frame(frame(1, 0.0, &mut rng)).unwrap();
    assert_eq!(pipeline.trajectory().len(), 1);
    let built = pipeline.finish();
    assert_eq!(built.trajectory.len(), 2);
}

#[test]
fn bad_input_is_refused_with_names() {
    let mut config = PipelineConfig::default();
    config.map.output_voxel_m = 0.0;
    let e = Pipeline::new(config).unwrap_err().to_string();
    assert!(e.contains("map.output-voxel-m"), "{e}");
    let mut pipeline = Pipeline::new(PipelineConfig::default()).unwrap();
    let f = LidarFrame {
        stamp_s: 1.0,
        points: Vec::new(),
    };
    pipeline.push_lidar_frame(f.clone()).unwrap();
    let e = pipeline.push_lidar_frame(f).unwrap_err().to_string();
    assert!(e.contains("lidar frame stamp 1"), "{e}");
}

#[test]
fn levelling_restores_roll_pitch_and_height_and_keeps_yaw() {
    // True world_from_robot: yaw 0.3, level, on the ground. The frame sees the world ground
    // (z = 0) from there; the estimate has 1 degree of pitch and 2 cm of height error.
    let truth = Pose::from_xyz_rpy([1.0, 0.5, 0.0], [0.0, 0.0, 0.3]);
    let n_r = truth.inverse().apply_vector(V3::new(0.0, 0.0, 1.0));
    let d_r = -n_r.dot(&truth.inverse().apply(V3::new(0.0, 0.0, 0.0)));
    let estimate = Pose::from_xyz_rpy([1.0, 0.5, 0.02], [0.0, 0.0175, 0.3]);
    let fixed = level_with_ground(&estimate, (n_r, d_r), (V3::new(0.0, 0.0, 1.0), 0.0));
    let rpy = fixed.rpy();
    assert!(rpy[0].abs() < 1e-9 && rpy[1].abs() < 1e-9, "{rpy:?}");
    assert!((rpy[2] - 0.3).abs() < 1e-3, "{rpy:?}");
    assert!(fixed.translation[2].abs() < 1e-9, "{:?}", fixed.translation);
}

#[test]
fn a_coarser_ground_voxel_thins_the_floor_and_keeps_the_rest() {
    let mut config = PipelineConfig::default();
    config.map.ground_voxel_m = 0.0;
    let (_, fine) = run(config.clone(), 10, Some(0.0));
    config.map.ground_voxel_m = 0.05;
    let (_, coarse) = run(config.clone(), 10, Some(0.0));
    let below = |c: &BuiltCloud, z: f64| c.points_in_world.iter().filter(|p| p[2] < z).count();
    let above = |c: &BuiltCloud| c.points_in_world.len() - below(c, 0.03);
    // The floor (z ~ 0) is thinned to 5 cm cells: (5 / 1)^2 = 25 times fewer where it is dense.
    assert!(
        below(&coarse, 0.03) * 5 < below(&fine, 0.03),
        "ground {} -> {}",
        below(&fine, 0.03),
        below(&coarse, 0.03)
    );
    // Everything above the floor is the same cloud, up to the few points of voxels that held
    // ground and non-ground points together.
    let (a, b) = (above(&fine), above(&coarse));
    assert!(a.abs_diff(b) * 100 < a, "above the floor {a} -> {b}");
    config.map.ground_voxel_m = -1.0;
    let e = Pipeline::new(config).unwrap_err().to_string();
    assert!(e.contains("map.ground-voxel-m"), "{e}");
}

#[test]
fn a_config_text_is_parsed_and_checked_and_errors_name_the_key() {
    let c = PipelineConfig::from_toml("[fusion]\nuse-visual = true\n").unwrap();
    assert!(c.fusion.use_visual);
    assert_eq!(
        PipelineConfig::from_toml("").unwrap(),
        PipelineConfig::default()
    );
    let e = PipelineConfig::from_toml("[fusion]\nwheel-speed-sigma-mps = -1.0\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("fusion.wheel-speed-sigma-mps"), "{e}");
    let e = PipelineConfig::from_toml("[visual]\nmax-depth-m = nan\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("visual.max-depth-m"), "{e}");
    let e = PipelineConfig::from_toml("[fusion]\nuse-visuals = true\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("use-visuals"), "{e}");
    // The method's parameters are checked too, where code sets them.
    let mut config = PipelineConfig::default();
    config.laser.max_residual_rad = -0.1;
    let e = Pipeline::new(config).unwrap_err().to_string();
    assert!(e.contains("laser.max-residual-rad"), "{e}");
    for spacing in [-0.01, 0.2, f64::NAN] {
        let mut config = PipelineConfig::default();
        config.map.min_point_spacing_m = spacing;
        let e = Pipeline::new(config).unwrap_err().to_string();
        assert!(e.contains("map.min-point-spacing-m"), "{spacing}: {e}");
    }
}

/// The synthetic runs' outputs, bit for bit, against a committed golden file: a refactor must
/// leave them as they are, and a change that moves them shows up as a diff to review.
/// `UPDATE_GOLDEN=1 cargo test -p pipeline --lib outputs_match` rewrites the file.
#[test]
fn outputs_match_the_golden_digests() {
    use std::fmt::Write as _;
    use std::hash::{Hash, Hasher};
    let mut out = String::new();
    let mut slipping = PipelineConfig::default();
    slipping.map.residual_sigma_m = 0.02;
    let mut laser_only = PipelineConfig::default();
    laser_only.fusion.use_wheel = false;
    for (name, cfg, slip) in [
        ("default", PipelineConfig::default(), Some(0.0)),
        ("slip", slipping, Some(0.05)),
        ("laser", laser_only, None),
    ] {
        let (_, built) = run(cfg, 30, slip);
        let mut h = std::collections::hash_map::DefaultHasher::new();
        for p in &built.points_in_world {
            [p.x, p.y, p.z].map(f64::to_bits).hash(&mut h);
        }
        for t in &built.trajectory {
            format!("{t:?}").hash(&mut h);
        }
        format!("{:?}", built.stats).hash(&mut h);
        let _ = writeln!(
            out,
            "{name} {} {:x}",
            built.points_in_world.len(),
            h.finish()
        );
    }
    let d = run_with_depth(PipelineConfig::default(), 20);
    let _ = writeln!(
        out,
        "depth {} {:?}",
        d.points_in_world.len(),
        d.trajectory.last()
    );
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/golden/synthetic-runs.txt");
    if std::env::var_os("UPDATE_GOLDEN").is_some() {
        std::fs::write(&path, &out).unwrap();
        return;
    }
    let golden = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        golden == out,
        "pipeline outputs differ from {}:\n{out}\nRegenerate with UPDATE_GOLDEN=1 if the change is intended.",
        path.display()
    );
}

#[test]
fn the_stated_x_error_mixes_the_wheels_and_the_map_by_frames() {
    // 61 frames over 6 s, 1.8 m at 0.3 m/s.
    let built = |rejected: bool| BuiltCloud {
        points_in_world: Vec::new(),
        trajectory: (0..=60)
            .map(|i| TrajectoryPoint {
                stamp_s: 0.1 * f64::from(i),
                world_from_robot: Pose {
                    translation: V3::new(0.03 * f64::from(i), 0.0, 0.0),
                    ..Pose::IDENTITY
                },
                chosen: [Source::Wheel; 6],
                laser_degenerate: [false; 6],
                refine_rejected: [false, false, false, rejected, false, false],
            })
            .collect(),
        stats: PipelineStats::default(),
    };
    let fusion = config::FusionConfig::default();
    // Every frame's x from the wheels: their speed error over the speed (0.003 / 0.3).
    let wheels = built(true).x_sigma_per_m(&fusion);
    assert!(
        (wheels - fusion.wheel_speed_sigma_mps / 0.3).abs() < 1e-9,
        "{wheels}"
    );
    // Every frame's x from the map.
    let map = built(false).x_sigma_per_m(&fusion);
    assert!((map - MAP_X_SIGMA_PER_M).abs() < 1e-12, "{map}");
}

#[test]
fn the_cameras_points_join_the_cloud_only_where_the_lidar_does_not_see() {
    let min_range_m = 0.4;
    // 1 m ahead (lidar frame: z up): at 0.2 m up the lidar sees it (11 degrees), at 0.5 m not
    // (27 degrees); likewise below; within the near limit nothing is seen.
    assert!(!outside_lidar_view(V3::new(0.0, 1.0, 0.2), min_range_m));
    assert!(outside_lidar_view(V3::new(0.0, 1.0, 0.5), min_range_m));
    assert!(outside_lidar_view(V3::new(1.0, 0.0, -0.3), min_range_m));
    assert!(outside_lidar_view(V3::new(0.2, 0.1, 0.0), min_range_m));
    // The underside right above the robot.
    assert!(outside_lidar_view(V3::new(0.1, 0.2, 0.3), min_range_m));
}
