//! Builds the cloud of a recorded run directory and writes it as PLY (for `passangle angles`).
//! `cargo run --release -p onboard --example process_run -- RUN_DIR OUT.ply [PROCESSING.toml]`
//! (the optional file holds the `[processing]` section's keys, e.g. `[pipeline.fusion]`).

use std::path::PathBuf;

use clap::Parser;

/// Build a recorded run's cloud and write it as PLY.
#[derive(Parser)]
struct Args {
    /// The run directory.
    dir: PathBuf,
    /// Output PLY file.
    out: PathBuf,
    /// A TOML file with the `[processing]` section's keys.
    processing: Option<PathBuf>,
}

fn main() -> Result<(), String> {
    let args = Args::parse();
    let out = args.out.display().to_string();
    let t = std::time::Instant::now();
    let config: onboard::process::ProcessConfig = match &args.processing {
        Some(path) => {
            let path = path.display();
            let text =
                std::fs::read_to_string(path.to_string()).map_err(|e| format!("{path}: {e}"))?;
            toml::from_str(&text).map_err(|e| format!("{path}: {e}"))?
        }
        None => onboard::process::ProcessConfig::default(),
    };
    let (cloud, counts) = onboard::process::build_cloud(&args.dir, &config)?;
    eprintln!(
        "{counts:?}: {} points in {:.2} s",
        cloud.points_m.len(),
        t.elapsed().as_secs_f64()
    );
    let f = std::fs::File::create(&args.out).map_err(|e| format!("{out}: {e}"))?;
    cloud_io::write_ply(
        std::io::BufWriter::new(f),
        &cloud,
        cloud_io::PlyEncoding::BinaryLittleEndian,
    )
    .map_err(|e| format!("{out}: {e}"))
}
