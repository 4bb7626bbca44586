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
//! the IO worker (`IoWorker`, bounded queues), so the loop (MCU heartbeat, radio) never waits on
//! disk or CPU work. Warnings about dropped radio frames are rate limited (one line per
//! [`DROP_LOG_PERIOD_US`] with the counts), so a flood cannot fill the log.
//!
//! Safety: on shutdown, and whenever the loop ends for any reason, the MCU gets an immediate stop;
//! if the process dies instead, the firmware stops by heartbeat loss.

use std::io::{self, Write};
use std::net::SocketAddrV4;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TryRecvError, TrySendError, sync_channel};
use std::thread;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use protocol::common::LogLevel;
use protocol::radio::{
    MAX_RECORD_LEN, MeasurementResult, Phase, RecordFile, RefuseReason, RobotStatus,
    StartMeasurement,
};

// The depth frame and the processor interface are built without the `service` feature (the
// handheld's replay uses the processing); the service's users name them from here as well.
pub use crate::camera::DepthFrame;
pub use crate::process::{LiveRun, ProcessInput, Processed, Processor, SensorItem};

use crate::config::{self, CameraSource, OnboardConfig};
use crate::recorder::{self, RecordedOutcome, Recording, ResultRecord, RunRecorder};
use crate::report::LabFile;
use crate::run::{Action, Observations, Outcome, RunMachine};
use crate::signed::{self, Signer};
use link::Port;
use link::mcu::{McuEvent, McuSession, McuSessionConfig, MotionIntent};
use link::preview;
use link::radio::{OnboardRadio, RadioRequest, START_ID};
use link::record_files::OutgoingRecord;
use link::reliable::LinkConfig;
use link::session::Entropy;
use vlp16::Vlp16Packet;

/// Period of the main loop.
pub const LOOP_PERIOD: Duration = Duration::from_millis(2);

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

/// Items waiting for the live worker: about 4 s of lidar packets, beyond which the worker has
/// fallen behind for good and the run is processed from its recording instead.
const LIVE_QUEUE: usize = 4_096;

/// The live processing of the current run.
enum LiveWorker {
    /// On its own thread, fed through a bounded queue.
    Thread {
        data: SyncSender<SensorItem>,
        finish: SyncSender<ProcessInput>,
        result: Receiver<WorkerMsg>,
    },
    /// On the loop's thread ([`Execution::Inline`]): each item is processed as it arrives.
    Inline(Box<dyn LiveRun>),
}

/// Finishes a live run and reports its result and files (on whichever thread runs it).
fn finish_live(
    run_id: u32,
    live: Box<dyn LiveRun>,
    input: &ProcessInput,
    preview: config::PreviewConfig,
    tx: &SyncSender<WorkerMsg>,
) {
    let started = Instant::now();
    let outcome = live.finish(input);
    tracing::info!(
        run_id,
        seconds = started.elapsed().as_secs_f64(),
        "live processing finished"
    );
    complete(outcome, input, preview, tx);
}

impl LiveWorker {
    /// Starts `live` (on a thread for [`Execution::Threads`]); `None` (logged) if the thread
    /// cannot start.
    fn spawn(
        run_id: u32,
        mut live: Box<dyn LiveRun>,
        preview: config::PreviewConfig,
        execution: Execution,
    ) -> Option<Self> {
        if execution == Execution::Inline {
            return Some(Self::Inline(live));
        }
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
                    finish_live(run_id, live, &input, preview, &result_tx);
                }
            });
        match spawned {
            Ok(_) => Some(Self::Thread {
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
    Keys(#[from] link::keys::KeyFileError),
    /// No random source for the radio sessions.
    #[error("radio session: {0}")]
    Session(#[from] link::session::SessionError),
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
    pub radio: link::radio::RadioStats,
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
    Done(Result<Box<Ready>, String>),
    /// `cloud.ply` and `side_view.svg` are written (errors, e.g. a full disk, named).
    Saved(Vec<String>),
}

/// A result ready to send.
struct Ready {
    result: MeasurementResult,
    preview_mm: Vec<[i16; 3]>,
    /// The calculator's own words for each quantity it did not measure (`result.json` keeps
    /// them; the wire carries only the kind).
    not_measured: Vec<(&'static str, String)>,
    /// The standards' profiles, for `result.json` only.
    profiles: Vec<link::record::ProfileRecord>,
    /// The run's record files as written (a recorded run's; a live run's are read when its
    /// recording closes).
    records: Vec<OutgoingRecord>,
}

/// A lab file sent with a start, if it is one ([`LabFile::parse_bytes`]); the
/// error names what is wrong, for the refusal.
fn checked_lab(bytes: Vec<u8>) -> Result<Vec<u8>, String> {
    LabFile::parse_bytes(&bytes).map_err(|e| format!("lab file: {e:#}"))?;
    Ok(bytes)
}

/// The record files of the run in `dir` that go to the handheld byte-exact: `result.json`, the
/// lab report `report.html` when the run has a lab file and, when the robot signs, their
/// signatures. A file missing is not sent (no signature without a
/// device key: the handheld says so, nothing is invented); a file longer than the radio carries
/// is announced by its length, logged, and not read.
fn read_records(dir: &std::path::Path) -> Vec<OutgoingRecord> {
    let mut out = Vec::new();
    // The report (about 150 kB, half a minute of radio) goes only with a run started with a lab
    // file: the operator asked for the lab's report. Every run's report stays on the robot.
    let report = dir.join(crate::report::LAB_FILE).exists();
    let files = [RecordFile::ResultJson, RecordFile::ResultSig]
        .into_iter()
        .chain(
            report
                .then_some([RecordFile::ReportHtml, RecordFile::ReportSig])
                .into_iter()
                .flatten(),
        );
    for file in files {
        let path = dir.join(file.file_name());
        let len = match std::fs::metadata(&path) {
            Ok(m) => m.len(),
            Err(e) if e.kind() == io::ErrorKind::NotFound => continue,
            Err(e) => {
                tracing::warn!("{}: {e}: not sent to the handheld", path.display());
                continue;
            }
        };
        if len > u64::from(MAX_RECORD_LEN) {
            tracing::error!(
                "{} is {len} bytes, more than the {MAX_RECORD_LEN} the radio carries: not sent",
                path.display()
            );
            out.push(OutgoingRecord::too_large(file, len));
            continue;
        }
        match std::fs::read(&path) {
            Ok(bytes) => out.push(OutgoingRecord::new(file, bytes)),
            Err(e) => tracing::warn!("{}: {e}: not sent to the handheld", path.display()),
        }
    }
    if !out.iter().any(|r| r.file == RecordFile::ResultJson) {
        // A signature without its file verifies nothing.
        out.clear();
    }
    out
}

/// The end of every processing thread (live or from the recording): the heavy work after the
/// angles (preview decimation, PLY encoding, writing the files) stays off the service loop, and
/// the result is reported before the files are written.
fn complete(
    outcome: Result<Processed, String>,
    input: &ProcessInput,
    preview: config::PreviewConfig,
    tx: &SyncSender<WorkerMsg>,
) {
    let run_dir = &input.run_dir;
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
    let not_measured = processed
        .angles
        .as_ref()
        .map(|a| {
            a.not_measured
                .iter()
                .map(|n| (n.quantity.name(), n.reason.clone()))
                .collect()
        })
        .unwrap_or_default();
    let _ = tx.send(WorkerMsg::Done(Ok(Box::new(Ready {
        result: processed.result,
        preview_mm,
        not_measured,
        profiles: processed.profiles,
        records: Vec::new(),
    }))));
    let mut errors = Vec::new();
    let mut ply = Vec::new();
    match cloud_io::write_ply(
        &mut ply,
        &processed.cloud,
        cloud_io::PlyEncoding::BinaryLittleEndian,
    ) {
        Ok(()) => {
            if let Err(e) = signed::write_signed(&run_dir.join("cloud.ply"), &ply, &input.signer) {
                errors.push(e.to_string());
            }
        }
        Err(e) => errors.push(format!("cloud.ply: {e}")),
    }
    if let Err(e) = signed::write_signed(
        &run_dir.join("side_view.svg"),
        processed.svg.as_bytes(),
        &input.signer,
    ) {
        errors.push(e.to_string());
    }
    if let Some(scan) = &processed.scan
        && let Err(e) = signed::write_signed(
            &run_dir.join(crate::scan_file::SCAN_FILE),
            scan.to_toml().as_bytes(),
            &input.signer,
        )
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
    /// With a result, the lab report (`report.html`, signed) is written last, from the closed
    /// run's files; the loop queues this job only once the processing thread has written the
    /// cloud and the side view.
    Finish {
        run_id: u32,
        recorder: Box<RunRecorder>,
        result: Option<Box<ResultRecord>>,
        outcome: RecordedOutcome,
        /// When the run closes (the report's date), Unix seconds.
        closed_unix_s: u64,
    },
}

/// What the IO worker reports.
enum IoDone {
    Fetched {
        run_id: u32,
        seq: u16,
        ready: Option<Box<Ready>>,
    },
    Marked {
        run_id: u32,
        error: Option<String>,
    },
    Finished {
        run_id: u32,
        errors: Vec<String>,
        /// The closed run's record files, when it has a result.
        records: Vec<OutgoingRecord>,
    },
}

/// Does one IO job (on the IO worker's thread, or inline).
fn run_io_job(root: &std::path::Path, preview: config::PreviewConfig, job: IoJob) -> IoDone {
    match job {
        IoJob::Fetch { run_id, seq } => IoDone::Fetched {
            run_id,
            seq,
            ready: Recording::open_run(root, run_id)
                .ok()
                .and_then(|rec| recorded_ready(&rec, preview))
                .map(Box::new),
        },
        IoJob::MarkDelivered { run_id } => IoDone::Marked {
            run_id,
            error: recorder::mark_delivered(root, run_id)
                .err()
                .map(|e| e.to_string()),
        },
        IoJob::Finish {
            run_id,
            mut recorder,
            result,
            outcome,
            closed_unix_s,
        } => {
            let dir = recorder.dir().to_path_buf();
            let signer = recorder.signer().clone();
            if let Some(r) = &result {
                recorder.save_result(r);
            }
            let mut errors = recorder.finish(outcome);
            if result.is_some() {
                match crate::report::write_on_robot(&dir, &signer, closed_unix_s) {
                    Ok(id) => tracing::info!(run_id, report = %id, "lab report written"),
                    Err(e) => errors.push(format!("the lab report: {e:#}")),
                }
            }
            IoDone::Finished {
                run_id,
                errors,
                records: if result.is_some() {
                    read_records(&dir)
                } else {
                    Vec::new()
                },
            }
        }
    }
}

/// The IO worker (see the module docs).
enum IoWorker {
    /// Its own thread with bounded job and result queues.
    Thread {
        jobs: SyncSender<IoJob>,
        done: Receiver<IoDone>,
        handle: Option<thread::JoinHandle<()>>,
    },
    /// [`Execution::Inline`]: each job runs when it is handed over; its report waits for the
    /// loop's next look.
    Inline {
        root: PathBuf,
        preview: config::PreviewConfig,
        done: std::collections::VecDeque<IoDone>,
    },
}

impl IoWorker {
    fn spawn(
        root: PathBuf,
        preview: config::PreviewConfig,
        execution: Execution,
    ) -> io::Result<Self> {
        if execution == Execution::Inline {
            return Ok(Self::Inline {
                root,
                preview,
                done: std::collections::VecDeque::new(),
            });
        }
        let (jobs, job_rx) = sync_channel::<IoJob>(IO_QUEUE);
        let (done_tx, done) = sync_channel::<IoDone>(IO_QUEUE);
        let handle = thread::Builder::new()
            .name("radio-io".into())
            .spawn(move || {
                while let Ok(job) = job_rx.recv() {
                    if done_tx.send(run_io_job(&root, preview, job)).is_err() {
                        return;
                    }
                }
            })?;
        Ok(Self::Thread {
            jobs,
            done,
            handle: Some(handle),
        })
    }

    /// Hands a job over; a full queue gives it back (by value, as `SyncSender::try_send` does).
    #[allow(clippy::result_large_err)]
    fn submit(&mut self, job: IoJob) -> Result<(), TrySendError<IoJob>> {
        match self {
            Self::Thread { jobs, .. } => jobs.try_send(job),
            Self::Inline {
                root,
                preview,
                done,
            } => {
                done.push_back(run_io_job(root, *preview, job));
                Ok(())
            }
        }
    }

    /// The next report, if one is there.
    fn try_done(&mut self) -> Option<IoDone> {
        match self {
            Self::Thread { done, .. } => done.try_recv().ok(),
            Self::Inline { done, .. } => done.pop_front(),
        }
    }

    /// Runs `waiting` and everything queued to the end (closing recordings), then stops the
    /// thread. Results are read and dropped meanwhile, so the worker never blocks on them.
    fn drain(mut self, waiting: impl IntoIterator<Item = IoJob>) {
        for job in waiting {
            let mut job = job;
            loop {
                match self.submit(job) {
                    Ok(()) => break,
                    Err(TrySendError::Full(j)) => {
                        job = j;
                        while self.try_done().is_some() {}
                        thread::sleep(Duration::from_millis(1));
                    }
                    Err(TrySendError::Disconnected(_)) => return,
                }
            }
        }
        let Self::Thread {
            jobs,
            done,
            handle: Some(handle),
        } = self
        else {
            return;
        };
        drop(jobs);
        while !handle.is_finished() {
            while done.try_recv().is_ok() {}
            thread::sleep(Duration::from_millis(1));
        }
        let _ = handle.join();
    }
}

/// A recorded run's result with its preview decimated from `cloud.ply` (none without a result).
fn recorded_ready(rec: &Recording, preview: config::PreviewConfig) -> Option<Ready> {
    let result = rec.result.as_ref()?;
    let points = cloud_io::read_cloud(&rec.dir.join("cloud.ply"))
        .map(|(c, _)| c.points_m)
        .unwrap_or_default();
    Some(Ready {
        result: result.to_wire(),
        preview_mm: preview::decimate(&points, preview.voxel_m, preview.max_points),
        not_measured: Vec::new(),
        profiles: result.profiles.clone(),
        records: read_records(&rec.dir),
    })
}

/// Where the service's background work (live processing, processing a recording, the IO
/// worker's disk jobs) runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Execution {
    /// On threads, so the loop never waits for it: the robot.
    Threads,
    /// On the loop's own thread, when it is handed over: one thread and one order of events, so
    /// the same inputs give the same recording and result (the simulator's lockstep mode). The
    /// loop then does the processing's CPU work itself, which on a wall clock would delay the
    /// MCU heartbeat; on a simulated clock it costs no simulated time.
    Inline,
}

/// What the service takes from its surroundings besides its configuration.
pub struct Startup {
    /// Randomness for the radio sessions (the OS's on the robot, seeded in the simulator).
    pub entropy: Entropy,
    /// Wall clock at loop time 0, us since the Unix epoch: recordings stamp everything with
    /// this plus the loop time, and link sequence numbers start from it.
    pub wall_epoch_us: u64,
    /// Threads or inline.
    pub execution: Execution,
}

/// The onboard service between loop iterations: [`Service::step`] is one iteration at a time
/// given by the caller. [`run`] steps it on the monotonic clock; the simulator's lockstep mode
/// steps it on its simulated clock.
pub struct Service {
    config: OnboardConfig,
    config_text: String,
    /// Signs each run's whole files (`signing.key-file`; none: not signed).
    signer: Signer,
    execution: Execution,
    radio: OnboardRadio,
    io_worker: IoWorker,
    /// Jobs (delivered marks, closing recordings) waiting for room in the IO worker's queue, in
    /// order; bounded by the runs and results there are.
    io_waiting: std::collections::VecDeque<IoJob>,
    /// The current run's result, saved with its recording when the run ends.
    result_record: Option<ResultRecord>,
    /// The lab file the last start sent, kept in the run's recording when it begins.
    start_lab: Option<Vec<u8>>,
    /// A run's closing job held until its processing thread has written the cloud and the side
    /// view, which the lab report reads.
    finish_after_save: Option<IoJob>,
    /// A live run's result and preview, sent once its recording is closed and its record files
    /// can be read.
    awaiting_records: Option<(MeasurementResult, Vec<[i16; 3]>)>,
    /// Radio counters at the last drop log line.
    logged_radio: link::radio::RadioStats,
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
    /// The ESC faults of the last firmware status, per ESC slot.
    esc_faults_seen: [protocol::mcu::EscFaults; 4],
    /// The first ESC fault latched since the firmware's faults were last clear: the cause, which
    /// a refused drive does not name (it names the lowest interlock bit set).
    first_esc_fault: Option<String>,
    /// Wall clock at loop time 0, us since the Unix epoch ([`Startup::wall_epoch_us`]).
    wall_epoch_us: u64,
    next_watchdog_us: u64,
    next_flush_us: u64,
    last_phase: Phase,
}

fn millis(ms: u64) -> u64 {
    ms.saturating_mul(1_000)
}

/// Runs the service on the monotonic clock until `shutdown` is set, one [`Service::step`] every
/// [`LOOP_PERIOD`], with its background work on threads. `config_text` is recorded with every
/// run.
pub fn run(
    config: OnboardConfig,
    config_text: String,
    mut io: Io,
    processor: Arc<dyn Processor>,
    shutdown: &AtomicBool,
    notifier: &mut dyn Notifier,
    shared: SharedStats,
) -> Result<(), ServiceError> {
    let startup = Startup {
        entropy: Entropy::from_os()?,
        wall_epoch_us: wall_us(),
        execution: Execution::Threads,
    };
    let epoch = Instant::now();
    let mut s = Service::start(config, config_text, processor, shared, startup)?;
    notifier.ready();
    notifier.status("idle");
    let now_us = || u64::try_from(epoch.elapsed().as_micros()).unwrap_or(u64::MAX);
    let crashed = |io: &Io| io.crash.as_ref().is_some_and(|c| c.load(Ordering::Relaxed));
    let mut last_start: Option<u64> = None;
    let mut result = Ok(());
    while !shutdown.load(Ordering::Relaxed) && !crashed(&io) {
        let loop_start = Instant::now();
        let cpu_start = thread_cpu_us();
        let now = now_us();
        if let Some(t) = last_start {
            s.stats.max_loop_gap_us = s.stats.max_loop_gap_us.max(now - t);
        }
        last_start = Some(now);
        if let Err(e) = s.step(now, &mut io, notifier) {
            result = Err(e);
            break;
        }
        let work = u64::try_from(loop_start.elapsed().as_micros()).unwrap_or(u64::MAX);
        s.stats.max_loop_work_us = s.stats.max_loop_work_us.max(work);
        let cpu = thread_cpu_us().saturating_sub(cpu_start);
        s.stats.max_loop_cpu_us = s.stats.max_loop_cpu_us.max(cpu);
        if let Some(rest) = LOOP_PERIOD.checked_sub(loop_start.elapsed()) {
            thread::sleep(rest);
        }
    }
    if crashed(&io) {
        s.kill();
        return result;
    }
    s.stop(now_us(), &mut io, notifier);
    result
}

impl Service {
    /// Reads the pairing keys, opens the recording root and offers the newest undelivered
    /// result again; the loop time starts at 0.
    pub fn start(
        config: OnboardConfig,
        config_text: String,
        processor: Arc<dyn Processor>,
        shared: SharedStats,
        startup: Startup,
    ) -> Result<Self, ServiceError> {
        // The device key is checked before anything else starts: when it is configured, a run
        // that could not be signed is not recorded at all.
        let signer = if let Some(key) = config.device_key()? {
            tracing::info!(key_id = %key.public().id(), public_key = %key.public(), "signing run records");
            Signer::new(key)
        } else {
            tracing::warn!(
                "signing.key-file is not set: run records are not signed (docs/security.md)"
            );
            Signer::none()
        };
        let keys: Vec<_> = link::keys::read(&config.radio.key_file)?
            .into_iter()
            .map(|e| {
                tracing::info!(key_id = %format_args!("{:08x}", e.id), label = %e.label, "paired handheld");
                e.key
            })
            .collect();
        std::fs::create_dir_all(&config.recording.root).map_err(|e| {
            recorder::RecorderError::Io {
                path: config.recording.root.clone(),
                source: e,
            }
        })?;
        let next_run_id = recorder::next_run_id(&config.recording.root)?;
        // Seqs start from the clock so a restarted service does not reuse the seqs the peer
        // remembers.
        let seed_seq = (startup.wall_epoch_us / 1_000) as u16;
        let mcu = McuSession::new(
            McuSessionConfig {
                link: LinkConfig::MCU,
                heartbeat_period_us: millis(config.mcu.heartbeat_period_ms),
                resend_us: 200_000,
                firmware: config.mcu.firmware,
                accel_mps2: config.mcu.accel_mps2,
                jerk_mps3: config.mcu.jerk_mps3,
                status_timeout_us: 500_000,
            },
            seed_seq,
        );
        let mut s = Self {
            radio: OnboardRadio::new(
                LinkConfig::RADIO,
                keys,
                startup.entropy,
                seed_seq.wrapping_add(0x8000),
            ),
            io_worker: IoWorker::spawn(
                config.recording.root.clone(),
                config.preview,
                startup.execution,
            )
            .map_err(|source| ServiceError::Io {
                what: "starting the radio IO thread",
                source,
            })?,
            execution: startup.execution,
            io_waiting: std::collections::VecDeque::new(),
            result_record: None,
            start_lab: None,
            finish_after_save: None,
            awaiting_records: None,
            logged_radio: link::radio::RadioStats::default(),
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
            esc_faults_seen: [protocol::mcu::EscFaults::EMPTY; 4],
            first_esc_fault: None,
            wall_epoch_us: startup.wall_epoch_us,
            next_watchdog_us: 0,
            next_flush_us: 0,
            last_phase: Phase::Idle,
            signer,
            config,
            config_text,
        };
        s.recover_runs();
        Ok(s)
    }

    /// The robot stops now, the open recording is closed as aborted, and the recordings the IO
    /// worker still has to close are closed before this returns. Whatever ended the loop, this
    /// is how it ends.
    pub fn stop(mut self, now: u64, io: &mut Io, notifier: &mut dyn Notifier) {
        self.mcu.set_intent(MotionIntent::StopNow);
        self.mcu.poll(now);
        let bytes = self.mcu.transmit(now);
        let _ = io.mcu.write_all(&bytes);
        let _ = io.mcu.flush();
        if let Some(r) = self.recorder.take() {
            r.finish(RecordedOutcome::Aborted("service stopped".into()));
        }
        let waiting: Vec<IoJob> = self.io_waiting.drain(..).collect();
        self.io_worker.drain(waiting);
        notifier.stopping();
    }

    /// The simulator's kill: everything is left as a dead process leaves it (the recording
    /// open and marked incomplete, no stop sent to the MCU).
    pub fn kill(mut self) {
        std::mem::forget(self.recorder.take());
    }

    /// The counters.
    pub fn stats(&self) -> ServiceStats {
        self.stats
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
        match self
            .radio
            .deliver_with_records(ready.result, &ready.preview_mm, &ready.records)
        {
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
            match self.io_worker.submit(job) {
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
        while let Some(done) = self.io_worker.try_done() {
            match done {
                IoDone::Fetched {
                    run_id,
                    seq: _,
                    ready: Some(r),
                } => {
                    if let Err(e) =
                        self.radio
                            .deliver_with_records(r.result, &r.preview_mm, &r.records)
                    {
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
                IoDone::Finished {
                    run_id,
                    errors,
                    records,
                } => {
                    for e in errors {
                        tracing::error!(run_id, "{e}");
                    }
                    if let Some((result, preview_mm)) =
                        self.awaiting_records.take_if(|(r, _)| r.run_id == run_id)
                        && let Err(e) =
                            self.radio
                                .deliver_with_records(result, &preview_mm, &records)
                    {
                        tracing::error!("cannot send the result: {e}");
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

    /// One loop iteration at loop time `now_us` (us, never decreasing): reads the ports and
    /// channels, advances the cores, writes what they send.
    pub fn step(
        &mut self,
        now: u64,
        io: &mut Io,
        notifier: &mut dyn Notifier,
    ) -> Result<(), ServiceError> {
        let mut buf = [0u8; 4096];
        let n = read_available(io.radio.as_mut(), &mut buf).map_err(|source| ServiceError::Io {
            what: "radio port",
            source,
        })?;
        for req in self.radio.receive(now, &buf[..n]) {
            self.on_request(now, req);
        }
        let n = read_available(io.mcu.as_mut(), &mut buf).map_err(|source| ServiceError::Io {
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
        if now >= self.next_watchdog_us {
            self.next_watchdog_us = now + 1_000_000;
            notifier.watchdog();
        }
        if now >= self.next_flush_us {
            self.next_flush_us = now + millis(self.config.recording.flush_period_ms);
            if let Some(r) = &mut self.recorder {
                r.flush();
            }
            self.report_recorder_errors();
        }
        if self.run.phase() != self.last_phase {
            self.last_phase = self.run.phase();
            notifier.status(&format!("run {}: {}", self.run.run_id(), self.last_phase));
        }
        self.stats.radio = self.radio.stats();
        if let Ok(mut shared) = self.shared.lock() {
            *shared = self.stats;
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
                lab,
                seq,
                key_id,
            } => {
                tracing::info!(key_id = %format_args!("{key_id:08x}"), "start from a paired handheld");
                match lab.map(|l| l.and_then(checked_lab)) {
                    Some(Err(detail)) => {
                        self.stats.starts_refused += 1;
                        tracing::warn!("start refused: {detail}");
                        self.radio
                            .refuse(START_ID, seq, RefuseReason::InvalidParameter, &detail);
                        return;
                    }
                    lab => self.start_lab = lab.and_then(Result::ok),
                }
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
                if self.io_worker.submit(IoJob::Fetch { run_id, seq }).is_err() {
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
            McuEvent::Status(status) => self.report_esc_faults(&status),
            McuEvent::Rejected(r) => {
                let mut why = format!("{} {}", r.reason, r.field.as_str());
                if let Some(first) = &self.first_esc_fault {
                    why = format!("{} (first fault: {first})", why.trim_end());
                }
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

    /// Names each ESC fault when it appears, in the order the firmware latched them, on the log
    /// and to the handheld: the first is the cause (an ESC stuck at its current latches
    /// `NOT_FOLLOWING`; the contactor then opens and all four ESCs go `MISSING` a few ms later,
    /// which is what a refused drive names).
    fn report_esc_faults(&mut self, status: &protocol::mcu::Status) {
        let was_clean = self.esc_faults_seen.iter().all(|f| f.is_empty());
        if status.esc.iter().all(|e| e.faults.is_empty()) {
            self.first_esc_fault = None;
        }
        for (esc, seen) in status.esc.iter().zip(self.esc_faults_seen.iter_mut()) {
            let new = protocol::mcu::EscFaults(esc.faults.0 & !seen.0);
            *seen = esc.faults;
            if new.is_empty() {
                continue;
            }
            let names: Vec<&str> = new.names().collect();
            if was_clean && self.first_esc_fault.is_none() {
                self.first_esc_fault = Some(format!("ESC {} {}", esc.esc_id, names.join(", ")));
            }
            let text = format!(
                "firmware: ESC {} latched {} ({:.1} A measured, {:.1} A commanded)",
                esc.esc_id,
                names.join(", "),
                esc.current_a,
                esc.command_a
            );
            tracing::warn!("{text}");
            self.radio.send_log(LogLevel::Warn, &text);
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
        let why = match &mut self.live {
            None => return,
            Some(LiveWorker::Inline(live)) => {
                live.push(item);
                return;
            }
            Some(LiveWorker::Thread { data, .. }) => match data.try_send(item) {
                Ok(()) => return,
                Err(TrySendError::Full(_)) => "it fell behind the sensors",
                Err(TrySendError::Disconnected(_)) => "its thread ended",
            },
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
                    self.release_finish();
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
                    self.release_finish();
                }
            }
        }
    }

    /// Queues the closing job held for the processing thread's files.
    fn release_finish(&mut self) {
        if let Some(job) = self.finish_after_save.take() {
            self.io_waiting.push_back(job);
            self.check_io();
        }
    }

    /// `result.json` (and its signature) is written when the run's recording closes, on the IO
    /// worker; the result goes to the handheld then, with those files byte-exact, so the
    /// handheld's copy is the signed record. A run that could not be recorded sends its result
    /// at once, without files. The cloud and the SVG are written by the processing thread.
    fn deliver(&mut self, r: &Ready) {
        if self.recorder.is_none() {
            if let Err(e) = self.radio.deliver(r.result.clone(), &r.preview_mm) {
                tracing::error!("cannot send the result: {e}");
            }
        } else {
            self.awaiting_records = Some((r.result.clone(), r.preview_mm.clone()));
            let mut record = ResultRecord::from_wire(&r.result);
            for (quantity, reason) in &r.not_measured {
                if let Some(n) = record.not_measured.get_mut(*quantity) {
                    n.reason.clone_from(reason);
                }
            }
            record.profiles.clone_from(&r.profiles);
            self.result_record = Some(record);
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
                    let execution = self.execution;
                    self.live = self.processor.start_live().and_then(|live| {
                        LiveWorker::spawn(run_id, live, self.config.preview, execution)
                    });
                    match RunRecorder::begin_signed(
                        &self.config.recording.root,
                        run_id,
                        &params,
                        self.wall_of(now),
                        &self.config_text,
                        self.signer.clone(),
                    ) {
                        Ok(mut r) => {
                            let signed = self.signer.key().is_some();
                            tracing::info!(run_id, dir = %r.dir().display(), signed, "recording");
                            if let Some(lab) = self.start_lab.take() {
                                r.save_file(crate::report::LAB_FILE, &lab);
                            }
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
                    self.start_worker(now, run_id, travelled_m, short_run);
                }
                Action::CancelProcessing { .. } => {
                    self.worker = None;
                    self.live = None;
                    self.release_finish();
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
                        // The fsyncs and the final files go to the IO worker, once the
                        // processing thread has written the files the report reads.
                        let job = IoJob::Finish {
                            run_id,
                            recorder: Box::new(r),
                            result: self.result_record.take().map(Box::new),
                            outcome: recorded,
                            closed_unix_s: self.wall_of(now) / 1_000_000,
                        };
                        if self.worker.as_ref().is_some_and(|w| w.run_id == run_id) {
                            // One job is held at a time: an earlier one goes now.
                            self.release_finish();
                            self.finish_after_save = Some(job);
                        } else {
                            self.io_waiting.push_back(job);
                            self.check_io();
                        }
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
    }

    fn start_worker(&mut self, now: u64, run_id: u32, travelled_m: f32, short_run: bool) {
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
        // A closing job still held for an earlier run's files goes now, as this run's worker
        // replaces that run's: its report may miss them, its record is not lost.
        self.release_finish();
        let input = ProcessInput {
            run_dir,
            run_id,
            params,
            travelled_m,
            short_run,
            signer: self.signer.clone(),
        };
        let preview = self.config.preview;
        match self.live.take() {
            // The worker has everything up to the stop: it finishes as soon as its queue is empty.
            Some(LiveWorker::Thread { finish, result, .. })
                if finish.try_send(input.clone()).is_ok() =>
            {
                tracing::info!(run_id, "finishing the live processing");
                self.worker = Some(Worker {
                    run_id,
                    rx: result,
                    delivered: false,
                });
                return;
            }
            Some(LiveWorker::Inline(live)) => {
                let (tx, rx) = sync_channel(2);
                finish_live(run_id, live, &input, preview, &tx);
                self.worker = Some(Worker {
                    run_id,
                    rx,
                    delivered: false,
                });
                return;
            }
            Some(LiveWorker::Thread { .. }) | None => {}
        }
        let (tx, rx) = sync_channel(2);
        if self.execution == Execution::Inline {
            complete(self.processor.process(&input), &input, preview, &tx);
            self.worker = Some(Worker {
                run_id,
                rx,
                delivered: false,
            });
            return;
        }
        let processor = Arc::clone(&self.processor);
        let spawned = thread::Builder::new()
            .name(format!("process-run-{run_id}"))
            .spawn(move || {
                complete(processor.process(&input), &input, preview, &tx);
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
) -> Result<(Receiver<LidarPacket>, SocketAddrV4), vlp16::source::SourceError> {
    use vlp16::source::{PACKET_BUF_LEN, PacketKind, PacketSource, SourceError, UdpSource};
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
    let data_dst = SocketAddrV4::new(*data_bound.ip(), vlp16::packet::DATA_PORT);
    let position_dst = SocketAddrV4::new(
        *to_v4(source.position_addr()).ip(),
        vlp16::position::POSITION_PORT,
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
