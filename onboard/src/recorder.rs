//! Run recordings: one directory per run, written so that a crash never leaves a corrupt file.
//!
//! ```text
//! <root>/run-000007/
//!   INCOMPLETE          created first, removed last: present = the run did not finish cleanly
//!   meta.json           run id, parameters, start time, outcome, robot id (rewritten atomically)
//!   config.toml         the onboard configuration used
//!   lidar.pcap          raw VLP-16 UDP packets (data and position), opens in Wireshark/VeloView
//!   odometry.csv        wheel odometry: wall_us,mcu_us,x_m,y_m,yaw_rad,vx_mps,vy_mps,wz_radps,w_fl,w_fr,w_rl,w_rr
//!   depth/index.csv     frame,wall_us,width,height,fx,fy,cx,cy,depth_scale_m
//!   depth/NNNNNN.z16    one depth frame: width x height u16 little-endian, 0 = no return
//!   result.json         the measurement ([`ResultRecord`])
//!   cloud.ply           the fused cloud, vehicle frame, metres (binary PLY)
//!   side_view.svg       the side-view report
//!   DELIVERED           the handheld acknowledged the result
//!   *.sig               with a device key (`signing.key-file`): the signature of each whole file
//!                       above but the markers and depth frames (`onboard::signed`)
//! ```
//!
//! Every stamp in the streams is the host's wall clock (`wall_us`, microseconds since the Unix
//! epoch; the pcap's own clock), advanced monotonically by the service; `mcu_us` is the firmware's
//! clock as reported.
//!
//! Whole files (`meta.json`, `config.toml`, `result.json`, `cloud.ply`, `side_view.svg`, each
//! depth frame) are written atomically: a temporary file in the same directory, `fsync`, rename,
//! `fsync` of the directory. Streams (`lidar.pcap`, `odometry.csv`, `depth/index.csv`) are
//! appended as data arrives; after a crash their last record may be cut short, which the pcap
//! reader reports as a truncation and the CSV readers as a short last line; the `INCOMPLETE`
//! marker says so up front. A write error (disk full included) disables that stream, is counted
//! and reported, and never stops the robot or the run.

use std::fs::{self, File, OpenOptions};
use std::io::{self, BufWriter, Write};
use std::net::SocketAddrV4;
use std::path::{Path, PathBuf};

use protocol::mcu::Odometry;
use protocol::radio::{StartMeasurement, Zone};
use serde::{Deserialize, Serialize};

use crate::signed::{Signer, write_signed};
use vlp16::pcap::PcapWriter;

// `result.json`'s record lives with the link, whose client saves it on the handheld; the
// recorder writes and reads the same record.
pub use link::record::{NotMeasuredRecord, QUANTITIES, ResultRecord, run_dir_name};

/// Name of the marker of an unfinished run.
pub const INCOMPLETE: &str = "INCOMPLETE";
/// Name of the marker of a result the handheld acknowledged.
pub const DELIVERED: &str = "DELIVERED";

/// A recorder error, naming the file.
#[derive(Debug, thiserror::Error)]
pub enum RecorderError {
    /// The disk (or quota) is full.
    #[error("{path}: disk full")]
    DiskFull {
        /// The file.
        path: PathBuf,
    },
    /// Any other IO error.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The error.
        source: io::Error,
    },
    /// A file of a recording did not parse.
    #[error("{path}: {detail}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// What was wrong.
        detail: String,
    },
}

impl RecorderError {
    pub(crate) fn io(path: &Path, source: io::Error) -> Self {
        if source.kind() == io::ErrorKind::StorageFull || source.raw_os_error() == Some(28) {
            Self::DiskFull {
                path: path.to_owned(),
            }
        } else {
            Self::Io {
                path: path.to_owned(),
                source,
            }
        }
    }

    /// Whether this is a full disk.
    pub fn is_disk_full(&self) -> bool {
        matches!(self, Self::DiskFull { .. })
    }
}

/// Writes `bytes` to `path` atomically: temp file in the same directory, fsync, rename, fsync dir.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), RecorderError> {
    let dir = path.parent().unwrap_or(Path::new("."));
    let name = path
        .file_name()
        .map_or_else(|| "file".into(), |n| n.to_string_lossy().into_owned());
    let tmp = dir.join(format!(".{name}.tmp"));
    let result = (|| {
        let mut f = File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        fs::rename(&tmp, path)?;
        File::open(dir)?.sync_all()
    })();
    result.map_err(|e| {
        let _ = fs::remove_file(&tmp);
        RecorderError::io(path, e)
    })
}

/// Run outcome as recorded in `meta.json`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", tag = "state", content = "detail")]
pub enum RecordedOutcome {
    /// Still running (or crashed: see the `INCOMPLETE` marker).
    Running,
    /// Measured.
    Completed,
    /// Aborted, with the reason.
    Aborted(String),
    /// Failed, with the reason.
    Failed(String),
}

/// `meta.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunMeta {
    /// The run.
    pub run_id: u32,
    /// Vehicle identifier.
    pub vehicle_id: String,
    /// Requested speed, m/s.
    pub speed_mps: f32,
    /// Requested distance, m.
    pub distance_m: f32,
    /// Zone convention: `tyre` or `axle`.
    pub zone: String,
    /// Wall clock at the start, microseconds since the Unix epoch.
    pub started_unix_us: u64,
    /// Outcome so far.
    pub outcome: RecordedOutcome,
    /// Files or streams that failed to write, with the error.
    #[serde(default)]
    pub write_errors: Vec<String>,
    /// The robot: the id of its device key (`signing.key-file`, [`signing::PublicKey::id`]),
    /// the key that signs this run's files, so that a report names the robot from the run itself.
    /// Absent when the robot signs nothing (it has no other identity).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub robot_id: Option<String>,
}

/// Camera intrinsics written with every depth frame (V4L2 gives none: they come from config).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct Intrinsics {
    /// Focal length x, pixels.
    pub fx: f32,
    /// Focal length y, pixels.
    pub fy: f32,
    /// Principal point x, pixels.
    pub cx: f32,
    /// Principal point y, pixels.
    pub cy: f32,
    /// Metres per depth unit (0.001 for the D435's default).
    pub depth_scale_m: f32,
}

/// The next free run id under `root` (1 if none).
pub fn next_run_id(root: &Path) -> Result<u32, RecorderError> {
    let mut max = 0u32;
    match fs::read_dir(root) {
        Ok(entries) => {
            for e in entries.flatten() {
                let name = e.file_name();
                if let Some(id) = name
                    .to_str()
                    .and_then(|n| n.strip_prefix("run-"))
                    .and_then(|n| n.parse::<u32>().ok())
                {
                    max = max.max(id);
                }
            }
        }
        Err(e) if e.kind() == io::ErrorKind::NotFound => {}
        Err(e) => return Err(RecorderError::io(root, e)),
    }
    Ok(max.saturating_add(1))
}

/// A stream file that turns itself off on the first write error.
#[derive(Debug)]
struct Stream<W> {
    path: PathBuf,
    writer: Option<W>,
}

impl<W> Stream<W> {
    fn write(&mut self, errors: &mut Vec<RecorderError>, f: impl FnOnce(&mut W) -> io::Result<()>) {
        if let Some(w) = &mut self.writer
            && let Err(e) = f(w)
        {
            self.writer = None;
            errors.push(RecorderError::io(&self.path, e));
        }
    }
}

/// One run being recorded. See the module docs.
#[derive(Debug)]
pub struct RunRecorder {
    dir: PathBuf,
    meta: RunMeta,
    lidar: Stream<PcapWriter<BufWriter<File>>>,
    odometry: Stream<BufWriter<File>>,
    depth_index: Stream<BufWriter<File>>,
    depth_frames: u32,
    errors: Vec<RecorderError>,
    reported: usize,
    signer: Signer,
}

fn open_stream(path: &Path) -> io::Result<BufWriter<File>> {
    OpenOptions::new()
        .create_new(true)
        .write(true)
        .open(path)
        .map(BufWriter::new)
}

impl RunRecorder {
    /// Creates `<root>/run-NNNNNN` with its `INCOMPLETE` marker, `meta.json`, `config.toml` and
    /// the stream files. Fails only if the directory itself cannot be made. Nothing is signed.
    pub fn begin(
        root: &Path,
        run_id: u32,
        params: &StartMeasurement,
        started_unix_us: u64,
        config_toml: &str,
    ) -> Result<Self, RecorderError> {
        Self::begin_signed(
            root,
            run_id,
            params,
            started_unix_us,
            config_toml,
            Signer::none(),
        )
    }

    /// [`Self::begin`], signing every whole file the recorder writes (`meta.json`,
    /// `config.toml`, `result.json` and whatever [`Self::save_file`] saves) with `signer`.
    pub fn begin_signed(
        root: &Path,
        run_id: u32,
        params: &StartMeasurement,
        started_unix_us: u64,
        config_toml: &str,
        signer: Signer,
    ) -> Result<Self, RecorderError> {
        let dir = root.join(run_dir_name(run_id));
        fs::create_dir_all(dir.join("depth")).map_err(|e| RecorderError::io(&dir, e))?;
        write_atomic(
            &dir.join(INCOMPLETE),
            format!("run {run_id} started at {started_unix_us} us since the Unix epoch\n")
                .as_bytes(),
        )?;
        let meta = RunMeta {
            run_id,
            vehicle_id: params.vehicle_id.as_str().to_owned(),
            speed_mps: params.speed_mps,
            distance_m: params.distance_m,
            zone: match params.zone {
                Zone::Tyre => "tyre",
                Zone::Axle => "axle",
            }
            .to_owned(),
            started_unix_us,
            outcome: RecordedOutcome::Running,
            write_errors: Vec::new(),
            robot_id: signer.key().map(|k| k.public().id()),
        };
        let mut errors = Vec::new();
        let mut stream = |name: &str, header: &[u8]| {
            let path = dir.join(name);
            let writer = open_stream(&path).and_then(|mut w| {
                w.write_all(header)?;
                Ok(w)
            });
            match writer {
                Ok(w) => Stream {
                    path,
                    writer: Some(w),
                },
                Err(e) => {
                    errors.push(RecorderError::io(&path, e));
                    Stream { path, writer: None }
                }
            }
        };
        let odometry = stream(
            "odometry.csv",
            b"wall_us,mcu_us,x_m,y_m,yaw_rad,vx_mps,vy_mps,wz_radps,w_fl_radps,w_fr_radps,w_rl_radps,w_rr_radps\n",
        );
        let depth_index = stream(
            "depth/index.csv",
            b"frame,wall_us,width,height,fx,fy,cx,cy,depth_scale_m\n",
        );
        let lidar_path = dir.join("lidar.pcap");
        let lidar = match open_stream(&lidar_path).and_then(PcapWriter::new) {
            Ok(w) => Stream {
                path: lidar_path,
                writer: Some(w),
            },
            Err(e) => {
                errors.push(RecorderError::io(&lidar_path, e));
                Stream {
                    path: lidar_path,
                    writer: None,
                }
            }
        };
        let mut rec = Self {
            dir,
            meta,
            lidar,
            odometry,
            depth_index,
            depth_frames: 0,
            errors,
            reported: 0,
            signer,
        };
        rec.save_file("config.toml", config_toml.as_bytes());
        rec.save_meta();
        Ok(rec)
    }

    /// The run directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The run id.
    pub fn run_id(&self) -> u32 {
        self.meta.run_id
    }

    /// Appends a raw lidar UDP packet (host wall clock in ns since the Unix epoch).
    pub fn lidar_packet(
        &mut self,
        stamp_unix_ns: u64,
        src: SocketAddrV4,
        dst: SocketAddrV4,
        payload: &[u8],
    ) {
        self.lidar.write(&mut self.errors, |w| {
            w.write_udp(stamp_unix_ns, src, dst, payload)
        });
    }

    /// Appends an odometry report with its host arrival time.
    pub fn odometry(&mut self, wall_us: u64, o: &Odometry) {
        self.odometry.write(&mut self.errors, |w| {
            let [a, b, c, d] = o.wheel_speed_radps;
            writeln!(
                w,
                "{wall_us},{},{},{},{},{},{},{},{a},{b},{c},{d}",
                o.stamp_us, o.x_m, o.y_m, o.yaw_rad, o.vx_mps, o.vy_mps, o.wz_radps
            )
        });
    }

    /// Writes a depth frame (Z16, row-major) and its index line.
    pub fn depth_frame(
        &mut self,
        wall_us: u64,
        width: u16,
        height: u16,
        depth: &[u16],
        k: &Intrinsics,
    ) {
        if self.depth_index.writer.is_none() {
            return;
        }
        let n = self.depth_frames;
        self.depth_frames += 1;
        let bytes: Vec<u8> = depth.iter().flat_map(|v| v.to_le_bytes()).collect();
        if let Err(e) = write_atomic(&self.dir.join(format!("depth/{n:06}.z16")), &bytes) {
            self.depth_index.writer = None;
            self.errors.push(e);
            return;
        }
        self.depth_index.write(&mut self.errors, |w| {
            writeln!(
                w,
                "{n},{wall_us},{width},{height},{},{},{},{},{}",
                k.fx, k.fy, k.cx, k.cy, k.depth_scale_m
            )
        });
    }

    /// Flushes the streams (call every second or so, so a crash loses little).
    pub fn flush(&mut self) {
        self.lidar.write(&mut self.errors, PcapWriter::flush);
        self.odometry.write(&mut self.errors, Write::flush);
        self.depth_index.write(&mut self.errors, Write::flush);
    }

    /// The key the run's files are signed with.
    pub fn signer(&self) -> &Signer {
        &self.signer
    }

    /// Saves a whole file of the run atomically, with its signature when the recorder signs
    /// (errors are recorded, not returned).
    pub fn save_file(&mut self, name: &str, bytes: &[u8]) {
        if let Err(e) = write_signed(&self.dir.join(name), bytes, &self.signer) {
            self.errors.push(e);
        }
    }

    /// Saves `result.json`.
    pub fn save_result(&mut self, result: &ResultRecord) {
        match serde_json::to_vec_pretty(result) {
            Ok(bytes) => self.save_file("result.json", &bytes),
            Err(e) => self.errors.push(RecorderError::Parse {
                path: self.dir.join("result.json"),
                detail: e.to_string(),
            }),
        }
    }

    fn save_meta(&mut self) {
        self.meta.write_errors = self.errors.iter().map(ToString::to_string).collect();
        if let Ok(bytes) = serde_json::to_vec_pretty(&self.meta) {
            self.save_file("meta.json", &bytes);
        }
    }

    /// Errors not yet reported (the shell logs them and tells the handheld).
    pub fn take_new_errors(&mut self) -> Vec<String> {
        let new = self.errors[self.reported..]
            .iter()
            .map(ToString::to_string)
            .collect();
        self.reported = self.errors.len();
        new
    }

    /// Whether any write hit a full disk.
    pub fn disk_full(&self) -> bool {
        self.errors.iter().any(RecorderError::is_disk_full)
    }

    /// Closes the run: flushes and fsyncs the streams, writes the outcome, removes `INCOMPLETE`.
    pub fn finish(mut self, outcome: RecordedOutcome) -> Vec<String> {
        self.flush();
        if let Some(w) = self.lidar.writer.take() {
            let _ = w.into_inner().into_inner().map(|f| f.sync_all());
        }
        for s in [&mut self.odometry, &mut self.depth_index] {
            if let Some(w) = s.writer.take() {
                let _ = w.into_inner().map(|f| f.sync_all());
            }
        }
        self.meta.outcome = outcome;
        self.save_meta();
        if let Err(e) = fs::remove_file(self.dir.join(INCOMPLETE)) {
            self.errors
                .push(RecorderError::io(&self.dir.join(INCOMPLETE), e));
        }
        self.take_new_errors()
    }
}

/// Marks a run's result as acknowledged by the handheld.
pub fn mark_delivered(root: &Path, run_id: u32) -> Result<(), RecorderError> {
    write_atomic(&root.join(run_dir_name(run_id)).join(DELIVERED), b"")
}

/// What a recording directory holds, read back (for `fetch`, `replay` and crash recovery).
#[derive(Debug, Clone, PartialEq)]
pub struct Recording {
    /// The directory.
    pub dir: PathBuf,
    /// `meta.json`.
    pub meta: RunMeta,
    /// The run did not finish cleanly (`INCOMPLETE` present).
    pub incomplete: bool,
    /// `result.json`, if the run got that far.
    pub result: Option<ResultRecord>,
    /// The handheld acknowledged the result.
    pub delivered: bool,
}

fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<Option<T>, RecorderError> {
    match fs::read(path) {
        Ok(bytes) => serde_json::from_slice(&bytes)
            .map(Some)
            .map_err(|e| RecorderError::Parse {
                path: path.to_owned(),
                detail: e.to_string(),
            }),
        Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(RecorderError::io(path, e)),
    }
}

impl Recording {
    /// Reads a run directory.
    pub fn open(dir: &Path) -> Result<Self, RecorderError> {
        let meta_path = dir.join("meta.json");
        let meta = read_json::<RunMeta>(&meta_path)?.ok_or_else(|| RecorderError::Parse {
            path: meta_path,
            detail: "missing: not a passangle run directory".to_owned(),
        })?;
        Ok(Self {
            dir: dir.to_owned(),
            incomplete: dir.join(INCOMPLETE).exists(),
            result: read_json(&dir.join("result.json"))?,
            delivered: dir.join(DELIVERED).exists(),
            meta,
        })
    }

    /// Reads run `run_id` under `root`.
    pub fn open_run(root: &Path, run_id: u32) -> Result<Self, RecorderError> {
        Self::open(&root.join(run_dir_name(run_id)))
    }

    /// The odometry stream, parsed line by line; a cut-short last line (a crash) is skipped and
    /// counted in the second value.
    pub fn odometry(&self) -> Result<(Vec<(u64, Odometry)>, usize), RecorderError> {
        let path = self.dir.join("odometry.csv");
        let text = fs::read_to_string(&path).map_err(|e| RecorderError::io(&path, e))?;
        parse_odometry_csv(&text).map_err(|detail| RecorderError::Parse { path, detail })
    }
}

/// Parses the text of an `odometry.csv` (a header line, then one report per line). Pure; never
/// panics; allocates one entry per line present. A cut-short last line (a crash while
/// appending) is skipped and counted in the second value; any other malformed or non-finite
/// line is an error naming the line (1-based, the header is line 1) and the column.
pub fn parse_odometry_csv(text: &str) -> Result<(Vec<(u64, Odometry)>, usize), String> {
    let mut out = Vec::new();
    let mut bad = 0;
    let lines = text.lines().count();
    for (i, line) in text.lines().enumerate().skip(1) {
        match parse_odometry_line(line) {
            Ok(v) => out.push(v),
            Err(OdometryLineError::Malformed) if i + 1 == lines => bad += 1,
            Err(e) => return Err(format!("line {}: {e}: {line:?}", i + 1)),
        }
    }
    Ok((out, bad))
}

/// Why an `odometry.csv` line was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
enum OdometryLineError {
    /// Not 12 comma-separated numbers (or a stamp that is not an integer).
    #[error("not 12 numbers")]
    Malformed,
    /// A value that parses but is NaN or infinite: no writer produces it and the pipeline would
    /// carry it into the trajectory, so it is refused even on the last line.
    #[error("column {column} ({name}) is not finite")]
    NonFinite {
        /// 1-based column.
        column: usize,
        /// The column's name in the file's header.
        name: &'static str,
    },
}

const ODOMETRY_COLUMNS: [&str; 12] = [
    "wall_us", "mcu_us", "x_m", "y_m", "yaw_rad", "vx_mps", "vy_mps", "wz_radps", "w_fl", "w_fr",
    "w_rl", "w_rr",
];

fn parse_odometry_line(line: &str) -> Result<(u64, Odometry), OdometryLineError> {
    let f: Vec<&str> = line.split(',').collect();
    if f.len() != 12 {
        return Err(OdometryLineError::Malformed);
    }
    let num = |i: usize| -> Result<f32, OdometryLineError> {
        let v = f[i]
            .parse::<f32>()
            .map_err(|_| OdometryLineError::Malformed)?;
        if v.is_finite() {
            Ok(v)
        } else {
            Err(OdometryLineError::NonFinite {
                column: i + 1,
                name: ODOMETRY_COLUMNS[i],
            })
        }
    };
    let int = |i: usize| f[i].parse().map_err(|_| OdometryLineError::Malformed);
    Ok((
        int(0)?,
        Odometry {
            stamp_us: int(1)?,
            x_m: num(2)?,
            y_m: num(3)?,
            yaw_rad: num(4)?,
            vx_mps: num(5)?,
            vy_mps: num(6)?,
            wz_radps: num(7)?,
            wheel_speed_radps: [num(8)?, num(9)?, num(10)?, num(11)?],
        },
    ))
}

/// Free space on the file system holding `path`, MiB (saturating).
// `blocks_available` is u64 on Linux but narrower elsewhere: the conversion is not useless there.
#[allow(clippy::useless_conversion)]
pub fn disk_free_mib(path: &Path) -> Option<u32> {
    let s = nix::sys::statvfs::statvfs(path).ok()?;
    let bytes = u64::from(s.blocks_available()).saturating_mul(s.fragment_size());
    Some(u32::try_from(bytes >> 20).unwrap_or(u32::MAX))
}

#[cfg(test)]
mod tests {
    use super::*;
    use protocol::bounded::Text;
    use protocol::radio::{Absence, MeasurementResult, ResultWarnings};
    use vlp16::pcap::PcapReader;

    fn tmp(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("passangle-rec-{name}-{}", std::process::id()));
        let _ = fs::remove_dir_all(&d);
        d
    }

    fn params() -> StartMeasurement {
        StartMeasurement {
            vehicle_id: Text::truncated("ABC-123"),
            speed_mps: 0.2,
            distance_m: 6.0,
            zone: Zone::Axle,
            lab: protocol::radio::LabRef::NONE,
        }
    }

    /// A measured result of run 1, vehicle ABC-123, with `warnings`.
    fn abc_result(warnings: ResultWarnings) -> MeasurementResult {
        MeasurementResult {
            run_id: 1,
            vehicle_id: Text::truncated("ABC-123"),
            approach_rad: 0.5,
            departure_rad: 0.4,
            breakover_rad: 0.3,
            ground_clearance_m: 0.2,
            approach_u_rad: 0.01,
            departure_u_rad: 0.01,
            breakover_u_rad: 0.01,
            ground_clearance_u_m: 0.003,
            absent: [
                Absence::Measured,
                Absence::Measured,
                Absence::Measured,
                Absence::Measured,
            ],
            wheelbase_m: 2.7,
            track_m: 1.5,
            approach_support: 1,
            departure_support: 2,
            breakover_support: 3,
            tyre_fit_rms_m: 0.01,
            warnings,
            cloud_points: 99,
            preview_chunks: 0,
            records: protocol::bounded::List::default(),
        }
    }

    fn odo(t: u64) -> Odometry {
        Odometry {
            stamp_us: t,
            x_m: t as f32 * 1e-6,
            y_m: 0.0,
            yaw_rad: 0.0,
            vx_mps: 0.2,
            vy_mps: 0.0,
            wz_radps: 0.0,
            wheel_speed_radps: [2.6; 4],
        }
    }

    #[test]
    fn a_finished_run_has_every_file_and_no_marker() {
        let root = tmp("finished");
        assert_eq!(next_run_id(&root).unwrap(), 1);
        let mut r =
            RunRecorder::begin(&root, 1, &params(), 1_700_000_000_000_000, "x = 1\n").unwrap();
        let src = SocketAddrV4::new([192, 168, 1, 201].into(), 2368);
        let dst = SocketAddrV4::new([255, 255, 255, 255].into(), 2368);
        for i in 0..10u64 {
            r.lidar_packet(
                1_700_000_000_000_000_000 + i * 1_327_000,
                src,
                dst,
                &[i as u8; 1206],
            );
            r.odometry(i * 10_000, &odo(i * 10_000));
        }
        let k = Intrinsics {
            fx: 420.0,
            fy: 420.0,
            cx: 424.0,
            cy: 240.0,
            depth_scale_m: 0.001,
        };
        r.depth_frame(5, 4, 2, &[1, 2, 3, 4, 5, 6, 7, 0], &k);
        let wire = abc_result(ResultWarnings::SHORT_RUN);
        r.save_result(&ResultRecord::from_wire(&wire));
        assert!(root.join("run-000001").join(INCOMPLETE).exists());
        assert!(r.finish(RecordedOutcome::Completed).is_empty());
        let rec = Recording::open_run(&root, 1).unwrap();
        assert!(!rec.incomplete);
        assert_eq!(rec.meta.outcome, RecordedOutcome::Completed);
        // Without a device key the robot has no id, and meta.json has no `robot_id` key.
        assert_eq!(rec.meta.robot_id, None);
        let meta = fs::read_to_string(root.join("run-000001/meta.json")).unwrap();
        assert!(!meta.contains("robot_id"), "{meta}");
        assert_eq!(
            rec.result.as_ref().unwrap().to_wire(),
            wire,
            "result round-trips"
        );
        assert_eq!(rec.odometry().unwrap().0.len(), 10);
        let bytes = fs::read(root.join("run-000001/depth/000000.z16")).unwrap();
        assert_eq!(bytes.len(), 16);
        let mut pcap =
            PcapReader::new(File::open(root.join("run-000001/lidar.pcap")).unwrap()).unwrap();
        let mut n = 0;
        while let Some(rec) = pcap.next_record().unwrap() {
            assert_eq!(rec.data.len(), 14 + 20 + 8 + 1206);
            n += 1;
        }
        assert_eq!(n, 10);
        assert_eq!(next_run_id(&root).unwrap(), 2);
        assert!(
            fs::read_dir(root.join("run-000001")).unwrap().all(|e| !e
                .unwrap()
                .file_name()
                .to_string_lossy()
                .ends_with(".tmp"))
        );
        fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn a_signed_run_signs_its_whole_files_and_a_changed_digit_is_named() {
        let root = tmp("signed");
        let key = signing::DeviceKey::from_seed(&[3; signing::SEED_LEN]);
        let public = key.public();
        let mut r = RunRecorder::begin_signed(
            &root,
            1,
            &params(),
            1_700_000_000_000_000,
            "x = 1\n",
            Signer::new(key),
        )
        .unwrap();
        let record = ResultRecord::from_wire(&abc_result(ResultWarnings::EMPTY));
        r.save_result(&record);
        assert!(r.finish(RecordedOutcome::Completed).is_empty());
        let dir = root.join("run-000001");
        let verify = |name: &str| {
            let sig = fs::read(dir.join(format!("{name}.sig"))).unwrap();
            signing::Sidecar::parse(&sig)
                .unwrap()
                .verify(&fs::read(dir.join(name)).unwrap(), &[public])
                .unwrap()
        };
        for name in ["result.json", "meta.json", "config.toml"] {
            assert_eq!(
                verify(name),
                signing::Verdict::Verified { key: public },
                "{name}"
            );
        }
        // meta.json names the robot by the id of the key that signs the run.
        let meta = Recording::open_run(&root, 1).unwrap().meta;
        assert_eq!(meta.robot_id, Some(public.id()));
        // One digit of the approach angle, changed in place: named by its pointer.
        let text = fs::read_to_string(dir.join("result.json")).unwrap();
        let line = text
            .lines()
            .find(|l| l.contains("\"approach_deg\""))
            .unwrap();
        let digit = line.rfind(|c: char| c.is_ascii_digit()).unwrap();
        let mut changed = line.to_owned();
        let d = changed.as_bytes()[digit];
        changed.replace_range(digit..=digit, if d == b'1' { "2" } else { "1" });
        fs::write(dir.join("result.json"), text.replacen(line, &changed, 1)).unwrap();
        let signing::Verdict::Changed { changes, .. } = verify("result.json") else {
            panic!("a changed digit verified");
        };
        assert_eq!(changes, [signing::Change::Value("/approach_deg".into())]);
        // The changed record still reads: the signature is beside it, not in it.
        let read = Recording::open_run(&root, 1)
            .unwrap()
            .result
            .unwrap()
            .approach_deg;
        assert!((read - record.approach_deg).abs() > 1e-6);
        fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn an_undetermined_angle_round_trips_as_null() {
        let root = tmp("nan");
        let mut r = RunRecorder::begin(&root, 1, &params(), 1_700_000_000_000_000, "").unwrap();
        let wire = MeasurementResult {
            run_id: 1,
            vehicle_id: Text::truncated("SUV"),
            approach_rad: f32::NAN,
            departure_rad: 0.45,
            breakover_rad: 0.33,
            ground_clearance_m: 0.25,
            approach_u_rad: f32::NAN,
            departure_u_rad: 0.01,
            breakover_u_rad: 0.01,
            ground_clearance_u_m: 0.003,
            absent: [
                Absence::NotCovered,
                Absence::Measured,
                Absence::Measured,
                Absence::Measured,
            ],
            wheelbase_m: 3.1,
            track_m: 1.6,
            approach_support: 0,
            departure_support: 365,
            breakover_support: 607,
            tyre_fit_rms_m: 0.004,
            warnings: ResultWarnings::LOW_SUPPORT,
            cloud_points: 1_322_335,
            preview_chunks: 0,
            records: protocol::bounded::List::default(),
        };
        r.save_result(&ResultRecord::from_wire(&wire));
        assert!(r.finish(RecordedOutcome::Completed).is_empty());
        let text = fs::read_to_string(root.join("run-000001/result.json")).unwrap();
        assert!(text.contains("\"approach_rad\": null"), "{text}");
        assert!(text.contains("\"approach_u_deg\": null"), "{text}");
        assert!(
            text.contains("\"approach\": {\n      \"kind\": \"not_covered\""),
            "{text}"
        );
        let rec = Recording::open_run(&root, 1).expect("a NaN angle leaves the run readable");
        let back = rec.result.unwrap().to_wire();
        assert!(back.approach_rad.is_nan());
        assert_eq!(
            back.absent, wire.absent,
            "why it was not measured round-trips"
        );
        assert_eq!(back.departure_rad.to_bits(), wire.departure_rad.to_bits());
        assert_eq!(back.cloud_points, wire.cloud_points);
        fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn a_crashed_run_is_marked_incomplete_and_still_readable() {
        let root = tmp("crashed");
        let mut r = RunRecorder::begin(&root, 4, &params(), 0, "").unwrap();
        for i in 0..5 {
            r.odometry(i, &odo(i));
        }
        r.flush();
        // Simulate a crash mid-line: append half a record, then drop without finish().
        let path = r.dir().join("odometry.csv");
        drop(r);
        let mut f = OpenOptions::new().append(true).open(&path).unwrap();
        f.write_all(b"123,45,0.1").unwrap();
        let rec = Recording::open_run(&root, 4).unwrap();
        assert!(rec.incomplete);
        assert_eq!(rec.meta.outcome, RecordedOutcome::Running);
        assert!(rec.result.is_none());
        let (odo, cut) = rec.odometry().unwrap();
        assert_eq!((odo.len(), cut), (5, 1));
        fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn non_finite_odometry_is_refused_naming_line_and_column() {
        let root = tmp("nonfinite");
        let mut r = RunRecorder::begin(&root, 5, &params(), 0, "").unwrap();
        for i in 0..3 {
            r.odometry(i, &odo(i));
        }
        let mut bad = odo(3);
        bad.vx_mps = f32::NAN;
        r.odometry(3, &bad);
        r.odometry(4, &odo(4));
        let mut inf = odo(5);
        inf.wheel_speed_radps[2] = f32::INFINITY;
        r.odometry(5, &inf);
        r.flush();
        drop(r);
        let rec = Recording::open_run(&root, 5).unwrap();
        let path = rec.dir.join("odometry.csv");
        let err = rec.odometry().unwrap_err().to_string();
        assert!(
            err.starts_with(&path.display().to_string())
                && err.contains("line 5: column 6 (vx_mps) is not finite"),
            "{err}"
        );
        // Non-finite on the last line is refused too, not taken for a cut-short line.
        let text = fs::read_to_string(&path).unwrap();
        let without_nan: Vec<&str> = text.lines().filter(|l| !l.contains("NaN")).collect();
        fs::write(&path, without_nan.join("\n")).unwrap();
        let err = rec.odometry().unwrap_err().to_string();
        assert!(
            err.contains("line 6: column 11 (w_rl) is not finite"),
            "{err}"
        );
        fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn disk_full_is_reported_not_fatal() {
        // /dev/full answers every write with ENOSPC.
        if !Path::new("/dev/full").exists() {
            eprintln!("SKIPPED: /dev/full is absent on this system");
            return;
        }
        let root = tmp("full");
        let mut r = RunRecorder::begin(&root, 1, &params(), 0, "").unwrap();
        r.odometry = Stream {
            path: PathBuf::from("/dev/full"),
            writer: Some(BufWriter::with_capacity(
                16,
                OpenOptions::new().write(true).open("/dev/full").unwrap(),
            )),
        };
        for i in 0..10 {
            r.odometry(i, &odo(i));
        }
        assert!(r.disk_full());
        let errs = r.take_new_errors();
        assert_eq!(errs.len(), 1, "reported once: {errs:?}");
        assert!(errs[0].contains("/dev/full: disk full"));
        // The rest of the run still records.
        r.save_file("cloud.ply", b"ply\n");
        assert!(r.finish(RecordedOutcome::Completed).is_empty());
        let rec = Recording::open_run(&root, 1).unwrap();
        assert_eq!(rec.meta.write_errors.len(), 1);
        assert!(root.join("run-000001/cloud.ply").exists());
        fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn atomic_write_replaces_whole_files() {
        let root = tmp("atomic");
        fs::create_dir_all(&root).unwrap();
        let p = root.join("a.json");
        write_atomic(&p, b"one").unwrap();
        write_atomic(&p, b"two two").unwrap();
        assert_eq!(fs::read(&p).unwrap(), b"two two");
        assert!(write_atomic(&root.join("missing/a"), b"x").is_err());
        assert!(disk_free_mib(&root).is_some());
        fs::remove_dir_all(&root).unwrap();
    }
}
