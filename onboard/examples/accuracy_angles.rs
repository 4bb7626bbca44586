//! Accuracy sweep: every synthetic vehicle, several noise seeds, tilted + yawed + shifted; prints
//! the error of each angle against the brute-force truth and a summary.
//!
//! `cargo run -p onboard --release --example accuracy_angles -- [NOISE_M] [SEEDS] [SPACING_M] [jitter]`
//!
//! With `jitter`, the body is sampled along the profile from a seed-dependent offset, so the grid
//! generally misses the profile's corners (a real scan does too).
//!
//! `cargo run -p onboard --release --example accuracy_angles -- saved DIR [FILTER]` instead runs
//! the calculator on the clouds `bench_pipeline --save-clouds DIR` (or `oracle_angles
//! --save-clouds DIR`) wrote: every `DIR/*.ply` whose name contains FILTER, against the true angles
//! in the `.truth` file beside it (approach, breakover, departure in degrees), with the scan's path
//! from the `.path` file beside it where there is one (`x y z` per line; `NOPATH` set: ignored,
//! the calculator's cloud-only coverage check). Prints the error per
//! cloud (with the tyres, witnesses and warnings when `DEBUG` is set), then mean / sample standard
//! deviation per vehicle (the name up to its `-SEED-` part). Iterating on the calculator this way
//! takes seconds instead of the bench's hour.
#![allow(clippy::unwrap_used, missing_docs)]

#[path = "../tests/synth/mod.rs"]
mod synth;

use angles::{AnglesConfig, compute_angles};

/// The calculator's accuracy on synthetic vehicles or on saved clouds (see the module docs).
#[derive(clap::Parser)]
#[command(args_conflicts_with_subcommands = true)]
struct Args {
    #[command(subcommand)]
    saved: Option<Saved>,
    /// Isotropic range noise (sigma), metres.
    #[arg(default_value_t = 0.005)]
    noise_m: f64,
    /// Noise seeds per vehicle.
    #[arg(default_value_t = 5)]
    seeds: u64,
    /// Point spacing, metres.
    #[arg(default_value_t = 0.005)]
    spacing_m: f64,
    /// `jitter`: sample the body from a seed-dependent offset along the profile.
    jitter: Option<String>,
}

#[derive(clap::Subcommand)]
enum Saved {
    /// Run the calculator on the clouds a bench saved (`--save-clouds DIR`).
    Saved {
        /// The directory of `.ply` clouds with their `.truth` files.
        dir: std::path::PathBuf,
        /// Only clouds whose name contains this.
        #[arg(default_value = "")]
        filter: String,
    },
}

fn main() {
    let args = <Args as clap::Parser>::parse();
    if let Some(Saved::Saved { dir, filter }) = &args.saved {
        saved::run(dir, filter);
        return;
    }
    let (noise_m, seeds, spacing_m) = (args.noise_m, args.seeds, args.spacing_m);
    let jitter = match args.jitter.as_deref() {
        None => false,
        Some("jitter") => true,
        Some(other) => {
            eprintln!("unknown argument `{other}` (expected `jitter`)");
            std::process::exit(2);
        }
    };
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
            let cloud: Vec<angles::V3> = cloud.iter().map(|&p| p.into()).collect();
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

/// Mode `saved`: the calculator on clouds saved by the simulator benches.
mod saved {
    use std::collections::BTreeMap;
    use std::path::{Path, PathBuf};

    use angles::{AngleFinding, AnglesConfig, AnglesResult, compute_angles};
    use cloud_io::read_cloud;

    /// The vehicle of a saved cloud's file stem `NAME-SEED-VARIANT`: the part before the last
    /// all-digit `-` segment.
    fn vehicle_of(stem: &str) -> String {
        let parts: Vec<&str> = stem.split('-').collect();
        let seed_at = parts
            .iter()
            .rposition(|p| !p.is_empty() && p.bytes().all(|b| b.is_ascii_digit()))
            .unwrap_or(parts.len());
        parts[..seed_at].join("-")
    }

    fn read_truth(path: &Path) -> [f64; 3] {
        let text =
            std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let v: Vec<f64> = text
            .split_whitespace()
            .map(|s| {
                s.parse()
                    .unwrap_or_else(|e| panic!("{}: '{s}': {e}", path.display()))
            })
            .collect();
        assert!(
            v.len() == 3,
            "{}: need 3 angles, got {}",
            path.display(),
            v.len()
        );
        [v[0], v[1], v[2]]
    }

    /// The `.path` file's points; empty where there is none.
    fn read_path(path: &Path) -> Vec<[f64; 3]> {
        let Ok(text) = std::fs::read_to_string(path) else {
            return Vec::new();
        };
        text.lines()
            .enumerate()
            .map(|(i, l)| {
                let v: Vec<f64> = l
                    .split_whitespace()
                    .map(|s| {
                        s.parse().unwrap_or_else(|e| {
                            panic!("{} line {}: '{s}': {e}", path.display(), i + 1)
                        })
                    })
                    .collect();
                assert!(
                    v.len() == 3,
                    "{} line {}: need x y z",
                    path.display(),
                    i + 1
                );
                [v[0], v[1], v[2]]
            })
            .collect()
    }

    fn debug(r: &AnglesResult) {
        let w = |f: &Option<AngleFinding>| {
            f.as_ref().map_or_else(
                || "-".to_owned(),
                |f| {
                    let p = f.witness_in_vehicle;
                    format!(
                        "({:.3}, {:.3}, {:.3}) support {}",
                        p[0], p[1], p[2], f.support
                    )
                },
            )
        };
        println!(
            "    witnesses: approach {}  breakover {}  departure {}",
            w(&r.approach),
            w(&r.breakover),
            w(&r.departure)
        );
        println!(
            "    axles x {:.3} / {:.3} loaded r {:.4} / {:.4} free r {:.4} / {:.4}; yaw {:.2} deg, tilt {:.3} deg, noise {:.1} mm, bin {:.3} m, band {:.3}..{:.3}",
            r.front_axle.x_m,
            r.rear_axle.x_m,
            r.front_axle.loaded_radius_m,
            r.rear_axle.loaded_radius_m,
            r.front_axle.free_radius_m,
            r.rear_axle.free_radius_m,
            r.yaw_rad.to_degrees(),
            r.ground.tilt_rad.to_degrees(),
            r.noise_sigma_m * 1e3,
            r.bin_m,
            r.band_y_m.0,
            r.band_y_m.1
        );
        for t in &r.tyres {
            println!(
                "    tyre {} centre ({:.3}, {:.3}, {:.4}) in cloud x {:.4} free r {:.4} width {:.3} rms {:.1} mm, {} pts",
                t.position.label(),
                t.centre_in_vehicle[0],
                t.centre_in_vehicle[1],
                t.centre_in_vehicle[2],
                t.centre_in_cloud[0],
                t.free_radius_m,
                t.width_m,
                t.residual_rms_m * 1e3,
                t.fit_points
            );
        }
        for w in &r.warnings {
            println!("    warning: {w}");
        }
        if std::env::var_os("DEBUG_ENDS").is_some() {
            for (name, f) in [("approach", &r.approach), ("departure", &r.departure)] {
                let Some(f) = f else { continue };
                let x = f.witness_in_vehicle[0];
                let near: Vec<String> = r
                    .envelope
                    .iter()
                    .filter(|s| (s.x_m - x).abs() < 0.06)
                    .map(|s| format!("{:.4}:{:.4}/{}", s.x_m, s.z_m, s.support))
                    .collect();
                let c = f.witness_in_cloud;
                println!(
                    "    {name} witness in cloud ({:.4}, {:.4}, {:.4}); envelope near it: {}",
                    c[0],
                    c[1],
                    c[2],
                    near.join(" ")
                );
            }
        }
        let (f, b) = (r.front_axle, r.rear_axle);
        let gap = |lo: f64, hi: f64| {
            let xs: Vec<f64> = r
                .envelope
                .iter()
                .map(|s| s.x_m)
                .filter(|x| *x >= lo && *x <= hi)
                .collect();
            let inner = xs.windows(2).map(|w| w[1] - w[0]).fold(0.0, f64::max);
            let (first, last) = (
                xs.first().copied().unwrap_or(hi),
                xs.last().copied().unwrap_or(lo),
            );
            (first - lo, inner, hi - last)
        };
        let ends = (
            r.envelope.first().map_or(f64::NAN, |s| s.x_m),
            r.envelope.last().map_or(f64::NAN, |s| s.x_m),
        );
        println!(
            "    gaps (lead, inner, tail) m: rear zone {:.3?} between {:.3?} front zone {:.3?}; envelope ends {:.3?}",
            gap(ends.0, b.x_m - b.free_radius_m),
            gap(b.x_m + b.free_radius_m, f.x_m - f.free_radius_m),
            gap(f.x_m + f.free_radius_m, ends.1),
            ends
        );
    }

    pub fn run(dir: &Path, filter: &str) {
        let mut paths: Vec<PathBuf> = std::fs::read_dir(dir)
            .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|e| e == "ply"))
            .filter(|p| p.to_string_lossy().contains(filter))
            .collect();
        paths.sort();
        assert!(
            !paths.is_empty(),
            "no .ply clouds matching '{filter}' in {}",
            dir.display()
        );
        let verbose = std::env::var_os("DEBUG").is_some();
        let mut per_vehicle: BTreeMap<String, Vec<[f64; 3]>> = BTreeMap::new();
        for path in &paths {
            let stem = path
                .file_stem()
                .map_or_else(String::new, |s| s.to_string_lossy().into_owned());
            let truth = read_truth(&path.with_extension("truth"));
            let (cloud, _) = read_cloud(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            let config = AnglesConfig {
                scan_path_in_cloud: if std::env::var_os("NOPATH").is_some() {
                    Vec::new()
                } else {
                    read_path(&path.with_extension("path"))
                        .into_iter()
                        .map(Into::into)
                        .collect()
                },
                ..AnglesConfig::default()
            };
            let points: Vec<angles::V3> = cloud.points_m.iter().map(|&p| p.into()).collect();
            let errors = match compute_angles(&points, &config) {
                Ok(r) => {
                    let m = [&r.approach, &r.breakover, &r.departure]
                        .map(|a| a.as_ref().map_or(f64::NAN, |a| a.angle_rad.to_degrees()));
                    let e = [0, 1, 2].map(|k| m[k] - truth[k]);
                    println!(
                        "{stem:<32} {:>8} pts  error {:+6.2} {:+6.2} {:+6.2} deg",
                        cloud.points_m.len(),
                        e[0],
                        e[1],
                        e[2]
                    );
                    if verbose {
                        debug(&r);
                    }
                    e
                }
                Err(e) => {
                    println!("{stem:<32} {:>8} pts  refused: {e}", cloud.points_m.len());
                    [f64::NAN; 3]
                }
            };
            per_vehicle
                .entry(vehicle_of(&stem))
                .or_default()
                .push(errors);
        }
        println!();
        println!(
            "| vehicle | clouds | approach mean / sd deg | breakover mean / sd deg | departure mean / sd deg |"
        );
        println!("|---|---|---|---|---|");
        for (name, errors) in &per_vehicle {
            let stats = |k: usize| {
                let v: Vec<f64> = errors
                    .iter()
                    .map(|e| e[k])
                    .filter(|x| x.is_finite())
                    .collect();
                let n = v.len() as f64;
                let mean = v.iter().sum::<f64>() / n;
                let sd = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
                match v.len() {
                    0 => "no angle".to_owned(),
                    1 => format!("{mean:+.2} / - (1 ok)"),
                    k => format!("{mean:+.2} / {sd:.2} ({k} ok)"),
                }
            };
            println!(
                "| {name} | {} | {} | {} | {} |",
                errors.len(),
                stats(0),
                stats(1),
                stats(2)
            );
        }
    }
}
