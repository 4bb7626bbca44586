//! Oracle run: the onboard angle calculator on clouds built from the simulated sensors with the
//! TRUE poses (no odometry, no deskew error), against the true angles from the geometry. It
//! separates the calculator's own error from the point-cloud pipeline's: whatever differs here is
//! sensor coverage plus the calculator.
//!
//! Run: `cargo run --release -p hil-sim --example oracle_angles [EVERY_NTH_PACKET]
//! [DEPTH_EVERY_NTH_FRAME] [noiseless] [--seeds N] [--only NAME] [--duration-s S]
//! [--voxel-m V] [--save-clouds DIR]` (defaults 4, 0 = no D435 points, the scenario's noise, the
//! scenario's own seed). Prints one line per shipped scenario and seed.
//!
//! `--seeds N` runs seeds 1..=N (the seeds of `bench_pipeline`, so the sensor noise is the same);
//! `--voxel-m V` keeps one centroid per V-metre voxel, as the pipeline's output does (its default
//! is 0.005); `--save-clouds DIR` writes each cloud as `DIR/NAME-SEED-oracle.ply` with the true
//! angles in `.truth` beside it, the layout of `bench_pipeline --save-clouds`, for
//! `accuracy_angles saved DIR`.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use angles::{AnglesConfig, compute_angles};
use cloud_io::{Cloud, PlyEncoding, write_ply};
use hil_sim::d435::{D435Sim, Intrinsics};
use hil_sim::geometry::Vec3;
use hil_sim::scenario::Scenario;
use hil_sim::trajectory::Trajectory;
use hil_sim::truth::{TruthOptions, true_angles};
use hil_sim::vlp16::{FiringTruth, Vlp16Sim};
use hil_sim::world::Scene;

fn lidar_cloud(scenario: &Scenario, scene: &Scene, every: u64) -> Vec<[f64; 3]> {
    let sim = Vlp16Sim::new(
        scene,
        &scenario.run,
        scenario.lidar_config(),
        scenario.lidar_seed(),
    );
    let mut cloud = Vec::new();
    let packets = Vlp16Sim::<hil_sim::trajectory::StraightRun>::packets_in(scenario.duration_s);
    for k in (0..packets).step_by(every as usize) {
        let repr = sim.data_packet_with_truth(k, |f: &FiringTruth| {
            if f.distance_raw == 0 {
                return;
            }
            // Rebuild the measured point in the sensor frame from the reported range, then map it
            // with the true pose (the same maths as the decoder plus a perfect trajectory).
            let laser = f.channel % 16;
            let (sin_w, cos_w) = hil_sim::vlp16::ELEVATION_DEG[laser].to_radians().sin_cos();
            let (sin_a, cos_a) = sim.azimuth_at(f.time_s).sin_cos();
            let r = f64::from(f.distance_raw) * 0.002;
            let offset = hil_sim::vlp16::VERTICAL_OFFSET_MM[laser] / 1000.0;
            let p = Vec3::new(r * cos_w * sin_a, r * cos_w * cos_a, r * sin_w + offset);
            let w = f.world_from_lidar.apply(p);
            cloud.push([w.x, w.y, w.z]);
        });
        let _ = repr;
    }
    cloud
}

fn depth_cloud(scenario: &Scenario, scene: &Scene, every: u64) -> Vec<[f64; 3]> {
    let sim = D435Sim::new(
        scene,
        &scenario.run,
        scenario.file.depth.clone(),
        scenario.depth_seed(),
    );
    let k: Intrinsics = scenario.file.depth.intrinsics();
    let mut cloud = Vec::new();
    for i in (0..sim.frames_in(scenario.duration_s)).step_by(every as usize) {
        let frame = sim.frame(i);
        let world_from_camera = sim.world_from_camera(i);
        // Every 4th pixel in each direction keeps the cloud to a size the calculator handles fast.
        for v in (0..k.height).step_by(4) {
            for u in (0..k.width).step_by(4) {
                let d = frame.depth_mm[(v * k.width + u) as usize];
                if d == 0 {
                    continue;
                }
                let z = f64::from(d) / 1000.0;
                let p = Vec3::new(
                    (f64::from(u) - k.cx_px) / k.fx_px * z,
                    (f64::from(v) - k.cy_px) / k.fy_px * z,
                    z,
                );
                let w = world_from_camera.apply(p);
                cloud.push([w.x, w.y, w.z]);
            }
        }
    }
    cloud
}

/// One centroid per occupied `voxel_m` cube (the pipeline's output reduction).
fn voxel_centroids(cloud: &[[f64; 3]], voxel_m: f64) -> Vec<[f64; 3]> {
    let mut cells: HashMap<[i64; 3], ([f64; 3], u32)> = HashMap::new();
    for p in cloud {
        let key = p.map(|v| (v / voxel_m).floor() as i64);
        let e = cells.entry(key).or_insert(([0.0; 3], 0));
        for (sum, v) in e.0.iter_mut().zip(p) {
            *sum += v;
        }
        e.1 += 1;
    }
    let mut out: Vec<[f64; 3]> = cells
        .into_values()
        .map(|(s, n)| s.map(|v| v / f64::from(n)))
        .collect();
    // HashMap order is random per process: sort so the calculator's input is reproducible.
    out.sort_by(|a, b| {
        a.iter()
            .zip(b)
            .map(|(x, y)| x.total_cmp(y))
            .find(|o| o.is_ne())
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    out
}

/// The robot's true positions every 0.1 s (vehicle frame): the scan's path.
fn true_path(scenario: &Scenario) -> Vec<[f64; 3]> {
    let lidar = scenario.file.lidar.robot_from_lidar().translation;
    (0..=(scenario.duration_s * 10.0) as u32)
        .map(|i| {
            let t = scenario
                .run
                .pose_at(f64::from(i) * 0.1)
                .to_isometry()
                .apply(lidar);
            [t.x, t.y, t.z]
        })
        .collect()
}

/// `DIR/STEM.ply`, `DIR/STEM.truth` (approach, breakover, departure, degrees) and `DIR/STEM.path`
/// (the true path, `x y z` per line).
fn save(
    dir: &Path,
    stem: &str,
    cloud: &[[f64; 3]],
    truth_deg: [f64; 3],
    path: &[[f64; 3]],
) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir)?;
    let file = std::fs::File::create(dir.join(format!("{stem}.ply")))?;
    let cloud = Cloud {
        points_m: cloud.to_vec(),
    };
    write_ply(
        std::io::BufWriter::new(file),
        &cloud,
        PlyEncoding::BinaryLittleEndian,
    )?;
    std::fs::write(
        dir.join(format!("{stem}.truth")),
        format!("{} {} {}\n", truth_deg[0], truth_deg[1], truth_deg[2]),
    )?;
    let mut text = String::new();
    for p in path {
        writeln!(text, "{} {} {}", p[0], p[1], p[2])?;
    }
    std::fs::write(dir.join(format!("{stem}.path")), text)?;
    Ok(())
}

/// The calculator on oracle clouds (see the module docs).
#[derive(clap::Parser)]
struct Args {
    /// Use every N-th lidar packet.
    #[arg(default_value_t = 4)]
    every: u64,
    /// Add the D435's points of every N-th depth frame (0: none).
    #[arg(default_value_t = 0)]
    depth_every: u64,
    /// `noiseless`: no range noise.
    noise: Option<String>,
    /// Run seeds 1..=N instead of the scenario's own.
    #[arg(long)]
    seeds: Option<u64>,
    /// Only scenarios whose path contains this.
    #[arg(long)]
    only: Option<String>,
    /// Simulated seconds per run instead of the scenario's.
    #[arg(long)]
    duration_s: Option<f64>,
    /// Keep one centroid per voxel of this size, metres.
    #[arg(long)]
    voxel_m: Option<f64>,
    /// Write each cloud with its true angles to this directory.
    #[arg(long = "save-clouds")]
    save_dir: Option<PathBuf>,
}

// The per-run report is one straight script.
#[allow(clippy::too_many_lines)]
fn main() -> anyhow::Result<()> {
    let Args {
        every,
        depth_every,
        noise,
        seeds,
        only,
        duration_s,
        voxel_m,
        save_dir,
    } = <Args as clap::Parser>::parse();
    let noiseless = match noise.as_deref() {
        None => false,
        Some("noiseless") => true,
        Some(other) => anyhow::bail!("unknown argument `{other}` (expected `noiseless`)"),
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
        "true vs angles on oracle clouds (true poses), degrees: approach / breakover / departure"
    );
    let runs: Vec<(&PathBuf, Option<u64>)> = paths
        .iter()
        .flat_map(|p| match seeds {
            None => vec![(p, None)],
            Some(n) => (1..=n).map(|s| (p, Some(s))).collect(),
        })
        .collect();
    for (path, seed) in runs {
        let base = Scenario::load(path)?;
        let mut file = base.file.clone();
        if let Some(s) = seed {
            file.seed = s;
        }
        if let Some(d) = duration_s {
            file.duration_s = Some(d);
        }
        let mut scenario = Scenario::from_parts(path, file, base.vehicle.clone())?;
        if noiseless {
            scenario.file.lidar.range_noise_sigma_m = 0.0;
            scenario.file.lidar.dropout_probability = 0.0;
            scenario.file.depth.noise_k_per_m = 0.0;
            scenario.file.depth.invalid_probability = 0.0;
        }
        let scene = Scene::from_vehicle(&scenario.vehicle);
        let truth = true_angles(&scenario.vehicle, &TruthOptions::default());
        let mut cloud = lidar_cloud(&scenario, &scene, every);
        if depth_every > 0 {
            cloud.extend(depth_cloud(&scenario, &scene, depth_every));
        }
        if let Some(v) = voxel_m {
            cloud = voxel_centroids(&cloud, v);
        }
        let stem = path
            .file_stem()
            .map_or_else(String::new, |s| s.to_string_lossy().into_owned());
        let name = match seed {
            Some(s) => format!("{stem}-{s}"),
            None => stem,
        };
        let path = true_path(&scenario);
        let t = [
            truth.approach.angle_rad,
            truth.breakover.angle_rad,
            truth.departure.angle_rad,
        ]
        .map(f64::to_degrees);
        if let Some(dir) = &save_dir {
            save(dir, &format!("{name}-oracle"), &cloud, t, &path)?;
        }
        let config = AnglesConfig {
            scan_path_in_cloud: path.into_iter().map(Into::into).collect(),
            range_accuracy_m: Some(vlp16::RANGE_ACCURACY_M),
            scanner_view: Some(angles::ScannerView::VLP16),
            ..AnglesConfig::default()
        };
        match compute_angles(
            &cloud.iter().map(|&p| p.into()).collect::<Vec<_>>(),
            &config,
        ) {
            Ok(r) => {
                let m = [&r.approach, &r.breakover, &r.departure]
                    .map(|a| a.as_ref().map_or(f64::NAN, |a| a.angle_rad.to_degrees()));
                println!(
                    "{name:<16} {:>8} pts  true {:6.2} {:6.2} {:6.2}  measured {:6.2} {:6.2} {:6.2}  error {:+5.2} {:+5.2} {:+5.2}",
                    cloud.len(),
                    t[0],
                    t[1],
                    t[2],
                    m[0],
                    m[1],
                    m[2],
                    m[0] - t[0],
                    m[1] - t[1],
                    m[2] - t[2]
                );
                let witness = |a: &Option<angles::AngleFinding>| {
                    a.as_ref().map_or_else(
                        || "-".to_owned(),
                        |a| {
                            let w = a.witness_in_vehicle;
                            format!("({:.3}, {:.3})", w[0], w[2])
                        },
                    )
                };
                let tw = |a: &hil_sim::truth::TrueAngle| {
                    a.witness.as_ref().map_or_else(
                        || "-".to_owned(),
                        |w| format!("({:.3}, {:.3})", w.x_m, w.z_m),
                    )
                };
                println!(
                    "{:<16} witnesses x,z: true {} {} {}  measured {} {} {} (calculator's vehicle frame)",
                    "",
                    tw(&truth.approach),
                    tw(&truth.breakover),
                    tw(&truth.departure),
                    witness(&r.approach),
                    witness(&r.breakover),
                    witness(&r.departure)
                );
            }
            Err(e) => println!(
                "{name:<16} {:>8} pts  true {:6.2} {:6.2} {:6.2}  calculator failed: {e}",
                cloud.len(),
                t[0],
                t[1],
                t[2]
            ),
        }
    }
    Ok(())
}
