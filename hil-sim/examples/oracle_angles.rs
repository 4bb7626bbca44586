//! Oracle run: the onboard angle calculator on clouds built from the simulated sensors with the
//! TRUE poses (no odometry, no deskew error), against the true angles from the geometry. It
//! separates the calculator's own error from the point-cloud pipeline's: whatever differs here is
//! sensor coverage plus the calculator.
//!
//! Run: `cargo run --release -p hil-sim --example oracle_angles [EVERY_NTH_PACKET]
//! [DEPTH_EVERY_NTH_FRAME] [noiseless]` (defaults 4, 0 = no D435 points, the scenario's noise).
//! Prints one line per shipped scenario.

use std::path::PathBuf;

use hil_sim::d435::{D435Sim, Intrinsics};
use hil_sim::geometry::Vec3;
use hil_sim::scenario::Scenario;
use hil_sim::truth::{TruthOptions, true_angles};
use hil_sim::vlp16::{FiringTruth, Vlp16Sim};
use hil_sim::world::Scene;
use onboard::angles::{AnglesConfig, compute_angles};

fn lidar_cloud(scenario: &Scenario, scene: &Scene, every: u64) -> Vec<[f64; 3]> {
    let sim = Vlp16Sim::new(
        scene,
        &scenario.run,
        scenario.file.lidar.clone(),
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

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let every: u64 = args.next().map_or(Ok(4), |s| s.parse())?;
    let depth_every: u64 = args.next().map_or(Ok(0), |s| s.parse())?;
    let noiseless = args.next().is_some_and(|s| s == "noiseless");
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenarios");
    let mut paths: Vec<PathBuf> = std::fs::read_dir(&dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    paths.sort();
    println!(
        "true vs onboard::angles on oracle clouds (true poses), degrees: approach / breakover / departure"
    );
    for path in &paths {
        let mut scenario = Scenario::load(path)?;
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
        let name = path
            .file_stem()
            .map_or_else(String::new, |s| s.to_string_lossy().into_owned());
        let t = [
            truth.approach.angle_rad,
            truth.breakover.angle_rad,
            truth.departure.angle_rad,
        ]
        .map(f64::to_degrees);
        match compute_angles(&cloud, &AnglesConfig::default()) {
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
                let witness = |a: &Option<onboard::angles::AngleFinding>| {
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
