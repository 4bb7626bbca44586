//! `passangle replay RUN_DIR`: rebuild a recorded run's point cloud offline with the onboard
//! pipeline (`pipeline`), optionally with another pipeline config, then compute the angles.
//!
//! Reads the run directory of `onboard::recorder` (`lidar.pcap`, `odometry.csv`,
//! `depth/index.csv` + `depth/NNNNNN.z16`) through `onboard::process::build_run`, the same
//! `RunBuilder` the service feeds during a live run, with the settings the run was made with (its
//! `config.toml`) unless `--pipeline-config` gives others, so a replay gives the service's cloud.
//! Stamps: the host wall clock of each stream (odometry at its MCU stamp mapped onto the host
//! clock), as seconds since the first complete lidar frame. A lidar frame is stamped
//! with the receive time of its first packet, which is up to one packet (1.3 ms) after its first
//! firing: an offset of 0.4 mm at 0.3 m/s, left uncorrected.
//!
//! Writes the cloud as binary PLY (`--out`, default `RUN_DIR/replay-cloud.ply`) and prints the
//! trajectory length, the pipeline's counters and the angles with their expanded uncertainties
//! (degrees at this boundary only), or with `--json` the run's whole result as one JSON object
//! (the fields of `passangle angles --json` plus the replay's counters and notes).

use std::io::Write;
use std::path::{Path, PathBuf};

use angles::{AnglesConfig, Quantity, compute_angles};
use anyhow::{Context, bail};
use cloud_io::{PlyEncoding, write_ply};
use onboard::process::{ProcessConfig, build_run};
use onboard::recorder::Recording;
use pipeline::{BuiltCloud, PipelineConfig};

/// Arguments of `passangle replay`.
#[derive(Debug, clap::Args)]
pub struct ReplayArgs {
    /// The run directory (holds meta.json, lidar.pcap, odometry.csv, depth/).
    pub run_dir: PathBuf,
    /// Pipeline config (TOML, the keys of the onboard config's `[processing.pipeline]`
    /// section). Absent: the settings the run was made with (its `config.toml`), or the
    /// pipeline's defaults for a run without one.
    #[arg(long)]
    pub pipeline_config: Option<PathBuf>,
    /// Where to write the cloud (binary PLY).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Direction of the vehicle's front in the built cloud: `+x` (the robot drove toward the
    /// front) or `-x`. Absent: as the run's `config.toml` says (`processing.enter-at-front`),
    /// else `-x`.
    #[arg(long, allow_hyphen_values = true)]
    pub front: Option<String>,
    /// Print the run's result as one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

/// The settings to rebuild a recorded run with (`replay`, `export --rebuild`): the run's own
/// `[processing]` (its `config.toml`; the defaults for a run without one), its pipeline section
/// replaced by `pipeline_config` when given; and where the pipeline's settings came from.
pub fn rebuild_config(
    run_dir: &Path,
    pipeline_config: Option<&Path>,
) -> anyhow::Result<(ProcessConfig, String)> {
    let (mut config, source) = match ProcessConfig::of_run(run_dir)
        .map_err(anyhow::Error::msg)
        .context("the run's config.toml (pass --pipeline-config to rebuild without it)")?
    {
        Some(recorded) => (recorded, "the run's config.toml".to_owned()),
        None => (
            ProcessConfig::default(),
            "the defaults (the run has no config.toml)".to_owned(),
        ),
    };
    let Some(path) = pipeline_config else {
        return Ok((config, source));
    };
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    config.pipeline = PipelineConfig::from_toml(&text)
        .with_context(|| format!("{}: pipeline config", path.display()))?;
    Ok((config, path.display().to_string()))
}

/// Run the command.
pub fn run(args: &ReplayArgs, out: &mut impl Write) -> anyhow::Result<()> {
    let recording = Recording::open(&args.run_dir)?;
    let mut notes = Vec::new();
    if recording.incomplete {
        notes.push("the run is marked INCOMPLETE; replaying what was recorded".to_owned());
    }
    let (config, source) = rebuild_config(&args.run_dir, args.pipeline_config.as_deref())?;
    notes.push(format!("pipeline settings: {source}"));
    let front_is_positive_x = match args.front.as_deref() {
        None => !config.enter_at_front,
        Some("+x") => true,
        Some("-x") => false,
        Some(other) => bail!("--front {other}: expected +x or -x"),
    };
    let (built, counts) = build_run(&args.run_dir, &config).map_err(anyhow::Error::msg)?;
    if counts.lidar_cut_short {
        notes.push(
            "lidar.pcap ends inside its last record (a crash while recording); the packets \
             before it were used"
                .to_owned(),
        );
    }
    if counts.odometry_cut_short {
        notes.push("odometry.csv ends with a cut-short line (skipped)".to_owned());
    }
    if counts.lidar_malformed > 0 || counts.out_of_order > 0 || counts.mcu_clock_resets > 0 {
        notes.push(format!(
            "{} malformed lidar packets skipped, {} items out of time order skipped, \
             {} MCU clock resets",
            counts.lidar_malformed, counts.out_of_order, counts.mcu_clock_resets
        ));
    }
    if !args.json {
        for note in &notes {
            writeln!(out, "note: {note}")?;
        }
    }
    let path = args
        .out
        .clone()
        .unwrap_or_else(|| args.run_dir.join("replay-cloud.ply"));
    let file =
        std::fs::File::create(&path).with_context(|| format!("creating {}", path.display()))?;
    write_ply(
        std::io::BufWriter::new(file),
        &onboard::frames::cloud_of(&built),
        PlyEncoding::BinaryLittleEndian,
    )
    .with_context(|| format!("writing {}", path.display()))?;
    let scan = Scan {
        lidar_path: built.lidar_path(config.pipeline.mounts.lidar_xyz_m.into()),
        x_sigma_per_m: built.x_sigma_per_m(&config.pipeline.fusion),
        front_is_positive_x,
    };
    report(&built, &path, args, scan, &notes, out)
}

/// What the calculator needs of the scan besides its cloud, as the service gives it.
struct Scan {
    /// The lidar's optical centre along the trajectory (the coverage check's path).
    lidar_path: Vec<pipeline::geom::V3>,
    /// The trajectory's stated error along x per metre.
    x_sigma_per_m: f64,
    /// Where the vehicle's front lies in the cloud.
    front_is_positive_x: bool,
}

fn report(
    built: &BuiltCloud,
    path: &Path,
    args: &ReplayArgs,
    scan: Scan,
    notes: &[String],
    out: &mut impl Write,
) -> anyhow::Result<()> {
    let s = &built.stats;
    let travelled = built.trajectory.last().map_or(0.0, |p| {
        let t = p.world_from_robot.translation;
        (t[0] * t[0] + t[1] * t[1] + t[2] * t[2]).sqrt()
    });
    let config = AnglesConfig {
        front_is_positive_x: scan.front_is_positive_x,
        // The lidar's path: what the scan did not cover is not measured.
        scan_path_in_cloud: scan.lidar_path,
        trajectory_x_sigma_per_m: scan.x_sigma_per_m,
        range_accuracy_m: Some(vlp16::RANGE_ACCURACY_M),
        scanner_view: Some(angles::ScannerView::VLP16),
        ..AnglesConfig::default()
    };
    // The cloud is written either way; the command fails when the angles were not all measured,
    // so scripts see a non-zero exit.
    let r = compute_angles(&built.points_in_world, &config)
        .with_context(|| format!("{}: computing the angles", path.display()));
    // Every standard's profile of the same cloud, in the JSON (as `passangle angles --json`).
    let profiles = match &r {
        Ok(found) if args.json => crate::angles::Profiles::compute(
            &built.points_in_world,
            &config,
            found,
            &angles::profiles::Standard::ALL,
            &[],
        ),
        _ => crate::angles::Profiles::none(),
    };
    if args.json {
        let mut v = serde_json::json!({
            "run_dir": args.run_dir.display().to_string(),
            "cloud": path.display().to_string(),
            "cloud_points": built.points_in_world.len(),
            "lidar_frames": s.frames,
            "depth_frames": s.depth_frames,
            "wheel_messages": s.wheel_messages,
            "travelled_m": (travelled * 1e4).round() / 1e4,
            "trajectory_x_sigma_per_m": config.trajectory_x_sigma_per_m,
            "notes": notes,
        });
        match &r {
            Ok(r) => v
                .as_object_mut()
                .expect("an object")
                .extend(crate::angles::result_json(r, &profiles)),
            Err(e) => v["error"] = serde_json::json!(format!("{e:#}")),
        }
        writeln!(out, "{}", serde_json::to_string_pretty(&v)?)?;
        let r = r?;
        if let Some(missing) = crate::angles::missing_angles(&r) {
            bail!("{}: not measured: {missing}", path.display());
        }
        return Ok(());
    }
    writeln!(
        out,
        "{} lidar frames, {} depth frames ({} tracked), {} wheel messages; travelled {travelled:.3} m",
        s.frames, s.depth_frames, s.visual_steps, s.wheel_messages
    )?;
    writeln!(
        out,
        "laser degenerate in {} frames; fused components from laser/visual/wheel/reference/none: {:?}",
        s.degenerate_frames, s.chosen
    )?;
    writeln!(
        out,
        "cloud: {} points -> {}",
        built.points_in_world.len(),
        path.display()
    )?;
    let r = r?;
    for (q, a) in [
        (Quantity::Approach, &r.approach),
        (Quantity::Breakover, &r.breakover),
        (Quantity::Departure, &r.departure),
    ] {
        let name = q.name();
        match a {
            Some(a) => writeln!(
                out,
                "{name:<10} {:6.2} deg  U {:.2} deg (k = 2)",
                a.angle_rad.to_degrees(),
                a.uncertainty.expanded.to_degrees()
            )?,
            None => writeln!(
                out,
                "{name:<10} not measured: {}",
                r.not_measured_reason(q).unwrap_or("no reason given")
            )?,
        }
    }
    if let Some(missing) = crate::angles::missing_angles(&r) {
        bail!("{}: not measured: {missing}", path.display());
    }
    Ok(())
}
