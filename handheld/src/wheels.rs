//! `passangle wheels RUN_DIR`: the wheels' distance scale from a recorded calibration drive
//! (docs/operator/run.md, "Calibrating the wheels' distance").
//!
//! The run must start and end parked (a second or more each) and drive straight toward or away
//! from a wall that stays in view. Reads the run's lidar frames (decoded with the run's own
//! `lidar-range-offsets-m`) and raw wheel reports (`onboard::process::read_streams`), measures
//! the travel between the two parked positions from the walls
//! (`onboard::wheel_calibration`), and prints the walls used, the travel and the wheels'
//! distance, the scale with its standard error, and the line for the onboard config
//! (`[processing] wheel-distance-scale`), or with `--json` the same as one JSON object. Exits
//! non-zero, naming what is missing, when the run cannot calibrate. The scale is of the raw
//! reports, so it replaces any scale configured before.

use std::io::Write;
use std::path::PathBuf;

use anyhow::Context;
use serde_json::json;

/// Arguments of `passangle wheels`.
#[derive(Debug, clap::Args)]
pub struct WheelsArgs {
    /// The calibration drive's run directory (holds lidar.pcap and odometry.csv).
    pub run_dir: PathBuf,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

/// `passangle wheels`.
pub fn run(args: &WheelsArgs, out: &mut impl Write) -> anyhow::Result<()> {
    let dir = &args.run_dir;
    let (config, _) = crate::replay::rebuild_config(dir, None)?;
    let (lidar, wheel) = onboard::process::read_streams(dir, &config)
        .map_err(anyhow::Error::msg)
        .with_context(|| format!("{}: reading the run", dir.display()))?;
    let cal = onboard::wheel_calibration::calibrate_wheels(&lidar, &wheel, &config.pipeline.mounts)
        .with_context(|| format!("{}: wheel calibration", dir.display()))?;
    // Five decimals: the standard error is a few parts in 10^5 over a few metres.
    let line = format!("wheel-distance-scale = {:.5}", cal.scale);
    let walls: Vec<_> = cal
        .travel
        .walls
        .iter()
        .map(|(a, b, travel)| {
            json!({
                "normal": a.normal,
                "distance_before_m": a.distance_m,
                "distance_after_m": b.distance_m,
                "returns_before": a.returns,
                "returns_after": b.returns,
                "travel_m": travel,
            })
        })
        .collect();
    if args.json {
        let doc = json!({
            "run_dir": dir.display().to_string(),
            "parked_before_s": cal.parked_s[0],
            "parked_after_s": cal.parked_s[1],
            "walls": walls,
            "travel_m": cal.travel.distance_m,
            "travel_standard_error_m": cal.travel.standard_error_m,
            "wheel_distance_m": cal.wheel_distance_m,
            "scale": cal.scale,
            "scale_standard_error": cal.standard_error,
            "configured_scale": config.wheel_distance_scale,
            "config_line": line,
        });
        writeln!(out, "{}", serde_json::to_string_pretty(&doc)?)?;
        return Ok(());
    }
    writeln!(
        out,
        "{}: parked {:.1}-{:.1} s before the drive, {:.1}-{:.1} s after it",
        dir.display(),
        cal.parked_s[0].0,
        cal.parked_s[0].1,
        cal.parked_s[1].0,
        cal.parked_s[1].1
    )?;
    for (a, b, travel) in &cal.travel.walls {
        writeln!(
            out,
            "  wall, normal ({:+.2}, {:+.2}, {:+.2}): {:.4} m before, {:.4} m after, travel {:.4} m",
            a.normal[0], a.normal[1], a.normal[2], a.distance_m, b.distance_m, travel
        )?;
    }
    writeln!(
        out,
        "travel {:.4} m +- {:.1} mm by the walls, {:.4} m by the wheels\n\
         wheel distance scale {:.5} +- {:.5} (configured for this run: {:.5})\n\
         \n\
         For the onboard config:\n\
         [processing]\n\
         {line}",
        cal.travel.distance_m,
        cal.travel.standard_error_m * 1e3,
        cal.wheel_distance_m,
        cal.scale,
        cal.standard_error,
        config.wheel_distance_scale
    )?;
    Ok(())
}
