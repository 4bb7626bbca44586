//! The handheld's imperative shell around [`HandheldRadio`]: a blocking client over any byte
//! [`Port`] (the radio modem's serial port, a pseudo-terminal in the simulator). Used by
//! `passangle measure/status/abort/fetch` and by `passangle-sim demo`.

use std::fmt::Write as _;
use std::io::{self, Read, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use protocol::auth::Key;
use protocol::common::LogLine;
use protocol::ids;
use protocol::radio::{
    MeasurementResult, Phase, Progress, RecordFile, Refused, RobotStatus, StartMeasurement,
};

use crate::Port;
use crate::handheld::{HandheldConfig, HandheldEvent, HandheldRadio};
use crate::preview;
use crate::record::ResultRecord;
use crate::record_files::ReceivedRecord;
use crate::session::{Entropy, SessionError};

/// Why a client command failed (each names what the operator should look at).
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// The port failed.
    #[error("radio port: {0}")]
    Io(#[from] io::Error),
    /// Nothing answered in time.
    #[error("no answer from the robot within {0:?} (out of range, off, or another pairing key?)")]
    Timeout(Duration),
    /// The radio gave the command up: none of its retransmissions was acknowledged.
    #[error(
        "the robot never acknowledged {what} ({attempts} tries over the radio): out of range, off, or another pairing key?"
    )]
    NotDelivered {
        /// Which command.
        what: &'static str,
        /// How many times it was sent.
        attempts: u32,
    },
    /// The robot refused the command.
    #[error("the robot refused {what}: {reason} ({detail})")]
    Refused {
        /// Which command.
        what: &'static str,
        /// Why.
        reason: String,
        /// Detail from the robot.
        detail: String,
    },
    /// The run ended without a result.
    #[error("run {run_id} {phase}: {log}")]
    RunEnded {
        /// The run.
        run_id: u32,
        /// Aborted or Failed.
        phase: Phase,
        /// The robot's last log lines.
        log: String,
    },
    /// A command could not be encoded.
    #[error("{0}")]
    Send(#[from] crate::reliable::SendError),
    /// The session could not be set up (no random source).
    #[error("radio session: {0}")]
    Session(#[from] SessionError),
    /// The robot speaks another protocol version.
    #[error("the robot speaks protocol version {theirs}, this handheld {ours}: update one of them")]
    Version {
        /// The robot's.
        theirs: u8,
        /// Ours.
        ours: u8,
    },
}

/// What the operator sees while a run goes on.
pub trait Observer {
    /// Progress of the run.
    fn progress(&mut self, p: &Progress);
    /// A log line from the robot.
    fn log(&mut self, l: &LogLine);
    /// The result arrived; the preview and the record files follow (`received`/`total` chunks
    /// of them together).
    fn preview(&mut self, received: usize, total: usize);
}

/// An observer that ignores everything.
#[derive(Debug, Default)]
pub struct Quiet;

impl Observer for Quiet {
    fn progress(&mut self, _: &Progress) {}
    fn log(&mut self, _: &LogLine) {}
    fn preview(&mut self, _: usize, _: usize) {}
}

/// A measurement as the handheld received it.
#[derive(Debug, Clone, PartialEq)]
pub struct Measured {
    /// The result.
    pub result: MeasurementResult,
    /// The decimated preview, millimetres.
    pub preview_mm: Vec<[i16; 3]>,
    /// The run's record files as the robot wrote them (`result.json`, and `result.json.sig` when
    /// the robot signs), byte-exact, or why one did not come.
    pub records: Vec<ReceivedRecord>,
    /// From the first `Processing` progress (the robot is at rest) to the result's arrival.
    pub stop_to_result: Option<Duration>,
    /// From the result to the complete preview.
    pub preview_time: Option<Duration>,
}

/// The client's time: what its loop reads, and how it waits for the radio.
pub trait ClientClock {
    /// Microseconds since the client started; never decreasing.
    fn now_us(&mut self) -> u64;
    /// Wall clock at the client's start, us since the Unix epoch (link sequence numbers start
    /// from it).
    fn wall_epoch_us(&mut self) -> u64;
    /// Waits a moment for bytes from the robot. On the wall clock this sleeps; the simulator's
    /// lockstep clock advances the whole simulated robot by one step instead.
    fn idle(&mut self);
}

/// The monotonic clock: [`ClientClock::idle`] sleeps 2 ms.
#[derive(Debug, Clone, Copy)]
pub struct WallClock {
    epoch: Instant,
}

impl WallClock {
    /// Time 0 is now.
    pub fn start() -> Self {
        Self {
            epoch: Instant::now(),
        }
    }
}

impl ClientClock for WallClock {
    fn now_us(&mut self) -> u64 {
        u64::try_from(self.epoch.elapsed().as_micros()).unwrap_or(u64::MAX)
    }

    fn wall_epoch_us(&mut self) -> u64 {
        SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| u64::try_from(d.as_micros()).unwrap_or(u64::MAX))
            .saturating_sub(self.now_us())
    }

    fn idle(&mut self) {
        std::thread::sleep(Duration::from_millis(2));
    }
}

/// The blocking client, on the wall clock unless another [`ClientClock`] is given.
pub struct Client<C: ClientClock = WallClock> {
    radio: HandheldRadio,
    port: Box<dyn Port>,
    clock: C,
    buf: Vec<u8>,
    recent_log: Vec<String>,
}

impl Client {
    /// A client over `port` with the pairing key; the handshake's randomness comes from the OS.
    pub fn new(port: Box<dyn Port>, key: Key) -> Result<Self, ClientError> {
        Ok(Self::with_entropy(port, key, Entropy::from_os()?))
    }

    /// A client with the given randomness (reproducible tests).
    pub fn with_entropy(port: Box<dyn Port>, key: Key, entropy: Entropy) -> Self {
        Self::with_clock(port, key, entropy, WallClock::start())
    }
}

impl<C: ClientClock> Client<C> {
    /// A client with the given randomness and clock (the simulator's lockstep mode).
    pub fn with_clock(port: Box<dyn Port>, key: Key, entropy: Entropy, mut clock: C) -> Self {
        let seq_seed = (clock.wall_epoch_us() / 1000) as u16;
        Self {
            radio: HandheldRadio::new(HandheldConfig::default(), key, entropy, seq_seed),
            port,
            clock,
            buf: vec![0; 4096],
            recent_log: Vec::new(),
        }
    }

    /// The clock.
    pub fn clock_mut(&mut self) -> &mut C {
        &mut self.clock
    }

    /// Ends the client, handing its clock back.
    pub fn into_clock(self) -> C {
        self.clock
    }

    fn now_us(&mut self) -> u64 {
        self.clock.now_us()
    }

    /// Moves bytes for up to `timeout`, handing every event to `on_event` until it returns
    /// `Some`. Returns that value, or [`ClientError::Timeout`].
    pub fn pump<T>(
        &mut self,
        timeout: Duration,
        mut on_event: impl FnMut(
            &mut HandheldRadio,
            &HandheldEvent,
            u64,
        ) -> Option<Result<T, ClientError>>,
    ) -> Result<T, ClientError> {
        let end = self
            .now_us()
            .saturating_add(u64::try_from(timeout.as_micros()).unwrap_or(u64::MAX));
        loop {
            let now = self.now_us();
            let n = match self.port.read(&mut self.buf) {
                Ok(n) => n,
                Err(e)
                    if matches!(
                        e.kind(),
                        io::ErrorKind::WouldBlock
                            | io::ErrorKind::TimedOut
                            | io::ErrorKind::Interrupted
                    ) =>
                {
                    0
                }
                Err(e) => return Err(e.into()),
            };
            let mut events = self.radio.receive(now, &self.buf[..n]);
            events.extend(self.radio.poll(now));
            for e in &events {
                if let HandheldEvent::Log(l) = e {
                    self.recent_log.push(l.text.as_str().to_owned());
                    if self.recent_log.len() > 5 {
                        self.recent_log.remove(0);
                    }
                }
                if let Some(done) = on_event(&mut self.radio, e, now) {
                    self.flush_out(now)?;
                    return done;
                }
            }
            self.flush_out(now)?;
            if self.now_us() >= end {
                return Err(ClientError::Timeout(timeout));
            }
            if n == 0 {
                self.clock.idle();
            }
        }
    }

    fn flush_out(&mut self, now: u64) -> Result<(), ClientError> {
        let out = self.radio.transmit(now);
        if !out.is_empty() {
            self.port.write_all(&out)?;
            self.port.flush()?;
        }
        Ok(())
    }

    /// Keeps the link running for `duration` (lets acks and the result ack leave).
    pub fn linger(&mut self, duration: Duration) -> Result<(), ClientError> {
        match self.pump::<()>(duration, |_, _, _| None) {
            Err(ClientError::Timeout(_)) | Ok(()) => Ok(()),
            Err(e) => Err(e),
        }
    }

    /// Opens the radio session (the handshake init is repeated until the robot answers).
    pub fn connect(&mut self, timeout: Duration) -> Result<(), ClientError> {
        let now = self.now_us();
        self.radio.connect(now)?;
        self.pump(timeout, |_, e, _| match e {
            HandheldEvent::Connected { .. } => Some(Ok(())),
            HandheldEvent::Version(h) if h.version != protocol::PROTOCOL_VERSION => {
                Some(Err(ClientError::Version {
                    theirs: h.version,
                    ours: protocol::PROTOCOL_VERSION,
                }))
            }
            _ => None,
        })
    }

    fn ensure_connected(&mut self, timeout: Duration) -> Result<(), ClientError> {
        if self.radio.is_connected() {
            Ok(())
        } else {
            self.connect(timeout)
        }
    }

    /// The radio end (counters, session).
    pub fn radio(&self) -> &HandheldRadio {
        &self.radio
    }

    /// Asks for the robot's status.
    pub fn status(&mut self, timeout: Duration) -> Result<RobotStatus, ClientError> {
        self.ensure_connected(timeout)?;
        self.radio.request_status()?;
        self.pump(timeout, |_, e, _| match e {
            HandheldEvent::Status(s) => Some(Ok(*s)),
            _ => None,
        })
    }

    /// Sends an abort and waits for its ack.
    pub fn abort(&mut self, run_id: u32, timeout: Duration) -> Result<(), ClientError> {
        self.ensure_connected(timeout)?;
        let seq = self.radio.abort(run_id)?;
        self.pump(timeout, |_, e, _| match e {
            HandheldEvent::Acked { msg_id, seq: s } if *msg_id == ids::ABORT && *s == seq => {
                Some(Ok(()))
            }
            _ => None,
        })
    }

    /// Fetches an earlier run's result and preview.
    pub fn fetch(
        &mut self,
        run_id: u32,
        timeout: Duration,
        observer: &mut dyn Observer,
    ) -> Result<Measured, ClientError> {
        self.ensure_connected(timeout)?;
        let seq = self.radio.fetch(run_id)?;
        let mut result_at = None;
        let out = self.pump(timeout, |radio, e, now| match e {
            HandheldEvent::Refused(r) if r.msg_id == ids::FETCH_RUN && r.seq == seq => {
                Some(Err(refused("fetch", r)))
            }
            HandheldEvent::Result(r) if r.run_id == run_id => {
                result_at.get_or_insert(now);
                observer.preview(0, usize::from(r.preview_chunks));
                None
            }
            HandheldEvent::Complete {
                result,
                preview_mm,
                records,
            } if result.run_id == run_id => Some(Ok(Measured {
                result: result.clone(),
                preview_mm: preview_mm.clone(),
                records: records.clone(),
                stop_to_result: None,
                preview_time: result_at.map(|t| micros(now.saturating_sub(t))),
            })),
            _ => {
                if let Some((got, total)) = radio.preview_progress(run_id) {
                    observer.preview(got, total);
                }
                None
            }
        })?;
        self.linger(Duration::from_millis(500))?;
        Ok(out)
    }

    /// Sends a lab file (lab, customer, vehicle: TOML) for the next start and waits until the
    /// robot has every chunk; returns what the start names ([`StartMeasurement::lab`]).
    ///
    /// # Errors
    /// [`ClientError::NotDelivered`] when a chunk is given up, [`ClientError::Send`] for a file
    /// longer than [`protocol::radio::MAX_LAB_LEN`], the link's errors.
    pub fn send_lab(
        &mut self,
        bytes: &[u8],
        timeout: Duration,
    ) -> Result<protocol::radio::LabRef, ClientError> {
        self.ensure_connected(timeout)?;
        // Any id unlike the last upload's will do: the robot keeps one upload at a time.
        #[allow(clippy::cast_possible_truncation)] // the low 16 bits, on purpose
        let upload = (self.now_us() / 1000) as u16;
        let (lab, seqs) = self.radio.send_lab(upload, bytes)?;
        let mut waiting: std::collections::BTreeSet<u16> = seqs.into_iter().collect();
        if waiting.is_empty() {
            return Ok(lab);
        }
        self.pump(timeout, |radio, e, _| match e {
            HandheldEvent::Acked { msg_id, seq } if *msg_id == ids::LAB_CHUNK => {
                waiting.remove(seq);
                waiting.is_empty().then_some(Ok(lab))
            }
            HandheldEvent::Lost { msg_id, .. } if *msg_id == ids::LAB_CHUNK => {
                Some(Err(ClientError::NotDelivered {
                    what: "the lab file",
                    attempts: radio.link().config().max_attempts,
                }))
            }
            _ => None,
        })
    }

    /// Starts a measurement and follows it to the result and its preview.
    pub fn measure(
        &mut self,
        params: &StartMeasurement,
        timeout: Duration,
        observer: &mut dyn Observer,
    ) -> Result<Measured, ClientError> {
        self.ensure_connected(timeout)?;
        let seq = self.radio.start(params)?;
        let mut run_id = None;
        let mut at_rest = None;
        let mut result_at: Option<u64> = None;
        let mut stop_to_result = None;
        let out = self.pump(timeout, |radio, e, now| {
            match e {
                HandheldEvent::Refused(r) if r.msg_id == ids::START_MEASUREMENT && r.seq == seq => {
                    return Some(Err(refused("the start", r)));
                }
                HandheldEvent::Lost { msg_id, .. } if *msg_id == ids::START_MEASUREMENT => {
                    return Some(Err(ClientError::NotDelivered {
                        what: "the start",
                        attempts: radio.link().config().max_attempts,
                    }));
                }
                HandheldEvent::Progress(p) => {
                    // Progress is best effort: the run is whichever the first progress of an
                    // active phase names (the robot was idle before this start), not only the
                    // `Checks` one, which a lossy radio may drop.
                    if run_id.is_none()
                        && matches!(
                            p.phase,
                            Phase::Checks | Phase::Driving | Phase::Stopping | Phase::Processing
                        )
                    {
                        run_id = Some(p.run_id);
                    }
                    if Some(p.run_id) == run_id {
                        observer.progress(p);
                        if p.phase == Phase::Processing {
                            at_rest.get_or_insert(now);
                        }
                        if matches!(p.phase, Phase::Aborted | Phase::Failed) {
                            return Some(Err(ClientError::RunEnded {
                                run_id: p.run_id,
                                phase: p.phase,
                                log: String::new(),
                            }));
                        }
                    }
                }
                HandheldEvent::Log(l) => observer.log(l),
                HandheldEvent::Result(r) if Some(r.run_id) == run_id || run_id.is_none() => {
                    run_id = Some(r.run_id);
                    if result_at.is_none() {
                        result_at = Some(now);
                        stop_to_result = at_rest.map(|t: u64| micros(now.saturating_sub(t)));
                    }
                    observer.preview(0, usize::from(r.preview_chunks));
                }
                HandheldEvent::Complete {
                    result,
                    preview_mm,
                    records,
                } if Some(result.run_id) == run_id => {
                    return Some(Ok(Measured {
                        result: result.clone(),
                        preview_mm: preview_mm.clone(),
                        records: records.clone(),
                        stop_to_result,
                        preview_time: result_at.map(|t| micros(now.saturating_sub(t))),
                    }));
                }
                _ => {}
            }
            if let Some(id) = run_id
                && let Some((got, total)) = radio.preview_progress(id)
            {
                observer.preview(got, total);
            }
            None
        });
        let out = match out {
            Err(ClientError::RunEnded { run_id, phase, .. }) => Err(ClientError::RunEnded {
                run_id,
                phase,
                log: self.recent_log.join("; "),
            }),
            other => other,
        }?;
        // Let the result ack leave (and be retransmitted if lost) before the program exits.
        self.linger(Duration::from_secs(2))?;
        Ok(out)
    }
}

fn micros(us: u64) -> Duration {
    Duration::from_micros(us)
}

fn refused(what: &'static str, r: &Refused) -> ClientError {
    ClientError::Refused {
        what,
        reason: r.reason.to_string(),
        detail: r.detail.as_str().to_owned(),
    }
}

/// Files the handheld saves for a measurement, under `dir`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SavedFiles {
    /// `run-NNNNNN.json`: the result rebuilt from the radio's values (no standards' profiles,
    /// not the signed file).
    pub json: PathBuf,
    /// `run-NNNNNN-preview.ply`.
    pub ply: PathBuf,
    /// `run-NNNNNN-side.svg`.
    pub svg: PathBuf,
    /// The robot's record files, byte-exact, in `run-NNNNNN/` (`result.json`, `result.json.sig`).
    pub records: Vec<PathBuf>,
    /// Why a record file is not among them: not sent (too long for the radio), or the robot
    /// does not sign (no `result.json.sig`).
    pub missing: Vec<String>,
}

impl SavedFiles {
    /// The robot's `result.json` as saved, if it came.
    pub fn result_json(&self) -> Option<&Path> {
        self.records
            .iter()
            .find(|p| p.file_name().is_some_and(|n| n == "result.json"))
            .map(PathBuf::as_path)
    }
}

/// Writes `bytes` to `path` through a temporary file beside it, so a reader never sees half.
fn write_whole(path: &Path, bytes: &[u8]) -> io::Result<()> {
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".part");
    let tmp = PathBuf::from(tmp);
    std::fs::write(&tmp, bytes)?;
    std::fs::rename(&tmp, path)
}

/// Saves the robot's record files byte-exact in `dir/run-NNNNNN/`. A signature left there by an
/// earlier fetch is removed when the robot sent none, so it never sits beside a file it does not
/// belong to.
fn save_records(dir: &Path, m: &Measured, files: &mut SavedFiles) -> io::Result<()> {
    if m.records.is_empty() {
        files.missing.push(
            "the robot sent no result.json (it could not record this run; see its log)".to_owned(),
        );
        return Ok(());
    }
    let run_dir = dir.join(crate::record::run_dir_name(m.result.run_id));
    std::fs::create_dir_all(&run_dir)?;
    for r in &m.records {
        let path = run_dir.join(r.file.file_name());
        match &r.bytes {
            Ok(bytes) => {
                write_whole(&path, bytes)?;
                files.records.push(path);
            }
            Err(e) => {
                remove_if_present(&path)?;
                files.missing.push(e.to_string());
            }
        }
    }
    if !m.records.iter().any(|r| r.file == RecordFile::ResultSig) {
        remove_if_present(&run_dir.join(RecordFile::ResultSig.file_name()))?;
        files.missing.push(
            "the robot sent no result.json.sig: it does not sign its records (no signing.key-file)"
                .to_owned(),
        );
    }
    // The robot sends its report only for a run started with a lab file; one left here by an
    // earlier copy of the run is not this robot's answer now.
    for file in [RecordFile::ReportHtml, RecordFile::ReportSig] {
        if !m.records.iter().any(|r| r.file == file) {
            remove_if_present(&run_dir.join(file.file_name()))?;
        }
    }
    Ok(())
}

fn remove_if_present(path: &Path) -> io::Result<()> {
    match std::fs::remove_file(path) {
        Err(e) if e.kind() != io::ErrorKind::NotFound => Err(e),
        _ => Ok(()),
    }
}

/// Saves the result JSON, the preview as PLY, a side-view SVG of the preview and the robot's
/// record files as they came.
pub fn save(dir: &Path, m: &Measured) -> io::Result<SavedFiles> {
    std::fs::create_dir_all(dir)?;
    let stem = crate::record::run_dir_name(m.result.run_id);
    let mut files = SavedFiles {
        json: dir.join(format!("{stem}.json")),
        ply: dir.join(format!("{stem}-preview.ply")),
        svg: dir.join(format!("{stem}-side.svg")),
        records: Vec::new(),
        missing: Vec::new(),
    };
    save_records(dir, m, &mut files)?;
    let json =
        serde_json::to_vec_pretty(&ResultRecord::from_wire(&m.result)).map_err(io::Error::other)?;
    std::fs::write(&files.json, json)?;
    let cloud = cloud_io::Cloud {
        points_m: m
            .preview_mm
            .iter()
            .map(|p| preview::dequantise(*p))
            .collect(),
    };
    let mut ply = Vec::new();
    cloud_io::write_ply(&mut ply, &cloud, cloud_io::PlyEncoding::BinaryLittleEndian)?;
    std::fs::write(&files.ply, ply)?;
    std::fs::write(&files.svg, preview_svg(m))?;
    Ok(files)
}

/// A side view (x right, z up) of the preview points with the three angles written on it.
pub fn preview_svg(m: &Measured) -> String {
    let (w, h) = (1000.0f64, 320.0f64);
    let pts: Vec<(f64, f64)> = m
        .preview_mm
        .iter()
        .map(|p| (f64::from(p[0]), f64::from(p[2])))
        .collect();
    let (mut x0, mut x1, mut z0, mut z1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, z) in &pts {
        x0 = x0.min(x);
        x1 = x1.max(x);
        z0 = z0.min(z);
        z1 = z1.max(z);
    }
    if pts.is_empty() {
        (x0, x1, z0, z1) = (0.0, 1.0, 0.0, 1.0);
    }
    let scale = ((w - 40.0) / (x1 - x0).max(1.0)).min((h - 80.0) / (z1 - z0).max(1.0));
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}">"#
    );
    let _ = writeln!(s, r#"<rect width="{w}" height="{h}" fill="white"/>"#);
    for (x, z) in pts {
        let px = 20.0 + (x - x0) * scale;
        let py = h - 20.0 - (z - z0) * scale;
        let _ = writeln!(
            s,
            r##"<circle cx="{px:.1}" cy="{py:.1}" r="1.2" fill="#335"/>"##
        );
    }
    let r = &m.result;
    let _ = writeln!(
        s,
        r#"<text x="20" y="24" font-family="sans-serif" font-size="16">run {} {}: approach {:.1} deg, departure {:.1} deg, breakover {:.1} deg (preview, {} points)</text>"#,
        r.run_id,
        xml_escape(r.vehicle_id.as_str()),
        r.approach_rad.to_degrees(),
        r.departure_rad.to_degrees(),
        r.breakover_rad.to_degrees(),
        m.preview_mm.len()
    );
    s.push_str("</svg>\n");
    s
}

fn xml_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}
