//! End-to-end tests of the onboard service and the handheld client, in one process, in real time:
//! the real `onboard::service` loop, the real handheld `Client`, the radio as a seeded lossy pipe,
//! and the real firmware logic (`control::Controller` in hil-sim's firmware-in-the-loop runner,
//! with simulated ESCs and robot physics) on the MCU link. The robot's true motion comes from the
//! simulated physics, so "the robot does not move" and "the robot stops" are checked on it.
//!
//! The rigs run in real time, so they take turns ([`ONE_RIG_AT_A_TIME`]): eight real-time rigs
//! at once on a two-core machine starved each other and made wall-clock figures fail. What needs
//! no wall clock is also checked in lockstep (`lockstep_faults.rs`).
//!
//! Not covered here: the point-cloud pipeline. Processing is a test double that derives its
//! result from the recorded files (so the recording is exercised) and keeps a copy, so the test
//! can check the handheld received exactly what was produced.

// Test helpers outside #[test] fns: unwrap is the right failure; `{:?}` quotes paths for TOML.
#![allow(
    clippy::unwrap_used,
    clippy::needless_pass_by_value,
    clippy::unnecessary_debug_formatting,
    clippy::unused_self
)]

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{SyncSender, sync_channel};
use std::sync::{Arc, Mutex};
use std::thread::{self, JoinHandle};
use std::time::{Duration, Instant};

use cloud_io::Cloud;
use hil_sim::can_bus::InProcessBus;
use hil_sim::fil::{Fil, FilConfig, Pacing};
use hil_sim::pty::MemPipe;
use hil_sim::robot::PoseSample;
use link::client::{Client, ClientError, Observer, Quiet};
use link::record::{ProfileQuantityRecord, ProfileRecord};
use link::session::Entropy;
use link::sim::{LossyPortPair, PipeConfig};
use onboard::config::{CameraSource, OnboardConfig};
use onboard::recorder::{RecordedOutcome, Recording};
use onboard::service::{
    self, Io, LidarPacket, NoNotify, ProcessInput, Processed, Processor, ServiceStats, SharedStats,
};
use passangle_tests::temp_root;
use protocol::auth::{KEY_LEN, Key};
use protocol::bounded::Text;
use protocol::common::LogLine;
use protocol::radio::{MeasurementResult, Progress, ResultWarnings, StartMeasurement, Zone};

/// What the handheld saw, with the time since the trace began: a failed run's panic prints it, so
/// a run that stalled says in which phase (new phases, logs, preview counts; repeats skipped).
struct Trace {
    t0: Instant,
    lines: Vec<String>,
}

impl Trace {
    fn new() -> Self {
        Self {
            t0: Instant::now(),
            lines: Vec::new(),
        }
    }

    fn push(&mut self, line: String) {
        if self.lines.last().is_none_or(|l| !l.ends_with(&line)) {
            let line = format!("{:.2} s {line}", self.t0.elapsed().as_secs_f64());
            self.lines.push(line);
        }
    }
}

impl Observer for Trace {
    fn progress(&mut self, p: &Progress) {
        self.push(format!("run {} {:?}", p.run_id, p.phase));
    }
    fn log(&mut self, l: &LogLine) {
        self.push(format!("log {:?} {}", l.level, l.text.as_str()));
    }
    fn preview(&mut self, received: usize, total: usize) {
        self.push(format!("preview {received}/{total}"));
    }
}

/// A processing double: its "angles" encode what the recording holds.
struct CountingProcessor {
    produced: Arc<Mutex<Vec<MeasurementResult>>>,
}

impl Processor for CountingProcessor {
    fn process(&self, input: &ProcessInput) -> Result<Processed, String> {
        let rec = Recording::open(&input.run_dir).map_err(|e| e.to_string())?;
        let (odometry, _) = rec.odometry().map_err(|e| e.to_string())?;
        let pcap_bytes = std::fs::metadata(input.run_dir.join("lidar.pcap"))
            .map_err(|e| e.to_string())?
            .len();
        let last_x = odometry.last().map_or(0.0, |(_, o)| o.x_m);
        let result = MeasurementResult {
            run_id: input.run_id,
            vehicle_id: input.params.vehicle_id.clone(),
            approach_rad: 0.1 + last_x,
            departure_rad: odometry.len() as f32 * 1e-4,
            breakover_rad: pcap_bytes as f32 * 1e-7,
            ground_clearance_m: 0.2,
            approach_u_rad: 0.01,
            departure_u_rad: 0.01,
            breakover_u_rad: 0.01,
            ground_clearance_u_m: 0.003,
            absent: [
                protocol::radio::Absence::Measured,
                protocol::radio::Absence::Measured,
                protocol::radio::Absence::Measured,
                protocol::radio::Absence::Measured,
            ],
            wheelbase_m: input.travelled_m,
            track_m: 1.5,
            approach_support: 11,
            departure_support: 12,
            breakover_support: 13,
            tyre_fit_rms_m: 0.003,
            warnings: ResultWarnings::EMPTY,
            cloud_points: 400,
            preview_chunks: 0,
            records: protocol::bounded::List::default(),
        };
        self.produced.lock().unwrap().push(result.clone());
        let cloud = Cloud {
            points_m: (0..400)
                .map(|i| {
                    [
                        f64::from(i) * 0.01,
                        f64::from(i % 7) * 0.1,
                        0.2 + f64::from(i % 5) * 0.01,
                    ]
                })
                .collect(),
        };
        Ok(Processed {
            result,
            cloud,
            svg: "<svg/>".into(),
            angles: None,
            profiles: vec![profile()],
            scan: None,
        })
    }
}

/// The one standard's profile the processing double reports: the service must write it into
/// `result.json`.
fn profile() -> ProfileRecord {
    ProfileRecord {
        standard: "cfr".into(),
        title: "49 CFR 523.2".into(),
        citation: "49 CFR 523.2".into(),
        notes: vec!["ahead of the tyre".into()],
        quantities: vec![ProfileQuantityRecord {
            id: "approach".into(),
            name: "approach angle".into(),
            unit: "deg".into(),
            value: Some(23.5),
            u: Some(0.4),
            not_measured: None,
        }],
    }
}

/// A valid VLP-16 data packet (strongest return, VLP-16) with blocks starting at `azimuth`.
fn data_packet(azimuth: u16, malformed: bool) -> Vec<u8> {
    let mut p = vec![0u8; 1206];
    for b in 0..12 {
        let o = b * 100;
        p[o] = 0xFF;
        p[o + 1] = if malformed && b == 3 { 0x00 } else { 0xEE };
        let az = (azimuth + b as u16 * 40) % 36_000;
        p[o + 2..o + 4].copy_from_slice(&az.to_le_bytes());
        for c in 0..32 {
            p[o + 4 + 3 * c..o + 6 + 3 * c].copy_from_slice(&500u16.to_le_bytes());
        }
    }
    p[1204] = 0x37;
    p[1205] = 0x22;
    p
}

fn feed_lidar(tx: SyncSender<LidarPacket>, stop: Arc<AtomicBool>, malformed_every: Option<u64>) {
    let mut azimuth = 0u16;
    let mut n = 0u64;
    while !stop.load(Ordering::Relaxed) {
        n += 1;
        let malformed = malformed_every.is_some_and(|k| n.is_multiple_of(k));
        let packet = LidarPacket {
            wall_ns: 1_700_000_000_000_000_000 + n * 1_327_000,
            src: "192.168.1.201:2368".parse().unwrap(),
            dst: "192.168.1.100:2368".parse().unwrap(),
            payload: data_packet(azimuth, malformed),
            position: false,
        };
        if !malformed {
            azimuth = (azimuth + 480) % 36_000;
        }
        let _ = tx.try_send(packet);
        thread::sleep(Duration::from_millis(5));
    }
}

/// The handheld's end of the radio shared with an attacker in range: both write into the same
/// channel (the attacker's bytes take the same lossy path to the robot).
#[derive(Clone)]
struct SharedPort(Arc<Mutex<link::sim::LossyPort>>);

impl std::io::Read for SharedPort {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        self.0.lock().unwrap().read(buf)
    }
}

impl std::io::Write for SharedPort {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.lock().unwrap().write(buf)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.0.lock().unwrap().flush()
    }
}

/// Held by each [`Rig`] for its whole life (module docs).
static ONE_RIG_AT_A_TIME: Mutex<()> = Mutex::new(());

struct Rig {
    /// This rig's turn (module docs); a failed test poisons the lock, the next still runs.
    _turn: std::sync::MutexGuard<'static, ()>,
    dir: PathBuf,
    attacker: Option<SharedPort>,
    radio: LossyPortPair,
    handheld_port: Option<link::sim::LossyPort>,
    key: Key,
    truth: Arc<Mutex<Vec<PoseSample>>>,
    produced: Arc<Mutex<Vec<MeasurementResult>>>,
    stats: SharedStats,
    stop: Arc<AtomicBool>,
    crash: Arc<AtomicBool>,
    threads: Vec<JoinHandle<()>>,
}

impl Rig {
    fn start(name: &str, radio: PipeConfig, malformed_every: Option<u64>) -> Self {
        Self::start_seeded(name, radio, malformed_every, 77)
    }

    fn start_seeded(
        name: &str,
        radio: PipeConfig,
        malformed_every: Option<u64>,
        radio_seed: u64,
    ) -> Self {
        Self::start_with(name, radio, malformed_every, radio_seed, None)
    }

    /// A rig whose robot signs its records with the device key drawn from `device_seed`.
    fn start_with(
        name: &str,
        radio: PipeConfig,
        malformed_every: Option<u64>,
        radio_seed: u64,
        device_seed: Option<[u8; onboard::signing::SEED_LEN]>,
    ) -> Self {
        let turn = ONE_RIG_AT_A_TIME
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let dir = temp_root(name);
        let key = Key([0x5a; KEY_LEN]);
        onboard::config::write_key(&dir.join("pairing.key"), &key).unwrap();
        let mut text = format!(
            "[recording]\nroot = {:?}\n[radio]\nport = \"mem\"\nkey-file = {:?}\n[mcu]\nport = \"mem\"\n[camera]\nsource = \"none\"\n",
            dir.join("runs"),
            dir.join("pairing.key"),
        );
        if let Some(seed) = device_seed {
            let path = dir.join("device.key");
            onboard::config::write_device_key(&path, &seed).unwrap();
            text = format!("{text}[signing]\nkey-file = {path:?}\n");
        }
        let mut config = OnboardConfig::parse(&text, Path::new("e2e.toml")).unwrap();
        let fw = control::Config::default();
        config.mcu.firmware = fw.to_mcu();
        config.run.max_speed_mps = config.mcu.firmware.max_speed_mps.min(0.5);
        config.mcu.accel_mps2 = config
            .mcu
            .accel_mps2
            .min(config.mcu.firmware.max_accel_mps2);
        assert_eq!(config.camera.source, CameraSource::None);

        let stop = Arc::new(AtomicBool::new(false));
        let crash = Arc::new(AtomicBool::new(false));
        let truth = Arc::new(Mutex::new(Vec::new()));
        let mut threads = Vec::new();

        // Firmware in the loop, real time.
        let (fw_uart, onboard_uart) = MemPipe::pair();
        let (stand_in, _unused) = MemPipe::pair();
        let bus = InProcessBus::new();
        let fil_config = FilConfig {
            pacing: Pacing::RealTime,
            ..FilConfig::default()
        };
        {
            let (stop, truth) = (Arc::clone(&stop), Arc::clone(&truth));
            // The runner is not Send: build it on its own thread.
            threads.push(thread::spawn(move || {
                let mut fil = Fil::new(
                    fil_config,
                    Box::new(bus.node()),
                    Box::new(bus.node()),
                    Box::new(fw_uart),
                    Box::new(stand_in),
                )
                .unwrap();
                let mut t = 0;
                while !stop.load(Ordering::Relaxed) {
                    t += 10_000;
                    fil.run_until(t).unwrap();
                    let _ = fil.take_trace();
                    truth.lock().unwrap().push(fil.truth());
                }
            }));
        }
        thread::sleep(Duration::from_millis(50));

        let (lidar_tx, lidar_rx) = sync_channel(4_000);
        {
            let stop = Arc::clone(&stop);
            threads.push(thread::spawn(move || {
                feed_lidar(lidar_tx, stop, malformed_every);
            }));
        }

        let (pair, handheld_port, onboard_port) = LossyPortPair::new(radio, radio_seed);
        let produced = Arc::new(Mutex::new(Vec::new()));
        let stats: SharedStats = Arc::new(Mutex::new(ServiceStats::default()));
        {
            let io = Io {
                radio: Box::new(onboard_port),
                mcu: Box::new(onboard_uart),
                lidar: lidar_rx,
                depth: None,
                crash: Some(Arc::clone(&crash)),
            };
            let processor = Arc::new(CountingProcessor {
                produced: Arc::clone(&produced),
            });
            let (stop, stats) = (Arc::clone(&stop), Arc::clone(&stats));
            threads.push(thread::spawn(move || {
                service::run(config, text, io, processor, &stop, &mut NoNotify, stats).unwrap();
            }));
        }
        Self {
            _turn: turn,
            dir,
            attacker: None,
            radio: pair,
            handheld_port: Some(handheld_port),
            key,
            truth,
            produced,
            stats,
            stop,
            crash,
            threads,
        }
    }

    fn client(&mut self, key: Key) -> Client {
        let port = SharedPort(Arc::new(Mutex::new(self.handheld_port.take().unwrap())));
        self.attacker = Some(port.clone());
        Client::with_entropy(Box::new(port), key, Entropy::from_test_seed(5))
    }

    fn max_abs_x_m(&self) -> f64 {
        self.truth
            .lock()
            .unwrap()
            .iter()
            .map(|p| p.x_m.abs())
            .fold(0.0, f64::max)
    }

    fn latest(&self) -> PoseSample {
        *self.truth.lock().unwrap().last().unwrap()
    }

    /// Waits up to 10 s for the robot to cruise; a run that ended before it drove says why
    /// (under load the firmware once refused the drive for a late heartbeat, which was a bare
    /// "never drove" before).
    fn wait_until_driving<R: std::fmt::Debug>(
        &self,
        handle: JoinHandle<Result<R, ClientError>>,
    ) -> JoinHandle<Result<R, ClientError>> {
        let t0 = Instant::now();
        while self.latest().vx_mps < 0.2 {
            if handle.is_finished() {
                let outcome = handle.join();
                panic!("the run ended before the robot drove: {outcome:?}");
            }
            assert!(t0.elapsed() < Duration::from_secs(10), "never drove");
            thread::sleep(Duration::from_millis(20));
        }
        handle
    }

    /// A client with the paired key, once the firmware is ready.
    fn ready_client(&mut self) -> Client {
        self.wait_firmware_ready();
        let key = self.key.clone();
        self.client(key)
    }

    fn wait_firmware_ready(&self) {
        // The service needs the firmware's hello, config and a status before checks pass.
        thread::sleep(Duration::from_millis(800));
    }

    fn finish(mut self) {
        self.stop.store(true, Ordering::Relaxed);
        for t in self.threads.drain(..) {
            t.join().unwrap();
        }
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

impl Drop for Rig {
    /// A test that fails before `finish` still stops its rig's threads before the next rig's
    /// turn.
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

fn params(distance_m: f32) -> StartMeasurement {
    StartMeasurement {
        vehicle_id: Text::truncated("E2E-1"),
        speed_mps: 0.3,
        distance_m,
        zone: Zone::Tyre,
        lab: protocol::radio::LabRef::NONE,
    }
}

#[test]
fn full_run_over_a_radio_with_20_percent_loss_and_corruption_delivers_the_exact_result() {
    let mut rig = Rig::start("lossy", PipeConfig::radio_lossy(0.2, 0.2), None);
    let mut client = rig.ready_client();
    client.connect(Duration::from_secs(10)).unwrap();
    let mut trace = Trace::new();
    let m = client
        .measure(&params(0.6), Duration::from_secs(60), &mut trace)
        .unwrap_or_else(|e| {
            let (up, down) = rig.radio.stats();
            panic!(
                "{e}; the handheld saw:\n{}\nradio up {up:?} down {down:?}",
                trace.lines.join("\n")
            )
        });
    let produced = rig.produced.lock().unwrap().clone();
    assert_eq!(produced.len(), 1);
    let mut expect = produced[0].clone();
    expect.preview_chunks = m.result.preview_chunks;
    expect.records.clone_from(&m.result.records);
    assert_eq!(m.result, expect, "exactly the result the robot produced");
    assert!(m.result.preview_chunks > 0 && !m.preview_mm.is_empty());
    let truth_x = rig.latest().x_m;
    assert!(truth_x > 0.55, "the robot drove the distance: {truth_x}");
    assert!(rig.latest().vx_mps.abs() < 0.01, "and stopped");
    let (up, down) = rig.radio.stats();
    assert!(
        up.lost > 0 && down.lost > 0 && down.corrupted > 0,
        "{up:?} {down:?}"
    );
    println!(
        "stop -> result on the handheld: {:?}; preview {} points in {:?}; radio up {up:?} down {down:?}",
        m.stop_to_result,
        m.preview_mm.len(),
        m.preview_time
    );
    let rec = Recording::open_run(&rig.dir.join("runs"), m.result.run_id).unwrap();
    assert!(!rec.incomplete);
    assert_eq!(rec.meta.outcome, RecordedOutcome::Completed);
    assert!(rec.delivered, "the handheld's ack reached the robot");
    // `passangle fetch`: the same result again, read back from the robot's disk.
    let again = client
        .fetch(m.result.run_id, Duration::from_secs(60), &mut Quiet)
        .unwrap();
    assert_eq!(again.result, m.result);
    assert_eq!(again.preview_mm, m.preview_mm);
    // The fetch's ack may still be on its way (20 % loss: retransmitted), so the robot may count
    // the result as pending for a moment: ask until it settles (or 10 s pass).
    let settled = Instant::now();
    let status = loop {
        let status = client.status(Duration::from_secs(10)).unwrap();
        let ok = status.firmware_ok && status.lidar_ok && status.pending_results == 0;
        if ok || settled.elapsed() > Duration::from_secs(10) {
            break status;
        }
        thread::sleep(Duration::from_millis(200));
    };
    assert!(
        status.firmware_ok && status.lidar_ok && status.pending_results == 0,
        "{status:?}"
    );
    assert!(
        rec.odometry().unwrap().0.len() > 100,
        "wheel odometry recorded"
    );
    rig.finish();
}

/// The lab file is in the run's signed record; the report the robot wrote shows it, says it
/// is signed, and verifies. Returns the report's bytes.
fn assert_signed_report(
    run_dir: &Path,
    lab_text: &str,
    public: onboard::signing::PublicKey,
) -> Vec<u8> {
    use onboard::signing::{Sidecar, Verdict};
    assert_eq!(
        std::fs::read_to_string(run_dir.join("lab.toml")).unwrap(),
        lab_text
    );
    let report = std::fs::read(run_dir.join("report.html")).unwrap();
    let report_text = String::from_utf8(report.clone()).unwrap();
    assert!(report_text.contains("WVWZZZ1JZ3W386752"));
    assert!(report_text.contains("Written by the robot when the run closed and signed"));
    assert!(
        report_text.contains("every signed file verifies"),
        "{report_text}"
    );
    for name in ["lab.toml", "report.html"] {
        let sidecar =
            Sidecar::parse(&std::fs::read(run_dir.join(format!("{name}.sig"))).unwrap()).unwrap();
        let bytes = std::fs::read(run_dir.join(name)).unwrap();
        assert_eq!(
            sidecar.verify(&bytes, &[public]),
            Ok(Verdict::Verified { key: public }),
            "{name}"
        );
    }

    report
}

/// `passangle measure` and `passangle fetch` bring back the robot's own `result.json` and
/// `result.json.sig`, byte for byte, over a lossy radio: the copy the handheld saves verifies
/// with the robot's public key, and one changed digit in it is named. The service's
/// `result.json` carries the standards' profiles the processing reported.
#[test]
fn measure_and_fetch_bring_back_the_robots_signed_result_json() {
    use onboard::signing::{Change, DeviceKey, Sidecar, Verdict};
    use protocol::radio::RecordFile;
    let seed = [0x42; onboard::signing::SEED_LEN];
    let public = DeviceKey::from_seed(&seed).public();
    let mut rig = Rig::start_with(
        "signed",
        PipeConfig::radio_lossy(0.1, 0.05),
        None,
        78,
        Some(seed),
    );
    let mut client = rig.ready_client();
    client.connect(Duration::from_secs(10)).unwrap();
    let mut trace = Trace::new();
    let lab_text = "[lab]\nname = \"Hall B\"\n[vehicle]\nvin = \"WVWZZZ1JZ3W386752\"\n";
    let lab = client
        .send_lab(lab_text.as_bytes(), Duration::from_secs(30))
        .unwrap();
    let m = client
        .measure(
            &StartMeasurement { lab, ..params(0.4) },
            Duration::from_secs(180),
            &mut trace,
        )
        .unwrap_or_else(|e| panic!("{e}; the handheld saw:\n{}", trace.lines.join("\n")));
    let run_dir = rig
        .dir
        .join("runs")
        .join(link::record::run_dir_name(m.result.run_id));
    let on_robot = std::fs::read(run_dir.join("result.json")).unwrap();
    let sig_on_robot = std::fs::read(run_dir.join("result.json.sig")).unwrap();

    let report = assert_signed_report(&run_dir, lab_text, public);

    // The service wrote the processing's profiles into its result.json.
    let json: serde_json::Value = serde_json::from_slice(&on_robot).unwrap();
    assert_eq!(
        json["profiles"][0]["standard"], "cfr",
        "profiles in the robot's result.json: {json}"
    );
    assert_eq!(json["profiles"][0]["quantities"][0]["value"], 23.5);

    // `measure`: both files, byte-exact.
    let files: Vec<RecordFile> = m.records.iter().map(|r| r.file).collect();
    assert_eq!(
        files,
        [
            RecordFile::ResultJson,
            RecordFile::ResultSig,
            RecordFile::ReportHtml,
            RecordFile::ReportSig
        ]
    );
    assert!(m.records[0].bytes.as_ref().unwrap() == &on_robot);
    assert!(m.records[1].bytes.as_ref().unwrap() == &sig_on_robot);
    assert!(m.records[2].bytes.as_ref().unwrap() == &report);

    // `fetch`: the same files read back from the robot's disk; saved and verified offline.
    let again = client
        .fetch(m.result.run_id, Duration::from_secs(60), &mut Quiet)
        .unwrap();
    assert_eq!(again.records, m.records);
    let saved = link::client::save(&rig.dir.join("handheld"), &again).unwrap();
    assert!(saved.missing.is_empty(), "{:?}", saved.missing);
    let copy = std::fs::read(saved.result_json().unwrap()).unwrap();
    let sidecar = Sidecar::parse(
        &std::fs::read(
            saved
                .result_json()
                .unwrap()
                .with_file_name("result.json.sig"),
        )
        .unwrap(),
    )
    .unwrap();
    assert_eq!(
        sidecar.verify(&copy, &[public]),
        Ok(Verdict::Verified { key: public })
    );
    let text = String::from_utf8(copy).unwrap();
    let line = text
        .lines()
        .find(|l| l.contains("\"approach_deg\""))
        .unwrap();
    let at = line.rfind(|c: char| c.is_ascii_digit()).unwrap();
    let mut changed = line.to_owned();
    changed.replace_range(at..=at, if &line[at..=at] == "1" { "2" } else { "1" });
    let forged = text.replacen(line, &changed, 1);
    assert_eq!(
        sidecar.verify(forged.as_bytes(), &[public]),
        Ok(Verdict::Changed {
            key: public,
            changes: vec![Change::Value("/approach_deg".into())]
        })
    );
    rig.finish();
}

/// A robot without a device key sends its `result.json` and no signature; the handheld saves
/// the file and says it is not signed, inventing nothing.
#[test]
fn an_unsigned_robot_sends_its_result_json_and_no_signature() {
    use protocol::radio::RecordFile;
    let mut rig = Rig::start("unsigned", PipeConfig::radio_lossy(0.0, 0.0), None);
    let mut client = rig.ready_client();
    client.connect(Duration::from_secs(10)).unwrap();
    // A lab file the robot cannot read refuses the start, naming it; nothing moves.
    let lab = client
        .send_lab(b"[garage]\ndoor = 1\n", Duration::from_secs(10))
        .unwrap();
    let e = client
        .measure(
            &StartMeasurement { lab, ..params(0.4) },
            Duration::from_secs(20),
            &mut Quiet,
        )
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("refused the start") && e.contains("lab file"),
        "{e}"
    );
    let m = client
        .measure(&params(0.4), Duration::from_secs(60), &mut Quiet)
        .unwrap();
    let run_dir = rig
        .dir
        .join("runs")
        .join(link::record::run_dir_name(m.result.run_id));
    assert!(!run_dir.join("result.json.sig").exists());
    assert_eq!(m.records.len(), 1);
    assert_eq!(m.records[0].file, RecordFile::ResultJson);
    assert!(
        m.records[0].bytes.as_ref().unwrap()
            == &std::fs::read(run_dir.join("result.json")).unwrap()
    );
    let saved = link::client::save(&rig.dir.join("handheld"), &m).unwrap();
    assert!(saved.result_json().is_some());
    assert_eq!(saved.records.len(), 1);
    assert!(
        saved
            .missing
            .iter()
            .any(|w| w.contains("no result.json.sig")),
        "{:?}",
        saved.missing
    );
    rig.finish();
}

/// The demo's radio at its worst tested setting, on the real service, client and firmware loop:
/// 30 % loss and 10 % corruption both ways, radio seeds 1 to 10; every run delivers its exact
/// result and preview.
#[test]
fn runs_deliver_on_every_seed_at_30_percent_loss_and_10_percent_corruption() {
    let mut lines = Vec::new();
    for seed in 1..=10 {
        let name = format!("seeds-{seed}");
        let mut rig = Rig::start_seeded(&name, PipeConfig::radio_lossy(0.3, 0.1), None, seed);
        let mut client = rig.ready_client();
        let t0 = Instant::now();
        client
            .connect(Duration::from_secs(30))
            .unwrap_or_else(|e| panic!("seed {seed}: {e}"));
        let connect = t0.elapsed();
        let mut trace = Trace::new();
        let m = client
            .measure(&params(0.4), Duration::from_secs(90), &mut trace)
            .unwrap_or_else(|e| {
                panic!(
                    "seed {seed}: {e}; the handheld saw:\n{}",
                    trace.lines.join("\n")
                )
            });
        let produced = rig.produced.lock().unwrap().clone();
        assert_eq!(produced.len(), 1, "seed {seed}");
        let mut expect = produced[0].clone();
        expect.preview_chunks = m.result.preview_chunks;
        expect.records.clone_from(&m.result.records);
        assert_eq!(m.result, expect, "seed {seed}: the exact result");
        let stats = *rig.stats.lock().unwrap();
        lines.push(format!(
            "seed {seed}: connect {:.1} s, whole run {:.1} s, longest loop gap {} us (work {} us)",
            connect.as_secs_f64(),
            t0.elapsed().as_secs_f64(),
            stats.max_loop_gap_us,
            stats.max_loop_work_us
        ));
        rig.finish();
    }
    println!("{}", lines.join("\n"));
}

#[test]
fn a_handheld_without_the_key_cannot_connect_and_the_robot_does_not_move() {
    let mut rig = Rig::start("auth", PipeConfig::CLEAN, None);
    rig.wait_firmware_ready();
    let mut wrong = rig.client(Key([0x11; KEY_LEN]));
    let e = wrong
        .measure(&params(0.6), Duration::from_secs(3), &mut Quiet)
        .unwrap_err();
    assert!(matches!(&e, ClientError::Timeout(_)), "{e}");
    let stats = *rig.stats.lock().unwrap();
    assert!(stats.radio.inits_refused >= 3, "{stats:?}");
    assert_eq!(stats.radio.sessions_opened, 0);
    thread::sleep(Duration::from_millis(500));
    assert!(
        rig.max_abs_x_m() < 0.001,
        "robot moved {} m",
        rig.max_abs_x_m()
    );
    rig.finish();
}

/// Plain frames of every kind the handheld may send (what protocol version 2 took unauthenticated:
/// Abort, ResultAck, FetchRun, Status, heartbeats, starts, acks), at about the radio's byte rate
/// for the whole run: the run completes, the result is delivered, and the service loop (which
/// sends the MCU heartbeat every 20 ms) never stalls.
fn attack_bytes(seq: u16) -> Vec<u8> {
    use protocol::common::Heartbeat;
    use protocol::radio::{Abort, FetchRun, ResultAck, StatusRequest};
    use protocol::{Flags, Message};
    fn frame<M: Message>(m: &M, seq: u16, flags: Flags) -> Vec<u8> {
        let mut buf = [0u8; 256];
        let n = m.encode_frame(seq, flags, &mut buf).unwrap();
        buf[..n].to_vec()
    }
    let ack = Flags::ACK_REQUESTED;
    let mut out = frame(&Abort { run_id: 0 }, seq, ack);
    out.extend(frame(&ResultAck { run_id: 1 }, seq, ack));
    out.extend(frame(&FetchRun { run_id: 1 }, seq, ack));
    out.extend(frame(&StatusRequest {}, seq, ack));
    out.extend(frame(&Heartbeat { counter: 1 }, seq, Flags::NONE));
    out.extend(frame(&params(0.1), seq, ack));
    out
}

#[test]
fn a_flood_of_unauthenticated_frames_while_driving_changes_nothing() {
    let mut rig = Rig::start("flood", PipeConfig::CLEAN, None);
    let mut client = rig.ready_client();
    let mut attacker = rig.attacker.clone().unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let flood = {
        let stop = Arc::clone(&stop);
        thread::spawn(move || {
            use std::io::Write as _;
            let mut seq = 0u16;
            let mut sent = 0usize;
            while !stop.load(Ordering::Relaxed) {
                // About 5 KB/s: the radio's whole byte rate.
                let bytes = attack_bytes(seq);
                sent += bytes.len();
                let _ = attacker.write_all(&bytes);
                seq = seq.wrapping_add(1);
                thread::sleep(Duration::from_millis(20));
            }
            sent
        })
    };
    let mut trace = Trace::new();
    let m = client
        .measure(&params(1.0), Duration::from_secs(60), &mut trace)
        .unwrap_or_else(|e| panic!("{e}; the handheld saw:\n{}", trace.lines.join("\n")));
    stop.store(true, Ordering::Relaxed);
    let sent = flood.join().unwrap();
    let stats = *rig.stats.lock().unwrap();
    println!(
        "flood of {sent} bytes: {:?}; longest loop gap {} us, longest iteration {} us ({} us CPU)",
        stats.radio, stats.max_loop_gap_us, stats.max_loop_work_us, stats.max_loop_cpu_us
    );
    assert!(stats.radio.unauthenticated > 500, "{stats:?}");
    assert_eq!(rig.produced.lock().unwrap().len(), 1, "one run, completed");
    assert!(
        rig.latest().x_m > 0.95,
        "drove the whole metre: {:?}",
        rig.latest()
    );
    let rec = Recording::open_run(&rig.dir.join("runs"), m.result.run_id).unwrap();
    assert_eq!(rec.meta.outcome, RecordedOutcome::Completed);
    // The firmware stops after 100 ms without a heartbeat; the run above completed, so it never
    // did. The loop's own work is judged by its CPU time, which a busy machine does not inflate
    // (the wall-clock gaps printed above do grow with the load).
    assert!(
        stats.max_loop_cpu_us < 50_000,
        "one loop iteration used {} us of CPU: the heartbeat budget is 100 ms",
        stats.max_loop_cpu_us
    );
    rig.finish();
}

/// A paired handheld asking 20 times in a row for a run whose cloud is large (a million points,
/// 12 MB): reading and decimating it happens on the IO worker, so no loop iteration waits for it,
/// the queue refuses what it cannot hold, and the fetch is answered.
#[test]
fn fetches_of_a_large_cloud_never_stall_the_loop() {
    use std::io::{Read as _, Write as _};

    use link::handheld::{HandheldConfig, HandheldEvent, HandheldRadio};
    let mut rig = Rig::start("fetch", PipeConfig::CLEAN, None);
    rig.wait_firmware_ready();
    let key = rig.key.clone();
    let mut client = rig.client(key.clone());
    let m = client
        .measure(&params(0.4), Duration::from_secs(60), &mut Quiet)
        .unwrap();
    let cloud = Cloud {
        points_m: (0..1_000_000)
            .map(|i| {
                let i = f64::from(i);
                [i * 1e-5, (i * 0.37).sin(), 0.2 + (i * 0.11).cos() * 0.1]
            })
            .collect(),
    };
    let dir = rig
        .dir
        .join("runs")
        .join(onboard::recorder::run_dir_name(m.result.run_id));
    let mut ply = Vec::new();
    cloud_io::write_ply(&mut ply, &cloud, cloud_io::PlyEncoding::BinaryLittleEndian).unwrap();
    std::fs::write(dir.join("cloud.ply"), ply).unwrap();
    let before = rig.stats.lock().unwrap().max_loop_work_us;

    let mut port = rig.attacker.clone().unwrap();
    let mut hh = HandheldRadio::new(
        HandheldConfig::default(),
        key,
        Entropy::from_test_seed(9),
        3,
    );
    let t0 = Instant::now();
    let now = |t0: Instant| u64::try_from(t0.elapsed().as_micros()).unwrap();
    hh.connect(0).unwrap();
    let mut buf = [0u8; 4096];
    let mut events = Vec::new();
    let mut asked = false;
    while t0.elapsed() < Duration::from_secs(20) {
        let t = now(t0);
        let n = port.read(&mut buf).unwrap_or(0);
        events.extend(hh.receive(t, &buf[..n]));
        events.extend(hh.poll(t));
        if hh.is_connected() && !asked {
            for _ in 0..20 {
                hh.fetch(m.result.run_id).unwrap();
            }
            asked = true;
        }
        port.write_all(&hh.transmit(t)).unwrap();
        if events
            .iter()
            .any(|e| matches!(e, HandheldEvent::Complete { result, .. } if result.run_id == m.result.run_id))
        {
            break;
        }
        thread::sleep(Duration::from_millis(2));
    }
    let stats = *rig.stats.lock().unwrap();
    println!(
        "20 fetches of a 1e6-point cloud: longest iteration {} us (before {before} us), {} us CPU, loop gap {} us, {} refused busy",
        stats.max_loop_work_us, stats.max_loop_cpu_us, stats.max_loop_gap_us, stats.fetches_busy
    );
    assert!(
        events
            .iter()
            .any(|e| matches!(e, HandheldEvent::Complete { .. })),
        "a fetch was answered: {events:?}"
    );
    // The firmware counts the heartbeat lost after 100 ms. Reading and decimating this cloud on
    // the loop would cost it hundreds of ms of CPU; on the IO worker the loop's iterations stay
    // far below. CPU time, not the wall-clock gap, so a busy machine cannot fail this.
    assert!(
        stats.max_loop_cpu_us < 50_000,
        "one loop iteration used {} us of CPU (longest wall-clock gap {} us)",
        stats.max_loop_cpu_us,
        stats.max_loop_gap_us
    );
    rig.finish();
}

#[test]
fn the_handheld_vanishing_mid_run_stops_the_robot() {
    let mut rig = Rig::start("vanish", PipeConfig::CLEAN, None);
    let mut client = rig.ready_client();
    let handle =
        thread::spawn(move || client.measure(&params(5.0), Duration::from_secs(30), &mut Quiet));
    // Wait until the robot moves, then cut the radio.
    let handle = rig.wait_until_driving(handle);
    rig.radio.set_cut(true);
    let cut_at = Instant::now();
    while rig.latest().vx_mps.abs() > 0.005 {
        assert!(
            cut_at.elapsed() < Duration::from_secs(6),
            "robot still moving {:?}",
            rig.latest()
        );
        thread::sleep(Duration::from_millis(20));
    }
    println!(
        "robot at rest {:?} after the radio went silent (12 missed heartbeats, 2.4 s)",
        cut_at.elapsed()
    );
    assert!(
        rig.latest().x_m < 4.0,
        "stopped well before the requested 5 m"
    );
    // The run closes once the firmware reports idle (after its hold time).
    let mut rec = Recording::open_run(&rig.dir.join("runs"), 1).unwrap();
    while rec.meta.outcome == RecordedOutcome::Running && cut_at.elapsed() < Duration::from_secs(10)
    {
        thread::sleep(Duration::from_millis(50));
        rec = Recording::open_run(&rig.dir.join("runs"), 1).unwrap();
    }
    assert!(
        matches!(&rec.meta.outcome, RecordedOutcome::Aborted(r) if r.contains("handheld silent")),
        "{:?}",
        rec.meta.outcome
    );
    assert!(handle.join().unwrap().is_err());
    rig.finish();
}

#[test]
fn the_onboard_killed_mid_run_leaves_an_incomplete_recording_and_the_firmware_stops() {
    let mut rig = Rig::start("kill", PipeConfig::CLEAN, None);
    let mut client = rig.ready_client();
    let handle =
        thread::spawn(move || client.measure(&params(5.0), Duration::from_secs(8), &mut Quiet));
    let handle = rig.wait_until_driving(handle);
    thread::sleep(Duration::from_millis(1_500));
    rig.crash.store(true, Ordering::Relaxed);
    let killed_at = Instant::now();
    while rig.latest().vx_mps.abs() > 0.005 {
        assert!(
            killed_at.elapsed() < Duration::from_secs(3),
            "robot still moving {:?}",
            rig.latest()
        );
        thread::sleep(Duration::from_millis(10));
    }
    println!(
        "firmware stopped the robot {:?} after the onboard died (heartbeat timeout 100 ms + ramp)",
        killed_at.elapsed()
    );
    let rec = Recording::open_run(&rig.dir.join("runs"), 1).unwrap();
    assert!(rec.incomplete, "INCOMPLETE marker left");
    assert_eq!(rec.meta.outcome, RecordedOutcome::Running);
    let (odo, _) = rec.odometry().unwrap();
    assert!(
        !odo.is_empty(),
        "what was flushed before the crash is readable"
    );
    assert!(handle.join().unwrap().is_err());
    rig.finish();
}

#[test]
fn malformed_lidar_packets_change_nothing_but_a_counter() {
    let mut rig = Rig::start("malformed", PipeConfig::CLEAN, Some(10));
    let mut client = rig.ready_client();
    let m = client
        .measure(&params(0.6), Duration::from_secs(60), &mut Quiet)
        .unwrap();
    println!(
        "clean radio: robot at rest -> result on the handheld {:?}, preview of {} points {:?} later",
        m.stop_to_result,
        m.preview_mm.len(),
        m.preview_time
    );
    let stats = *rig.stats.lock().unwrap();
    assert!(stats.lidar_malformed > 0, "{stats:?}");
    let ratio = stats.lidar_malformed as f64 / (stats.lidar_malformed + stats.lidar_packets) as f64;
    assert!((ratio - 0.1).abs() < 0.02, "{ratio}");
    // Only valid packets were recorded: every pcap record is a full VLP-16 packet.
    let pcap = rig.dir.join("runs/run-000001/lidar.pcap");
    let mut reader = vlp16::pcap::PcapReader::new(std::fs::File::open(pcap).unwrap()).unwrap();
    let mut n = 0;
    while let Some(r) = reader.next_record().unwrap() {
        let udp = vlp16::pcap::udp_in_frame(r.link_type, r.data).unwrap();
        vlp16::Vlp16Packet::new_checked(udp.payload)
            .unwrap()
            .check_fields()
            .unwrap();
        n += 1;
    }
    assert!(n > 50);
    assert_eq!(m.result.run_id, 1);
    rig.finish();
}
