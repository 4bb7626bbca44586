//! Write a synthetic vehicle's cloud as PLY and print its true angles (for trying `passangle angles`).
//!
//! `cargo run -p onboard --release --example synth_cloud -- VEHICLE OUT.ply [NOISE_M] [SPACING_M]`
//! with VEHICLE one of sedan, suv, off-roader, pickup+hitch, van, rounded. The cloud is placed
//! tilted 4 degrees, yawed 8 degrees and shifted, as in the tests.
#![allow(clippy::unwrap_used, missing_docs)]

#[path = "../tests/synth/mod.rs"]
mod synth;

use std::io::BufWriter;
use std::path::PathBuf;

use clap::Parser;

use cloud_io::{Cloud, PlyEncoding, write_ply};

/// Write a synthetic vehicle's cloud as PLY and print its true angles.
#[derive(Parser)]
struct Args {
    /// Vehicle: sedan, suv, off-roader, pickup+hitch, van or rounded.
    vehicle: String,
    /// Output PLY file.
    out: PathBuf,
    /// Isotropic range noise (sigma), metres.
    #[arg(default_value_t = 0.0)]
    noise_m: f64,
    /// Point spacing, metres.
    #[arg(default_value_t = 0.005)]
    spacing_m: f64,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    let v = synth::all()
        .into_iter()
        .find(|v| v.name == args.vehicle)
        .ok_or_else(|| format!("unknown vehicle `{}`", args.vehicle))?;
    let (noise_m, spacing_m) = (args.noise_m, args.spacing_m);
    let pose = synth::Pose {
        yaw_rad: 8f64.to_radians(),
        tilt_rad: 4f64.to_radians(),
        tilt_axis_rad: 0.5,
        shift_m: [12.0, -3.5, 1.3],
    };
    let scan = synth::Scan {
        noise_m,
        ..synth::Scan::noiseless(spacing_m)
    };
    let cloud = Cloud {
        points_m: synth::sample(&v, scan)
            .into_iter()
            .map(|p| pose.apply(p))
            .collect(),
    };
    let file = std::fs::File::create(&args.out)?;
    write_ply(
        BufWriter::new(file),
        &cloud,
        PlyEncoding::BinaryLittleEndian,
    )?;
    let t = synth::truth(&v, false);
    println!(
        "{}: {} points -> {}; true approach {:.3} deg, departure {:.3} deg, breakover {:.3} deg",
        v.name,
        cloud.points_m.len(),
        args.out.display(),
        t.approach_rad.to_degrees(),
        t.departure_rad.to_degrees(),
        t.breakover_rad.to_degrees()
    );
    Ok(())
}
