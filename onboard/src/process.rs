//! Processing a run: sensor streams in, cloud and angles out.
//!
//! [`RunBuilder`] is the one path from recorded data to the fused cloud. The service feeds it
//! during the drive, item by item as the recorder writes them ([`Processor::start_live`]), so
//! that when the robot stops only the last [`REORDER_WINDOW_S`], the filter and the angles are
//! left; [`build_run`] feeds it a run directory (complete or marked `INCOMPLETE`), which is
//! what `passangle replay` and the service's fallback (live processing fell behind) run:
//! 1. `lidar.pcap` through the VLP-16 frame assembler (malformed packets are counted and
//!    skipped), `odometry.csv` and the depth frames of `depth/`.
//! 2. Every stamp on one clock: seconds since the first complete lidar frame's host stamp (the
//!    recorder stamps every stream on the host's wall clock; odometry reports are placed at their
//!    MCU stamps mapped onto it, [`McuClockMap`]).
//! 3. Everything, in time order, into [`Pipeline`]; `finish` gives the fused cloud in the robot
//!    frame of the first lidar frame (x forward, z up, ground at z = 0 below the robot).
//! 4. [`compute_angles`] on the cloud with the robot's path (its coverage check), the zone of the
//!    start command; the side-view SVG.
//!
//! The two feeds give the same cloud (tests/tests/live_processing.rs).

use std::fs;
use std::path::{Path, PathBuf};

use protocol::bounded::Text;
use protocol::mcu::Odometry;
use protocol::radio::{
    Absence, MeasurementResult, ResultWarnings, StartMeasurement, Zone as WireZone,
};
use serde::Deserialize;

use crate::mcu_clock::McuClockMap;
use crate::recorder::{Intrinsics, Recording};
use crate::scan_file::ScanRecord;
use crate::signed::Signer;
use angles::profiles::{ProfileResult, Standard, compute_profiles};
use angles::{self, AnglesConfig, AnglesResult, Zone, compute_angles, side_view_svg};
use cloud_io::Cloud;
use link::record::{ProfileQuantityRecord, ProfileRecord};
use pipeline::geom::V3;
use pipeline::{BuiltCloud, DepthImage, LidarFrame, Pipeline, PipelineConfig, WheelOdometry};
use vlp16::source::{PACKET_BUF_LEN, PacketKind, PacketSource, PcapSource};
use vlp16::{DecoderConfig, FrameAssembler};

/// What processing a run gets.
#[derive(Debug, Clone, PartialEq)]
pub struct ProcessInput {
    /// The run directory (streams flushed).
    pub run_dir: PathBuf,
    /// The run.
    pub run_id: u32,
    /// Its parameters.
    pub params: StartMeasurement,
    /// Distance driven, m.
    pub travelled_m: f32,
    /// The drive ended early.
    pub short_run: bool,
    /// Signs `cloud.ply`, `side_view.svg` and `scan.toml` (`signing.key-file`).
    pub signer: Signer,
}

/// What processing a run produces.
#[derive(Debug, Clone, PartialEq)]
pub struct Processed {
    /// The result (`preview_chunks` is set when offered).
    pub result: MeasurementResult,
    /// The cloud, vehicle frame, metres.
    pub cloud: Cloud,
    /// The side-view report.
    pub svg: String,
    /// The angle calculator's whole finding (witnesses, tyres, ground), where the processor
    /// ran it: for reports and the simulator's checks; not sent or recorded.
    pub angles: Option<Box<AnglesResult>>,
    /// Every configured standard's quantities from the same cloud, for `result.json` (not sent
    /// over the radio).
    pub profiles: Vec<ProfileRecord>,
    /// What the calculator had besides the cloud (the lidar's path, the trajectory's error), for
    /// `scan.toml`; `None` where the processor gave it none.
    pub scan: Option<ScanRecord>,
}

/// Builds the cloud and computes the angles of a recorded run (the service's default is
/// [`PipelineProcessor`]).
pub trait Processor: Send + Sync {
    /// Processes one run from its recording; `Err` says why it failed, for the operator.
    fn process(&self, input: &ProcessInput) -> Result<Processed, String>;

    /// Starts processing a run while it is recorded (`None`: this processor works on recordings
    /// only). The service feeds it on a worker thread with exactly what the recorder writes.
    fn start_live(&self) -> Option<Box<dyn LiveRun>> {
        None
    }
}

/// One sensor item of a run, as the recorder writes it (the same values and stamps, so a live
/// run and the replay of its recording see the same data).
#[derive(Debug, Clone, PartialEq)]
pub enum SensorItem {
    /// A lidar UDP payload; `wall_ns` is rounded down to the recording's whole microseconds.
    Lidar {
        /// Host wall clock, ns since the Unix epoch.
        wall_ns: u64,
        /// The payload.
        payload: Vec<u8>,
        /// From the position port.
        position: bool,
    },
    /// A wheel odometry report.
    Odometry {
        /// Host wall clock at reception, us since the Unix epoch.
        wall_us: u64,
        /// The report.
        odometry: Odometry,
    },
    /// A depth frame (only those the recorder keeps: every `camera.record-every`-th).
    Depth {
        /// Host wall clock, us since the Unix epoch.
        wall_us: u64,
        /// Width, pixels.
        width: u16,
        /// Height, pixels.
        height: u16,
        /// Row-major Z16.
        depth: Vec<u16>,
        /// The camera's intrinsics from the config.
        intrinsics: Intrinsics,
    },
}

/// A run processed while it is recorded (see [`Processor::start_live`]).
pub trait LiveRun: Send {
    /// The next item, in arrival order.
    fn push(&mut self, item: SensorItem);
    /// The robot is at rest and the recording closed: the result.
    fn finish(self: Box<Self>, input: &ProcessInput) -> Result<Processed, String>;
}

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
    /// `true` (default): build the cloud during the drive, from the same data the recorder
    /// writes, so only the last moments, the filter and the angles are left when the robot stops.
    /// If the processing falls behind the sensors, the run is processed from its recording after
    /// the stop instead (with a warning in the log). `false`: always from the recording.
    pub live: bool,
    /// The point-cloud pipeline's settings (its own documented defaults).
    pub pipeline: PipelineConfig,
    /// The standards whose profiles `result.json` carries (`standards = ["cfr", "eu"]`; default
    /// all; `[]`: none). Each distinct zone and band costs one more calculator run (up to four
    /// for all six).
    #[serde(deserialize_with = "standards_from_ids")]
    pub standards: Vec<Standard>,
    /// Each VLP-16 laser's range offset, metres, by laser id (the firing order: -15, 1, -13, 3,
    /// ... 15 degrees), taken off its every return when the run's frames are decoded for the
    /// cloud (the recording keeps the raw packets). From `passangle lidar CAPTURE --calibrate`
    /// (docs/operator/run.md, "Calibrating the lidar's range"); zero (the default): the factory's
    /// calibration as it is. Each within +-0.1 m.
    pub lidar_range_offsets_m: [f32; 16],
    /// The wheels' distance scale on this floor: true distance over the distance the wheels
    /// report, applied to every wheel report when a run is built (the recording keeps the raw
    /// reports). From `passangle wheels RUN_DIR` on a calibration drive (docs/operator/run.md,
    /// "Calibrating the wheels' distance"); 1 (the default): the wheels as they report. Within
    /// [`pipeline::fusion::WHEEL_SCALE_RANGE`].
    pub wheel_distance_scale: f64,
}

/// `standards`: ids as `passangle angles --standard` takes them (`all` allowed).
fn standards_from_ids<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Vec<Standard>, D::Error> {
    let ids = Vec::<String>::deserialize(d)?;
    if ids.is_empty() {
        return Ok(Vec::new());
    }
    Standard::parse_list(&ids.join(",")).map_err(serde::de::Error::custom)
}

impl Default for ProcessConfig {
    fn default() -> Self {
        Self {
            enter_at_front: true,
            min_cloud_points: 1_000,
            live: true,
            pipeline: PipelineConfig::default(),
            standards: Standard::ALL.to_vec(),
            lidar_range_offsets_m: [0.0; 16],
            wheel_distance_scale: 1.0,
        }
    }
}

impl ProcessConfig {
    /// The `[processing]` settings a run was made with: the `config.toml` the recorder keeps in
    /// every run directory (the service's whole configuration), or `None` if the run has none.
    /// An offline rebuild (`passangle replay`, `export --rebuild`) starts from these, so that
    /// it reproduces the run: the pipeline's defaults can differ from what the robot ran (the
    /// demo's robot keeps the D435's points out of its cloud, its camera mounted elsewhere than
    /// the default mount says).
    ///
    /// # Errors
    /// The file exists but cannot be read or is not a valid onboard configuration (named, with
    /// where).
    pub fn of_run(dir: &Path) -> Result<Option<Self>, String> {
        let path = dir.join("config.toml");
        let text = match fs::read_to_string(&path) {
            Ok(text) => text,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(format!("reading {}: {e}", path.display())),
        };
        crate::config::OnboardConfig::parse(&text, &path)
            .map(|c| Some(c.processing))
            .map_err(|e| e.to_string())
    }
}

/// The profiles as `result.json` records them.
pub fn profile_records(profiles: &[ProfileResult]) -> Vec<ProfileRecord> {
    profiles
        .iter()
        .map(|p| ProfileRecord {
            standard: p.standard.id().to_owned(),
            title: p.standard.title().to_owned(),
            citation: p.standard.citation().to_owned(),
            notes: p.notes.iter().map(|n| (*n).to_owned()).collect(),
            quantities: p
                .quantities
                .iter()
                .map(|q| {
                    let (value, u) = q.measure.value_u().unzip();
                    ProfileQuantityRecord {
                        id: q.kind.id().to_owned(),
                        name: q.name.to_owned(),
                        unit: q.kind.unit().symbol().to_owned(),
                        value,
                        u,
                        not_measured: q.measure.reason().map(str::to_owned),
                    }
                })
                .collect(),
        })
        .collect()
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

    fn start_live(&self) -> Option<Box<dyn LiveRun>> {
        if !self.config.live {
            return None;
        }
        match RunBuilder::new(&self.config) {
            Ok(builder) => Some(Box::new(LivePipeline {
                builder,
                config: self.config.clone(),
            })),
            Err(e) => {
                tracing::error!("live processing not started: {e}");
                None
            }
        }
    }
}

/// [`PipelineProcessor`]'s live run: a [`RunBuilder`] fed as the data arrives.
struct LivePipeline {
    builder: RunBuilder,
    config: ProcessConfig,
}

impl LiveRun for LivePipeline {
    fn push(&mut self, item: SensorItem) {
        match item {
            SensorItem::Lidar {
                wall_ns,
                payload,
                position,
            } => self.builder.push_lidar_packet(wall_ns, &payload, position),
            SensorItem::Odometry { wall_us, odometry } => {
                self.builder.push_odometry(wall_us, &odometry);
            }
            SensorItem::Depth {
                wall_us,
                width,
                height,
                depth,
                intrinsics,
            } => self
                .builder
                .push_depth(wall_us, width, height, depth, &intrinsics),
        }
        self.builder.release(REORDER_WINDOW_S);
    }

    fn finish(self: Box<Self>, input: &ProcessInput) -> Result<Processed, String> {
        let min_points = self.builder.min_cloud_points;
        let (built, counts) = self.builder.finish_built()?;
        let (cloud, scan) = cloud_and_path(built, min_points, &self.config.pipeline)?;
        let mut p = angles_of(
            cloud,
            scan,
            counts,
            &self.config,
            input.params.zone,
            input.short_run,
        )?;
        p.result.run_id = input.run_id;
        p.result.vehicle_id = input.params.vehicle_id.clone();
        Ok(p)
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
    /// `odometry.csv` ended in a cut-short line (a crash while writing it), skipped.
    pub odometry_cut_short: bool,
    /// `lidar.pcap` ended inside its last record (a crash while recording); the packets before
    /// it were used. A corrupt record is an error of [`build_run`] instead.
    pub lidar_cut_short: bool,
    /// Depth frames read.
    pub depth_frames: usize,
    /// Items the pipeline refused because they broke their stream's time order (a clock step);
    /// skipped, the run goes on.
    pub out_of_order: usize,
    /// Times the MCU's clock went backwards (it rebooted) and its map onto the host clock
    /// started over ([`McuClockMap`]).
    pub mcu_clock_resets: u32,
}

/// How long (in stamp time) [`RunBuilder::release`] holds items back before handing them to the
/// pipeline in stamp order. The streams reach the service slightly out of order (a lidar frame is
/// stamped at its first firing but complete one revolution later: 0.1 s at 10 Hz, 0.2 s at 5 Hz,
/// plus the loop's latency); a replay sorts the whole recording. Holding items this long makes the
/// live order the replay order, so live processing and `passangle replay` give the same cloud.
pub const REORDER_WINDOW_S: f64 = 0.5;

enum Item {
    Wheel(WheelOdometry),
    Depth(DepthImage),
    Lidar(LidarFrame),
}

/// An item on the host's wall clock, before the run's time origin is known.
enum Timed {
    Wheel(u64, Odometry),
    Depth(u64, DepthImage),
    Lidar(u64, vlp16::Frame),
}

impl Timed {
    /// Position among items of equal stamp (a replay's stable sort keeps wheel, depth, lidar).
    fn rank(&self) -> u8 {
        match self {
            Timed::Wheel(..) => 0,
            Timed::Depth(..) => 1,
            Timed::Lidar(..) => 2,
        }
    }

    /// On the pipeline's clock: seconds since `t0_ns`, the first complete lidar frame's stamp.
    fn on_clock(self, t0_ns: u64) -> Item {
        let secs = |wall_us: u64| (wall_us as f64 - t0_ns as f64 / 1e3) * 1e-6;
        match self {
            Timed::Wheel(wall_us, o) => Item::Wheel(WheelOdometry::from_mcu(&o, secs(wall_us))),
            Timed::Depth(wall_us, mut d) => {
                d.stamp_s = secs(wall_us);
                Item::Depth(d)
            }
            Timed::Lidar(ns, f) => Item::Lidar(crate::frames::lidar_frame(
                &f,
                (ns as f64 - t0_ns as f64) * 1e-9,
            )),
        }
    }
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

/// An item waiting in the reorder heap; the heap's top is the earliest.
struct Held {
    stamp_s: f64,
    rank: u8,
    seq: u64,
    item: Item,
}

impl Held {
    fn key(&self) -> (f64, u8, u64) {
        (self.stamp_s, self.rank, self.seq)
    }
}

impl PartialEq for Held {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other).is_eq()
    }
}
impl Eq for Held {}
impl PartialOrd for Held {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Held {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        let (a, b) = (self.key(), other.key());
        // Reversed: `BinaryHeap` is a max-heap.
        b.0.total_cmp(&a.0).then(b.1.cmp(&a.1)).then(b.2.cmp(&a.2))
    }
}

/// Builds a run's cloud from its sensor streams, pushed as the recorder stores them (host wall
/// clock stamps, the lidar's raw UDP payloads). The same code serves a recording read back
/// ([`build_cloud`]: everything pushed, then [`RunBuilder::finish`]) and the live run in the
/// service (items pushed as they arrive, [`RunBuilder::release`] after each, so the pipeline works
/// during the drive and only the last [`REORDER_WINDOW_S`] and the filter are left at the stop).
///
/// Time: every stamp becomes seconds since the first complete lidar frame's host stamp; until
/// that frame is seen, items wait with their wall stamps. Items reach the pipeline in stamp order
/// (ties: wheel, depth, lidar, then arrival), exactly the order of a sorted replay.
pub struct RunBuilder {
    pipeline: Pipeline,
    wheel_distance_scale: f64,
    /// With `Some`, released items go here instead of into the pipeline ([`read_streams`]).
    collected: Option<Collected>,
    min_cloud_points: usize,
    assembler: FrameAssembler,
    t0_ns: Option<u64>,
    waiting: Vec<(Timed, u64)>,
    held: std::collections::BinaryHeap<Held>,
    newest_s: f64,
    released_s: f64,
    seq: u64,
    counts: ReadCounts,
    mcu_clock: McuClockMap,
}

impl std::fmt::Debug for RunBuilder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RunBuilder")
            .field("t0_ns", &self.t0_ns)
            .field("held", &self.held.len())
            .field("counts", &self.counts)
            .finish_non_exhaustive()
    }
}

impl RunBuilder {
    /// A builder with the run's processing settings; `Err` names a bad pipeline setting.
    pub fn new(config: &ProcessConfig) -> Result<Self, String> {
        Ok(Self {
            pipeline: Pipeline::new(config.pipeline.clone())
                .map_err(|e| format!("pipeline config: {e}"))?,
            wheel_distance_scale: config.wheel_distance_scale,
            collected: None,
            min_cloud_points: config.min_cloud_points,
            assembler: FrameAssembler::new(DecoderConfig {
                range_offsets_m: config.lidar_range_offsets_m,
                ..DecoderConfig::default()
            })
            .map_err(|e| format!("processing.lidar-range-offsets-m: {e}"))?,
            t0_ns: None,
            waiting: Vec::new(),
            held: std::collections::BinaryHeap::new(),
            newest_s: f64::NEG_INFINITY,
            released_s: f64::NEG_INFINITY,
            seq: 0,
            counts: ReadCounts::default(),
            mcu_clock: McuClockMap::new(),
        })
    }

    /// What has been read so far.
    pub fn counts(&self) -> ReadCounts {
        ReadCounts {
            lidar_malformed: self.assembler.stats().malformed_data_total(),
            mcu_clock_resets: self.mcu_clock.resets(),
            ..self.counts
        }
    }

    /// Lidar frames the pipeline has processed so far.
    pub fn frames_processed(&self) -> usize {
        self.pipeline.trajectory().len()
    }

    /// A lidar UDP payload (data or position port) with its host stamp, ns since the Unix epoch.
    /// Use the recording's resolution (whole microseconds) for results equal to a replay's.
    /// Malformed packets are counted and skipped.
    pub fn push_lidar_packet(&mut self, wall_ns: u64, payload: &[u8], position: bool) {
        if position {
            let _ = self.assembler.push_position(payload);
            return;
        }
        let _ = self.assembler.push_data(payload, wall_ns);
        while let Some(f) = self.assembler.pop_frame() {
            if f.is_complete() {
                self.counts.lidar_frames += 1;
                if self.t0_ns.is_none() {
                    self.t0_ns = Some(f.start_host_ns);
                }
                self.hold(Timed::Lidar(f.start_host_ns, f));
            }
        }
    }

    /// A wheel odometry report with its host arrival time, us since the Unix epoch. It is placed
    /// on the host clock at its MCU stamp, not its arrival ([`McuClockMap`]).
    pub fn push_odometry(&mut self, wall_us: u64, odometry: &Odometry) {
        self.counts.odometry += 1;
        let measured_us = self.mcu_clock.map(wall_us, odometry.stamp_us);
        self.hold(Timed::Wheel(measured_us, *odometry));
    }

    /// A depth frame (Z16, row-major) with its host stamp, us since the Unix epoch.
    pub fn push_depth(
        &mut self,
        wall_us: u64,
        width: u16,
        height: u16,
        depth: Vec<u16>,
        k: &Intrinsics,
    ) {
        self.counts.depth_frames += 1;
        self.hold(Timed::Depth(
            wall_us,
            DepthImage {
                stamp_s: 0.0,
                width: usize::from(width),
                height: usize::from(height),
                intrinsics_px: [k.fx, k.fy, k.cx, k.cy].map(f64::from),
                depth_scale_m: f64::from(k.depth_scale_m),
                depth,
            },
        ));
    }

    fn hold(&mut self, item: Timed) {
        self.seq += 1;
        self.waiting.push((item, self.seq));
        let Some(t0_ns) = self.t0_ns else { return };
        for (item, seq) in self.waiting.drain(..) {
            let rank = item.rank();
            let item = item.on_clock(t0_ns);
            let stamp_s = item.stamp_s();
            self.newest_s = self.newest_s.max(stamp_s);
            self.held.push(Held {
                stamp_s,
                rank,
                seq,
                item,
            });
        }
    }

    /// Hands the pipeline every held item older than the newest stamp minus `window_s`.
    pub fn release(&mut self, window_s: f64) {
        let until_s = self.newest_s - window_s;
        while self.held.peek().is_some_and(|h| h.stamp_s < until_s) {
            let Some(h) = self.held.pop() else { break };
            self.released_s = self.released_s.max(h.stamp_s);
            if let Some(c) = &mut self.collected {
                match h.item {
                    Item::Wheel(w) => c.wheel.push(w),
                    Item::Lidar(l) => {
                        let t0_us = self.t0_ns.unwrap_or(0) as f64 * 1e-3;
                        let wall_us = l.stamp_s * 1e6 + t0_us;
                        let driving = c
                            .skip_us
                            .is_some_and(|(a, b)| wall_us > a as f64 && wall_us < b as f64);
                        if !driving {
                            c.lidar.push(l);
                        }
                    }
                    Item::Depth(_) => {}
                }
                continue;
            }
            // Items that break a source's ordering (a clock step) are counted and skipped.
            let pushed = match h.item {
                Item::Wheel(w) => self
                    .pipeline
                    .push_wheel_odometry(w.scaled(self.wheel_distance_scale)),
                Item::Depth(d) => self.pipeline.push_depth_frame(d),
                Item::Lidar(l) => self.pipeline.push_lidar_frame(l),
            };
            if let Err(e) = pushed {
                self.counts.out_of_order += 1;
                tracing::debug!("run builder: skipped: {e}");
            }
        }
    }

    /// Everything left through the pipeline; the fused, filtered cloud. `Err` if there was no
    /// complete lidar frame or the cloud is too small.
    pub fn finish(self) -> Result<(Cloud, ReadCounts), String> {
        let min_points = self.min_cloud_points;
        let (built, counts) = self.finish_built()?;
        Ok((
            cloud_and_path(built, min_points, &PipelineConfig::default())?.0,
            counts,
        ))
    }

    /// Everything left through the pipeline; the pipeline's whole result (cloud, trajectory,
    /// counters), whatever its size. `Err` if there was no complete lidar frame.
    pub fn finish_built(mut self) -> Result<(BuiltCloud, ReadCounts), String> {
        if self.t0_ns.is_none() {
            return Err("no complete lidar frame".into());
        }
        self.release(f64::NEG_INFINITY);
        let counts = self.counts();
        Ok((self.pipeline.finish(), counts))
    }
}

/// The cloud (if it has at least `min_points`) and what the angle calculator needs to know of
/// the scan.
fn cloud_and_path(
    built: BuiltCloud,
    min_points: usize,
    pipeline: &PipelineConfig,
) -> Result<(Cloud, Scan), String> {
    let x_sigma_per_m = built.x_sigma_per_m(&pipeline.fusion);
    let path = built.lidar_path(pipeline.mounts.lidar_xyz_m.into());
    if built.points_in_world.len() < min_points {
        return Err(format!(
            "the fused cloud has {} points, fewer than {min_points}",
            built.points_in_world.len(),
        ));
    }
    let cloud = Cloud {
        points_m: built.points_in_world.into_iter().map(Into::into).collect(),
    };
    Ok((
        cloud,
        Scan {
            path,
            x_sigma_per_m,
        },
    ))
}

/// What the angle calculator needs to know of a scan besides its cloud.
struct Scan {
    /// The lidar's path in the cloud (its optical centre along the trajectory), for the coverage
    /// and view checks.
    path: Vec<V3>,
    /// The trajectory's stated error along x per metre, for the uncertainty budget.
    x_sigma_per_m: f64,
}

/// Reads a run directory and builds its fused cloud (vehicle-agnostic: no angles yet).
pub fn build_cloud(dir: &Path, config: &ProcessConfig) -> Result<(Cloud, ReadCounts), String> {
    let (built, counts) = build_run(dir, config)?;
    Ok((
        cloud_and_path(built, config.min_cloud_points, &config.pipeline)?.0,
        counts,
    ))
}

/// A run directory's raw wheel reports (without `wheel-distance-scale`) and its lidar frames
/// while parked, on the clock a [`RunBuilder`] puts them on, in the order it releases them: what
/// a calibration drive gives `crate::wheel_calibration::calibrate_wheels`. The frames from
/// [`SKIP_MARGIN_US`] after the wheels start moving to that before they stop are left out, so
/// that memory holds the parked captures, not the drive (a frame holds about 29,000 points).
pub fn read_streams(
    dir: &Path,
    config: &ProcessConfig,
) -> Result<(Vec<LidarFrame>, Vec<WheelOdometry>), String> {
    let odometry = read_odometry(dir)?;
    let mut builder = RunBuilder::new(config)?;
    let mut collected = Collected::default();
    let moving = |o: &&(u64, Odometry)| {
        crate::wheel_calibration::moving(f64::from(o.1.vx_mps), f64::from(o.1.vy_mps))
    };
    if let (Some(first), Some(last)) = (
        odometry.0.iter().find(moving),
        odometry.0.iter().rev().find(moving),
    ) {
        collected.skip_us = Some((
            first.0 + SKIP_MARGIN_US,
            last.0.saturating_sub(SKIP_MARGIN_US),
        ));
    }
    builder.collected = Some(collected);
    feed_recording(dir, &mut builder, &odometry)?;
    if builder.t0_ns.is_none() {
        return Err(format!(
            "{}: no complete lidar frame",
            dir.join("lidar.pcap").display()
        ));
    }
    builder.release(f64::NEG_INFINITY);
    let c = builder.collected.take().unwrap_or_default();
    Ok((c.lidar, c.wheel))
}

/// What [`read_streams`] collects from a [`RunBuilder`]: its lidar frames, except those whose
/// host wall time (us) lies within `skip_us` (the drive), and its raw wheel reports.
#[derive(Default)]
struct Collected {
    lidar: Vec<LidarFrame>,
    wheel: Vec<WheelOdometry>,
    skip_us: Option<(u64, u64)>,
}

/// How far into the drive [`read_streams`] still keeps lidar frames, us: the wheel reports'
/// arrival jitter (tens of milliseconds) and a frame's length, with room to spare; the
/// calibration itself takes only the frames that end before the wheels move.
pub const SKIP_MARGIN_US: u64 = 500_000;

/// A run directory's wheel reports with their arrival times, and how many lines were cut
/// short (`Recording::odometry`).
fn read_odometry(dir: &Path) -> Result<(Vec<(u64, Odometry)>, usize), String> {
    Recording::open(dir)
        .and_then(|rec| rec.odometry())
        .map_err(|e| e.to_string())
}

/// Feeds a run directory's lidar packets and its wheel reports (`read_odometry`) into
/// `builder`.
fn feed_recording(
    dir: &Path,
    builder: &mut RunBuilder,
    (odometry, cut): &(Vec<(u64, Odometry)>, usize),
) -> Result<(), String> {
    let pcap = dir.join("lidar.pcap");
    let mut source = PcapSource::open(&pcap).map_err(|e| e.to_string())?;
    let mut buf = [0u8; PACKET_BUF_LEN];
    // Ends at the end of the file, or at a cut-short last record after a crash (keeping what
    // came before it); a corrupt record anywhere fails the run with its byte offset.
    while let Some(meta) = source.next_packet(&mut buf).map_err(|e| e.to_string())? {
        builder.push_lidar_packet(
            meta.recv_host_ns,
            &buf[..meta.len],
            meta.kind == PacketKind::Position,
        );
    }
    builder.counts.lidar_cut_short = source.truncated().is_some();
    builder.counts.odometry_cut_short = *cut > 0;
    for (wall_us, o) in odometry {
        builder.push_odometry(*wall_us, o);
    }
    Ok(())
}

/// Reads a run directory through a [`RunBuilder`]: the pipeline's whole result (cloud,
/// trajectory, counters) and what was read. `passangle replay` prints it.
pub fn build_run(dir: &Path, config: &ProcessConfig) -> Result<(BuiltCloud, ReadCounts), String> {
    let odometry = read_odometry(dir)?;
    let mut builder = RunBuilder::new(config)?;
    feed_recording(dir, &mut builder, &odometry)?;
    let pcap = dir.join("lidar.pcap");
    read_depth(dir, &mut builder)?;
    builder.finish_built().map_err(|e| {
        if e.starts_with("no complete") {
            format!("{}: {e}", pcap.display())
        } else {
            e
        }
    })
}

/// The angles of a built cloud as the service reports them (`run_id` and `vehicle_id` left for
/// the caller).
fn angles_of(
    cloud: Cloud,
    scan: Scan,
    counts: ReadCounts,
    config: &ProcessConfig,
    zone: WireZone,
    short_run: bool,
) -> Result<Processed, String> {
    let record = ScanRecord {
        trajectory_x_sigma_per_m: scan.x_sigma_per_m,
        path_m: scan.path.iter().map(|&p| p.into()).collect(),
    };
    let angles_config = AnglesConfig {
        front_is_positive_x: !config.enter_at_front,
        zone: match zone {
            WireZone::Tyre => Zone::Tyre,
            WireZone::Axle => Zone::Axle,
        },
        scan_path_in_cloud: scan.path,
        trajectory_x_sigma_per_m: scan.x_sigma_per_m,
        range_accuracy_m: Some(vlp16::RANGE_ACCURACY_M),
        scanner_view: Some(angles::ScannerView::VLP16),
        ..AnglesConfig::default()
    };
    let points: Vec<V3> = cloud.points_m.iter().map(|&p| p.into()).collect();
    let found = compute_angles(&points, &angles_config).map_err(|e| format!("angles: {e}"))?;
    let mut result = wire_result(&found, cloud.points_m.len());
    if short_run {
        result.warnings.insert(ResultWarnings::SHORT_RUN);
    }
    if counts.lidar_malformed > 0 {
        result.warnings.insert(ResultWarnings::LIDAR_LOSS);
    }
    if counts.out_of_order > 0 || counts.mcu_clock_resets > 0 {
        tracing::warn!(
            "processing: {} items out of time order skipped, MCU clock reset {} times (reboot?)",
            counts.out_of_order,
            counts.mcu_clock_resets
        );
    }
    let svg = side_view_svg(&found);
    let profiles = profile_records(&compute_profiles(
        &points,
        &angles_config,
        Some(&found),
        &config.standards,
    ));
    Ok(Processed {
        result,
        cloud,
        svg,
        angles: Some(Box::new(found)),
        profiles,
        scan: Some(record),
    })
}

/// Reads a run directory and builds its cloud and angles. `Err` names what is missing or wrong.
pub fn process_run(
    dir: &Path,
    config: &ProcessConfig,
    zone: WireZone,
    short_run: bool,
) -> Result<(Processed, ReadCounts), String> {
    let rec = Recording::open(dir).map_err(|e| e.to_string())?;
    let (built, counts) = build_run(dir, config)?;
    let (cloud, scan) = cloud_and_path(built, config.min_cloud_points, &config.pipeline)?;
    let mut processed = angles_of(cloud, scan, counts, config, zone, short_run)?;
    processed.result.vehicle_id = Text::truncated(&rec.meta.vehicle_id);
    processed.result.run_id = rec.meta.run_id;
    Ok((processed, counts))
}

/// The wire result of an angle computation: a quantity that was not measured is NaN with its
/// [`Absence`], never a number.
pub fn wire_result(a: &AnglesResult, cloud_points: usize) -> MeasurementResult {
    let mut warnings = ResultWarnings::EMPTY;
    let angle =
        |f: &Option<angles::AngleFinding>| f.as_ref().map_or(f32::NAN, |f| f.angle_rad as f32);
    let u = |f: &Option<angles::AngleFinding>| {
        f.as_ref()
            .map_or(f32::NAN, |f| f.uncertainty.expanded as f32)
    };
    let absent = [
        angles::Quantity::Approach,
        angles::Quantity::Departure,
        angles::Quantity::Breakover,
        angles::Quantity::GroundClearance,
    ]
    .map(|q| {
        a.not_measured
            .iter()
            .find(|n| n.quantity == q)
            .map_or(Absence::Measured, |n| match n.kind {
                angles::Absence::NothingInZone => Absence::NothingInZone,
                angles::Absence::NotCovered => Absence::NotCovered,
            })
    });
    let support = |f: &Option<angles::AngleFinding>| {
        f.as_ref()
            .map_or(0, |f| f.support.min(usize::from(u16::MAX)) as u16)
    };
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
        approach_u_rad: u(&a.approach),
        departure_u_rad: u(&a.departure),
        breakover_u_rad: u(&a.breakover),
        ground_clearance_u_m: a
            .ground_clearance
            .as_ref()
            .map_or(f32::NAN, |c| c.uncertainty.expanded as f32),
        absent,
        wheelbase_m: a.wheelbase_m as f32,
        track_m: a.track_m.map_or(f32::NAN, |t| t as f32),
        approach_support: support(&a.approach),
        departure_support: support(&a.departure),
        breakover_support: support(&a.breakover),
        tyre_fit_rms_m: rms as f32,
        warnings,
        cloud_points: u32::try_from(cloud_points).unwrap_or(u32::MAX),
        preview_chunks: 0,
        records: protocol::bounded::List::default(),
    }
}

/// Pushes the depth frames of `depth/index.csv` (a cut-short last line or a missing frame file
/// ends them: a crash's leftovers). The intrinsics are read as the `f32` they were written from.
fn read_depth(dir: &Path, builder: &mut RunBuilder) -> Result<(), String> {
    let index = dir.join("depth/index.csv");
    let Ok(text) = fs::read_to_string(&index) else {
        return Ok(());
    };
    for (i, line) in text.lines().enumerate().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        if f.len() != 9 {
            break;
        }
        let num = |i: usize| f[i].parse::<f32>().ok();
        let (Ok(n), Ok(wall_us), Ok(width), Ok(height)) = (
            f[0].parse::<u32>(),
            f[1].parse::<u64>(),
            f[2].parse::<u16>(),
            f[3].parse::<u16>(),
        ) else {
            break;
        };
        let (Some(fx), Some(fy), Some(cx), Some(cy), Some(depth_scale_m)) =
            (num(4), num(5), num(6), num(7), num(8))
        else {
            break;
        };
        // Intrinsics that parse but are NaN, infinite or not positive would project every
        // depth pixel to garbage: refused, naming the line.
        let positive = [fx, fy, depth_scale_m]
            .iter()
            .all(|v| v.is_finite() && *v > 0.0);
        if !(positive && cx.is_finite() && cy.is_finite()) {
            return Err(format!(
                "{}: line {}: intrinsics fx {fx}, fy {fy}, cx {cx}, cy {cy}, depth scale \
                 {depth_scale_m}: each must be finite, fx, fy and the scale above 0",
                index.display(),
                i + 1
            ));
        }
        let path = dir.join(format!("depth/{n:06}.z16"));
        let expected = 2 * usize::from(width) * usize::from(height);
        // The size is checked before reading, so a huge file is never read into memory.
        let Ok(meta) = fs::metadata(&path) else {
            break;
        };
        if meta.len() != expected as u64 {
            return Err(format!(
                "{}: frame {n} has {} bytes, expected {expected}",
                index.display(),
                meta.len(),
            ));
        }
        let Ok(bytes) = fs::read(&path) else {
            break;
        };
        if bytes.len() != expected {
            return Err(format!(
                "{}: frame {n} has {} bytes, expected {expected}",
                index.display(),
                bytes.len(),
            ));
        }
        let depth = bytes
            .chunks_exact(2)
            .map(|c| u16::from_le_bytes([c[0], c[1]]))
            .collect();
        let k = Intrinsics {
            fx,
            fy,
            cx,
            cy,
            depth_scale_m,
        };
        builder.push_depth(wall_us, width, height, depth, &k);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_run_is_rebuilt_with_the_settings_it_was_made_with() {
        let dir = std::env::temp_dir().join(format!("passangle-of-run-{}", std::process::id()));
        fs::create_dir_all(&dir).unwrap();
        assert_eq!(ProcessConfig::of_run(&dir), Ok(None));
        let config = "[radio]\nport = \"sim\"\n[mcu]\nport = \"sim\"\n[processing]\n\
                      enter-at-front = false\n[processing.pipeline.visual]\nadd-to-cloud = false\n";
        fs::write(dir.join("config.toml"), config).unwrap();
        let recorded = ProcessConfig::of_run(&dir).unwrap().unwrap();
        assert!(!recorded.enter_at_front);
        assert!(!recorded.pipeline.visual.add_to_cloud);
        assert!(PipelineConfig::default().visual.add_to_cloud);
        fs::write(
            dir.join("config.toml"),
            "[processing]\nenter-at-front = 3\n",
        )
        .unwrap();
        let e = ProcessConfig::of_run(&dir).unwrap_err();
        assert!(e.contains("config.toml"), "{e}");
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn profile_records_keep_values_with_u_and_reasons_without_numbers() {
        use angles::profiles::{Measure, ProfileQuantity, QuantityKind};
        let p = ProfileResult {
            standard: Standard::Eu2018_858,
            quantities: vec![
                ProfileQuantity {
                    kind: QuantityKind::Breakover,
                    name: Standard::Eu2018_858.term(QuantityKind::Breakover),
                    measure: Measure::Value {
                        value: 21.5,
                        u: 0.4,
                        witness_in_vehicle: V3::new(0.0, 0.0, 0.3),
                    },
                },
                ProfileQuantity {
                    kind: QuantityKind::ClearanceUnderRearAxle,
                    name: "ground clearance under the rear axle",
                    measure: Measure::NotMeasured("no underside seen".into()),
                },
            ],
            notes: Standard::Eu2018_858.notes(),
        };
        let r = profile_records(&[p]);
        assert_eq!(r[0].standard, "eu");
        assert_eq!(r[0].quantities[0].name, "ramp angle");
        assert_eq!(
            (r[0].quantities[0].value, r[0].quantities[0].u),
            (Some(21.5), Some(0.4))
        );
        assert_eq!(r[0].quantities[0].unit, "deg");
        let q = &r[0].quantities[1];
        assert_eq!((q.value, q.u, q.unit.as_str()), (None, None, "m"));
        assert_eq!(q.not_measured.as_deref(), Some("no underside seen"));
        assert!(r[0].notes.iter().any(|n| n.contains("steps")));
    }

    #[test]
    fn a_corrupt_lidar_record_fails_the_replay_naming_its_offset() {
        use crate::recorder::{RecordedOutcome, RunRecorder};
        use protocol::bounded::Text;
        use protocol::radio::{StartMeasurement, Zone};
        let root = std::env::temp_dir().join(format!("passangle-replay-{}", std::process::id()));
        let _ = fs::remove_dir_all(&root);
        let params = StartMeasurement {
            vehicle_id: Text::truncated("V"),
            speed_mps: 0.2,
            distance_m: 1.0,
            zone: Zone::Tyre,
            lab: protocol::radio::LabRef::NONE,
        };
        let mut r = RunRecorder::begin(&root, 1, &params, 0, "").unwrap();
        let src = std::net::SocketAddrV4::new([192, 168, 1, 201].into(), 2368);
        let dst = std::net::SocketAddrV4::new([255, 255, 255, 255].into(), 2368);
        for i in 0..10u64 {
            r.lidar_packet(
                1_700_000_000_000_000_000 + i * 1_327_000,
                src,
                dst,
                &[0; 1206],
            );
        }
        let dir = r.dir().to_owned();
        assert!(r.finish(RecordedOutcome::Completed).is_empty());
        // Record 3's original length below its captured length.
        let pcap = dir.join("lidar.pcap");
        let mut bytes = fs::read(&pcap).unwrap();
        let at = 24 + 3 * (16 + 1248);
        bytes[at + 12..at + 16].copy_from_slice(&7u32.to_le_bytes());
        fs::write(&pcap, &bytes).unwrap();
        let err = build_run(&dir, &ProcessConfig::default()).unwrap_err();
        assert!(
            err.contains("lidar.pcap")
                && err.contains(&format!("record 3 at byte {at} is corrupt")),
            "{err}"
        );
        fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn non_finite_depth_intrinsics_are_refused_naming_the_line() {
        let dir = std::env::temp_dir().join(format!("passangle-depth-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        fs::create_dir_all(dir.join("depth")).unwrap();
        fs::write(dir.join("depth/000000.z16"), [0u8; 16]).unwrap();
        fs::write(dir.join("depth/000001.z16"), [0u8; 16]).unwrap();
        let head = "frame,wall_us,width,height,fx,fy,cx,cy,depth_scale_m\n";
        let good = "0,5,4,2,420,420,2,1,0.001\n";
        fs::write(
            dir.join("depth/index.csv"),
            format!("{head}{good}1,6,4,2,NaN,420,2,1,0.001\n"),
        )
        .unwrap();
        let mut builder = RunBuilder::new(&ProcessConfig::default()).unwrap();
        let err = read_depth(&dir, &mut builder).unwrap_err();
        assert!(
            err.contains("depth/index.csv: line 3: intrinsics fx NaN"),
            "{err}"
        );
        // A frame file whose size disagrees with the index is refused before it is read.
        fs::write(dir.join("depth/index.csv"), format!("{head}{good}")).unwrap();
        fs::write(dir.join("depth/000000.z16"), [0u8; 18]).unwrap();
        let err = read_depth(&dir, &mut builder).unwrap_err();
        assert!(err.contains("frame 0 has 18 bytes, expected 16"), "{err}");
        fs::remove_dir_all(&dir).unwrap();
    }
}
