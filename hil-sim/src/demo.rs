//! `passangle-sim demo`: a whole measurement in software, in real time, in one process.
//!
//! ```text
//!  handheld Client --radio (57600 B/8, seeded loss)-- onboard service --MCU link (in-memory)-- firmware control
//!                                                        ^   ^                                     | CAN (in-process)
//!                VLP-16 packets (loopback UDP) ----+   +---- odometry                      ESCs + robot physics
//!                       (ray cast at the robot's *simulated* pose, which the firmware drives)
//! ```
//!
//! Every part is the product's code: the handheld client, the onboard service loop with its run
//! state machine, recorder and processing (pipeline + angle calculator), and the firmware's
//! `control::Controller` driving simulated C620 ESCs and the chassis. The lidar model casts its
//! rays from the pose the simulated robot actually has (firmware in the loop), placed in the
//! scenario's start pose under the vehicle. The depth camera is rendered the same way at a quarter
//! of the D435's resolution and 6 fps (full size costs too much CPU in real time beside everything
//! else on two cores) and reaches the service as `camera.source = "simulated"` (`demo_camera`).
//!
//! The result is compared with the vehicle's true angles (`crate::truth`, brute force on the
//! vehicle geometry, independent of the onboard code).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread;
use std::time::{Duration, Instant};

use angles::{self, AnglesResult};
use anyhow::Context;
use link::client::{Client, Measured, Observer};
use link::sim::{LossyPortPair, PipeConfig};
use onboard::config::{CameraSource, OnboardConfig};
use onboard::process::PipelineProcessor;
use onboard::service::{
    self, Io, LiveRun, NoNotify, ProcessInput, Processed, Processor, SensorItem, ServiceStats,
    SharedStats,
};
use protocol::auth::{KEY_LEN, Key};
use protocol::bounded::Text;
use protocol::radio::{StartMeasurement, Zone};

use crate::can_bus::InProcessBus;
use crate::fil::{Fil, FilConfig, FilError, Pacing};
use crate::geometry::{Pose, Vec3};
use crate::pty::MemPipe;
use crate::scenario::Scenario;
use crate::trajectory::Trajectory;
use crate::truth::{TrueAngles, TruthOptions, true_angles};
use crate::vlp16::{PACKET_S, Vlp16Sim};

/// Demo settings.
#[derive(Debug, Clone)]
pub struct DemoOptions {
    /// The scenario file (vehicle, start pose, speed, distance, sensor settings).
    pub scenario: PathBuf,
    /// Where the robot records its runs.
    pub run_root: PathBuf,
    /// Radio frame loss probability (0..1).
    pub radio_loss: f64,
    /// Radio frame corruption probability (0..1).
    pub radio_corrupt: f64,
    /// Seed of the radio impairments (and of the faults in lockstep).
    pub seed: u64,
    /// Run on the wall clock with threads, loopback UDP and real sleeps instead of lockstep.
    pub realtime: bool,
    /// Faults to inject (lockstep only).
    pub faults: crate::lockstep::Faults,
}

/// How a demo ran.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Mode {
    /// Every part on one simulated clock, one thread ([`crate::lockstep`]).
    Lockstep,
    /// Threads on the wall clock.
    RealTime,
}

/// Angles in degrees.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct AnglesDeg {
    /// Approach angle.
    pub approach_deg: f64,
    /// Departure angle.
    pub departure_deg: f64,
    /// Ramp breakover angle.
    pub breakover_deg: f64,
}

/// Which part of the vehicle decided an angle: the measured witness and the true one.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct WitnessReport {
    /// The part nearest the measured witness (a vehicle section or part name from the vehicle
    /// file), or `none` when no part is within [`WITNESS_PART_M`].
    pub part: String,
    /// The measured witness in the simulator's vehicle frame (x forward from the front axle,
    /// height above the ground), m.
    pub x_m: f64,
    /// Height, m.
    pub z_m: f64,
    /// How far the measured witness is from that part's outline, m.
    pub off_part_m: f64,
    /// The part the truth's witness belongs to.
    pub true_part: String,
}

/// A measured witness further than this from every part's side-view outline belongs to none.
pub const WITNESS_PART_M: f64 = 0.03;

/// What the demo measured.
#[derive(Debug, Clone, serde::Serialize)]
pub struct DemoReport {
    /// The vehicle.
    pub vehicle: String,
    /// Measured by the robot, as the handheld received them.
    pub measured: AnglesDeg,
    /// From the vehicle's geometry.
    pub truth: AnglesDeg,
    /// The run directory on the (simulated) robot.
    pub run_dir: PathBuf,
    /// From the robot at rest (first `Processing` progress seen) to the result on the handheld,
    /// s on the robot's clock (in lockstep the processing itself takes no simulated time).
    pub stop_to_result_s: Option<f64>,
    /// From the connection to the result, s on the robot's clock (simulated in lockstep).
    pub run_s: f64,
    /// The whole demo on the wall clock, s. Not in the JSON, which is the same for the same
    /// inputs in lockstep.
    #[serde(skip)]
    pub wall_s: f64,
    /// Lockstep or real time.
    pub mode: Mode,
    /// Lidar data packets the simulated VLP-16 sent.
    pub lidar_packets_sent: u64,
    /// Lidar data packets the service received (good and malformed): in real time, those the
    /// UDP path or a late loop dropped are missing; in lockstep none is.
    pub lidar_packets_received: u64,
    /// Points in the robot's cloud.
    pub cloud_points: u32,
    /// Ground clearance, m.
    pub ground_clearance_m: f64,
    /// Wheelbase, m.
    pub wheelbase_m: f64,
    /// Cloud points supporting the approach, departure and breakover witnesses.
    pub support: [u16; 3],
    /// The approach, departure and breakover witnesses' parts (`None` where the calculator
    /// found no witness).
    pub witnesses: [Option<WitnessReport>; 3],
    /// Warnings the robot attached.
    pub warnings: String,
}

/// (simulation time s, x m, y m, yaw rad) samples of the simulated robot, shared between threads.
pub(crate) type PoseLog = Arc<Mutex<Vec<(f64, f64, f64, f64)>>>;

/// Robot poses from the firmware-in-the-loop runner, as a [`Trajectory`] in the vehicle frame.
#[derive(Clone)]
pub(crate) struct LiveTrajectory {
    pub(crate) start: Pose,
    /// (simulation time s, x, y, yaw) in the robot's odometry frame (starts at 0).
    pub(crate) samples: PoseLog,
}

impl LiveTrajectory {
    fn latest_s(&self) -> f64 {
        self.samples
            .lock()
            .map_or(0.0, |s| s.last().map_or(0.0, |x| x.0))
    }
}

impl Trajectory for LiveTrajectory {
    fn pose_at(&self, t_s: f64) -> Pose {
        let (x, y, yaw) = self.samples.lock().map_or((0.0, 0.0, 0.0), |s| {
            let i = s.partition_point(|p| p.0 <= t_s);
            match (i.checked_sub(1).and_then(|j| s.get(j)), s.get(i)) {
                (Some(a), Some(b)) if b.0 > a.0 => {
                    let f = (t_s - a.0) / (b.0 - a.0);
                    (
                        a.1 + f * (b.1 - a.1),
                        a.2 + f * (b.2 - a.2),
                        a.3 + f * (b.3 - a.3),
                    )
                }
                (Some(a), _) => (a.1, a.2, a.3),
                (None, Some(b)) => (b.1, b.2, b.3),
                (None, None) => (0.0, 0.0, 0.0),
            }
        });
        let (s, c) = self.start.yaw_rad.sin_cos();
        Pose {
            position_m: Vec3::new(
                self.start.position_m.x + c * x - s * y,
                self.start.position_m.y + s * x + c * y,
                self.start.position_m.z,
            ),
            roll_rad: 0.0,
            pitch_rad: 0.0,
            yaw_rad: self.start.yaw_rad + yaw,
        }
    }

    fn wheel_distance_at(&self, _t_s: f64) -> f64 {
        0.0
    }
}

/// Prints progress lines to stderr.
pub(crate) struct StderrObserver {
    pub(crate) quiet: bool,
}

impl Observer for StderrObserver {
    fn progress(&mut self, p: &protocol::radio::Progress) {
        if !self.quiet {
            eprintln!(
                "run {} {:<10} {:3}%  {:.2} m  {} lidar frames",
                p.run_id,
                p.phase.name(),
                p.percent,
                p.travelled_m,
                p.lidar_frames
            );
        }
    }
    fn log(&mut self, l: &protocol::common::LogLine) {
        if !self.quiet {
            eprintln!("robot: {}", l.text.as_str());
        }
    }
    fn preview(&mut self, _: usize, _: usize) {}
}

fn lidar_thread(
    scenario: &Scenario,
    live: &LiveTrajectory,
    to: std::net::SocketAddr,
    stop: &AtomicBool,
    sent: &AtomicU64,
) -> anyhow::Result<()> {
    // The VLP-16 sends UDP datagrams; the service reads them with its production reader.
    let socket =
        std::net::UdpSocket::bind("127.0.0.1:0").context("binding the lidar's UDP socket")?;
    let scene = scenario.scene();
    let on_floor = crate::world::OnFloor {
        inner: live,
        floor: scenario.hall.as_deref().map(|h| &h.floor),
    };
    let sim = Vlp16Sim::new(
        &scene,
        &on_floor,
        scenario.lidar_config(),
        scenario.lidar_seed(),
    );
    let mut index = 0u64;
    while !stop.load(Ordering::Relaxed) {
        // Cast a packet once the robot's pose at its time is known (the runner reports every 10 ms).
        let t = index as f64 * PACKET_S;
        if live.latest_s() < t + 0.001 {
            thread::sleep(Duration::from_millis(1));
            continue;
        }
        socket
            .send_to(&sim.data_packet(index).to_bytes(), to)
            .context("sending a lidar packet")?;
        index += 1;
        sent.fetch_add(1, Ordering::Relaxed);
    }
    Ok(())
}

/// The demo's depth camera: the scenario's D435 at a quarter of its resolution (212 x 120) and 6
/// frames per second, so that rendering it in real time beside everything else fits two cores.
/// It exercises the service's whole depth path (camera channel, liveness check, recording,
/// live processing with visual odometry); its points stay out of the cloud (`DEMO_PIPELINE`).
pub(crate) fn demo_camera(scenario: &Scenario) -> crate::d435::D435Config {
    crate::d435::D435Config {
        fps: 6.0,
        ..scenario.file.depth.scaled(0.25)
    }
}

fn camera_thread(
    scenario: &Scenario,
    live: &LiveTrajectory,
    tx: &std::sync::mpsc::SyncSender<service::DepthFrame>,
    stop: &AtomicBool,
) {
    let scene = scenario.scene();
    let on_floor = crate::world::OnFloor {
        inner: live,
        floor: scenario.hall.as_deref().map(|h| &h.floor),
    };
    let sim = crate::d435::D435Sim::new(
        &scene,
        &on_floor,
        demo_camera(scenario),
        scenario.depth_seed(),
    );
    let mut index = 0u64;
    while !stop.load(Ordering::Relaxed) {
        // Render a frame once the robot's pose at its exposure is known.
        if live.latest_s() < sim.frame_time_s(index) + 0.001 {
            thread::sleep(Duration::from_millis(2));
            continue;
        }
        let f = sim.frame(index);
        let frame = service::DepthFrame {
            width: u16::try_from(f.width).unwrap_or(u16::MAX),
            height: u16::try_from(f.height).unwrap_or(u16::MAX),
            depth: f.depth_mm,
        };
        // A full channel drops the frame, as a camera driver would.
        let _ = tx.try_send(frame);
        index += 1;
    }
}

/// The firmware's controller with the simulated ESCs and chassis on an in-process CAN bus, its
/// UART at `fw_uart` (the service holds the other end; the runner's own host stand-in stays
/// silent).
pub(crate) fn robot_in_the_loop(fw_uart: MemPipe, pacing: Pacing) -> Result<Fil, FilError> {
    let (stand_in, _unused) = MemPipe::pair();
    let bus = InProcessBus::new();
    Fil::new(
        FilConfig {
            pacing,
            ..FilConfig::default()
        },
        Box::new(bus.node()),
        Box::new(bus.node()),
        Box::new(fw_uart),
        Box::new(stand_in),
    )
}

/// The demo's `[processing.pipeline]` overrides: the product's laser + wheel pipeline (laser
/// odometry, fusion, scan-to-map refinement) without the depth camera, whose frames are tracked
/// (visual odometry runs) but neither fused nor added to the cloud: the demo's camera is a
/// quarter-resolution stand-in, and its mount differs from the pipeline's default
/// (`mounts.camera-*`). The output voxel (5 mm) and the bilateral filter (off) are the
/// pipeline's defaults. Fusing visual odometry is off by default too; the camera's points in the
/// cloud are on by default (decision record 037) and off here. The run's `config.toml` keeps
/// these overrides, and `passangle replay` starts from it.
const DEMO_PIPELINE: &str = "[processing.pipeline.fusion]\nuse-visual = false\n[processing.pipeline.visual]\nadd-to-cloud = false\n";

/// Everything both modes set up the same way: the scenario, its truth, the robot's config and
/// pairing key, where the robot starts and what the handheld asks for.
pub(crate) struct Prepared {
    pub(crate) scenario: Scenario,
    pub(crate) truth: TrueAngles,
    pub(crate) config: OnboardConfig,
    /// The config file's text (recorded with every run).
    pub(crate) text: String,
    pub(crate) key: Key,
    /// The robot's start pose in the vehicle frame.
    pub(crate) start: Pose,
    pub(crate) params: StartMeasurement,
    /// How long the handheld waits for the result.
    pub(crate) time_limit: Duration,
}

/// The simulated robot's device key seed for a demo seed (never a real robot's: those come from
/// the OS's random source, `passangle-onboard device-key --generate`).
pub fn device_seed(seed: u64) -> [u8; onboard::signing::SEED_LEN] {
    use rand::{RngCore, SeedableRng};
    let mut out = [0u8; onboard::signing::SEED_LEN];
    rand_chacha::ChaCha20Rng::seed_from_u64(seed ^ 0xde71_ce0c_5e1f_0000).fill_bytes(&mut out);
    out
}

/// Loads the scenario, computes its truth and writes the robot's config, pairing key and device
/// key under `options.run_root`.
// `{:?}` quotes paths for TOML.
#[allow(clippy::unnecessary_debug_formatting)]
pub(crate) fn prepare(options: &DemoOptions) -> anyhow::Result<Prepared> {
    let scenario = Scenario::load(&options.scenario)
        .with_context(|| format!("loading {}", options.scenario.display()))?;
    let truth = true_angles(&scenario.vehicle, &TruthOptions::default());
    let run_spec = &scenario.file.robot;
    std::fs::create_dir_all(&options.run_root)?;
    let etc = options.run_root.join("etc");
    std::fs::create_dir_all(&etc)?;
    let key_file = etc.join("pairing.key");
    let key = Key([0x42; KEY_LEN]);
    if !key_file.exists() {
        onboard::config::write_key(&key_file, &key)?;
    }
    let key = onboard::config::read_key(&key_file)?;
    // The simulated robot signs its records like a real one, with a key drawn from the seed so
    // that two runs of a scenario give the same signatures (a real robot's comes from the OS).
    let device_key_file = etc.join("device.key");
    let _ = std::fs::remove_file(&device_key_file);
    onboard::config::write_device_key(&device_key_file, &device_seed(options.seed))?;
    let text = format!(
        "[recording]\nroot = {:?}\n[radio]\nport = \"sim\"\nkey-file = {:?}\n[mcu]\nport = \"sim\"\n[camera]\nsource = \"none\"\n[signing]\nkey-file = {:?}\n[processing]\nenter-at-front = {}\n{DEMO_PIPELINE}",
        options.run_root.join("runs"),
        key_file,
        device_key_file,
        run_spec.heading_deg.rem_euclid(360.0) > 90.0
            && run_spec.heading_deg.rem_euclid(360.0) < 270.0,
    );
    let mut config = OnboardConfig::parse(&text, Path::new("demo.toml"))?;
    let fw = control::Config::default();
    config.mcu.firmware = fw.to_mcu();
    // The scenario's ramp, if it has one (0 means "cruising from t = 0", which a real robot
    // cannot do): else the service's default ramp.
    if run_spec.accel_mps2 > 0.0 {
        config.mcu.accel_mps2 =
            (run_spec.accel_mps2 as f32).min(config.mcu.firmware.max_accel_mps2);
    }
    config.run.max_speed_mps = config.mcu.firmware.max_speed_mps;
    // The stop must fit in the run's stop timeout at this speed and ramp (the service refuses
    // such a config; so does the demo).
    config.run.stop_timeout_us = config
        .run
        .stop_timeout_us
        .max((config.stop_time_s() * 1e6) as u64 + 2_000_000);
    config.check(Path::new("demo.toml"))?;
    let camera = demo_camera(&scenario).intrinsics();
    config.camera.source = CameraSource::Simulated;
    config.camera.width = u16::try_from(camera.width)?;
    config.camera.height = u16::try_from(camera.height)?;
    config.camera.fps = 6;
    config.camera.record_every = 1;
    config.camera.intrinsics = onboard::recorder::Intrinsics {
        fx: camera.fx_px as f32,
        fy: camera.fy_px as f32,
        cx: camera.cx_px as f32,
        cy: camera.cy_px as f32,
        depth_scale_m: 0.001,
    };
    let start = Pose {
        position_m: Vec3::new(run_spec.start_x_m, run_spec.lateral_offset_m, 0.0),
        roll_rad: 0.0,
        pitch_rad: 0.0,
        yaw_rad: run_spec.heading_deg.to_radians(),
    };
    let params = StartMeasurement {
        vehicle_id: Text::truncated(&scenario.vehicle.name),
        speed_mps: run_spec.speed_mps as f32,
        distance_m: run_spec.distance_m as f32,
        zone: Zone::Tyre,
        lab: protocol::radio::LabRef::NONE,
    };
    let time_limit = Duration::from_secs_f64(run_spec.distance_m / run_spec.speed_mps + 300.0);
    Ok(Prepared {
        scenario,
        truth,
        config,
        text,
        key,
        start,
        params,
        time_limit,
    })
}

impl Prepared {
    /// The report of a measurement the handheld received.
    pub(crate) fn report(
        &self,
        options: &DemoOptions,
        m: &Measured,
        timing: Timing,
        angles: Option<&AnglesResult>,
    ) -> DemoReport {
        let r = &m.result;
        let deg = |x: f32| f64::from(x).to_degrees();
        let truth = &self.truth;
        DemoReport {
            vehicle: self.scenario.vehicle.name.clone(),
            measured: AnglesDeg {
                approach_deg: deg(r.approach_rad),
                departure_deg: deg(r.departure_rad),
                breakover_deg: deg(r.breakover_rad),
            },
            truth: AnglesDeg {
                approach_deg: truth.approach.angle_rad.to_degrees(),
                departure_deg: truth.departure.angle_rad.to_degrees(),
                breakover_deg: truth.breakover.angle_rad.to_degrees(),
            },
            run_dir: options
                .run_root
                .join("runs")
                .join(onboard::recorder::run_dir_name(r.run_id)),
            stop_to_result_s: m.stop_to_result.map(|d| d.as_secs_f64()),
            run_s: timing.run_s,
            wall_s: timing.wall_s,
            mode: timing.mode,
            lidar_packets_sent: timing.lidar_packets[0],
            lidar_packets_received: timing.lidar_packets[1],
            cloud_points: r.cloud_points,
            ground_clearance_m: f64::from(r.ground_clearance_m),
            wheelbase_m: f64::from(r.wheelbase_m),
            support: [r.approach_support, r.departure_support, r.breakover_support],
            warnings: r.warnings.to_string(),
            witnesses: self.witnesses(angles),
        }
    }

    /// Names the part behind each measured witness: the nearest point of the vehicle's
    /// side-view outline (the truth's own outline, 5 mm spacing, flexible parts included).
    fn witnesses(&self, angles: Option<&AnglesResult>) -> [Option<WitnessReport>; 3] {
        let Some(a) = angles else {
            return [None, None, None];
        };
        let outline = self.scenario.vehicle.outline_points(0.005);
        let truth = &self.truth;
        let name = |w: &Option<crate::vehicle::OutlinePoint>| {
            w.as_ref()
                .map_or_else(|| "none".to_owned(), |p| p.source.clone())
        };
        let report = |f: &Option<angles::AngleFinding>, t: &crate::truth::TrueAngle| {
            let f = f.as_ref()?;
            // The calculator's vehicle frame has its origin between the axles; the simulator's
            // is under the front axle.
            let x = f.witness_in_vehicle[0] - a.front_axle.x_m;
            let z = f.witness_in_vehicle[2];
            let nearest = outline
                .iter()
                .map(|p| (p, (p.x_m - x).hypot(p.z_m - z)))
                .min_by(|a, b| a.1.total_cmp(&b.1));
            let (part, off) = match nearest {
                Some((p, d)) if d <= WITNESS_PART_M => (p.source.clone(), d),
                Some((_, d)) => ("none".to_owned(), d),
                None => ("none".to_owned(), f64::INFINITY),
            };
            Some(WitnessReport {
                part,
                x_m: x,
                z_m: z,
                off_part_m: off,
                true_part: name(&t.witness),
            })
        };
        [
            report(&a.approach, &truth.approach),
            report(&a.departure, &truth.departure),
            report(&a.breakover, &truth.breakover),
        ]
    }
}

/// The product's processor, keeping the calculator's finding of the last run for the report.
pub(crate) struct Capturing {
    inner: PipelineProcessor,
    last: Arc<Mutex<Option<Box<AnglesResult>>>>,
}

impl Capturing {
    pub(crate) fn new(inner: PipelineProcessor) -> Self {
        Self {
            inner,
            last: Arc::new(Mutex::new(None)),
        }
    }

    /// The calculator's finding of the last processed run.
    pub(crate) fn last(&self) -> Option<Box<AnglesResult>> {
        self.last.lock().ok().and_then(|l| l.clone())
    }
}

fn keep(last: &Mutex<Option<Box<AnglesResult>>>, p: &Processed) {
    if let Ok(mut l) = last.lock() {
        l.clone_from(&p.angles);
    }
}

impl Processor for Capturing {
    fn process(&self, input: &ProcessInput) -> Result<Processed, String> {
        let p = self.inner.process(input)?;
        keep(&self.last, &p);
        Ok(p)
    }

    fn start_live(&self) -> Option<Box<dyn LiveRun>> {
        let inner = self.inner.start_live()?;
        Some(Box::new(CapturingLive {
            inner,
            last: Arc::clone(&self.last),
        }))
    }
}

struct CapturingLive {
    inner: Box<dyn LiveRun>,
    last: Arc<Mutex<Option<Box<AnglesResult>>>>,
}

impl LiveRun for CapturingLive {
    fn push(&mut self, item: SensorItem) {
        self.inner.push(item);
    }

    fn finish(self: Box<Self>, input: &ProcessInput) -> Result<Processed, String> {
        let p = self.inner.finish(input)?;
        keep(&self.last, &p);
        Ok(p)
    }
}

/// How long a demo took.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Timing {
    /// The run on the robot's clock, s (simulated in lockstep).
    pub(crate) run_s: f64,
    /// The demo on the wall clock, s.
    pub(crate) wall_s: f64,
    pub(crate) mode: Mode,
    /// Lidar data packets the simulated VLP-16 sent and the service received.
    pub(crate) lidar_packets: [u64; 2],
}

/// Runs the demo (lockstep unless `options.realtime`); prints progress to stderr unless `quiet`.
pub fn run(options: &DemoOptions, quiet: bool) -> anyhow::Result<DemoReport> {
    if options.realtime {
        anyhow::ensure!(
            options.faults == crate::lockstep::Faults::default(),
            "faults are injected in lockstep only (drop --realtime)"
        );
        run_realtime(options, quiet)
    } else {
        crate::lockstep::run(options, quiet)
    }
}

/// The real-time demo: threads, loopback UDP for the lidar, the wall clock.
// The wiring reads top to bottom as the diagram in the module docs.
#[allow(clippy::too_many_lines)]
fn run_realtime(options: &DemoOptions, quiet: bool) -> anyhow::Result<DemoReport> {
    let prepared = prepare(options)?;
    let Prepared {
        scenario,
        config,
        text,
        key,
        start,
        ..
    } = &prepared;
    let (config, text, key) = (config.clone(), text.clone(), key.clone());

    let stop = Arc::new(AtomicBool::new(false));
    let samples = Arc::new(Mutex::new(Vec::new()));
    let live = LiveTrajectory {
        start: *start,
        samples: Arc::clone(&samples),
    };
    let mut threads = Vec::new();
    let (fw_uart, onboard_uart) = MemPipe::pair();
    {
        let (stop, samples) = (Arc::clone(&stop), Arc::clone(&samples));
        threads.push(thread::spawn(move || -> anyhow::Result<()> {
            let mut fil = robot_in_the_loop(fw_uart, Pacing::RealTime)?;
            let mut t = 0;
            while !stop.load(Ordering::Relaxed) {
                t += 5_000;
                fil.run_until(t)?;
                let _ = fil.take_trace();
                let p = fil.truth();
                if let Ok(mut s) = samples.lock() {
                    s.push((p.stamp_us as f64 * 1e-6, p.x_m, p.y_m, p.yaw_rad));
                }
            }
            Ok(())
        }));
    }
    let lidar_config = onboard::config::LidarConfig {
        data_addr: "127.0.0.1:0".parse()?,
        position_addr: None,
        alive_timeout_ms: 500,
    };
    let (lidar_rx, lidar_addr) = service::spawn_lidar_reader(&lidar_config, Arc::clone(&stop))?;
    let lidar_sent = Arc::new(AtomicU64::new(0));
    {
        let (stop, scenario, live) = (Arc::clone(&stop), scenario.clone(), live.clone());
        let sent = Arc::clone(&lidar_sent);
        threads.push(thread::spawn(move || {
            lidar_thread(&scenario, &live, lidar_addr.into(), &stop, &sent)
        }));
    }
    let (depth_tx, depth_rx) = std::sync::mpsc::sync_channel(8);
    {
        let (stop, scenario, live) = (Arc::clone(&stop), scenario.clone(), live.clone());
        threads.push(thread::spawn(move || {
            camera_thread(&scenario, &live, &depth_tx, &stop);
            Ok(())
        }));
    }
    let radio = PipeConfig::radio_lossy(options.radio_loss, options.radio_corrupt);
    let (_pair, handheld_port, onboard_port) = LossyPortPair::new(radio, options.seed);
    let stats: SharedStats = Arc::new(Mutex::new(ServiceStats::default()));
    let capturing = Arc::new(Capturing::new(PipelineProcessor {
        config: config.processing.clone(),
    }));
    {
        let io = Io {
            radio: Box::new(onboard_port),
            mcu: Box::new(onboard_uart),
            lidar: lidar_rx,
            depth: Some(depth_rx),
            crash: None,
        };
        let processor = Arc::clone(&capturing);
        let (stop, stats) = (Arc::clone(&stop), Arc::clone(&stats));
        threads.push(thread::spawn(move || {
            service::run(config, text, io, processor, &stop, &mut NoNotify, stats)?;
            Ok(())
        }));
    }

    let t0 = Instant::now();
    let outcome = (|| -> anyhow::Result<Measured> {
        let mut client = Client::with_entropy(
            Box::new(handheld_port),
            key,
            link::session::Entropy::from_test_seed(options.seed),
        );
        client.connect(Duration::from_secs(30))?;
        // Let the service see the firmware and the lidar before the checks.
        thread::sleep(Duration::from_millis(500));
        Ok(client.measure(
            &prepared.params,
            prepared.time_limit,
            &mut StderrObserver { quiet },
        )?)
    })();
    stop.store(true, Ordering::Relaxed);
    for t in threads {
        match t.join() {
            Ok(r) => r?,
            Err(_) => anyhow::bail!("a simulator thread panicked"),
        }
    }
    let m = outcome?;
    let wall_s = t0.elapsed().as_secs_f64();
    let received = stats
        .lock()
        .map_or(0, |s| s.lidar_packets + s.lidar_malformed);
    Ok(prepared.report(
        options,
        &m,
        Timing {
            run_s: wall_s,
            wall_s,
            mode: Mode::RealTime,
            lidar_packets: [lidar_sent.load(Ordering::Relaxed), received],
        },
        capturing.last().as_deref(),
    ))
}

/// The scenario file of a built-in vehicle name: `scenarios/NAME-pass.toml`, else the first
/// `scenarios/NAME-*.toml` (e.g. `suv` -> `suv-offset.toml`).
pub fn scenario_for(vehicle: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios");
    let exact = dir.join(format!("{vehicle}-pass.toml"));
    if exact.exists() {
        return exact;
    }
    let mut others: Vec<PathBuf> = std::fs::read_dir(&dir)
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path())
        .filter(|p| {
            p.extension().is_some_and(|e| e == "toml")
                && p.file_name()
                    .and_then(|n| n.to_str())
                    .is_some_and(|n| n.starts_with(&format!("{vehicle}-")))
        })
        .collect();
    others.sort();
    others.into_iter().next().unwrap_or(exact)
}
