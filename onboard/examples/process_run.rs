//! Builds the cloud of a recorded run directory and writes it as PLY (for `passangle angles`).
//! `cargo run --release -p onboard --example process_run -- RUN_DIR OUT.ply [PROCESSING.toml]`
//! (the optional file holds the `[processing]` section's keys, e.g. `[pipeline.fusion]`).

fn main() -> Result<(), String> {
    let args: Vec<String> = std::env::args().collect();
    let (Some(dir), Some(out)) = (args.get(1), args.get(2)) else {
        return Err("usage: process_run RUN_DIR OUT.ply".into());
    };
    let t = std::time::Instant::now();
    let config: onboard::process::ProcessConfig = match args.get(3) {
        Some(path) => {
            let text = std::fs::read_to_string(path).map_err(|e| format!("{path}: {e}"))?;
            toml::from_str(&text).map_err(|e| format!("{path}: {e}"))?
        }
        None => onboard::process::ProcessConfig::default(),
    };
    let (cloud, counts) = onboard::process::build_cloud(std::path::Path::new(dir), &config)?;
    eprintln!(
        "{counts:?}: {} points in {:.2} s",
        cloud.points_m.len(),
        t.elapsed().as_secs_f64()
    );
    let f = std::fs::File::create(out).map_err(|e| format!("{out}: {e}"))?;
    onboard::cloud::write_ply(
        std::io::BufWriter::new(f),
        &cloud,
        onboard::cloud::PlyEncoding::BinaryLittleEndian,
    )
    .map_err(|e| format!("{out}: {e}"))
}
