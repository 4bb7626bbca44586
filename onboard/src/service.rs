//! The onboard service's imperative shell: moves bytes, packets, frames and time between the IO
//! (serial ports, the lidar socket, the camera, the disk) and the pure cores ([`OnboardRadio`],
//! [`McuSession`], [`RunMachine`], [`RunRecorder`]).
//!
//! It lives in the library so that the `passangle-onboard` binary and the simulator's demo run the
//! very same loop: the binary opens real serial ports and sockets, the simulator hands in
//! pseudo-terminals and a simulated camera. One thread runs the loop (every
//! [`LOOP_PERIOD`]); the lidar socket and the camera have their own reader threads feeding bounded
//! channels; processing a run runs on a worker thread, and the radio's disk work (reading an
//! earlier run's cloud for a fetch, decimating its preview, marking a result delivered) runs on
//! the IO worker ([`IoWorker`], bounded queues), so the loop (MCU heartbeat, radio) never waits on
//! disk or CPU work. Warnings about dropped radio frames are rate limited (one line per
//! [`DROP_LOG_PERIOD_US`] with the counts), so a flood cannot fill the log.
//!
//! Safety: on shutdown, and whenever the loop ends for any reason, the MCU gets an immediate stop;
//! if the process dies instead, the firmware stops by heartbeat loss.

use std::io::{self, Read, Write};
use std::net::SocketAddrV4;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TryRecvError, TrySendError, sync_channel};
use std::thread;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use protocol::common::LogLevel;
use protocol::radio::{MeasurementResult, Phase, RefuseReason, RobotStatus, StartMeasurement};

use crate::cloud::Cloud;
use crate::config::{self, CameraSource, OnboardConfig};
use crate::link::mcu::{McuEvent, McuSession, McuSessionConfig, MotionIntent};
use crate::link::preview;
use crate::link::radio::{OnboardRadio, RadioRequest, START_ID};
use crate::link::reliable::LinkConfig;
use crate::recorder::{self, RecordedOutcome, Recording, ResultRecord, RunRecorder};
use crate::run::{Action, Observations, Outcome, RunMachine};
use crate::vlp16::Vlp16Packet;

/// Period of the main loop.
pub const LOOP_PERIOD: Duration = Duration::from_millis(2);

/// A byte stream to a peer (a serial port, a pseudo-terminal, an in-memory pipe). Reads return
/// `Ok(0)`, `WouldBlock` or `TimedOut` when nothing is there; they must not block for long.
pub trait Port: Read + Write + Send {}
impl<T: Read + Write + Send> Port for T {}

/// One UDP datagram from the lidar.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LidarPacket {
    /// Wall clock at reception, ns since the Unix epoch (the pcap stamp).
    pub wall_ns: u64,
    /// Sender.
    pub src: SocketAddrV4,
    /// Receiver (the bound address).
    pub dst: SocketAddrV4,
    /// UDP payload.
    pub payload: Vec<u8>,
    /// From the position port (8308) rather than the data port.
    pub position: bool,
}

/// One depth frame (Z16).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DepthFrame {
    /// Width, pixels.
    pub width: u16,
    /// Height, pixels.
    pub height: u16,
    /// Row-major depth in units of the configured depth scale, 0 = no return.
    pub depth: Vec<u16>,
}

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
}

/// Builds the cloud and computes the angles of a recorded run (see `crate::process`).
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
        odometry: protocol::mcu::Odometry,
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
        intrinsics: recorder::Intrinsics,
    },
}

/// A run processed while it is recorded (see [`Processor::start_live`]).
pub trait LiveRun: Send {
    /// The next item, in arrival order.
    fn push(&mut self, item: SensorItem);
    /// The robot is at rest and the recording closed: the result.
    fn finish(self: Box<Self>, input: &ProcessInput) -> Result<Processed, String>;
}

/// Items waiting for the live worker: about 4 s of lidar packets, beyond which the worker has
/// fallen behind for good and the run is processed from its recording instead.
const LIVE_QUEUE: usize = 4_096;

/// The live processing of the current run, on its own thread.
struct LiveWorker {
    data: SyncSender<SensorItem>,
    finish: SyncSender<ProcessInput>,
    result: Receiver<WorkerMsg>,
}

impl LiveWorker {
    /// Starts `live` on a thread; `None` (logged) if the thread cannot start.
    fn spawn(
        run_id: u32,
        mut live: Box<dyn LiveRun>,
        preview: config::PreviewConfig,
    ) -> Option<Self> {
        let (data, data_rx) = sync_channel::<SensorItem>(LIVE_QUEUE);
        let (finish, finish_rx) = sync_channel::<ProcessInput>(1);
        let (result_tx, result) = sync_channel(2);
        let spawned = thread::Builder::new()
            .name(format!("live-run-{run_id}"))
            .spawn(move || {
                // Ends when the service drops the data sender: at the stop (then the finish
                // input is waiting) or when the run is cancelled or falls behind (then not).
                while let Ok(item) = data_rx.recv() {
                    live.push(item);
                }
                if let Ok(input) = finish_rx.recv() {
                    let started = Instant::now();
                    let outcome = live.finish(&input);
                    tracing::info!(
                        run_id,
                        seconds = started.elapsed().as_secs_f64(),
                        "live processing finished"
                    );
                    complete(outcome, &input.run_dir, preview, &result_tx);
                }
            });
        match spawned {
            Ok(_) => Some(Self {
                data,
                finish,
                result,
            }),
            Err(e) => {
                tracing::warn!(run_id, "live processing not started: {e}");
                None
            }
        }
    }
}

/// systemd notifications (the binary sends them with `sd_notify`; tests ignore them).
pub trait Notifier {
    /// Sockets, ports and camera are open.
    fn ready(&mut self);
    /// The loop is alive.
    fn watchdog(&mut self);
    /// A one-line status for `systemctl status`.
    fn status(&mut self, text: &str);
    /// Shutting down.
    fn stopping(&mut self);
}

/// A notifier that does nothing.
#[derive(Debug, Default)]
pub struct NoNotify;

impl Notifier for NoNotify {
    fn ready(&mut self) {}
    fn watchdog(&mut self) {}
    fn status(&mut self, _: &str) {}
    fn stopping(&mut self) {}
}

/// Everything the loop reads from and writes to.
pub struct Io {
    /// The radio modem.
    pub radio: Box<dyn Port>,
    /// The UART to the firmware.
    pub mcu: Box<dyn Port>,
    /// Lidar packets (from [`spawn_lidar_reader`] or the simulator).
    pub lidar: Receiver<LidarPacket>,
    /// Depth frames (`None`: no camera).
    pub depth: Option<Receiver<DepthFrame>>,
    /// Fault injection for the simulator: when set, the loop ends at once *without* stopping the
    /// robot or closing the run, as if the process had been killed (`None` in production).
    pub crash: Option<Arc<AtomicBool>>,
}

/// Why the service could not start or had to stop.
#[derive(Debug, thiserror::Error)]
pub enum ServiceError {
    /// Configuration files.
    #[error(transparent)]
    Config(#[from] config::ConfigError),
    /// The pairing-key file.
    #[error(transparent)]
    Keys(#[from] crate::link::keys::KeyFileError),
    /// No random source for the radio sessions.
    #[error("radio session: {0}")]
    Session(#[from] crate::link::session::SessionError),
    /// The recording root.
    #[error(transparent)]
    Recorder(#[from] recorder::RecorderError),
    /// A port failed for good.
    #[error("{what}: {source}")]
    Io {
        /// Which port.
        what: &'static str,
        /// The error.
        source: io::Error,
    },
}

/// Counters exposed for logs and tests.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ServiceStats {
    /// What the radio end dropped (unauthenticated, unopened, rate limited) and opened.
    pub radio: crate::link::radio::RadioStats,
    /// Longest time between the starts of two loop iterations since the service started, us
    /// (the MCU heartbeat leaves once per iteration; the firmware stops after 100 ms without).
    pub max_loop_gap_us: u64,
    /// Longest time one loop iteration spent working (the gap less the sleep and the
    /// scheduler's lateness), us: what the loop itself waited for, including any time the
    /// scheduler gave its core to other work.
    pub max_loop_work_us: u64,
    /// Most CPU time the loop's thread used in one iteration, us. Unlike the two wall-clock
    /// figures above it does not grow when the machine is busy, so it says whether the loop
    /// itself does long work (a fetch read on the loop would cost hundreds of ms here).
    pub max_loop_cpu_us: u64,
    /// Fetches refused because the IO worker's queue was full.
    pub fetches_busy: u64,
    /// Lidar data packets that passed the checked view.
    pub lidar_packets: u64,
    /// Lidar packets that did not (wrong length, bad block flags, ...): dropped and counted.
    pub lidar_malformed: u64,
    /// Lidar frames (revolutions) seen in the current or last run.
    pub lidar_frames: u32,
    /// Depth frames received.
    pub depth_frames: u64,
    /// Starts refused (authentication, replay, busy, parameters).
    pub starts_refused: u64,
}

/// Handle to read the service's counters from another thread (tests, the simulator).
pub type SharedStats = Arc<std::sync::Mutex<ServiceStats>>;

fn wall_us() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_micros()).unwrap_or(u64::MAX))
}

/// CPU time used by the calling thread, us (0 where the clock is unavailable).
fn thread_cpu_us() -> u64 {
    use nix::time::{ClockId, clock_gettime};
    clock_gettime(ClockId::CLOCK_THREAD_CPUTIME_ID).map_or(0, |t| {
        u64::try_from(t.tv_sec()).unwrap_or(0) * 1_000_000
            + u64::try_from(t.tv_nsec()).unwrap_or(0) / 1_000
    })
}

fn is_quiet(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut | io::ErrorKind::Interrupted
    )
}

fn read_available(port: &mut dyn Port, buf: &mut [u8]) -> io::Result<usize> {
    match port.read(buf) {
        Ok(n) => Ok(n),
        Err(e) if is_quiet(&e) => Ok(0),
        Err(e) => Err(e),
    }
}

struct Worker {
    run_id: u32,
    rx: Receiver<WorkerMsg>,
    /// The result has been handed to the run machine; only the files are still being written.
    delivered: bool,
}

/// What a processing thread reports, in this order.
enum WorkerMsg {
    /// The result and its preview (or why there is none): goes to the handheld at once.
    Done(Result<Ready, String>),
    /// `cloud.ply` and `side_view.svg` are written (errors, e.g. a full disk, named).
    Saved(Vec<String>),
}

/// A result ready to send.
struct Ready {
    result: MeasurementResult,
    preview_mm: Vec<[i16; 3]>,
}

/// The end of every processing thread (live or from the recording): the heavy work after the
/// angles (preview decimation, PLY encoding, writing the files) stays off the service loop, and
/// the result is reported before the files are written.
fn complete(
    outcome: Result<Processed, String>,
    run_dir: &std::path::Path,
    preview: config::PreviewConfig,
    tx: &SyncSender<WorkerMsg>,
) {
    let processed = match outcome {
        Ok(p) => p,
        Err(e) => {
            let _ = tx.send(WorkerMsg::Done(Err(e)));
            return;
        }
    };
    let preview_mm = preview::decimate(
        &processed.cloud.points_m,
        preview.voxel_m,
        preview.max_points,
    );
    let _ = tx.send(WorkerMsg::Done(Ok(Ready {
        result: processed.result,
        preview_mm,
    })));
    let mut errors = Vec::new();
    let mut ply = Vec::new();
    match crate::cloud::write_ply(
        &mut ply,
        &processed.cloud,
        crate::cloud::PlyEncoding::BinaryLittleEndian,
    ) {
        Ok(()) => {
            if let Err(e) = recorder::write_atomic(&run_dir.join("cloud.ply"), &ply) {
                errors.push(e.to_string());
            }
        }
        Err(e) => errors.push(format!("cloud.ply: {e}")),
    }
    if let Err(e) = recorder::write_atomic(&run_dir.join("side_view.svg"), processed.svg.as_bytes())
    {
        errors.push(e.to_string());
    }
    let _ = tx.send(WorkerMsg::Saved(errors));
}

/// How often the loop logs the radio frames it dropped (one line with the counts), us.
pub const DROP_LOG_PERIOD_US: u64 = 10_000_000;

/// Jobs the IO worker's queue holds: a handheld asking for more waits for a refusal (`Busy`).
const IO_QUEUE: usize = 4;

/// Disk and CPU work the loop hands off.
enum IoJob {
    /// Read an earlier run's result and cloud, decimate the preview.
    Fetch { run_id: u32, seq: u16 },
    /// Mark a run's result delivered (`DELIVERED` file).
    MarkDelivered { run_id: u32 },
    /// Close a run's recording: `result.json` (if any), fsync the streams, the outcome in
    /// `meta.json`, remove `INCOMPLETE`. The jobs run in order, so a later fetch of the run finds
    /// its result on disk.
    Finish {
        run_id: u32,
        recorder: Box<RunRecorder>,
        result: Option<ResultRecord>,
        outcome: RecordedOutcome,
    },
}

/// What the IO worker reports.
enum IoDone {
    Fetched {
        run_id: u32,
        seq: u16,
        ready: Option<Ready>,
    },
    Marked {
        run_id: u32,
        error: Option<String>,
    },
    Finished {
        run_id: u32,
        errors: Vec<String>,
    },
}

/// The IO worker thread (see the module docs): bounded job and result queues.
struct IoWorker {
    jobs: SyncSender<IoJob>,
    done: Receiver<IoDone>,
    handle: Option<thread::JoinHandle<()>>,
}

impl IoWorker {
    fn spawn(root: PathBuf, preview: config::PreviewConfig) -> io::Result<Self> {
        let (jobs, job_rx) = sync_channel::<IoJob>(IO_QUEUE);
        let (done_tx, done) = sync_channel::<IoDone>(IO_QUEUE);
        let handle = thread::Builder::new()
            .name("radio-io".into())
            .spawn(move || {
                while let Ok(job) = job_rx.recv() {
                    let out = match job {
                        IoJob::Fetch { run_id, seq } => IoDone::Fetched {
                            run_id,
                            seq,
                            ready: Recording::open_run(&root, run_id)
                                .ok()
                                .and_then(|rec| recorded_ready(&rec, preview)),
                        },
                        IoJob::MarkDelivered { run_id } => IoDone::Marked {
                            run_id,
                            error: recorder::mark_delivered(&root, run_id)
                                .err()
                                .map(|e| e.to_string()),
                        },
                        IoJob::Finish {
                            run_id,
                            mut recorder,
                            result,
                            outcome,
                        } => {
                            if let Some(r) = &result {
                                recorder.save_result(r);
                            }
                            IoDone::Finished {
                                run_id,
                                errors: recorder.finish(outcome),
                            }
                        }
                    };
                    if done_tx.send(out).is_err() {
                        return;
                    }
                }
            })?;
        Ok(Self {
            jobs,
            done,
            handle: Some(handle),
        })
    }

    /// Runs `waiting` and everything queued to the end (closing recordings), then stops the
    /// thread. Results are read and dropped meanwhile, so the worker never blocks on them.
    fn drain(mut self, waiting: impl IntoIterator<Item = IoJob>) {
        for job in waiting {
            let mut job = job;
            loop {
                match self.jobs.try_send(job) {
                    Ok(()) => break,
                    Err(TrySendError::Full(j)) => {
                        job = j;
                        while self.done.try_recv().is_ok() {}
                        thread::sleep(Duration::from_millis(1));
                    }
                    Err(TrySendError::Disconnected(_)) => return,
                }
            }
        }
        let Some(handle) = self.handle.take() else {
            return;
        };
        drop(self.jobs);
        while !handle.is_finished() {
            while self.done.try_recv().is_ok() {}
            thread::sleep(Duration::from_millis(1));
        }
        let _ = handle.join();
    }
}

/// A recorded run's result with its preview decimated from `cloud.ply` (none without a result).
fn recorded_ready(rec: &Recording, preview: config::PreviewConfig) -> Option<Ready> {
    let result = rec.result.as_ref()?;
    let points = crate::cloud::read_cloud(&rec.dir.join("cloud.ply"))
        .map(|(c, _)| c.points_m)
        .unwrap_or_default();
    Some(Ready {
        result: result.to_wire(),
        preview_mm: preview::decimate(&points, preview.voxel_m, preview.max_points),
    })
}

/// The service state between loop iterations.
struct Service {
    config: OnboardConfig,
    config_text: String,
    radio: OnboardRadio,
    io_worker: IoWorker,
    /// Jobs (delivered marks, closing recordings) waiting for room in the IO worker's queue, in
    /// order; bounded by the runs and results there are.
    io_waiting: std::collections::VecDeque<IoJob>,
    /// The current run's result, saved with its recording when the run ends.
    result_record: Option<ResultRecord>,
    /// Radio counters at the last drop log line.
    logged_radio: crate::link::radio::RadioStats,
    next_drop_log_us: u64,
    mcu: McuSession,
    run: RunMachine,
    recorder: Option<RunRecorder>,
    params: Option<StartMeasurement>,
    worker: Option<Worker>,
    live: Option<LiveWorker>,
    processor: Arc<dyn Processor>,
    stats: ServiceStats,
    shared: SharedStats,
    last_lidar_us: Option<u64>,
    last_depth_us: Option<u64>,
    last_azimuth: Option<u16>,
    depth_seen: u64,
    odometry_xy_m: Option<[f32; 2]>,
    epoch: Instant,
    /// Wall clock at `epoch`, us since the Unix epoch: recordings stamp everything on the wall
    /// clock (the pcap's clock), advanced by the monotonic clock so stamps never go backwards.
    wall_epoch_us: u64,
}

fn millis(ms: u64) -> u64 {
    ms.saturating_mul(1_000)
}

/// Runs the service until `shutdown` is set. `config_text` is recorded with every run.
pub fn run(
    config: OnboardConfig,
    config_text: String,
    mut io: Io,
    processor: Arc<dyn Processor>,
    shutdown: &AtomicBool,
    notifier: &mut dyn Notifier,
    shared: SharedStats,
) -> Result<(), ServiceError> {
    let keys: Vec<_> = crate::link::keys::read(&config.radio.key_file)?
        .into_iter()
        .map(|e| {
            tracing::info!(key_id = %format_args!("{:08x}", e.id), label = %e.label, "paired handheld");
            e.key
        })
        .collect();
    let entropy = crate::link::session::Entropy::from_os()?;
    std::fs::create_dir_all(&config.recording.root).map_err(|e| recorder::RecorderError::Io {
        path: config.recording.root.clone(),
        source: e,
    })?;
    let next_run_id = recorder::next_run_id(&config.recording.root)?;
    let epoch = Instant::now();
    // Seqs start from the clock so a restarted service does not reuse the seqs the peer remembers.
    let seed_seq = (wall_us() / 1_000) as u16;
    let mcu = McuSession::new(
        McuSessionConfig {
            link: LinkConfig::MCU,
            heartbeat_period_us: millis(config.mcu.heartbeat_period_ms),
            resend_us: 200_000,
            firmware: config.mcu.firmware.to_wire(),
            accel_mps2: config.mcu.accel_mps2,
            jerk_mps3: config.mcu.jerk_mps3,
            status_timeout_us: 500_000,
        },
        seed_seq,
    );
    let mut s = Service {
        radio: OnboardRadio::new(
            LinkConfig::RADIO,
            keys,
            entropy,
            seed_seq.wrapping_add(0x8000),
        ),
        io_worker: IoWorker::spawn(config.recording.root.clone(), config.preview).map_err(
            |source| ServiceError::Io {
                what: "starting the radio IO thread",
                source,
            },
        )?,
        io_waiting: std::collections::VecDeque::new(),
        result_record: None,
        logged_radio: crate::link::radio::RadioStats::default(),
        next_drop_log_us: DROP_LOG_PERIOD_US,
        mcu,
        run: RunMachine::new(config.run, next_run_id),
        recorder: None,
        params: None,
        worker: None,
        live: None,
        processor,
        stats: ServiceStats::default(),
        shared,
        last_lidar_us: None,
        last_depth_us: None,
        last_azimuth: None,
        depth_seen: 0,
        odometry_xy_m: None,
        epoch,
        wall_epoch_us: wall_us(),
        config,
        config_text,
    };
    s.recover_runs();
    notifier.ready();
    notifier.status("idle");
    let result = s.main_loop(&mut io, shutdown, notifier);
    if io.crash.as_ref().is_some_and(|c| c.load(Ordering::Relaxed)) {
        // Simulated kill: leave everything as a dead process would.
        std::mem::forget(s.recorder.take());
        return result;
    }
    // Whatever ended the loop: stop the robot now.
    s.mcu.set_intent(MotionIntent::StopNow);
    let now = s.now_us();
    s.mcu.poll(now);
    let bytes = s.mcu.transmit(now);
    let _ = io.mcu.write_all(&bytes);
    let _ = io.mcu.flush();
    if let Some(r) = s.recorder.take() {
        r.finish(RecordedOutcome::Aborted("service stopped".into()));
    }
    // Recordings the IO worker still has to close are closed before the service ends.
    let waiting: Vec<IoJob> = s.io_waiting.drain(..).collect();
    s.io_worker.drain(waiting);
    notifier.stopping();
    result
}

impl Service {
    fn now_us(&self) -> u64 {
        u64::try_from(self.epoch.elapsed().as_micros()).unwrap_or(u64::MAX)
    }

    /// Sensor streams are recorded from the checks until the robot is at rest: processing needs
    /// nothing after that, and a shorter recording processes faster.
    fn recording_sensors(&self) -> bool {
        matches!(
            self.run.phase(),
            Phase::Checks | Phase::Driving | Phase::Stopping
        )
    }

    fn wall_of(&self, mono_us: u64) -> u64 {
        self.wall_epoch_us.saturating_add(mono_us)
    }

    /// At start: report crashed runs, and offer the newest undelivered result again.
    fn recover_runs(&mut self) {
        let root = self.config.recording.root.clone();
        let last = self.run.run_id().max(1);
        let next = recorder::next_run_id(&root).unwrap_or(last);
        let mut offered = false;
        for run_id in (1..next).rev().take(50) {
            let Ok(rec) = Recording::open_run(&root, run_id) else {
                continue;
            };
            if rec.incomplete {
                tracing::warn!(run_id, dir = %rec.dir.display(), "run did not finish (crash?): recording kept, marked INCOMPLETE");
            }
            if !offered && !rec.delivered && rec.result.is_some() {
                offered = true;
                self.offer_recorded(&rec);
            }
        }
    }

    fn offer_recorded(&mut self, rec: &Recording) -> bool {
        let Some(ready) = recorded_ready(rec, self.config.preview) else {
            return false;
        };
        match self.radio.deliver(ready.result, &ready.preview_mm) {
            Ok(()) => true,
            Err(e) => {
                tracing::error!("cannot offer run {}: {e}", rec.dir.display());
                false
            }
        }
    }

    /// Results of the IO worker; delivered marks that waited for room.
    fn check_io(&mut self) {
        while let Some(job) = self.io_waiting.pop_front() {
            match self.io_worker.jobs.try_send(job) {
                Ok(()) => {}
                Err(TrySendError::Full(job)) => {
                    self.io_waiting.push_front(job);
                    break;
                }
                Err(TrySendError::Disconnected(_)) => {
                    tracing::error!("the radio IO thread ended: recordings are not closed");
                    break;
                }
            }
        }
        while let Ok(done) = self.io_worker.done.try_recv() {
            match done {
                IoDone::Fetched {
                    run_id,
                    seq: _,
                    ready: Some(r),
                } => {
                    if let Err(e) = self.radio.deliver(r.result, &r.preview_mm) {
                        tracing::error!("cannot offer run {run_id}: {e}");
                    }
                }
                IoDone::Fetched {
                    run_id,
                    seq,
                    ready: None,
                } => self.radio.refuse(
                    protocol::ids::FETCH_RUN,
                    seq,
                    RefuseReason::UnknownRun,
                    &format!("run {run_id} has no result on the robot"),
                ),
                IoDone::Marked {
                    run_id,
                    error: None,
                } => tracing::info!(run_id, "result delivered to the handheld"),
                IoDone::Marked {
                    run_id,
                    error: Some(e),
                } => tracing::warn!("run {run_id}: result acknowledged, but {e}"),
                IoDone::Finished { run_id, errors } => {
                    for e in errors {
                        tracing::error!(run_id, "{e}");
                    }
                }
            }
        }
    }

    /// One warning per [`DROP_LOG_PERIOD_US`] with what the radio dropped since the last one.
    fn log_radio_drops(&mut self, now: u64) {
        if now < self.next_drop_log_us {
            return;
        }
        self.next_drop_log_us = now + DROP_LOG_PERIOD_US;
        let s = self.radio.stats();
        let l = self.logged_radio;
        let d = |a: u64, b: u64| a.saturating_sub(b);
        let dropped = d(s.unauthenticated, l.unauthenticated)
            + d(s.unopened, l.unopened)
            + d(s.inits_refused, l.inits_refused)
            + d(s.rate_limited, l.rate_limited);
        if dropped > 0 {
            tracing::warn!(
                unauthenticated = d(s.unauthenticated, l.unauthenticated),
                unopened = d(s.unopened, l.unopened),
                inits_refused = d(s.inits_refused, l.inits_refused),
                rate_limited = d(s.rate_limited, l.rate_limited),
                replies_suppressed = d(s.replies_suppressed, l.replies_suppressed),
                "radio frames dropped in the last {} s",
                DROP_LOG_PERIOD_US / 1_000_000
            );
        }
        self.logged_radio = s;
    }

    fn main_loop(
        &mut self,
        io: &mut Io,
        shutdown: &AtomicBool,
        notifier: &mut dyn Notifier,
    ) -> Result<(), ServiceError> {
        let mut buf = [0u8; 4096];
        let mut next_watchdog = 0;
        let mut next_flush = 0;
        let mut last_phase = Phase::Idle;
        let mut last_start: Option<u64> = None;
        while !shutdown.load(Ordering::Relaxed)
            && !io.crash.as_ref().is_some_and(|c| c.load(Ordering::Relaxed))
        {
            let loop_start = Instant::now();
            let cpu_start = thread_cpu_us();
            let now = self.now_us();
            if let Some(t) = last_start {
                self.stats.max_loop_gap_us = self.stats.max_loop_gap_us.max(now - t);
            }
            last_start = Some(now);
            let n =
                read_available(io.radio.as_mut(), &mut buf).map_err(|source| ServiceError::Io {
                    what: "radio port",
                    source,
                })?;
            for req in self.radio.receive(now, &buf[..n]) {
                self.on_request(now, req);
            }
            let n =
                read_available(io.mcu.as_mut(), &mut buf).map_err(|source| ServiceError::Io {
                    what: "MCU port",
                    source,
                })?;
            for ev in self.mcu.receive(now, &buf[..n]) {
                self.on_mcu(now, ev);
            }
            self.drain_lidar(now, &io.lidar);
            if let Some(depth) = &io.depth {
                self.drain_depth(now, depth);
            }
            self.check_worker(now);
            self.check_io();
            self.log_radio_drops(now);
            let obs = self.observations(now);
            let actions = self.run.tick(now, &obs);
            self.execute(now, actions);
            self.radio.poll(now);
            self.mcu.poll(now);
            let out = self.mcu.transmit(now);
            if !out.is_empty() {
                io.mcu.write_all(&out).map_err(|source| ServiceError::Io {
                    what: "MCU port",
                    source,
                })?;
            }
            let out = self.radio.transmit(now);
            if !out.is_empty() {
                io.radio
                    .write_all(&out)
                    .map_err(|source| ServiceError::Io {
                        what: "radio port",
                        source,
                    })?;
            }
            if now >= next_watchdog {
                next_watchdog = now + 1_000_000;
                notifier.watchdog();
            }
            if now >= next_flush {
                next_flush = now + millis(self.config.recording.flush_period_ms);
                if let Some(r) = &mut self.recorder {
                    r.flush();
                }
                self.report_recorder_errors();
            }
            if self.run.phase() != last_phase {
                last_phase = self.run.phase();
                notifier.status(&format!("run {}: {}", self.run.run_id(), last_phase));
            }
            self.stats.radio = self.radio.stats();
            if let Ok(mut shared) = self.shared.lock() {
                *shared = self.stats;
            }
            let work = u64::try_from(loop_start.elapsed().as_micros()).unwrap_or(u64::MAX);
            self.stats.max_loop_work_us = self.stats.max_loop_work_us.max(work);
            let cpu = thread_cpu_us().saturating_sub(cpu_start);
            self.stats.max_loop_cpu_us = self.stats.max_loop_cpu_us.max(cpu);
            if let Some(rest) = LOOP_PERIOD.checked_sub(loop_start.elapsed()) {
                thread::sleep(rest);
            }
        }
        Ok(())
    }

    fn observations(&self, now: u64) -> Observations {
        let fresh = |t: Option<u64>, timeout_ms: u64| {
            t.is_some_and(|t| now.saturating_sub(t) <= millis(timeout_ms))
        };
        Observations {
            lidar_ok: fresh(self.last_lidar_us, self.config.lidar.alive_timeout_ms),
            camera_ok: self.config.camera.source == CameraSource::None
                || fresh(self.last_depth_us, self.config.camera.alive_timeout_ms),
            firmware_ok: self.mcu.firmware_ok(now),
            interlocks: self.mcu.interlocks(),
            at_rest: self.mcu.at_rest(),
            odometry_xy_m: self.odometry_xy_m,
            handheld_silent_us: self.radio.handheld_silent_us(now),
            lidar_frames: self.stats.lidar_frames,
            battery_mv: self.mcu.battery_mv(),
        }
    }

    fn on_request(&mut self, now: u64, req: RadioRequest) {
        match req {
            RadioRequest::Start {
                params,
                seq,
                key_id,
            } => {
                tracing::info!(key_id = %format_args!("{key_id:08x}"), "start from a paired handheld");
                let actions = self.run.start(now, params, seq);
                self.execute(now, actions);
            }
            RadioRequest::Abort { run_id } => {
                let actions = self.run.abort(now, run_id);
                self.execute(now, actions);
            }
            RadioRequest::ResultAck { run_id } => {
                // Bounded: at most 64 marks wait for the worker (a handheld acks each run once
                // per offer, and the link drops duplicates).
                let waiting = self
                    .io_waiting
                    .iter()
                    .filter(|j| matches!(j, IoJob::MarkDelivered { .. }))
                    .count();
                if waiting < 64 {
                    self.io_waiting.push_back(IoJob::MarkDelivered { run_id });
                }
            }
            RadioRequest::Fetch { run_id, seq } => {
                if self
                    .io_worker
                    .jobs
                    .try_send(IoJob::Fetch { run_id, seq })
                    .is_err()
                {
                    self.stats.fetches_busy += 1;
                    self.radio.refuse(
                        protocol::ids::FETCH_RUN,
                        seq,
                        RefuseReason::Busy,
                        "earlier fetches are still being read from disk; ask again",
                    );
                }
            }
            RadioRequest::Status => {
                let status = self.status(now);
                if let Err(e) = self.radio.send_status(&status) {
                    tracing::error!("status: {e}");
                }
            }
            RadioRequest::Refused { reason, detail } => {
                tracing::warn!(%reason, "refused radio command: {detail}");
            }
        }
    }

    fn status(&self, now: u64) -> RobotStatus {
        let obs = self.observations(now);
        RobotStatus {
            phase: self.run.phase(),
            run_id: self.run.run_id(),
            firmware_ok: obs.firmware_ok,
            lidar_ok: obs.lidar_ok,
            camera_ok: obs.camera_ok,
            interlocks: obs.interlocks,
            pending_results: self.radio.pending_results(),
            disk_free_mib: recorder::disk_free_mib(&self.config.recording.root).unwrap_or(0),
            battery_mv: obs.battery_mv,
        }
    }

    fn on_mcu(&mut self, now: u64, ev: McuEvent) {
        match ev {
            McuEvent::Hello(h) => tracing::info!(version = h.version, "firmware said hello"),
            McuEvent::Odometry { rx_us, odometry } => {
                self.odometry_xy_m = Some([odometry.x_m, odometry.y_m]);
                let wall = self.wall_of(rx_us);
                let record = self.recording_sensors();
                if let Some(r) = self.recorder.as_mut().filter(|_| record) {
                    r.odometry(wall, &odometry);
                }
                if record {
                    self.feed_live(SensorItem::Odometry {
                        wall_us: wall,
                        odometry,
                    });
                }
            }
            McuEvent::Status(_) => {}
            McuEvent::Rejected(r) => {
                let why = format!("{} {}", r.reason, r.field.as_str());
                let text = format!("firmware rejected {:#06x}: {why}", r.msg_id);
                tracing::warn!("{text}");
                self.radio.send_log(LogLevel::Warn, &text);
                if r.msg_id == protocol::ids::DRIVE && self.run.is_active() {
                    let actions = self.run.drive_refused(now, why.trim_end());
                    self.execute(now, actions);
                }
            }
            McuEvent::DriveRetried(r) => {
                let text = format!(
                    "firmware refused the drive ({} {}): heartbeat late once, sending it again",
                    r.reason,
                    r.field.as_str()
                );
                tracing::warn!("{text}");
                self.radio.send_log(LogLevel::Warn, &text);
            }
            McuEvent::Log(l) => tracing::info!(target: "firmware", "{}", l.text.as_str()),
            McuEvent::Undecodable(e) => tracing::debug!("MCU frame: {e}"),
        }
    }

    fn drain_lidar(&mut self, now: u64, rx: &Receiver<LidarPacket>) {
        loop {
            let p = match rx.try_recv() {
                Ok(p) => p,
                Err(TryRecvError::Empty | TryRecvError::Disconnected) => return,
            };
            let record = self.recording_sensors();
            if p.position {
                if record {
                    self.record_lidar(p);
                }
                continue;
            }
            let Ok(view) = Vlp16Packet::new_checked(&p.payload[..]) else {
                self.stats.lidar_malformed += 1;
                continue;
            };
            if view.check_fields().is_err() {
                self.stats.lidar_malformed += 1;
                continue;
            }
            self.stats.lidar_packets += 1;
            self.last_lidar_us = Some(now);
            let azimuth = view.azimuth_raw(0);
            if self.last_azimuth.is_some_and(|a| azimuth < a) && record {
                self.stats.lidar_frames += 1;
            }
            self.last_azimuth = Some(azimuth);
            if record {
                self.record_lidar(p);
            }
        }
    }

    /// A lidar packet (data or position) into the recording and the live processing.
    fn record_lidar(&mut self, p: LidarPacket) {
        if let Some(r) = self.recorder.as_mut() {
            r.lidar_packet(p.wall_ns, p.src, p.dst, &p.payload);
        }
        self.feed_live(SensorItem::Lidar {
            wall_ns: p.wall_ns / 1_000 * 1_000,
            payload: p.payload,
            position: p.position,
        });
    }

    /// Hands an item to the live processing, if it runs; a full queue or a dead worker ends it
    /// (the run is then processed from its recording after the stop).
    fn feed_live(&mut self, item: SensorItem) {
        let Some(live) = &self.live else { return };
        let why = match live.data.try_send(item) {
            Ok(()) => return,
            Err(TrySendError::Full(_)) => "it fell behind the sensors",
            Err(TrySendError::Disconnected(_)) => "its thread ended",
        };
        let text = format!(
            "run {}: live processing stopped ({why}); the run is processed from its recording after the stop",
            self.run.run_id()
        );
        tracing::warn!("{text}");
        self.radio.send_log(LogLevel::Warn, &text);
        self.live = None;
    }

    fn drain_depth(&mut self, now: u64, rx: &Receiver<DepthFrame>) {
        while let Ok(f) = rx.try_recv() {
            self.stats.depth_frames += 1;
            let expected = usize::from(f.width) * usize::from(f.height);
            if f.depth.len() != expected {
                tracing::warn!(
                    len = f.depth.len(),
                    expected,
                    "depth frame of the wrong size dropped"
                );
                continue;
            }
            self.last_depth_us = Some(now);
            self.depth_seen += 1;
            let record = self.recording_sensors()
                && self
                    .depth_seen
                    .is_multiple_of(u64::from(self.config.camera.record_every));
            if !record {
                continue;
            }
            let wall_us = self.wall_epoch_us.saturating_add(now);
            let intrinsics = self.config.camera.intrinsics;
            if let Some(r) = self.recorder.as_mut() {
                r.depth_frame(wall_us, f.width, f.height, &f.depth, &intrinsics);
            }
            self.feed_live(SensorItem::Depth {
                wall_us,
                width: f.width,
                height: f.height,
                depth: f.depth,
                intrinsics,
            });
        }
    }

    fn check_worker(&mut self, now: u64) {
        loop {
            let Some(w) = &mut self.worker else { return };
            let msg = match w.rx.try_recv() {
                Ok(m) => m,
                Err(TryRecvError::Empty) => return,
                Err(TryRecvError::Disconnected) if w.delivered => {
                    self.worker = None;
                    return;
                }
                Err(TryRecvError::Disconnected) => {
                    WorkerMsg::Done(Err("processing thread died".to_owned()))
                }
            };
            let run_id = w.run_id;
            match msg {
                WorkerMsg::Done(outcome) => {
                    w.delivered = true;
                    let outcome = outcome.map(|r| self.deliver(&r));
                    let actions = self.run.processing_finished(now, run_id, outcome);
                    self.execute(now, actions);
                }
                WorkerMsg::Saved(errors) => {
                    self.worker = None;
                    for e in errors {
                        let text = format!("run {run_id}: {e}");
                        tracing::error!("{text}");
                        self.radio.send_log(LogLevel::Error, &text);
                    }
                }
            }
        }
    }

    /// The result goes out first; `result.json` is written when the run's recording closes (on
    /// the IO worker); the cloud and the SVG are written by the processing thread.
    fn deliver(&mut self, r: &Ready) {
        if let Err(e) = self.radio.deliver(r.result.clone(), &r.preview_mm) {
            tracing::error!("cannot send the result: {e}");
        }
        if self.recorder.is_some() {
            self.result_record = Some(ResultRecord::from_wire(&r.result));
        }
    }

    fn execute(&mut self, now: u64, actions: Vec<Action>) {
        for a in actions {
            match a {
                Action::Refuse {
                    seq,
                    reason,
                    detail,
                } => {
                    self.stats.starts_refused += 1;
                    tracing::warn!(%reason, "start refused: {detail}");
                    self.radio.refuse(START_ID, seq, reason, &detail);
                }
                Action::BeginRecording { run_id, params } => {
                    self.stats.lidar_frames = 0;
                    self.live = self
                        .processor
                        .start_live()
                        .and_then(|live| LiveWorker::spawn(run_id, live, self.config.preview));
                    match RunRecorder::begin(
                        &self.config.recording.root,
                        run_id,
                        &params,
                        wall_us(),
                        &self.config_text,
                    ) {
                        Ok(r) => {
                            tracing::info!(run_id, dir = %r.dir().display(), "recording");
                            self.recorder = Some(r);
                        }
                        Err(e) => {
                            let text = format!("run {run_id}: cannot record: {e}");
                            tracing::error!("{text}");
                            self.radio.send_log(LogLevel::Error, &text);
                        }
                    }
                    self.params = Some(params);
                }
                Action::Motion(intent) => self.mcu.set_intent(intent),
                Action::StartProcessing {
                    run_id,
                    travelled_m,
                    short_run,
                } => {
                    self.start_worker(run_id, travelled_m, short_run);
                }
                Action::CancelProcessing { .. } => {
                    self.worker = None;
                    self.live = None;
                }
                Action::FinishRecording { run_id, outcome } => {
                    if !matches!(outcome, Outcome::Completed) {
                        self.live = None;
                    }
                    if let Some(r) = self.recorder.take() {
                        let recorded = match outcome {
                            Outcome::Completed => RecordedOutcome::Completed,
                            Outcome::Aborted(s) => RecordedOutcome::Aborted(s),
                            Outcome::Failed(s) => RecordedOutcome::Failed(s),
                        };
                        // The fsyncs and the final files go to the IO worker.
                        self.io_waiting.push_back(IoJob::Finish {
                            run_id,
                            recorder: Box::new(r),
                            result: self.result_record.take(),
                            outcome: recorded,
                        });
                        self.check_io();
                    }
                }
                Action::Progress(p) => {
                    let _ = self.radio.send_progress(&p);
                }
                Action::Log { level, text } => {
                    match level {
                        LogLevel::Error => tracing::error!("{text}"),
                        LogLevel::Warn => tracing::warn!("{text}"),
                        _ => tracing::info!("{text}"),
                    }
                    self.radio.send_log(level, &text);
                }
            }
        }
        let _ = now;
    }

    fn start_worker(&mut self, run_id: u32, travelled_m: f32, short_run: bool) {
        let Some(params) = self.params.clone() else {
            return;
        };
        let run_dir = self
            .config
            .recording
            .root
            .join(recorder::run_dir_name(run_id));
        if let Some(r) = &mut self.recorder {
            r.flush();
        }
        let input = ProcessInput {
            run_dir,
            run_id,
            params,
            travelled_m,
            short_run,
        };
        if let Some(live) = self.live.take() {
            // The worker has everything up to the stop: it finishes as soon as its queue is empty.
            if live.finish.try_send(input.clone()).is_ok() {
                tracing::info!(run_id, "finishing the live processing");
                self.worker = Some(Worker {
                    run_id,
                    rx: live.result,
                    delivered: false,
                });
                return;
            }
        }
        let (tx, rx) = sync_channel(2);
        let processor = Arc::clone(&self.processor);
        let preview = self.config.preview;
        let spawned = thread::Builder::new()
            .name(format!("process-run-{run_id}"))
            .spawn(move || {
                complete(processor.process(&input), &input.run_dir, preview, &tx);
            });
        match spawned {
            Ok(_) => {
                self.worker = Some(Worker {
                    run_id,
                    rx,
                    delivered: false,
                });
            }
            Err(e) => {
                let now = self.now_us();
                let actions = self.run.processing_finished(
                    now,
                    run_id,
                    Err(format!("cannot start processing: {e}")),
                );
                self.execute(now, actions);
            }
        }
    }

    fn report_recorder_errors(&mut self) {
        let Some(r) = &mut self.recorder else { return };
        for e in r.take_new_errors() {
            tracing::error!("recording: {e}");
            self.radio
                .send_log(LogLevel::Error, &format!("recording: {e}"));
        }
    }
}

/// Starts a thread that reads the lidar socket(s) into a bounded channel (about 2 s of packets;
/// when the loop falls behind, the newest packets are dropped and the reader logs it). Returns the
/// channel and the bound data address (useful after binding port 0).
pub fn spawn_lidar_reader(
    config: &config::LidarConfig,
    shutdown: Arc<AtomicBool>,
) -> Result<(Receiver<LidarPacket>, SocketAddrV4), crate::vlp16::source::SourceError> {
    use crate::vlp16::source::{PACKET_BUF_LEN, PacketKind, PacketSource, SourceError, UdpSource};
    let mut source = UdpSource::bind(
        config.data_addr,
        config.position_addr,
        Duration::from_millis(100),
    )?;
    let to_v4 = |a: Option<std::net::SocketAddr>| match a {
        Some(std::net::SocketAddr::V4(v4)) => v4,
        _ => SocketAddrV4::new([0, 0, 0, 0].into(), 0),
    };
    let data_bound = to_v4(source.data_addr().ok());
    // The recording shows the packets as the VLP-16 addressed them: to its standard ports 2368 and
    // 8308, whatever port this service listens on (a test or the demo binds an ephemeral one), so
    // `passangle replay`, VeloView and Wireshark read every recording the same way.
    let data_dst = SocketAddrV4::new(*data_bound.ip(), crate::vlp16::packet::DATA_PORT);
    let position_dst = SocketAddrV4::new(
        *to_v4(source.position_addr()).ip(),
        crate::vlp16::position::POSITION_PORT,
    );
    let (tx, rx) = sync_channel(4_000);
    thread::Builder::new()
        .name("lidar".into())
        .spawn(move || {
            let mut buf = [0u8; PACKET_BUF_LEN];
            let mut dropped = 0u64;
            while !shutdown.load(Ordering::Relaxed) {
                match source.next_packet(&mut buf) {
                    Ok(Some(meta)) => {
                        let position = meta.kind == PacketKind::Position;
                        let packet = LidarPacket {
                            wall_ns: wall_us().saturating_mul(1_000),
                            src: to_v4(meta.src),
                            dst: if position { position_dst } else { data_dst },
                            payload: buf[..meta.len].to_vec(),
                            position,
                        };
                        if tx.try_send(packet).is_err() {
                            dropped += 1;
                            if dropped.is_power_of_two() {
                                tracing::warn!(
                                    dropped,
                                    "lidar packets dropped: the service loop falls behind"
                                );
                            }
                        }
                    }
                    Ok(None) | Err(SourceError::TimedOut(_)) => {}
                    Err(e) => {
                        tracing::error!("lidar: {e}");
                        thread::sleep(Duration::from_millis(100));
                    }
                }
            }
        })
        .map_err(|e| SourceError::Io {
            what: "starting the lidar thread".into(),
            source: e,
        })?;
    Ok((rx, data_bound))
}
