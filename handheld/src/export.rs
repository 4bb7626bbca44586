//! `passangle export RUN_DIR --mcap OUT.mcap`: a recorded run as one MCAP file for Foxglove.
//!
//! Encoding: every message is JSON (`message_encoding = "json"`) with a JSON Schema
//! (`schema encoding = "jsonschema"`), byte arrays as base64 strings, the way Foxglove reads
//! its own schemas in JSON. JSON rather than protobuf: it needs no schema compiler or protobuf
//! runtime (serde_json is already here), each message is readable with any JSON tool, and the
//! cost, base64's 4/3 on the point and image bytes, is acceptable for a file that is viewed, not
//! streamed. Chunks are not compressed: the `mcap` crate's zstd and lz4 are C builds, left out.
//!
//! Channels (what the recording keeps, see `onboard::recorder`):
//! - `/lidar/points` (`foxglove.PointCloud`, frame `lidar`): one message per complete VLP-16
//!   frame of `lidar.pcap`, x, y, z (float32, metres), intensity and ring (uint8), stamped with
//!   the host time of the frame's first packet;
//! - `/cloud` (`foxglove.PointCloud`, frame `run`): the fused cloud of `cloud.ply` (the robot
//!   frame at the first lidar frame), one message at the first lidar frame's time;
//! - `/tf` (`foxglove.FrameTransform`): `odom` -> `base_link` for every wheel-odometry report
//!   (the recording keeps the wheel odometry, not the pipeline's fused trajectory), `odom` ->
//!   `run` (the odometry pose at the first lidar frame), `base_link` -> `lidar` and `base_link`
//!   -> `camera` (the mount of the run's `config.toml`, or the defaults when it does not parse);
//!   with `--rebuild`, the pipeline is run on the recording as `passangle replay` does and its
//!   fused trajectory is added as `run` -> `base_link_fused`, one per lidar frame;
//! - `/camera/depth` (`foxglove.RawImage`, `16UC1`, frame `camera`): every recorded depth frame
//!   (raw D435 units; `depth_scale_m` is in `/camera/depth_info`);
//! - `/camera/depth_info` (`passangle.DepthInfo`): intrinsics and depth scale per frame;
//! - `/odometry` (`passangle.WheelOdometry`): every `odometry.csv` line as recorded;
//! - `/result` (`passangle.Result`): `result.json`, when the run got that far.
//!
//! A channel without data (no depth frames, no result) is left out and named in the summary.

use std::collections::BTreeMap;
use std::fs::{self, File};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use cloud_io::read_cloud;
use onboard::config::OnboardConfig;
use onboard::process::{ProcessConfig, build_run};
use onboard::recorder::Recording;
use pipeline::PipelineConfig;
use pipeline::config::MountConfig;
use pipeline::geom::{M3, Pose};
use protocol::mcu::Odometry;
use serde_json::{Value, json};
use vlp16::source::{PACKET_BUF_LEN, PacketKind, PacketSource, PcapSource};
use vlp16::{DecoderConfig, Frame, FrameAssembler};

/// Arguments of `passangle export`.
#[derive(Debug, clap::Args)]
pub struct ExportArgs {
    /// The run directory (holds meta.json, lidar.pcap, odometry.csv, depth/, cloud.ply).
    pub run_dir: PathBuf,
    /// Write the run as MCAP (Foxglove schemas, JSON encoding) to this file.
    #[arg(long, value_name = "OUT.mcap")]
    pub mcap: PathBuf,
    /// Also run the pipeline on the recording (as `passangle replay`) and publish its fused
    /// trajectory (`run` -> `base_link_fused` on `/tf`).
    #[arg(long)]
    pub rebuild: bool,
    /// Pipeline config for `--rebuild` (TOML, as for `passangle replay`). The run's other
    /// processing settings (its lidar range offsets) stay. Absent: the settings the run was made
    /// with (its `config.toml`), or the defaults for a run without one.
    #[arg(long, requires = "rebuild")]
    pub pipeline_config: Option<PathBuf>,
}

/// Messages written per topic.
pub type TopicCounts = BTreeMap<&'static str, u64>;

/// Run the command: write the file, print the messages per topic.
pub fn run(args: &ExportArgs, out: &mut impl Write) -> anyhow::Result<()> {
    let rebuild = if args.rebuild {
        let (config, _) =
            crate::replay::rebuild_config(&args.run_dir, args.pipeline_config.as_deref())?;
        Some(config)
    } else {
        None
    };
    let (counts, notes) = export(&args.run_dir, &args.mcap, rebuild)?;
    for note in notes {
        writeln!(out, "note: {note}")?;
    }
    writeln!(out, "{}:", args.mcap.display())?;
    for (topic, n) in &counts {
        writeln!(out, "  {topic:<20} {n:>7} messages")?;
    }
    Ok(())
}

/// Writes the run in `run_dir` to `out_path`; returns the messages per topic and notes on what
/// was missing or assumed. `rebuild`: run the pipeline with these settings for the fused
/// trajectory.
pub fn export(
    run_dir: &Path,
    out_path: &Path,
    rebuild: Option<ProcessConfig>,
) -> anyhow::Result<(TopicCounts, Vec<String>)> {
    let recording = Recording::open(run_dir)?;
    let mut notes = Vec::new();
    if recording.incomplete {
        notes.push("the run is marked INCOMPLETE; exporting what was recorded".to_owned());
    }
    let file =
        File::create(out_path).with_context(|| format!("creating {}", out_path.display()))?;
    let options = mcap::WriteOptions::new()
        .compression(None)
        .profile("")
        .library(concat!("passangle ", env!("CARGO_PKG_VERSION")));
    let writer = options
        .create(BufWriter::new(file))
        .with_context(|| format!("{}: starting the MCAP file", out_path.display()))?;
    let mut mcap = Mcap {
        writer,
        channels: BTreeMap::new(),
        counts: TopicCounts::new(),
    };

    let mount = mounts(run_dir, &mut notes);
    let t0_ns = write_lidar(&mut mcap, run_dir)?;
    let (odometry, cut) = recording.odometry()?;
    if cut > 0 {
        notes.push("odometry.csv ends with a cut-short line (skipped)".to_owned());
    }
    write_odometry(&mut mcap, &odometry)?;
    let static_at = t0_ns.or_else(|| odometry.first().map(|(us, _)| us * 1000));
    if let Some(t0_ns) = static_at {
        let odom_from_run = odometry_pose_at(&odometry, t0_ns / 1000);
        for (parent, child, pose) in [
            ("odom", "run", odom_from_run),
            (
                "base_link",
                "lidar",
                Pose::from_xyz_rpy(mount.lidar_xyz_m, mount.lidar_rpy_rad),
            ),
            (
                "base_link",
                "camera",
                Pose::from_xyz_rpy(mount.camera_xyz_m, mount.camera_rpy_rad),
            ),
        ] {
            mcap.transform(t0_ns, parent, child, &pose)?;
        }
    }
    let depth = write_depth(&mut mcap, run_dir)?;
    if depth == 0 {
        notes.push("no depth frames recorded: /camera/depth left out".to_owned());
    }
    let cloud = run_dir.join("cloud.ply");
    if cloud.exists() {
        let (c, _) = read_cloud(&cloud)?;
        let points: Vec<[f32; 3]> = c
            .points_m
            .iter()
            .map(|p| [p[0] as f32, p[1] as f32, p[2] as f32])
            .collect();
        mcap.point_cloud("/cloud", static_at.unwrap_or(0), "run", &points, &[])?;
    } else {
        notes.push("no cloud.ply (the run was not processed): /cloud left out".to_owned());
    }
    if let Some(result) = &recording.result {
        let stamp = static_at.unwrap_or(0);
        let v = serde_json::to_value(result)?;
        mcap.message("/result", &RESULT, stamp, &v)?;
    } else {
        notes.push("no result.json: /result left out".to_owned());
    }
    if let Some(config) = rebuild {
        let (built, _) = build_run(run_dir, &config).map_err(anyhow::Error::msg)?;
        let t0 = t0_ns.context("--rebuild: no complete lidar frame")?;
        for t in &built.trajectory {
            let stamp = t0 + (t.stamp_s * 1e9).round() as u64;
            mcap.transform(stamp, "run", "base_link_fused", &t.world_from_robot)?;
        }
    } else {
        notes.push(
            "the trajectory on /tf is the wheel odometry the run recorded (`--rebuild` adds the \
             pipeline's fused trajectory)"
                .to_owned(),
        );
    }
    mcap.writer
        .finish()
        .with_context(|| format!("{}: finishing the MCAP file", out_path.display()))?;
    Ok((mcap.counts, notes))
}

/// The sensor mounts of the run's `config.toml`, or the defaults (with a note).
fn mounts(run_dir: &Path, notes: &mut Vec<String>) -> MountConfig {
    let config_path = run_dir.join("config.toml");
    let parsed = fs::read_to_string(&config_path)
        .map_err(|e| format!("{}: {e}", config_path.display()))
        .and_then(|text| OnboardConfig::parse(&text, &config_path).map_err(|e| e.to_string()));
    match parsed {
        Ok(c) => c.processing.pipeline.mounts,
        Err(e) => {
            let e = e.split_whitespace().collect::<Vec<_>>().join(" ");
            notes.push(format!("{e}; the sensor mounts on /tf are the defaults"));
            PipelineConfig::default().mounts
        }
    }
}

struct Mcap {
    writer: mcap::Writer<BufWriter<File>>,
    /// Topic -> (channel id, next sequence number).
    channels: BTreeMap<&'static str, (u16, u32)>,
    counts: TopicCounts,
}

/// A schema: its name and its JSON Schema.
struct Schema {
    name: &'static str,
    json: fn() -> Value,
}

impl Mcap {
    fn message(
        &mut self,
        topic: &'static str,
        schema: &Schema,
        stamp_ns: u64,
        v: &Value,
    ) -> anyhow::Result<()> {
        let (id, seq) = if let Some(c) = self.channels.get_mut(topic) {
            c.1 += 1;
            *c
        } else {
            let s = (schema.json)().to_string();
            let schema_id = self
                .writer
                .add_schema(schema.name, "jsonschema", s.as_bytes())?;
            let id = self
                .writer
                .add_channel(schema_id, topic, "json", &BTreeMap::new())?;
            self.channels.insert(topic, (id, 0));
            (id, 0)
        };
        let data = serde_json::to_vec(v)?;
        self.writer.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: id,
                sequence: seq,
                log_time: stamp_ns,
                publish_time: stamp_ns,
            },
            &data,
        )?;
        *self.counts.entry(topic).or_insert(0) += 1;
        Ok(())
    }

    fn transform(
        &mut self,
        stamp_ns: u64,
        parent: &str,
        child: &str,
        pose: &Pose,
    ) -> anyhow::Result<()> {
        let t = pose.translation;
        let q = quaternion(&pose.rotation);
        let v = json!({
            "timestamp": time(stamp_ns),
            "parent_frame_id": parent,
            "child_frame_id": child,
            "translation": {"x": t[0], "y": t[1], "z": t[2]},
            "rotation": {"x": q[0], "y": q[1], "z": q[2], "w": q[3]},
        });
        self.message("/tf", &FRAME_TRANSFORM, stamp_ns, &v)
    }

    /// A `foxglove.PointCloud` of float32 x, y, z and, when `extra` is not empty, one uint8
    /// intensity and one uint8 ring per point.
    fn point_cloud(
        &mut self,
        topic: &'static str,
        stamp_ns: u64,
        frame: &str,
        xyz: &[[f32; 3]],
        extra: &[[u8; 2]],
    ) -> anyhow::Result<()> {
        let stride = if extra.is_empty() { 12 } else { 16 };
        let mut data = Vec::with_capacity(xyz.len() * stride);
        for (i, p) in xyz.iter().enumerate() {
            for v in p {
                data.extend_from_slice(&v.to_le_bytes());
            }
            if let Some(e) = extra.get(i) {
                data.extend_from_slice(&[e[0], e[1], 0, 0]);
            }
        }
        // foxglove.NumericType: UINT8 = 1, FLOAT32 = 7.
        let mut fields = vec![
            json!({"name": "x", "offset": 0, "type": 7}),
            json!({"name": "y", "offset": 4, "type": 7}),
            json!({"name": "z", "offset": 8, "type": 7}),
        ];
        if !extra.is_empty() {
            fields.push(json!({"name": "intensity", "offset": 12, "type": 1}));
            fields.push(json!({"name": "ring", "offset": 13, "type": 1}));
        }
        let v = json!({
            "timestamp": time(stamp_ns),
            "frame_id": frame,
            "pose": identity_pose(),
            "point_stride": stride,
            "fields": fields,
            "data": base64(&data),
        });
        self.message(topic, &POINT_CLOUD, stamp_ns, &v)
    }
}

/// Every complete lidar frame; the host stamp of the first one (`None`: no complete frame).
fn write_lidar(mcap: &mut Mcap, run_dir: &Path) -> anyhow::Result<Option<u64>> {
    let pcap = run_dir.join("lidar.pcap");
    let mut source = PcapSource::open(&pcap)?;
    let mut assembler = FrameAssembler::new(DecoderConfig::default())?;
    let mut buf = [0u8; PACKET_BUF_LEN];
    let mut first = None;
    let mut emit = |mcap: &mut Mcap, f: &Frame| -> anyhow::Result<()> {
        if !f.is_complete() {
            return Ok(());
        }
        first.get_or_insert(f.start_host_ns);
        let xyz: Vec<[f32; 3]> = f.points.iter().map(|p| [p.x_m, p.y_m, p.z_m]).collect();
        let extra: Vec<[u8; 2]> = f.points.iter().map(|p| [p.intensity, p.ring]).collect();
        mcap.point_cloud("/lidar/points", f.start_host_ns, "lidar", &xyz, &extra)
    };
    while let Some(meta) = source
        .next_packet(&mut buf)
        .with_context(|| format!("{}", pcap.display()))?
    {
        if meta.kind == PacketKind::Position {
            let _ = assembler.push_position(&buf[..meta.len]);
            continue;
        }
        let _ = assembler.push_data(&buf[..meta.len], meta.recv_host_ns);
        while let Some(f) = assembler.pop_frame() {
            emit(mcap, &f)?;
        }
    }
    assembler.finish();
    while let Some(f) = assembler.pop_frame() {
        emit(mcap, &f)?;
    }
    Ok(first)
}

fn write_odometry(mcap: &mut Mcap, odometry: &[(u64, Odometry)]) -> anyhow::Result<()> {
    for (wall_us, o) in odometry {
        let stamp = wall_us * 1000;
        let v = json!({
            "timestamp": time(stamp),
            "mcu_stamp_us": o.stamp_us,
            "x_m": o.x_m, "y_m": o.y_m, "yaw_rad": o.yaw_rad,
            "vx_mps": o.vx_mps, "vy_mps": o.vy_mps, "wz_radps": o.wz_radps,
            "wheel_speed_radps": o.wheel_speed_radps,
        });
        mcap.message("/odometry", &WHEEL_ODOMETRY, stamp, &v)?;
        let pose = Pose::from_xyz_rpy(
            [f64::from(o.x_m), f64::from(o.y_m), 0.0],
            [0.0, 0.0, f64::from(o.yaw_rad)],
        );
        mcap.transform(stamp, "odom", "base_link", &pose)?;
    }
    Ok(())
}

/// The odometry pose of the last report at or before `wall_us` (the first report before them).
fn odometry_pose_at(odometry: &[(u64, Odometry)], wall_us: u64) -> Pose {
    let i = odometry.partition_point(|(t, _)| *t <= wall_us);
    odometry
        .get(i.saturating_sub(1))
        .map_or(Pose::IDENTITY, |(_, o)| {
            Pose::from_xyz_rpy(
                [f64::from(o.x_m), f64::from(o.y_m), 0.0],
                [0.0, 0.0, f64::from(o.yaw_rad)],
            )
        })
}

/// Every depth frame of `depth/index.csv`; the count. The index is read as the replay reads it:
/// a cut-short or malformed last line ends it; a frame file whose size disagrees with its line
/// is an error, found before the frame is read.
fn write_depth(mcap: &mut Mcap, run_dir: &Path) -> anyhow::Result<u64> {
    let index = run_dir.join("depth/index.csv");
    let Ok(text) = fs::read_to_string(&index) else {
        return Ok(0);
    };
    let mut n_frames = 0;
    for (i, line) in text.lines().enumerate().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let [n, wall_us, width, height, fx, fy, cx, cy, scale] = f[..] else {
            break;
        };
        let (Ok(n), Ok(wall_us), Ok(width), Ok(height)) = (
            n.parse::<u32>(),
            wall_us.parse::<u64>(),
            width.parse::<u16>(),
            height.parse::<u16>(),
        ) else {
            break;
        };
        let k: Vec<f64> = [fx, fy, cx, cy, scale]
            .iter()
            .map_while(|v| v.parse::<f64>().ok().filter(|v| v.is_finite()))
            .collect();
        let [fx, fy, cx, cy, depth_scale_m] = k[..] else {
            bail!(
                "{}: line {}: intrinsics and depth scale must be finite numbers",
                index.display(),
                i + 1
            );
        };
        let path = run_dir.join(format!("depth/{n:06}.z16"));
        let expected = 2 * u64::from(width) * u64::from(height);
        let size = fs::metadata(&path)
            .with_context(|| format!("{}: line {}", index.display(), i + 1))?
            .len();
        if size != expected {
            bail!(
                "{}: frame {n} ({}) has {size} bytes, expected {expected} for {width} x {height}",
                index.display(),
                path.display()
            );
        }
        let bytes = fs::read(&path).with_context(|| format!("reading {}", path.display()))?;
        let stamp = wall_us * 1000;
        let image = json!({
            "timestamp": time(stamp),
            "frame_id": "camera",
            "width": width,
            "height": height,
            "encoding": "16UC1",
            "step": 2 * u32::from(width),
            "data": base64(&bytes),
        });
        mcap.message("/camera/depth", &RAW_IMAGE, stamp, &image)?;
        let info = json!({
            "timestamp": time(stamp),
            "frame": n,
            "width": width, "height": height,
            "fx": fx, "fy": fy, "cx": cx, "cy": cy,
            "depth_scale_m": depth_scale_m,
        });
        mcap.message("/camera/depth_info", &DEPTH_INFO, stamp, &info)?;
        n_frames += 1;
    }
    Ok(n_frames)
}

fn time(ns: u64) -> Value {
    json!({"sec": ns / 1_000_000_000, "nsec": ns % 1_000_000_000})
}

fn identity_pose() -> Value {
    json!({"position": {"x": 0.0, "y": 0.0, "z": 0.0}, "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}})
}

/// Unit quaternion `[x, y, z, w]` of a rotation matrix (Shepperd's method).
fn quaternion(m: &M3) -> [f64; 4] {
    let trace = m[(0, 0)] + m[(1, 1)] + m[(2, 2)];
    let q = if trace > 0.0 {
        let s = (trace + 1.0).sqrt() * 2.0;
        [
            (m[(2, 1)] - m[(1, 2)]) / s,
            (m[(0, 2)] - m[(2, 0)]) / s,
            (m[(1, 0)] - m[(0, 1)]) / s,
            0.25 * s,
        ]
    } else if m[(0, 0)] > m[(1, 1)] && m[(0, 0)] > m[(2, 2)] {
        let s = (1.0 + m[(0, 0)] - m[(1, 1)] - m[(2, 2)]).sqrt() * 2.0;
        [
            0.25 * s,
            (m[(0, 1)] + m[(1, 0)]) / s,
            (m[(0, 2)] + m[(2, 0)]) / s,
            (m[(2, 1)] - m[(1, 2)]) / s,
        ]
    } else if m[(1, 1)] > m[(2, 2)] {
        let s = (1.0 + m[(1, 1)] - m[(0, 0)] - m[(2, 2)]).sqrt() * 2.0;
        [
            (m[(0, 1)] + m[(1, 0)]) / s,
            0.25 * s,
            (m[(1, 2)] + m[(2, 1)]) / s,
            (m[(0, 2)] - m[(2, 0)]) / s,
        ]
    } else {
        let s = (1.0 + m[(2, 2)] - m[(0, 0)] - m[(1, 1)]).sqrt() * 2.0;
        [
            (m[(0, 2)] + m[(2, 0)]) / s,
            (m[(1, 2)] + m[(2, 1)]) / s,
            0.25 * s,
            (m[(1, 0)] - m[(0, 1)]) / s,
        ]
    };
    let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    q.map(|v| v / n)
}

/// Standard base64 with padding (RFC 4648), as JSON carries Foxglove's `bytes` fields.
fn base64(bytes: &[u8]) -> String {
    const ABC: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for c in bytes.chunks(3) {
        let b = [
            c[0],
            c.get(1).copied().unwrap_or(0),
            c.get(2).copied().unwrap_or(0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            if k <= c.len() {
                out.push(char::from(ABC[((n >> (18 - 6 * k)) & 63) as usize]));
            } else {
                out.push('=');
            }
        }
    }
    out
}

fn time_schema() -> Value {
    json!({
        "type": "object",
        "title": "time",
        "properties": {
            "sec": {"type": "integer", "minimum": 0},
            "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999},
        },
    })
}

fn vector3_schema() -> Value {
    json!({"type": "object", "properties": {
        "x": {"type": "number"}, "y": {"type": "number"}, "z": {"type": "number"}}})
}

fn quaternion_schema() -> Value {
    json!({"type": "object", "properties": {
        "x": {"type": "number"}, "y": {"type": "number"}, "z": {"type": "number"},
        "w": {"type": "number"}}})
}

const POINT_CLOUD: Schema = Schema {
    name: "foxglove.PointCloud",
    json: || {
        json!({
            "title": "foxglove.PointCloud",
            "description": "A collection of N-dimensional points, which may contain additional fields with information like normals, intensity, etc.",
            "type": "object",
            "properties": {
                "timestamp": time_schema(),
                "frame_id": {"type": "string"},
                "pose": {"type": "object", "properties": {
                    "position": vector3_schema(), "orientation": quaternion_schema()}},
                "point_stride": {"type": "integer", "minimum": 0},
                "fields": {"type": "array", "items": {"type": "object", "properties": {
                    "name": {"type": "string"},
                    "offset": {"type": "integer", "minimum": 0},
                    "type": {"type": "integer", "description": "foxglove.NumericType: UINT8 = 1, FLOAT32 = 7"},
                }}},
                "data": {"type": "string", "contentEncoding": "base64"},
            },
        })
    },
};

const FRAME_TRANSFORM: Schema = Schema {
    name: "foxglove.FrameTransform",
    json: || {
        json!({
            "title": "foxglove.FrameTransform",
            "description": "A transform between two reference frames in 3D space",
            "type": "object",
            "properties": {
                "timestamp": time_schema(),
                "parent_frame_id": {"type": "string"},
                "child_frame_id": {"type": "string"},
                "translation": vector3_schema(),
                "rotation": quaternion_schema(),
            },
        })
    },
};

const RAW_IMAGE: Schema = Schema {
    name: "foxglove.RawImage",
    json: || {
        json!({
            "title": "foxglove.RawImage",
            "description": "A raw image",
            "type": "object",
            "properties": {
                "timestamp": time_schema(),
                "frame_id": {"type": "string"},
                "width": {"type": "integer", "minimum": 0},
                "height": {"type": "integer", "minimum": 0},
                "encoding": {"type": "string"},
                "step": {"type": "integer", "minimum": 0},
                "data": {"type": "string", "contentEncoding": "base64"},
            },
        })
    },
};

const DEPTH_INFO: Schema = Schema {
    name: "passangle.DepthInfo",
    json: || {
        json!({
            "title": "passangle.DepthInfo",
            "description": "A recorded depth frame's pinhole intrinsics (pixels) and depth scale (metres per raw unit)",
            "type": "object",
            "properties": {
                "timestamp": time_schema(),
                "frame": {"type": "integer"},
                "width": {"type": "integer"}, "height": {"type": "integer"},
                "fx": {"type": "number"}, "fy": {"type": "number"},
                "cx": {"type": "number"}, "cy": {"type": "number"},
                "depth_scale_m": {"type": "number"},
            },
        })
    },
};

const WHEEL_ODOMETRY: Schema = Schema {
    name: "passangle.WheelOdometry",
    json: || {
        json!({
            "title": "passangle.WheelOdometry",
            "description": "A firmware odometry report as recorded in odometry.csv (timestamp: host arrival)",
            "type": "object",
            "properties": {
                "timestamp": time_schema(),
                "mcu_stamp_us": {"type": "integer"},
                "x_m": {"type": "number"}, "y_m": {"type": "number"},
                "yaw_rad": {"type": "number"},
                "vx_mps": {"type": "number"}, "vy_mps": {"type": "number"},
                "wz_radps": {"type": "number"},
                "wheel_speed_radps": {"type": "array", "items": {"type": "number"},
                    "minItems": 4, "maxItems": 4},
            },
        })
    },
};

const RESULT: Schema = Schema {
    name: "passangle.Result",
    json: || {
        json!({
            "title": "passangle.Result",
            "description": "The run's result.json (onboard::recorder::ResultRecord)",
            "type": "object",
        })
    },
};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc_4648_vectors() {
        for (input, expected) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(base64(input.as_bytes()), expected);
        }
    }

    #[test]
    fn quaternions_of_rotations() {
        for rpy in [
            [0.0, 0.0, 0.0],
            [0.0, 0.0, -std::f64::consts::FRAC_PI_2],
            [0.3, -0.2, 2.9],
            [3.1, 0.1, -3.0],
        ] {
            let m = Pose::from_xyz_rpy([0.0; 3], rpy).rotation;
            let [x, y, z, w] = quaternion(&m);
            // Back to a matrix: each entry matches.
            let back = [
                [
                    1.0 - 2.0 * (y * y + z * z),
                    2.0 * (x * y - w * z),
                    2.0 * (x * z + w * y),
                ],
                [
                    2.0 * (x * y + w * z),
                    1.0 - 2.0 * (x * x + z * z),
                    2.0 * (y * z - w * x),
                ],
                [
                    2.0 * (x * z - w * y),
                    2.0 * (y * z + w * x),
                    1.0 - 2.0 * (x * x + y * y),
                ],
            ];
            for i in 0..3 {
                for j in 0..3 {
                    assert!(
                        (back[i][j] - m[(i, j)]).abs() < 1e-12,
                        "{rpy:?}: {back:?} vs {m:?}"
                    );
                }
            }
        }
    }
}
