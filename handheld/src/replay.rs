//! `passangle replay RUN_DIR`: rebuild a recorded run's point cloud offline with the onboard
//! pipeline (`onboard::pipeline`), optionally with another pipeline config, then compute the angles.
//!
//! Reads the run directory of `onboard::recorder` (`lidar.pcap`, `odometry.csv`,
//! `depth/index.csv` + `depth/NNNNNN.z16`). Every stream carries the host wall clock, which becomes
//! the pipeline's common clock (seconds since the first lidar packet). A lidar frame is stamped with
//! the receive time of its first packet, which is up to one packet (1.3 ms) after its first firing:
//! an offset of 0.4 mm at 0.3 m/s, left uncorrected.
//!
//! Writes the cloud as binary PLY (`--out`, default `RUN_DIR/replay-cloud.ply`) and prints the
//! trajectory length, the pipeline's counters and the angles (degrees at this boundary only).

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use onboard::angles::{AnglesConfig, compute_angles};
use onboard::cloud::{PlyEncoding, write_ply};
use onboard::pipeline::{
    BuiltCloud, DepthFrame, LidarFrame, Pipeline, PipelineConfig, WheelOdometry,
};
use onboard::recorder::Recording;
use onboard::vlp16::source::{PACKET_BUF_LEN, PacketKind, PacketSource, PcapSource};
use onboard::vlp16::{DecoderConfig, FrameAssembler};

/// Arguments of `passangle replay`.
#[derive(Debug, clap::Args)]
pub struct ReplayArgs {
    /// The run directory (holds meta.json, lidar.pcap, odometry.csv, depth/).
    pub run_dir: PathBuf,
    /// Pipeline config (TOML, the keys of the onboard config's `[pipeline]` section); defaults
    /// when absent.
    #[arg(long)]
    pub pipeline_config: Option<PathBuf>,
    /// Where to write the cloud (binary PLY).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Direction of the vehicle's front in the built cloud: `+x` (the robot drove toward the
    /// front) or `-x`.
    #[arg(long, default_value = "-x", allow_hyphen_values = true)]
    pub front: String,
}

/// One input in arrival order.
enum Input {
    Lidar(LidarFrame),
    Depth(DepthFrame),
    Wheel(WheelOdometry),
}

/// Run the command.
pub fn run(args: &ReplayArgs, out: &mut impl Write) -> anyhow::Result<()> {
    let config = match &args.pipeline_config {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("reading {}", path.display()))?;
            toml::from_str::<PipelineConfig>(&text)
                .with_context(|| format!("{}: pipeline config", path.display()))?
        }
        None => PipelineConfig::default(),
    };
    let recording = Recording::open(&args.run_dir)?;
    if recording.incomplete {
        writeln!(
            out,
            "note: the run is marked INCOMPLETE; replaying what was recorded"
        )?;
    }
    let (lidar, t0_ns) = read_lidar(&args.run_dir.join("lidar.pcap"))?;
    let t0_us = t0_ns / 1000;
    let mut inputs: Vec<(f64, Input)> = Vec::new();
    for f in lidar {
        inputs.push((f.stamp_s + 0.1, Input::Lidar(f)));
    }
    let (odometry, cut) = recording.odometry()?;
    if cut > 0 {
        writeln!(
            out,
            "note: odometry.csv ends with a cut-short line (skipped)"
        )?;
    }
    for (wall_us, o) in &odometry {
        let stamp_s = seconds_since(*wall_us, t0_us);
        inputs.push((stamp_s, Input::Wheel(WheelOdometry::from_mcu(o, stamp_s))));
    }
    for d in read_depth(&args.run_dir, t0_us)? {
        inputs.push((d.stamp_s, Input::Depth(d)));
    }
    inputs.sort_by(|a, b| a.0.total_cmp(&b.0));
    let built = replay(config, inputs)?;
    let path = args
        .out
        .clone()
        .unwrap_or_else(|| args.run_dir.join("replay-cloud.ply"));
    let file =
        std::fs::File::create(&path).with_context(|| format!("creating {}", path.display()))?;
    write_ply(
        std::io::BufWriter::new(file),
        &built.to_cloud(),
        PlyEncoding::BinaryLittleEndian,
    )
    .with_context(|| format!("writing {}", path.display()))?;
    report(&built, &path, &args.front, out)
}

fn seconds_since(wall_us: u64, t0_us: u64) -> f64 {
    (wall_us as f64 - t0_us as f64) * 1e-6
}

/// Complete lidar frames from the pcap, stamped relative to the first packet; returns the frames
/// and the first packet's wall time (ns).
fn read_lidar(path: &Path) -> anyhow::Result<(Vec<LidarFrame>, u64)> {
    let mut source = PcapSource::open(path)?;
    let mut assembler = FrameAssembler::new(DecoderConfig::default())?;
    let mut buf = [0u8; PACKET_BUF_LEN];
    let mut t0_ns = None;
    let mut frames = Vec::new();
    let collect = |a: &mut FrameAssembler, t0: u64, frames: &mut Vec<LidarFrame>| {
        while let Some(f) = a.pop_frame() {
            if f.is_complete() {
                let stamp_s = (f.start_host_ns as f64 - t0 as f64) * 1e-9;
                frames.push(LidarFrame::from_vlp16(&f, stamp_s));
            }
        }
    };
    while let Some(meta) = source.next_packet(&mut buf)? {
        let payload = &buf[..meta.len];
        let t0 = *t0_ns.get_or_insert(meta.recv_host_ns);
        match meta.kind {
            PacketKind::Data => {
                // Malformed packets are counted by the assembler and skipped.
                let _ = assembler.push_data(payload, meta.recv_host_ns);
            }
            PacketKind::Position => {
                let _ = assembler.push_position(payload);
            }
        }
        collect(&mut assembler, t0, &mut frames);
    }
    assembler.finish();
    let Some(t0) = t0_ns else {
        bail!("{}: no VLP-16 packets", path.display());
    };
    collect(&mut assembler, t0, &mut frames);
    if let Some(reason) = source.truncated() {
        eprintln!("note: {}: {reason}", path.display());
    }
    Ok((frames, t0))
}

/// Depth frames listed in `depth/index.csv` (none if the run has no depth stream).
fn read_depth(run_dir: &Path, t0_us: u64) -> anyhow::Result<Vec<DepthFrame>> {
    let index = run_dir.join("depth").join("index.csv");
    let Ok(text) = std::fs::read_to_string(&index) else {
        return Ok(Vec::new());
    };
    let mut frames = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let f: Vec<&str> = line.split(',').collect();
        if f.len() != 9 || f[0].parse::<u64>().is_err() {
            continue; // header or a cut-short last line
        }
        let bad = |what: &str| format!("{} line {}: bad {what}", index.display(), i + 1);
        let num = |k: usize| f[k].parse::<f64>();
        let n: u64 = f[0].parse().with_context(|| bad("frame"))?;
        let wall_us: u64 = f[1].parse().with_context(|| bad("wall_us"))?;
        let width: usize = f[2].parse().with_context(|| bad("width"))?;
        let height: usize = f[3].parse().with_context(|| bad("height"))?;
        let k = [num(4), num(5), num(6), num(7), num(8)];
        let [Ok(fx), Ok(fy), Ok(cx), Ok(cy), Ok(scale)] = k else {
            bail!(bad("intrinsics"));
        };
        let path = run_dir.join("depth").join(format!("{n:06}.z16"));
        let bytes = std::fs::read(&path).with_context(|| format!("reading {}", path.display()))?;
        if bytes.len() != width * height * 2 {
            bail!(
                "{}: {} bytes for {width}x{height} Z16 (expected {})",
                path.display(),
                bytes.len(),
                width * height * 2
            );
        }
        frames.push(DepthFrame {
            stamp_s: seconds_since(wall_us, t0_us),
            width,
            height,
            intrinsics_px: [fx, fy, cx, cy],
            depth_scale_m: scale,
            depth: bytes
                .chunks_exact(2)
                .map(|c| u16::from_le_bytes([c[0], c[1]]))
                .collect(),
        });
    }
    Ok(frames)
}

fn replay(config: PipelineConfig, inputs: Vec<(f64, Input)>) -> anyhow::Result<BuiltCloud> {
    let mut pipeline = Pipeline::new(config)?;
    for (_, input) in inputs {
        let r = match input {
            Input::Lidar(f) => pipeline.push_lidar_frame(f),
            Input::Depth(d) => pipeline.push_depth_frame(d),
            Input::Wheel(w) => pipeline.push_wheel_odometry(w),
        };
        if let Err(e) = r {
            // One bad message (a stamp out of order after a clock step) is skipped, not fatal.
            eprintln!("note: skipped: {e}");
        }
    }
    Ok(pipeline.finish())
}

fn report(
    built: &BuiltCloud,
    path: &Path,
    front: &str,
    out: &mut impl Write,
) -> anyhow::Result<()> {
    let s = &built.stats;
    let travelled = built.trajectory.last().map_or(0.0, |p| {
        let t = p.world_from_robot.translation;
        (t[0] * t[0] + t[1] * t[1] + t[2] * t[2]).sqrt()
    });
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
    let config = AnglesConfig {
        front_is_positive_x: match front {
            "+x" => true,
            "-x" => false,
            other => bail!("--front {other}: expected +x or -x"),
        },
        ..AnglesConfig::default()
    };
    match compute_angles(&built.points_in_world, &config) {
        Ok(r) => {
            for (name, a) in [
                ("approach", &r.approach),
                ("breakover", &r.breakover),
                ("departure", &r.departure),
            ] {
                match a {
                    Some(a) => writeln!(out, "{name:<10} {:6.2} deg", a.angle_rad.to_degrees())?,
                    None => writeln!(out, "{name:<10} not found")?,
                }
            }
        }
        Err(e) => writeln!(out, "angles: {e}")?,
    }
    Ok(())
}
