//! `passangle-sim demo` in lockstep: the whole measurement on one simulated clock, on one
//! thread, so the same scenario and seed give the same recording and result on any machine at any
//! load, as fast as the CPU allows.
//!
//! The parts are the product's code on the same paths as in the real-time demo
//! ([`crate::demo`]): the handheld [`Client`] (its blocking loop, with a [`ClientClock`] whose
//! idle step advances the world instead of sleeping), the radio as the seeded [`LossyPortPair`]
//! on the simulated clock, the onboard [`Service`] stepped one [`service::LOOP_PERIOD`] at a
//! time with its background work inline ([`Execution::Inline`]), the firmware's controller with
//! the simulated ESCs and chassis ([`Fil`]), and the VLP-16 and D435 models casting rays from
//! the robot's simulated pose. Only the IO shells differ: in-memory channels instead of the UDP
//! socket and the camera thread, and no sleeps.
//!
//! One step of the world, every [`service::LOOP_PERIOD`] of simulated time `t`:
//! 1. the firmware, ESCs and chassis run to `t` (1 ms ticks);
//! 2. every lidar packet whose last firing is at least [`SENSOR_LATENCY_US`] before `t` is cast
//!    at the robot's pose and queued to the service, stamped with that firing time plus the
//!    latency; every depth frame exposed at least that long before `t` is queued too (the
//!    service stamps it when it reads it, as it does a camera's frame);
//! 3. the radio moves the bytes due by `t`; the service runs one loop iteration at `t`;
//! 4. the handheld reads what arrived and answers (in [`ClientClock::idle`]'s caller).
//!
//! What lockstep does not model: the processing's own duration (it runs inline and costs no
//! simulated time, so `stop_to_result_s` is the radio's part only) and the wall clock's
//! scheduling jitter (the real-time demo and the service tests keep those).
//!
//! Faults ([`Faults`]) are injected at simulated times and by seed, so each is reproducible.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicU64;
use std::sync::mpsc::SyncSender;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use link::client::{Client, ClientClock, ClientError, Measured};
use link::session::Entropy;
use link::sim::{LossyPortPair, PipeConfig, PipeStats};
use onboard::process::PipelineProcessor;
use onboard::service::{
    self, DepthFrame, Execution, Io, LidarPacket, NoNotify, Service, ServiceError, ServiceStats,
    Startup,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::d435::D435Sim;
use crate::demo::{
    Capturing, DemoOptions, DemoReport, LiveTrajectory, Mode, StderrObserver, Timing, demo_camera,
    prepare, robot_in_the_loop,
};
use crate::esc_model::EscFault;
use crate::fil::{self, Fil, Pacing};
use crate::pty::MemPipe;
use crate::vlp16::{PACKET_S, Vlp16Sim};
use crate::world::OnFloor;

/// The wall clock of the simulated robot at simulated time 0, us since the Unix epoch: the same
/// fixed epoch as the simulator's pcap files (`passangle-sim lidar`). Recordings stamp everything
/// with this plus the simulated time, so they do not depend on when the demo ran.
pub const WALL_EPOCH_US: u64 = 1_767_225_600_000_000;

/// From a lidar packet's last firing (or a depth frame's exposure) to its arrival at the
/// service, us: the sensor's output and the Ethernet or USB transfer, a stated assumption (the
/// real-time demo measures it instead, with the scheduler's jitter).
pub const SENSOR_LATENCY_US: u64 = 200;

/// How long a run with faults goes on after the handheld's answer, us.
const SETTLE_US: u64 = 5_000_000;

/// Where the VLP-16's packets come from and go to in the recording (its factory defaults).
const LIDAR_SRC: &str = "192.168.1.201:2368";
const LIDAR_DST: &str = "255.255.255.255:2368";

/// Faults injected into a lockstep run, at simulated times and by seed.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Faults {
    /// The radio goes silent both ways from this simulated time, s.
    pub radio_cut_at_s: Option<f64>,
    /// The onboard service dies at this simulated time, s, as a killed process does: no stop
    /// to the MCU, the recording left open and marked incomplete.
    pub onboard_crash_at_s: Option<f64>,
    /// An ESC fault at a simulated time, s.
    pub esc_fault: Option<(f64, u8, EscFault)>,
    /// The probability that a lidar data packet arrives malformed (truncated or with a broken
    /// block flag), drawn per packet from the run's seed.
    pub malformed_lidar: f64,
}

/// What a lockstep run observed besides the handheld's answer.
#[derive(Debug, Clone)]
pub struct Observed {
    /// The handheld's answer: the demo report, or the client's error.
    pub report: Result<DemoReport, String>,
    /// The service's counters at the end (or at its crash).
    pub service: ServiceStats,
    /// The radio's counters, handheld -> robot and robot -> handheld.
    pub radio: (PipeStats, PipeStats),
    /// The robot's true path: (simulated time s, x m, y m, speed m/s) every step.
    pub path: Vec<(f64, f64, f64, f64)>,
    /// Malformed lidar packets injected.
    pub malformed_sent: u64,
    /// Simulated time at the end, s.
    pub sim_s: f64,
}

/// The simulated world one lockstep step advances (module docs).
struct World<'s> {
    t_us: u64,
    radio_clock: Arc<AtomicU64>,
    fil: Fil,
    live: LiveTrajectory,
    path: Vec<(f64, f64, f64, f64)>,
    lidar: Vlp16Sim<'s, OnFloor<'s, LiveTrajectory>>,
    camera: D435Sim<'s, OnFloor<'s, LiveTrajectory>>,
    next_packet: u64,
    next_frame: u64,
    lidar_tx: SyncSender<LidarPacket>,
    depth_tx: SyncSender<DepthFrame>,
    service: Option<Service>,
    io: Io,
    /// The first error of the service loop; the world stops stepping the service after it.
    error: Option<ServiceError>,
    stats: ServiceStats,
    faults: Faults,
    fault_rng: ChaCha8Rng,
    malformed_sent: u64,
    radio: LossyPortPair,
    radio_cut: bool,
    lidar_src: std::net::SocketAddrV4,
    lidar_dst: std::net::SocketAddrV4,
}

impl World<'_> {
    fn step(&mut self) -> Result<(), fil::FilError> {
        let t = self.t_us + service::LOOP_PERIOD.as_micros() as u64;
        self.t_us = t;
        let at = |s: f64| (s * 1e6).round() as u64;
        if let Some(cut) = self.faults.radio_cut_at_s
            && !self.radio_cut
            && t >= at(cut)
        {
            self.radio.set_cut(true);
            self.radio_cut = true;
        }
        if let Some(crash) = self.faults.onboard_crash_at_s
            && t >= at(crash)
            && let Some(s) = self.service.take()
        {
            self.stats = s.stats();
            s.kill();
        }
        self.fil.run_until(t)?;
        let _ = self.fil.take_trace();
        let p = self.fil.truth();
        let t_s = p.stamp_us as f64 * 1e-6;
        if let Ok(mut s) = self.live.samples.lock() {
            s.push((t_s, p.x_m, p.y_m, p.yaw_rad));
        }
        self.path.push((
            t_s,
            p.x_m,
            p.y_m,
            f64::from(p.vx_mps).hypot(f64::from(p.vy_mps)),
        ));
        if self.service.is_none() {
            // A dead service reads no sensors: casting them would only cost time.
            return Ok(());
        }
        self.emit_sensors(t);
        let Some(service) = self.service.as_mut() else {
            return Ok(());
        };
        self.radio_clock
            .store(t, std::sync::atomic::Ordering::Release);
        if self.error.is_none()
            && let Err(e) = service.step(t, &mut self.io, &mut NoNotify)
        {
            self.error = Some(e);
        }
        self.stats = service.stats();
        Ok(())
    }

    /// Lidar packets and depth frames due by `t` (module docs, step 2).
    fn emit_sensors(&mut self, t: u64) {
        let packet_us = |i: u64| ((i + 1) as f64 * PACKET_S * 1e6).round() as u64;
        while packet_us(self.next_packet) + SENSOR_LATENCY_US <= t {
            let mut payload = self.lidar.data_packet(self.next_packet).to_bytes().to_vec();
            let arrival_us = packet_us(self.next_packet) + SENSOR_LATENCY_US;
            self.next_packet += 1;
            if self.faults.malformed_lidar > 0.0
                && self
                    .fault_rng
                    .random_bool(self.faults.malformed_lidar.min(1.0))
            {
                malform(&mut payload, &mut self.fault_rng);
                self.malformed_sent += 1;
            }
            let _ = self.lidar_tx.try_send(LidarPacket {
                wall_ns: (WALL_EPOCH_US + arrival_us) * 1_000,
                src: self.lidar_src,
                dst: self.lidar_dst,
                payload,
                position: false,
            });
        }
        let frame_us = |c: &D435Sim<'_, OnFloor<'_, LiveTrajectory>>, i: u64| {
            (c.frame_time_s(i) * 1e6).round() as u64
        };
        while frame_us(&self.camera, self.next_frame) + SENSOR_LATENCY_US <= t {
            let f = self.camera.frame(self.next_frame);
            self.next_frame += 1;
            // A full queue drops the frame, as a camera driver would.
            let _ = self.depth_tx.try_send(DepthFrame {
                width: u16::try_from(f.width).unwrap_or(u16::MAX),
                height: u16::try_from(f.height).unwrap_or(u16::MAX),
                depth: f.depth_mm,
            });
        }
    }
}

/// Breaks a VLP-16 data packet the way a bad link or a foreign sender would: cut short, or a
/// block's 0xFFEE flag damaged.
fn malform(payload: &mut Vec<u8>, rng: &mut ChaCha8Rng) {
    if rng.random_bool(0.5) {
        let keep = rng.random_range(0..payload.len());
        payload.truncate(keep);
    } else {
        let block = rng.random_range(0..12usize);
        if let Some(b) = payload.get_mut(block * 100) {
            *b ^= 0x5A;
        }
    }
}

/// The handheld's clock in lockstep: each idle moment is one step of the world.
struct Lockstep<'s> {
    world: World<'s>,
    /// Simulated time after which the world stops, us (a bound on any run).
    end_us: u64,
    fil_error: Option<fil::FilError>,
}

impl ClientClock for Lockstep<'_> {
    fn now_us(&mut self) -> u64 {
        self.world.t_us
    }

    fn wall_epoch_us(&mut self) -> u64 {
        WALL_EPOCH_US
    }

    fn idle(&mut self) {
        if self.fil_error.is_some() || self.world.t_us >= self.end_us {
            // Time still passes for the client's timeouts.
            self.world.t_us += service::LOOP_PERIOD.as_micros() as u64;
            return;
        }
        if let Err(e) = self.world.step() {
            self.fil_error = Some(e);
        }
    }
}

/// Runs the demo in lockstep (see the module docs); prints progress to stderr unless `quiet`.
pub fn run(options: &DemoOptions, quiet: bool) -> anyhow::Result<DemoReport> {
    observe(options, quiet)?.report.map_err(anyhow::Error::msg)
}

/// Runs a lockstep demo and returns everything it observed, also when the handheld got no
/// result (faults).
// One function wires the world as the module docs list it.
#[allow(clippy::too_many_lines)]
pub fn observe(options: &DemoOptions, quiet: bool) -> anyhow::Result<Observed> {
    let wall = Instant::now();
    fresh_robot_disk(&options.run_root)?;
    let prepared = prepare(options)?;
    let scenario = &prepared.scenario;
    // The scenario's world: the vehicle, and its hall (walls, pillars, other vehicles, floor)
    // where it has one; the robot rides on that floor.
    let scene = scenario.scene();
    let live = LiveTrajectory {
        start: prepared.start,
        samples: Arc::new(Mutex::new(vec![(0.0, 0.0, 0.0, 0.0)])),
    };
    let on_floor = OnFloor {
        inner: &live,
        floor: scenario.hall.as_deref().map(|h| &h.floor),
    };
    let lidar = Vlp16Sim::new(
        &scene,
        &on_floor,
        scenario.lidar_config(),
        scenario.lidar_seed(),
    );
    let camera = D435Sim::new(
        &scene,
        &on_floor,
        demo_camera(scenario),
        scenario.depth_seed(),
    );

    let (fw_uart, onboard_uart) = MemPipe::pair();
    let mut fil = robot_in_the_loop(fw_uart, Pacing::Virtual)?;
    if let Some((at_s, esc_id, fault)) = options.faults.esc_fault {
        fil.schedule([fil::Event {
            at_us: (at_s * 1e6).round() as u64,
            action: fil::Action::Fault { esc_id, fault },
        }]);
    }

    let radio_clock = Arc::new(AtomicU64::new(0));
    let radio_config = PipeConfig::radio_lossy(options.radio_loss, options.radio_corrupt);
    let (radio, handheld_port, onboard_port) =
        LossyPortPair::on_clock(radio_config, options.seed, Arc::clone(&radio_clock));
    // The service drains the queue every step: it never holds more than a step's packets.
    let (lidar_tx, lidar_rx) = std::sync::mpsc::sync_channel(4_000);
    let (depth_tx, depth_rx) = std::sync::mpsc::sync_channel(8);
    let io = Io {
        radio: Box::new(onboard_port),
        mcu: Box::new(onboard_uart),
        lidar: lidar_rx,
        depth: Some(depth_rx),
        crash: None,
    };
    let capturing = Arc::new(Capturing::new(PipelineProcessor {
        config: prepared.config.processing.clone(),
    }));
    let service = Service::start(
        prepared.config.clone(),
        prepared.text.clone(),
        capturing.clone(),
        Arc::new(Mutex::new(ServiceStats::default())),
        Startup {
            // The robot's randomness differs from the handheld's, both from the seed.
            entropy: Entropy::from_test_seed(options.seed ^ 0x5eed_0b07),
            wall_epoch_us: WALL_EPOCH_US,
            execution: Execution::Inline,
        },
    )?;
    let world = World {
        t_us: 0,
        radio_clock,
        fil,
        live: live.clone(),
        path: Vec::new(),
        lidar,
        camera,
        next_packet: 0,
        next_frame: 0,
        lidar_tx,
        depth_tx,
        service: Some(service),
        io,
        error: None,
        stats: ServiceStats::default(),
        faults: options.faults.clone(),
        fault_rng: ChaCha8Rng::seed_from_u64(options.seed ^ 0xfa17),
        malformed_sent: 0,
        radio: radio.clone(),
        radio_cut: false,
        lidar_src: LIDAR_SRC.parse()?,
        lidar_dst: LIDAR_DST.parse()?,
    };
    let time_limit = prepared.time_limit;
    let clock = Lockstep {
        world,
        end_us: u64::try_from((time_limit + Duration::from_secs(60)).as_micros())?,
        fil_error: None,
    };
    let mut client = Client::with_clock(
        Box::new(handheld_port),
        prepared.key.clone(),
        Entropy::from_test_seed(options.seed),
        clock,
    );
    let outcome = (|| -> Result<(Measured, u64), ClientError> {
        client.connect(Duration::from_secs(30))?;
        let connected_us = client.clock_mut().now_us();
        // Let the service see the firmware and the lidar before the checks.
        client.linger(Duration::from_millis(500))?;
        let m = client.measure(&prepared.params, time_limit, &mut StderrObserver { quiet })?;
        Ok((m, connected_us))
    })();
    let mut clock = client.into_clock();
    if options.faults != Faults::default() {
        // A fault's consequences (the robot coasting to rest, the recording closing) go on
        // after the handheld gave up: watch them for a while.
        let settle_end = clock.world.t_us + SETTLE_US;
        while clock.world.t_us < settle_end {
            clock.idle();
        }
    }
    if let Some(e) = clock.fil_error.take() {
        return Err(e.into());
    }
    if let Some(e) = clock.world.error.take() {
        return Err(e.into());
    }
    let mut world = clock.world;
    let end_us = world.t_us;
    if let Some(s) = world.service.take() {
        world.stats = s.stats();
        s.stop(end_us, &mut world.io, &mut NoNotify);
    }
    let sim_s = end_us as f64 * 1e-6;
    let report = outcome
        .map(|(m, connected_us)| {
            prepared.report(
                options,
                &m,
                Timing {
                    run_s: end_us.saturating_sub(connected_us) as f64 * 1e-6,
                    wall_s: wall.elapsed().as_secs_f64(),
                    mode: Mode::Lockstep,
                    lidar_packets: [
                        world.next_packet,
                        world.stats.lidar_packets + world.stats.lidar_malformed,
                    ],
                },
                capturing.last().as_deref(),
            )
        })
        .map_err(|e| e.to_string());
    Ok(Observed {
        report,
        service: world.stats,
        radio: radio.stats(),
        path: world.path,
        malformed_sent: world.malformed_sent,
        sim_s,
    })
}

/// A lockstep run starts from a fresh robot: an empty disk under `root` (marked as the
/// simulator's with [`DISK_MARK`], so a mistyped `--out` never wipes a directory it did not
/// make).
fn fresh_robot_disk(root: &Path) -> anyhow::Result<()> {
    let mark = root.join(DISK_MARK);
    if root.exists() {
        let empty = std::fs::read_dir(root)?.next().is_none();
        if !empty && !mark.exists() {
            anyhow::bail!(
                "{} exists and is not a simulated robot's disk (no {DISK_MARK}): choose another --out",
                root.display()
            );
        }
        for sub in ["runs", "etc"] {
            let p: PathBuf = root.join(sub);
            if p.exists() {
                std::fs::remove_dir_all(&p)?;
            }
        }
    }
    std::fs::create_dir_all(root)?;
    std::fs::write(
        &mark,
        "the simulated robot's disk of `passangle-sim demo`: emptied at every lockstep run\n",
    )?;
    Ok(())
}

/// The file that marks a directory as a simulated robot's disk.
pub const DISK_MARK: &str = ".passangle-sim-robot";
