//! Benchmark: the angle calculator on a one-million-point synthetic cloud, single thread.
//!
//! `cargo run -p onboard --release --example bench_angles`
//!
//! Prints the calculator's wall time (median of 5 runs) and, as a peer measured in the same run on
//! the same points, the time to parse the cloud from an in-memory binary PLY, with their ratio.
#![allow(clippy::unwrap_used, missing_docs)]

#[path = "../tests/synth/mod.rs"]
mod synth;

use std::time::{Duration, Instant};

use angles::{AnglesConfig, compute_angles};
use cloud_io::{Cloud, CloudFormat, PlyEncoding, parse_cloud, write_ply};

fn median(mut v: Vec<Duration>) -> Duration {
    v.sort();
    v[v.len() / 2]
}

fn main() {
    let v = synth::sedan();
    let scan = synth::Scan {
        noise_m: 0.005,
        ground_spacing_m: 0.006,
        ..synth::Scan::noiseless(0.0037)
    };
    let pose = synth::Pose {
        yaw_rad: 0.1,
        tilt_rad: 0.05,
        tilt_axis_rad: 1.0,
        shift_m: [3.0, 1.0, -0.5],
    };
    let points: Vec<[f64; 3]> = synth::sample(&v, scan)
        .into_iter()
        .map(|p| pose.apply(p))
        .collect();
    let cloud = Cloud { points_m: points };
    let mut ply = Vec::new();
    write_ply(&mut ply, &cloud, PlyEncoding::BinaryLittleEndian).unwrap();
    let config = AnglesConfig::default();
    let mut calc = Vec::new();
    let mut parse = Vec::new();
    let mut last = None;
    let points: Vec<angles::V3> = cloud.points_m.iter().map(|&p| p.into()).collect();
    for _ in 0..5 {
        let t = Instant::now();
        let parsed = parse_cloud(&ply, CloudFormat::Ply).unwrap();
        parse.push(t.elapsed());
        assert_eq!(parsed.0.points_m.len(), cloud.points_m.len());
        let t = Instant::now();
        last = Some(compute_angles(&points, &config).unwrap());
        calc.push(t.elapsed());
    }
    let r = last.unwrap();
    let (c, p) = (median(calc), median(parse));
    let t = synth::truth(&v, false);
    println!("points: {}", cloud.points_m.len());
    println!("compute_angles: {:.3} s (median of 5)", c.as_secs_f64());
    println!(
        "peer, binary PLY parse of the same points: {:.3} s",
        p.as_secs_f64()
    );
    println!(
        "ratio calculator / parse: {:.1}",
        c.as_secs_f64() / p.as_secs_f64()
    );
    println!(
        "errors vs truth (5 mm noise): approach {:+.3}, departure {:+.3}, breakover {:+.3} deg",
        (r.approach.unwrap().angle_rad - t.approach_rad).to_degrees(),
        (r.departure.unwrap().angle_rad - t.departure_rad).to_degrees(),
        (r.breakover.unwrap().angle_rad - t.breakover_rad).to_degrees()
    );
}
