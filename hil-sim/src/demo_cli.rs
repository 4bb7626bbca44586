//! `passangle-sim demo` (see `hil_sim::demo`).

use std::path::PathBuf;

use clap::Args;
use hil_sim::demo::{self, DemoOptions};
use hil_sim::lockstep::Faults;

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
    /// Seed of the radio impairments (and of injected faults).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Run in real time on threads, loopback UDP and the wall clock (for showing it and for
    /// timing), instead of in lockstep on one simulated clock (deterministic, as fast as the
    /// CPU allows).
    #[arg(long)]
    realtime: bool,
    /// Lockstep only: cut the radio at this simulated time, s.
    #[arg(long, value_name = "S")]
    radio_cut_at: Option<f64>,
    /// Lockstep only: kill the onboard service at this simulated time, s.
    #[arg(long, value_name = "S")]
    onboard_crash_at: Option<f64>,
    /// Lockstep only: the probability that a lidar data packet arrives malformed.
    #[arg(long, default_value_t = 0.0, value_name = "P")]
    malformed_lidar: f64,
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
            realtime: args.realtime,
            faults: Faults {
                radio_cut_at_s: args.radio_cut_at,
                onboard_crash_at_s: args.onboard_crash_at,
                esc_fault: None,
                malformed_lidar: args.malformed_lidar,
            },
        },
        args.json,
    )?;
    if args.json {
        // The JSON is the same for the same inputs in lockstep; the wall time goes to stderr.
        println!("{}", serde_json::to_string(&report)?);
        eprintln!("demo took {:.1} s of wall time", report.wall_s);
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
        "  whole run {:.1} s on the robot's clock, {} cloud points, warnings: {}",
        report.run_s, report.cloud_points, report.warnings
    );
    println!(
        "  lidar packets: {} sent, {} received by the service",
        report.lidar_packets_sent, report.lidar_packets_received
    );
    println!(
        "  {} demo, {:.1} s of wall time",
        match report.mode {
            demo::Mode::Lockstep => "lockstep",
            demo::Mode::RealTime => "real-time",
        },
        report.wall_s
    );
    Ok(())
}
