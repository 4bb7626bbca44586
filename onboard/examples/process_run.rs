//! Builds the cloud of a recorded run directory and writes it as PLY (for `passangle angles`).
//! `cargo run --release -p onboard --example process_run -- RUN_DIR OUT.ply`

fn main() -> Result<(), String> {
    let args: Vec<String> = std::env::args().collect();
    let (Some(dir), Some(out)) = (args.get(1), args.get(2)) else {
        return Err("usage: process_run RUN_DIR OUT.ply".into());
    };
    let t = std::time::Instant::now();
    let config = onboard::process::ProcessConfig::default();
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
