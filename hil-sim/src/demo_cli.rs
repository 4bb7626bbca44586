//! `passangle-sim demo` (see `hil_sim::demo`).

use std::path::PathBuf;

use clap::Args;
use hil_sim::demo::{self, DemoOptions};

/// `passangle-sim demo` arguments.
#[derive(Args, Debug)]
pub struct DemoArgs {
    /// Built-in vehicle (sedan, suv, pickup, van, offroader) or a scenario file path.
    #[arg(long, default_value = "sedan")]
    vehicle: String,
    /// Print one JSON object (`measured`, `truth`, `run_dir`, ...) instead of the table.
    #[arg(long)]
    json: bool,
    /// Where the simulated robot records its runs.
    #[arg(long, default_value = "target/passangle-demo")]
    out: PathBuf,
    /// Radio frame loss (0..1).
    #[arg(long, default_value_t = 0.0)]
    radio_loss: f64,
    /// Radio frame corruption (0..1).
    #[arg(long, default_value_t = 0.0)]
    radio_corrupt: f64,
    /// Seed of the radio impairments.
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

/// Runs the demo and prints the comparison.
pub fn demo(args: &DemoArgs) -> anyhow::Result<()> {
    let scenario = if std::path::Path::new(&args.vehicle)
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("toml"))
    {
        PathBuf::from(&args.vehicle)
    } else {
        demo::scenario_for(&args.vehicle)
    };
    let report = demo::run(
        &DemoOptions {
            scenario,
            run_root: args.out.clone(),
            radio_loss: args.radio_loss,
            radio_corrupt: args.radio_corrupt,
            seed: args.seed,
        },
        args.json,
    )?;
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
        return Ok(());
    }
    let (m, t) = (report.measured, report.truth);
    println!(
        "vehicle {}  (run {})",
        report.vehicle,
        report.run_dir.display()
    );
    println!(
        "  {:<16} {:>9} {:>9} {:>9}",
        "angle, degrees", "measured", "true", "error"
    );
    for (name, a, b) in [
        ("approach", m.approach_deg, t.approach_deg),
        ("departure", m.departure_deg, t.departure_deg),
        ("ramp breakover", m.breakover_deg, t.breakover_deg),
    ] {
        println!("  {name:<16} {a:>9.2} {b:>9.2} {:>+9.2}", a - b);
    }
    if let Some(s) = report.stop_to_result_s {
        println!("  robot at rest -> result on the handheld: {s:.2} s");
    }
    println!(
        "  whole run {:.1} s, {} cloud points, warnings: {}",
        report.run_s, report.cloud_points, report.warnings
    );
    Ok(())
}
