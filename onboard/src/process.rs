//! Processing a recorded run: recording in, cloud and angles out. This is what the service runs
//! after the robot stops, and what `passangle replay` can run on any run directory (complete or
//! marked `INCOMPLETE`).
//!
//! 1. Read `lidar.pcap` through the VLP-16 frame assembler (malformed packets are counted and
//!    skipped), `odometry.csv` and the depth frames of `depth/`.
//! 2. Put every stamp on one clock: seconds since the first lidar frame's host stamp (all streams
//!    are stamped on the host's wall clock by the recorder).
//! 3. Push everything, in time order, into [`Pipeline`]; `finish` gives the fused cloud in the
//!    robot frame of the first lidar frame (x forward, z up, ground at z = 0 below the robot).
//! 4. [`compute_angles`] on the cloud, with the zone of the start command; the side-view SVG.

use std::fs;
use std::path::Path;

use protocol::bounded::Text;
use protocol::radio::{MeasurementResult, ResultWarnings, Zone as WireZone};
use serde::Deserialize;

use crate::angles::{self, AnglesConfig, AnglesResult, Zone, compute_angles, side_view_svg};
use crate::cloud::Cloud;
use crate::pipeline::{DepthFrame, LidarFrame, Pipeline, PipelineConfig, WheelOdometry};
use crate::recorder::Recording;
use crate::service::{ProcessInput, Processed, Processor};
use crate::vlp16::source::{PACKET_BUF_LEN, PacketKind, PacketSource, PcapSource};
use crate::vlp16::{DecoderConfig, FrameAssembler};

/// `[processing]` of the onboard config.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields, default)]
pub struct ProcessConfig {
    /// `true` (default): the robot enters under the vehicle's front bumper and drives toward its
    /// rear, so in the cloud (robot frame, x forward) the vehicle's front is toward -x.
    /// `false`: the robot enters at the rear and the vehicle's front is toward +x.
    pub enter_at_front: bool,
    /// Points of the fused cloud a result needs (fewer: the run failed).
    pub min_cloud_points: usize,
    /// The point-cloud pipeline's settings (its own documented defaults).
    pub pipeline: PipelineConfig,
}

impl Default for ProcessConfig {
    fn default() -> Self {
        Self {
            enter_at_front: true,
            min_cloud_points: 1_000,
            pipeline: PipelineConfig::default(),
        }
    }
}

/// The service's default [`Processor`]: pipeline plus angle calculator.
#[derive(Debug, Clone)]
pub struct PipelineProcessor {
    /// Settings.
    pub config: ProcessConfig,
}

impl Processor for PipelineProcessor {
    fn process(&self, input: &ProcessInput) -> Result<Processed, String> {
        process_run(
            &input.run_dir,
            &self.config,
            input.params.zone,
            input.short_run,
        )
        .map(|(mut p, _)| {
            p.result.run_id = input.run_id;
            p.result.vehicle_id = input.params.vehicle_id.clone();
            p
        })
    }
}

/// Counts of what was read, for logs and `replay`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ReadCounts {
    /// Lidar frames pushed.
    pub lidar_frames: usize,
    /// Malformed lidar packets skipped.
    pub lidar_malformed: u64,
    /// Odometry lines read (a cut-short last line is not counted).
    pub odometry: usize,
    /// Depth frames read.
    pub depth_frames: usize,
}

enum Item {
    Wheel(WheelOdometry),
    Depth(DepthFrame),
    Lidar(LidarFrame),
}

impl Item {
    fn stamp_s(&self) -> f64 {
        match self {
            Item::Wheel(w) => w.stamp_s,
            Item::Depth(d) => d.stamp_s,
            Item::Lidar(l) => l.stamp_s,
        }
    }
}

/// Reads a run directory and builds its fused cloud (vehicle-agnostic: no angles yet).
pub fn build_cloud(dir: &Path, config: &ProcessConfig) -> Result<(Cloud, ReadCounts), String> {
    let rec = Recording::open(dir).map_err(|e| e.to_string())?;
    let mut counts = ReadCounts::default();
    let (frames, malformed) = read_lidar(&dir.join("lidar.pcap"))?;
    counts.lidar_malformed = malformed;
    counts.lidar_frames = frames.len();
    let Some(t0_ns) = frames.first().map(|(ns, _)| *ns) else {
        return Err(format!(
            "{}: no complete lidar frame",
            dir.join("lidar.pcap").display()
        ));
    };
    let secs = |wall_us: u64| (wall_us as f64 - t0_ns as f64 / 1e3) * 1e-6;
    let mut items: Vec<Item> = Vec::new();
    let (odometry, _) = rec.odometry().map_err(|e| e.to_string())?;
    counts.odometry = odometry.len();
    items.extend(
        odometry
            .iter()
            .map(|(wall_us, o)| Item::Wheel(WheelOdometry::from_mcu(o, secs(*wall_us)))),
    );
    let depth = read_depth(dir, &secs)?;
    counts.depth_frames = depth.len();
    items.extend(depth.into_iter().map(Item::Depth));
    items.extend(frames.into_iter().map(|(ns, f)| {
        Item::Lidar(LidarFrame::from_vlp16(
            &f,
            (ns as f64 - t0_ns as f64) * 1e-9,
        ))
    }));
    items.sort_by(|a, b| a.stamp_s().total_cmp(&b.stamp_s()));
    let mut pipeline =
        Pipeline::new(config.pipeline.clone()).map_err(|e| format!("pipeline config: {e}"))?;
    for item in items {
        // Items that break a source's ordering (duplicated stamps) are skipped, not fatal.
        let _ = match item {
            Item::Wheel(w) => pipeline.push_wheel_odometry(w),
            Item::Depth(d) => pipeline.push_depth_frame(d),
            Item::Lidar(l) => pipeline.push_lidar_frame(l),
        };
    }
    let cloud = pipeline.finish().to_cloud();
    if cloud.points_m.len() < config.min_cloud_points {
        return Err(format!(
            "the fused cloud has {} points, fewer than {}",
            cloud.points_m.len(),
            config.min_cloud_points
        ));
    }
    Ok((cloud, counts))
}

/// Reads a run directory and builds its cloud and angles. `Err` names what is missing or wrong.
pub fn process_run(
    dir: &Path,
    config: &ProcessConfig,
    zone: WireZone,
    short_run: bool,
) -> Result<(Processed, ReadCounts), String> {
    let rec = Recording::open(dir).map_err(|e| e.to_string())?;
    let (cloud, counts) = build_cloud(dir, config)?;
    let malformed = counts.lidar_malformed;
    let angles_config = AnglesConfig {
        front_is_positive_x: !config.enter_at_front,
        zone: match zone {
            WireZone::Tyre => Zone::Tyre,
            WireZone::Axle => Zone::Axle,
        },
        ..AnglesConfig::default()
    };
    let found =
        compute_angles(&cloud.points_m, &angles_config).map_err(|e| format!("angles: {e}"))?;
    let mut result = wire_result(&found, cloud.points_m.len());
    if short_run {
        result.warnings.insert(ResultWarnings::SHORT_RUN);
    }
    if malformed > 0 {
        result.warnings.insert(ResultWarnings::LIDAR_LOSS);
    }
    result.vehicle_id = Text::truncated(&rec.meta.vehicle_id);
    result.run_id = rec.meta.run_id;
    let svg = side_view_svg(&found);
    Ok((Processed { result, cloud, svg }, counts))
}

/// The wire result of an angle computation (a missing angle is NaN, and flagged LOW_SUPPORT).
pub fn wire_result(a: &AnglesResult, cloud_points: usize) -> MeasurementResult {
    let mut warnings = ResultWarnings::EMPTY;
    let angle =
        |f: &Option<angles::AngleFinding>| f.as_ref().map_or(f32::NAN, |f| f.angle_rad as f32);
    let support = |f: &Option<angles::AngleFinding>| {
        f.as_ref()
            .map_or(0, |f| f.support.min(usize::from(u16::MAX)) as u16)
    };
    if a.approach.is_none() || a.departure.is_none() || a.breakover.is_none() {
        warnings.insert(ResultWarnings::LOW_SUPPORT);
    }
    if a.tyres.len() < 4 {
        warnings.insert(ResultWarnings::MISSING_TYRE);
    }
    let rms = if a.tyres.is_empty() {
        0.0
    } else {
        (a.tyres
            .iter()
            .map(|t| t.residual_rms_m.powi(2))
            .sum::<f64>()
            / a.tyres.len() as f64)
            .sqrt()
    };
    if rms > 0.02 {
        warnings.insert(ResultWarnings::POOR_TYRE_FIT);
    }
    MeasurementResult {
        run_id: 0,
        vehicle_id: Text::default(),
        approach_rad: angle(&a.approach),
        departure_rad: angle(&a.departure),
        breakover_rad: angle(&a.breakover),
        ground_clearance_m: a
            .ground_clearance
            .as_ref()
            .map_or(f32::NAN, |c| c.height_m as f32),
        wheelbase_m: a.wheelbase_m as f32,
        track_m: a.track_m.map_or(f32::NAN, |t| t as f32),
        approach_support: support(&a.approach),
        departure_support: support(&a.departure),
        breakover_support: support(&a.breakover),
        tyre_fit_rms_m: rms as f32,
        warnings,
        cloud_points: u32::try_from(cloud_points).unwrap_or(u32::MAX),
        preview_chunks: 0,
    }
}

/// Complete lidar frames of a capture with their host stamps (ns), and the malformed count.
fn read_lidar(path: &Path) -> Result<(Vec<(u64, crate::vlp16::Frame)>, u64), String> {
    let mut source = PcapSource::open(path).map_err(|e| e.to_string())?;
    let mut assembler = FrameAssembler::new(DecoderConfig::default()).map_err(|e| e.to_string())?;
    let mut buf = [0u8; PACKET_BUF_LEN];
    let mut frames = Vec::new();
    // Ends at the end of the file, or at a cut-short last record after a crash (keeping what
    // came before it). Malformed packets are counted by the assembler and skipped.
    while let Ok(Some(meta)) = source.next_packet(&mut buf) {
        match meta.kind {
            PacketKind::Data => {
                let _ = assembler.push_data(&buf[..meta.len], meta.recv_host_ns);
            }
            PacketKind::Position => {
                let _ = assembler.push_position(&buf[..meta.len]);
            }
        }
        while let Some(f) = assembler.pop_frame() {
            if f.is_complete() {
                frames.push((f.start_host_ns, f));
            }
        }
    }
    Ok((frames, assembler.stats().malformed_data_total()))
}

/// Depth frames of `depth/index.csv` (a cut-short last line or a missing frame file ends it).
fn read_depth(dir: &Path, secs: &dyn Fn(u64) -> f64) -> Result<Vec<DepthFrame>, String> {
    let index = dir.join("depth/index.csv");
    let Ok(text) = fs::read_to_string(&index) else {
        return Ok(Vec::new());
    };
    let mut out = Vec::new();
    for line in text.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        if f.len() != 9 {
            break;
        }
        let num = |i: usize| f[i].parse::<f64>().ok();
        let (Ok(n), Ok(wall_us), Some(w), Some(h)) =
            (f[0].parse::<u32>(), f[1].parse::<u64>(), num(2), num(3))
        else {
            break;
        };
        let (Some(fx), Some(fy), Some(cx), Some(cy), Some(scale)) =
            (num(4), num(5), num(6), num(7), num(8))
        else {
            break;
        };
        let Ok(bytes) = fs::read(dir.join(format!("depth/{n:06}.z16"))) else {
            break;
        };
        let (width, height) = (w as usize, h as usize);
        if bytes.len() != 2 * width * height {
            return Err(format!(
                "{}: frame {n} has {} bytes, expected {}",
                index.display(),
                bytes.len(),
                2 * width * height
            ));
        }
        out.push(DepthFrame {
            stamp_s: secs(wall_us),
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
    Ok(out)
}
