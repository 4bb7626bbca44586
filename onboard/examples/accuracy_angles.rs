//! Accuracy sweep: every synthetic vehicle, several noise seeds, tilted + yawed + shifted; prints
//! the error of each angle against the brute-force truth and a summary.
//!
//! `cargo run -p onboard --release --example accuracy_angles -- [NOISE_M] [SEEDS] [SPACING_M] [jitter]`
//!
//! With `jitter`, the body is sampled along the profile from a seed-dependent offset, so the grid
//! generally misses the profile's corners (a real scan does too).
#![allow(clippy::unwrap_used, missing_docs)]

#[path = "../tests/synth/mod.rs"]
mod synth;

use onboard::angles::{AnglesConfig, compute_angles};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let noise_m: f64 = args.get(1).map_or(0.005, |s| s.parse().unwrap());
    let seeds: u64 = args.get(2).map_or(5, |s| s.parse().unwrap());
    let spacing_m: f64 = args.get(3).map_or(0.005, |s| s.parse().unwrap());
    let jitter = args.get(4).is_some_and(|s| s == "jitter");
    let pose = synth::Pose {
        yaw_rad: 8f64.to_radians(),
        tilt_rad: 4f64.to_radians(),
        tilt_axis_rad: 0.5,
        shift_m: [12.0, -3.5, 1.3],
    };
    let mut all = [Vec::new(), Vec::new(), Vec::new()];
    for v in synth::all() {
        let t = synth::truth(&v, false);
        let truth = [t.approach_rad, t.departure_rad, t.breakover_rad];
        for seed in 0..seeds {
            let scan = synth::Scan {
                noise_m,
                seed: 1000 + seed,
                phase_m: if jitter {
                    spacing_m * (0.137 + 0.618 * seed as f64).fract().max(0.05)
                } else {
                    0.0
                },
                ..synth::Scan::noiseless(spacing_m)
            };
            let cloud: Vec<[f64; 3]> = synth::sample(&v, scan)
                .into_iter()
                .map(|p| pose.apply(p))
                .collect();
            let r = compute_angles(&cloud, &AnglesConfig::default()).unwrap();
            let got =
                [&r.approach, &r.departure, &r.breakover].map(|f| f.as_ref().unwrap().angle_rad);
            let e: Vec<f64> = (0..3).map(|k| (got[k] - truth[k]).to_degrees()).collect();
            println!(
                "{:>13} seed {seed}: error {:+.3} {:+.3} {:+.3} deg",
                v.name, e[0], e[1], e[2]
            );
            if std::env::var_os("DEBUG").is_some() && e.iter().any(|e| e.abs() > 0.25) {
                println!("  breakover {:?}", r.breakover);
                println!("  approach {:?}", r.approach);
                for t in &r.tyres {
                    println!("  {t:?}");
                }
                println!("  warnings {:?}", r.warnings);
            }
            for k in 0..3 {
                all[k].push(e[k]);
            }
        }
    }
    for (k, name) in ["approach", "departure", "breakover"].iter().enumerate() {
        let n = all[k].len() as f64;
        let mean = all[k].iter().sum::<f64>() / n;
        let rms = (all[k].iter().map(|e| e * e).sum::<f64>() / n).sqrt();
        let max = all[k].iter().map(|e| e.abs()).fold(0.0, f64::max);
        println!(
            "{name:>10}: mean {mean:+.3}, rms {rms:.3}, max |error| {max:.3} deg over {n} runs"
        );
    }
}
