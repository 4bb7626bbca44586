//! Radio link: handheld <-> onboard, transparent serial radio at 57600 baud, slow and lossy.
//!
//! The handheld opens a session with [`HandshakeInit`] (answered by [`HandshakeReply`]); every
//! message of [`ToOnboard`] and [`ToHandheld`], acks and heartbeats included, then travels sealed
//! inside it (see [`crate::auth`]). Nothing else is accepted on the radio.
//!
//! Every command is sent with [`Flags::ACK_REQUESTED`](crate::frame::Flags) and retransmitted until
//! acked; a refused command is answered with [`Refused`]. Results are resent until the handheld
//! sends [`ResultAck`]; the cloud preview goes as [`CloudChunk`]s and the handheld asks for the
//! missing ones with [`ResendChunks`]. The run's record files as the robot wrote them
//! (`result.json` and its signature `result.json.sig`, named in
//! [`MeasurementResult::records`]) go byte-exact as [`RecordChunk`]s, the missing ones asked for
//! with [`ResendRecordChunks`], so the handheld's copy verifies against the robot's public key.

use postcard::experimental::max_size::MaxSize;
use serde::{Deserialize, Serialize};

use crate::bounded::{List, Text};
use crate::common::{Heartbeat, Hello, LogLine};
use crate::message::{bit_set, message_set, wire_enum};

wire_enum! {
    /// Which standard's zone limits the approach and departure search.
    pub enum Zone {
        /// Ahead of (behind) the tyre's contact, CFR / SAE J1100 style.
        Tyre = 1,
        /// Ahead of (behind) the axle, EU style.
        Axle = 2,
    }
}

/// Start a measurement run: the one radio command that moves the robot.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, MaxSize)]
pub struct StartMeasurement {
    /// Free-form vehicle identifier (plate, VIN, test number), up to 32 bytes.
    pub vehicle_id: Text<32>,
    /// Constant drive speed under the vehicle, m/s.
    pub speed_mps: f32,
    /// Distance to drive, m.
    pub distance_m: f32,
    /// Zone convention for the angles.
    pub zone: Zone,
    /// The lab file sent ahead of this start, if any ([`LabChunk`]s).
    pub lab: LabRef,
}

/// The lab file a start refers to: the [`LabChunk`]s of upload `upload`, `len` bytes in all.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
pub struct LabRef {
    /// The upload's id (the handheld's choice; a new upload replaces an unfinished one).
    pub upload: u16,
    /// The file's length, bytes (0: no lab file; at most [`MAX_LAB_LEN`]).
    pub len: u16,
}

impl LabRef {
    /// No lab file.
    pub const NONE: Self = Self { upload: 0, len: 0 };
}

/// Largest lab file a start may carry, bytes (the example lab file is about a quarter of it).
pub const MAX_LAB_LEN: u16 = 4096;

/// Bytes of a lab file per [`LabChunk`] (as [`RECORD_CHUNK_LEN`], which fits a sealed frame).
pub const LAB_CHUNK_LEN: usize = 190;

/// Chunks of a lab file of `len` bytes (0 for none).
#[allow(clippy::cast_possible_truncation)] // LAB_CHUNK_LEN is 190: fits a u16
pub const fn lab_chunk_count(len: u16) -> u16 {
    len.div_ceil(LAB_CHUNK_LEN as u16)
}

/// One chunk of the lab file (TOML: lab, customer, vehicle; docs/operator/lab.example.toml),
/// handheld -> onboard ahead of the [`StartMeasurement`] that names its upload. The robot keeps
/// the file in the run's record and its signed report.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
pub struct LabChunk {
    /// The upload's id ([`LabRef::upload`]).
    pub upload: u16,
    /// Chunk index, 0-based: the file's bytes from `index * LAB_CHUNK_LEN`.
    pub index: u8,
    /// Number of chunks ([`lab_chunk_count`] of the file's length).
    pub count: u8,
    /// The bytes (every chunk but the last is full).
    pub bytes: List<u8, LAB_CHUNK_LEN>,
}

/// First handshake message, handheld -> onboard (outside any session): Noise `NNpsk0`'s
/// `-> psk, e` with an empty payload, under the pairing key named by `key_id`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
pub struct HandshakeInit {
    /// Id of the pairing key ([`crate::auth::key_id`]); also in the Noise prologue.
    pub key_id: u32,
    /// The Noise message ([`crate::auth::HANDSHAKE_MSG_LEN`] bytes).
    pub noise: List<u8, 64>,
}

/// Second handshake message, onboard -> handheld: Noise `NNpsk0`'s `<- e, ee`. From here on both
/// ends have the session's transport keys.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
pub struct HandshakeReply {
    /// Id of the pairing key the init named.
    pub key_id: u32,
    /// The session id the sealed frames of this session carry in their header's seq field.
    pub session: u16,
    /// The Noise message ([`crate::auth::HANDSHAKE_MSG_LEN`] bytes).
    pub noise: List<u8, 64>,
}

/// Abort the running measurement: the robot stops first. Any paired handheld may abort.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
pub struct Abort {
    /// Run to abort (0 = whatever is running).
    pub run_id: u32,
}

/// The handheld has the result of `run_id`; the onboard stops resending it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
pub struct ResultAck {
    /// The run.
    pub run_id: u32,
}

/// Ask for cloud preview chunks again.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
pub struct ResendChunks {
    /// The run.
    pub run_id: u32,
    /// Chunk indices wanted (at most 32 per request).
    pub indices: List<u16, 32>,
}

/// Ask for record chunks of one file again.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
pub struct ResendRecordChunks {
    /// The run.
    pub run_id: u32,
    /// The file.
    pub file: RecordFile,
    /// Chunk indices wanted (at most 32 per request).
    pub indices: List<u16, 32>,
}

/// Ask for a [`RobotStatus`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
pub struct StatusRequest {}

/// Ask for the result (and preview) of an earlier run again.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
pub struct FetchRun {
    /// The run.
    pub run_id: u32,
}

wire_enum! {
    /// Phase of a measurement run.
    pub enum Phase {
        /// No run.
        Idle = 1,
        /// Pre-run checks: sensors alive, firmware hello, faults.
        Checks = 2,
        /// Driving under the vehicle.
        Driving = 3,
        /// Stopping the robot.
        Stopping = 4,
        /// Building the cloud and computing the angles.
        Processing = 5,
        /// Result ready and being delivered.
        Done = 6,
        /// Aborted by the operator.
        Aborted = 7,
        /// Failed (see the log lines).
        Failed = 8,
    }
}

/// Run progress, 2 Hz while a run is active.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, MaxSize)]
pub struct Progress {
    /// The run.
    pub run_id: u32,
    /// Phase.
    pub phase: Phase,
    /// Percent of the phase done (0..=100).
    pub percent: u8,
    /// Distance driven so far, m.
    pub travelled_m: f32,
    /// Lidar frames recorded so far.
    pub lidar_frames: u32,
}

bit_set! {
    /// Quality warnings attached to a result.
    pub struct ResultWarnings(u16) {
        /// Fewer tyres than four were fitted.
        const MISSING_TYRE = 0;
        /// Few points support a limiting feature.
        const LOW_SUPPORT = 1;
        /// The tyre fits have a large residual.
        const POOR_TYRE_FIT = 2;
        /// The run was shorter than requested.
        const SHORT_RUN = 3;
        /// Lidar packets were dropped or malformed.
        const LIDAR_LOSS = 4;
        /// The cloud's drift check failed.
        const DRIFT = 5;
    }
}

/// Why a quantity of a [`MeasurementResult`] was not measured; its value is NaN then, never a
/// number the calculator did not measure.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, MaxSize)]
pub enum Absence {
    /// Measured: the value is a number.
    #[default]
    Measured,
    /// No part of the vehicle lies in the quantity's zone.
    NothingInZone,
    /// The scan did not cover the quantity's part of the vehicle (an overhang not seen from
    /// below, a gap in the underside between the axles).
    NotCovered,
}

impl Absence {
    /// The reason in words, for tables and `result.json`; `None` when measured.
    pub fn reason(self) -> Option<&'static str> {
        match self {
            Absence::Measured => None,
            Absence::NothingInZone => Some("no part of the vehicle in the zone"),
            Absence::NotCovered => Some("the scan did not cover this part of the vehicle"),
        }
    }
}

/// The measurement result (radians inside; the handheld shows degrees). Every angle and the
/// clearance carry their expanded uncertainty (k = 2); a quantity that was not measured is NaN
/// with its [`Absence`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, MaxSize)]
pub struct MeasurementResult {
    /// The run.
    pub run_id: u32,
    /// Vehicle identifier from the start command.
    pub vehicle_id: Text<32>,
    /// Approach angle, rad.
    pub approach_rad: f32,
    /// Departure angle, rad.
    pub departure_rad: f32,
    /// Ramp breakover angle, rad.
    pub breakover_rad: f32,
    /// Smallest ground clearance between the axles, m.
    pub ground_clearance_m: f32,
    /// Expanded uncertainty (k = 2) of the approach angle, rad.
    pub approach_u_rad: f32,
    /// Expanded uncertainty (k = 2) of the departure angle, rad.
    pub departure_u_rad: f32,
    /// Expanded uncertainty (k = 2) of the ramp breakover angle, rad.
    pub breakover_u_rad: f32,
    /// Expanded uncertainty (k = 2) of the ground clearance, m.
    pub ground_clearance_u_m: f32,
    /// Why approach, departure, breakover and ground clearance (in that order) were not measured.
    pub absent: [Absence; 4],
    /// Wheelbase from the tyre fits, m.
    pub wheelbase_m: f32,
    /// Track from the tyre fits, m.
    pub track_m: f32,
    /// Points supporting the approach-limiting feature.
    pub approach_support: u16,
    /// Points supporting the departure-limiting feature.
    pub departure_support: u16,
    /// Points supporting the breakover-limiting feature.
    pub breakover_support: u16,
    /// RMS residual of the tyre fits, m.
    pub tyre_fit_rms_m: f32,
    /// Quality warnings.
    pub warnings: ResultWarnings,
    /// Points in the full cloud (kept on the robot).
    pub cloud_points: u32,
    /// Number of [`CloudChunk`]s of the preview.
    pub preview_chunks: u16,
    /// The run's record files that follow as [`RecordChunk`]s, with their lengths. A file the
    /// robot does not have (no `result.json.sig` without a device key) is not listed; a file
    /// longer than [`MAX_RECORD_LEN`] is listed with its length and not sent.
    pub records: List<RecordInfo, MAX_RECORD_FILES>,
}

wire_enum! {
    /// A file of a run's record on the robot, sent byte-exact.
    pub enum RecordFile {
        /// `result.json`.
        ResultJson = 1,
        /// `result.json.sig`, the device key's detached signature of `result.json`.
        ResultSig = 2,
        /// `report.html`, the lab report the robot writes when the run closes.
        ReportHtml = 3,
        /// `report.html.sig`, the device key's detached signature of `report.html`.
        ReportSig = 4,
    }
}

impl RecordFile {
    /// The file's name in the run directory.
    pub const fn file_name(self) -> &'static str {
        match self {
            Self::ResultJson => "result.json",
            Self::ResultSig => "result.json.sig",
            Self::ReportHtml => "report.html",
            Self::ReportSig => "report.html.sig",
        }
    }
}

/// Record files one result can name.
pub const MAX_RECORD_FILES: usize = 4;

/// Largest record file sent over the radio, bytes (about a minute at the radio's rate). A longer
/// file is named with its length in [`MeasurementResult::records`] and stays on the robot.
pub const MAX_RECORD_LEN: u32 = 256 * 1024;

/// Bytes of a record file per [`RecordChunk`] (the most that fits a sealed frame's inner payload
/// limit beside the chunk's other fields).
pub const RECORD_CHUNK_LEN: usize = 190;

/// Chunks of a record file of `len` bytes: at least one, so an empty file is sent too.
#[allow(clippy::cast_possible_truncation)] // RECORD_CHUNK_LEN is 190: fits a u32
pub const fn record_chunk_count(len: u32) -> u32 {
    let n = len.div_ceil(RECORD_CHUNK_LEN as u32);
    if n == 0 { 1 } else { n }
}

/// A record file that follows a result.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
pub struct RecordInfo {
    /// Which file.
    pub file: RecordFile,
    /// Its length on the robot, bytes.
    pub len: u32,
}

/// One chunk of a record file, byte-exact. Chunk `index` holds the file's bytes from
/// `index * RECORD_CHUNK_LEN`; every chunk but the last is full.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
pub struct RecordChunk {
    /// The run.
    pub run_id: u32,
    /// The file.
    pub file: RecordFile,
    /// Chunk index, 0-based.
    pub index: u16,
    /// Number of chunks ([`record_chunk_count`] of `total_len`).
    pub count: u16,
    /// The file's length, bytes (at most [`MAX_RECORD_LEN`]).
    pub total_len: u32,
    /// The bytes.
    pub bytes: List<u8, RECORD_CHUNK_LEN>,
}

/// Points of the cloud preview per chunk (i16 varints take up to 3 bytes each, so 21 points fit
/// a sealed frame's inner payload limit in the worst case).
pub const CHUNK_POINTS: usize = 21;

/// One chunk of the decimated, quantised cloud preview.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
pub struct CloudChunk {
    /// The run.
    pub run_id: u32,
    /// Chunk index, 0-based.
    pub index: u16,
    /// Number of chunks.
    pub count: u16,
    /// Points in the vehicle frame, millimetres (x, y, z), i16: +-32.767 m.
    pub points_mm: List<[i16; 3], CHUNK_POINTS>,
}

/// The robot's state for `passangle status`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, MaxSize)]
pub struct RobotStatus {
    /// Current phase.
    pub phase: Phase,
    /// Current or last run.
    pub run_id: u32,
    /// The firmware answered `Hello` and reports status.
    pub firmware_ok: bool,
    /// Lidar packets arrive.
    pub lidar_ok: bool,
    /// Depth frames arrive.
    pub camera_ok: bool,
    /// Firmware interlocks blocking motion (see [`crate::mcu::Interlocks`]).
    pub interlocks: crate::mcu::Interlocks,
    /// Results waiting for the handheld's ack.
    pub pending_results: u16,
    /// Free space for recordings, MiB (saturating).
    pub disk_free_mib: u32,
    /// Battery voltage as the firmware reports it, millivolts (0: not measured or no firmware).
    pub battery_mv: u16,
}

wire_enum! {
    /// Why the onboard refused a command.
    pub enum RefuseReason {
        /// Reserved (a value of protocol version 2's signed start; never sent now).
        BadTag = 1,
        /// Reserved (a value of protocol version 2's signed start; never sent now).
        Replay = 2,
        /// A run is already active.
        Busy = 3,
        /// Firmware interlocks or failed checks block motion.
        Interlocked = 4,
        /// A parameter is out of range (named in `detail`).
        InvalidParameter = 5,
        /// No such run.
        UnknownRun = 6,
        /// The sender speaks another protocol version.
        VersionMismatch = 7,
        /// The message did not decode.
        Malformed = 8,
    }
}

/// A command was refused.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
pub struct Refused {
    /// Id of the refused message.
    pub msg_id: u16,
    /// Its sequence number.
    pub seq: u16,
    /// Why.
    pub reason: RefuseReason,
    /// Detail for the operator (field name, interlock names).
    pub detail: Text<48>,
}

crate::message::impl_message! {
    StartMeasurement => crate::ids::START_MEASUREMENT,
    HandshakeInit => crate::ids::HANDSHAKE_INIT,
    HandshakeReply => crate::ids::HANDSHAKE_REPLY,
    Abort => crate::ids::ABORT,
    ResultAck => crate::ids::RESULT_ACK,
    ResendChunks => crate::ids::RESEND_CHUNKS,
    StatusRequest => crate::ids::STATUS_REQUEST,
    FetchRun => crate::ids::FETCH_RUN,
    Progress => crate::ids::PROGRESS,
    MeasurementResult => crate::ids::RESULT,
    CloudChunk => crate::ids::CLOUD_CHUNK,
    RobotStatus => crate::ids::ROBOT_STATUS,
    Refused => crate::ids::REFUSED,
    RecordChunk => crate::ids::RECORD_CHUNK,
    ResendRecordChunks => crate::ids::RESEND_RECORD_CHUNKS,
    LabChunk => crate::ids::LAB_CHUNK,
}

message_set! {
    /// Everything the onboard accepts from the handheld inside a session.
    pub enum ToOnboard {
        /// Version announcement.
        Hello(Hello),
        /// Liveness.
        Heartbeat(Heartbeat),
        /// Start.
        Start(StartMeasurement),
        /// Abort.
        Abort(Abort),
        /// Result received.
        ResultAck(ResultAck),
        /// Preview chunks wanted again.
        ResendChunks(ResendChunks),
        /// Status wanted.
        StatusRequest(StatusRequest),
        /// An earlier run wanted.
        FetchRun(FetchRun),
        /// Record chunks wanted again.
        ResendRecordChunks(ResendRecordChunks),
        /// A chunk of the lab file for the next start.
        LabChunk(LabChunk),
    }
}

message_set! {
    /// Everything the handheld accepts from the onboard inside a session.
    pub enum ToHandheld {
        /// Version announcement.
        Hello(Hello),
        /// Liveness.
        Heartbeat(Heartbeat),
        /// Run progress.
        Progress(Progress),
        /// Result.
        Result(MeasurementResult),
        /// Cloud preview chunk.
        CloudChunk(CloudChunk),
        /// Robot status.
        Status(RobotStatus),
        /// Refused command.
        Refused(Refused),
        /// Log line.
        LogLine(LogLine),
        /// Record file chunk.
        RecordChunk(RecordChunk),
    }
}

// Every message of every set fits a sealed frame, and the handshake fits a frame (compile-time
// checks).
const _: () = assert!(ToOnboard::MAX_PAYLOAD_LEN <= crate::auth::MAX_INNER_PAYLOAD_LEN);
const _: () = assert!(ToHandheld::MAX_PAYLOAD_LEN <= crate::auth::MAX_INNER_PAYLOAD_LEN);
const _: () = assert!(record_chunk_count(MAX_RECORD_LEN) <= u16::MAX as u32);
const _: () = assert!(lab_chunk_count(MAX_LAB_LEN) <= u8::MAX as u16);
const _: () = assert!(HandshakeReply::POSTCARD_MAX_SIZE <= crate::frame::MAX_PAYLOAD_LEN);
