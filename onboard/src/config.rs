//! The onboard service's configuration (`/etc/passangle/onboard.toml`) and the pairing files.
//!
//! Strict TOML: unknown keys are rejected and every error names the file, the key and the line
//! (toml's own span report). Every key has a documented default except the two serial ports; the
//! shipped `onboard/onboard.example.toml` lists them all and is checked by a test.
//!
//! Pairing: a pre-shared key is 32 random bytes stored as 64 hex digits in a file readable only by
//! its owner (`passangle pair` writes it on the handheld). The robot's `key-file` lists one key per
//! paired handheld ([`link::keys`]). Every radio session is a fresh Noise handshake keyed
//! with one of them, so nothing needs to persist between runs to refuse a replay
//! (docs/security.md).
//!
//! Signing: the robot's device key (`signing.key-file`) is a 32-byte Ed25519 seed stored the same
//! way, 64 hex digits in a file only its owner reads (`passangle-onboard device-key --generate`
//! writes it). When the key is configured, the service signs every whole file of a run with it
//! and refuses to start if the file is missing, malformed or open to others.

use std::fs;
use std::io;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use protocol::auth::{KEY_LEN, Key};
use protocol::mcu::McuConfig;
use serde::{Deserialize, Serialize};

use crate::recorder::Intrinsics;
use crate::run::RunConfig;

/// A configuration or pairing-file error, naming the file and what was wrong.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The error.
        source: io::Error,
    },
    /// The TOML did not parse or has unknown/mistyped keys (the message names key and line).
    #[error("{path}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// toml's report.
        message: String,
    },
    /// A value is out of range.
    #[error("{path}: `{key}` {problem}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// Dotted key.
        key: String,
        /// What is wrong.
        problem: String,
    },
}

/// The whole onboard configuration.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct OnboardConfig {
    /// Where runs are recorded.
    #[serde(default)]
    pub recording: RecordingConfig,
    /// The radio modem.
    pub radio: RadioConfig,
    /// The UART to the firmware.
    pub mcu: McuLinkConfig,
    /// The VLP-16.
    #[serde(default)]
    pub lidar: LidarConfig,
    /// The D435 depth stream.
    #[serde(default)]
    pub camera: CameraConfig,
    /// Run limits and timeouts.
    #[serde(default)]
    pub run: RunConfig,
    /// The cloud preview sent over the radio.
    #[serde(default)]
    pub preview: PreviewConfig,
    /// Cloud building and angles (`[processing]`, with the pipeline under `[processing.pipeline]`).
    #[serde(default)]
    pub processing: crate::process::ProcessConfig,
    /// Signed records.
    #[serde(default)]
    pub signing: SigningConfig,
}

/// `[signing]`.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields, default)]
pub struct SigningConfig {
    /// The robot's Ed25519 device key (64 hex digits, mode 0600), e.g.
    /// `/etc/passangle/device.key`. Unset: records are not signed, and the service says so in
    /// its log at start and with every run. Set: it must be a valid key file, or the service
    /// does not start.
    pub key_file: Option<PathBuf>,
}

/// `[recording]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields, default)]
pub struct RecordingConfig {
    /// Root directory of the run directories (default `/var/lib/passangle/runs`).
    pub root: PathBuf,
    /// How often the streams are flushed to disk, ms (default 1000).
    pub flush_period_ms: u64,
}

impl Default for RecordingConfig {
    fn default() -> Self {
        Self {
            root: PathBuf::from("/var/lib/passangle/runs"),
            flush_period_ms: 1_000,
        }
    }
}

/// `[radio]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct RadioConfig {
    /// Serial device of the radio modem (required), e.g. `/dev/ttyUSB0`.
    pub port: String,
    /// Baud rate (default 57600).
    #[serde(default = "default_radio_baud")]
    pub baud: u32,
    /// The paired handhelds' keys, one per line (default `/etc/passangle/pairing.key`).
    #[serde(default = "default_key_file")]
    pub key_file: PathBuf,
}

fn default_radio_baud() -> u32 {
    57_600
}
fn default_key_file() -> PathBuf {
    PathBuf::from("/etc/passangle/pairing.key")
}

/// `[mcu]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct McuLinkConfig {
    /// Serial device of the STM32 board (required), e.g. `/dev/ttyACM0`.
    pub port: String,
    /// Baud rate (default 921600).
    #[serde(default = "default_mcu_baud")]
    pub baud: u32,
    /// Heartbeat period, ms (default 20; the firmware stops after 100 ms without one).
    #[serde(default = "default_heartbeat_ms")]
    pub heartbeat_period_ms: u64,
    /// Acceleration of the speed ramp, m/s^2 (default 0.3).
    #[serde(default = "default_accel")]
    pub accel_mps2: f32,
    /// Jerk of the speed ramp, m/s^3 (default 1.0; 0 = trapezoid).
    #[serde(default = "default_jerk")]
    pub jerk_mps3: f32,
    /// The firmware's configuration, sent after its hello; a key missing from `[mcu.firmware]`
    /// takes the firmware's own default ([`firmware_defaults`]).
    #[serde(
        default = "firmware_defaults",
        deserialize_with = "firmware_over_defaults"
    )]
    pub firmware: McuConfig,
}

fn default_mcu_baud() -> u32 {
    921_600
}
fn default_heartbeat_ms() -> u64 {
    20
}
fn default_accel() -> f32 {
    0.3
}
fn default_jerk() -> f32 {
    1.0
}

/// The firmware's own built-in defaults (`control::Config::default`), so the configuration the
/// service sends after `Hello` is the one the firmware was tuned and tested with, not a copy.
pub fn firmware_defaults() -> McuConfig {
    control::Config::default().to_mcu()
}

/// `[mcu.firmware]` is [`McuConfig`] itself (its field docs are the keys' docs). The wire type
/// cannot know the firmware's defaults (they live in `control`, which depends on `protocol`), so
/// a partial table is laid over [`firmware_defaults`] here: every key given replaces its default,
/// and `McuConfig` itself refuses unknown keys.
fn firmware_over_defaults<'de, D: serde::Deserializer<'de>>(d: D) -> Result<McuConfig, D::Error> {
    use serde::de::Error as _;
    let given = toml::Table::deserialize(d)?;
    let mut table = toml::Table::try_from(firmware_defaults()).map_err(D::Error::custom)?;
    table.extend(given);
    McuConfig::deserialize(toml::Value::Table(table)).map_err(D::Error::custom)
}

/// `[lidar]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields, default)]
pub struct LidarConfig {
    /// Data packets (default `0.0.0.0:2368`).
    pub data_addr: SocketAddr,
    /// Position packets (default `0.0.0.0:8308`; remove to ignore them).
    pub position_addr: Option<SocketAddr>,
    /// The lidar counts as alive while its last packet is younger than this, ms (default 500).
    pub alive_timeout_ms: u64,
}

impl Default for LidarConfig {
    fn default() -> Self {
        Self {
            data_addr: SocketAddr::from(([0, 0, 0, 0], 2368)),
            position_addr: Some(SocketAddr::from(([0, 0, 0, 0], 8308))),
            alive_timeout_ms: 500,
        }
    }
}

/// Where depth frames come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CameraSource {
    /// The D435's UVC depth node through V4L2 (builds with the `v4l2` feature; refused at start otherwise).
    V4l2,
    /// Frames pushed in by the embedding program (the simulator).
    Simulated,
    /// No camera: runs proceed on lidar and wheel odometry only (the checks skip the camera).
    None,
}

/// `[camera]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields, default)]
pub struct CameraConfig {
    /// Source (default `none`: V4L2 capture needs a build with the `v4l2` feature).
    pub source: CameraSource,
    /// V4L2 device of the depth stream (default `/dev/video0`; the D435 exposes several nodes).
    pub device: PathBuf,
    /// Width, pixels (default 848).
    pub width: u16,
    /// Height, pixels (default 480).
    pub height: u16,
    /// Frames per second (default 30).
    pub fps: u32,
    /// Record every n-th frame (default 3: 10 Hz, enough for the near field at 0.2 m/s).
    pub record_every: u32,
    /// Intrinsics of the depth stream (V4L2 does not report them; defaults: D435 at 848x480).
    pub intrinsics: Intrinsics,
    /// The camera counts as alive while its last frame is younger than this, ms (default 500).
    pub alive_timeout_ms: u64,
}

impl Default for CameraConfig {
    fn default() -> Self {
        Self {
            source: CameraSource::None,
            device: PathBuf::from("/dev/video0"),
            width: 848,
            height: 480,
            fps: 30,
            record_every: 3,
            intrinsics: Intrinsics {
                fx: 421.0,
                fy: 421.0,
                cx: 424.0,
                cy: 240.0,
                depth_scale_m: 0.001,
            },
            alive_timeout_ms: 500,
        }
    }
}

/// `[preview]`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields, default)]
pub struct PreviewConfig {
    /// Largest number of preview points (default 1500: about 63 chunks, 13 s of airtime at 57600
    /// baud after the result itself).
    pub max_points: usize,
    /// Decimation voxel, m (default 0.05, doubled until the count fits).
    pub voxel_m: f64,
}

impl Default for PreviewConfig {
    fn default() -> Self {
        Self {
            max_points: 1_500,
            voxel_m: 0.05,
        }
    }
}

/// What `run.stop-timeout-us` must leave beyond [`OnboardConfig::stop_time_s`], seconds.
const STOP_MARGIN_S: f64 = 1.0;

impl OnboardConfig {
    /// Parses and checks a configuration text; `path` is only used in messages. The first
    /// problem is the error; [`OnboardConfig::parse_reporting_all`] gives every one.
    pub fn parse(text: &str, path: &Path) -> Result<Self, ConfigError> {
        Self::parse_reporting_all(text, path).map_err(|mut all| all.swap_remove(0))
    }

    /// Parses and checks a configuration text, returning every problem found (`check-config`):
    /// every number that is NaN or infinite anywhere in the file (TOML spells them `nan`, `inf`),
    /// then the typed parse, then every range check. The error list is never empty.
    pub fn parse_reporting_all(text: &str, path: &Path) -> Result<Self, Vec<ConfigError>> {
        match Self::parse_with_problems(text, path) {
            (Some(config), problems) if problems.is_empty() => Ok(config),
            (_, problems) => Err(problems),
        }
    }

    /// The typed configuration if the text parses (range problems or not), and every problem.
    fn parse_with_problems(text: &str, path: &Path) -> (Option<Self>, Vec<ConfigError>) {
        let mut problems = non_finite_values(text, path);
        match toml::from_str::<Self>(text) {
            Ok(config) => {
                problems.extend(config.problems(path));
                (Some(config), problems)
            }
            Err(e) => {
                problems.push(ConfigError::Parse {
                    path: path.to_owned(),
                    message: e.to_string(),
                });
                (None, problems)
            }
        }
    }

    /// What `check-config` reports: the configuration if it parses, and every problem of the
    /// file, of its values and of the key file it names (empty: all good).
    pub fn check_file(path: &Path) -> (Option<Self>, Vec<ConfigError>) {
        let text = match fs::read_to_string(path) {
            Ok(text) => text,
            Err(source) => {
                let e = ConfigError::Io {
                    path: path.to_owned(),
                    source,
                };
                return (None, vec![e]);
            }
        };
        let (config, mut problems) = Self::parse_with_problems(&text, path);
        if let Some(c) = &config {
            problems.extend(c.file_problems());
        }
        (config, problems)
    }

    /// Reads, parses and checks a configuration file.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        Self::load_reporting_all(path).map_err(|mut all| all.swap_remove(0))
    }

    /// Reads, parses and checks a configuration file, returning every problem found.
    pub fn load_reporting_all(path: &Path) -> Result<Self, Vec<ConfigError>> {
        let text = fs::read_to_string(path).map_err(|source| {
            vec![ConfigError::Io {
                path: path.to_owned(),
                source,
            }]
        })?;
        Self::parse_reporting_all(&text, path)
    }

    /// How long the firmware takes from a stop at `run.max-speed-mps` to reporting rest: the
    /// S-curve ramp down at `mcu.accel-mps2` and `mcu.jerk-mps3`, then its zero-speed hold.
    pub fn stop_time_s(&self) -> f64 {
        let v = f64::from(self.run.max_speed_mps);
        let a = f64::from(self.mcu.accel_mps2);
        let j = f64::from(self.mcu.jerk_mps3);
        let jerk_s = if j > 0.0 { a / j } else { 0.0 };
        #[allow(clippy::cast_precision_loss)]
        let hold_s = control::Config::default().hold_after_stop_us as f64 * 1e-6;
        v / a + jerk_s + hold_s
    }

    /// Range checks the types cannot express; the first problem is the error.
    pub fn check(&self, path: &Path) -> Result<(), ConfigError> {
        self.problems(path).into_iter().next().map_or(Ok(()), Err)
    }

    /// Every value outside its range, each naming its key. Every comparison is written so that
    /// NaN fails it.
    #[allow(clippy::too_many_lines)]
    pub fn problems(&self, path: &Path) -> Vec<ConfigError> {
        let mut problems = Vec::new();
        let mut bad = |key: &str, problem: String| {
            problems.push(ConfigError::Invalid {
                path: path.to_owned(),
                key: key.to_owned(),
                problem,
            });
        };
        if self.recording.flush_period_ms == 0 {
            bad("recording.flush-period-ms", "must be above 0".into());
        }
        if self.radio.baud == 0 {
            bad("radio.baud", "must be above 0".into());
        }
        if self.mcu.baud == 0 {
            bad("mcu.baud", "must be above 0".into());
        }
        if !(5..=50).contains(&self.mcu.heartbeat_period_ms) {
            bad(
                "mcu.heartbeat-period-ms",
                format!(
                    "{} is outside 5..=50 (the firmware stops after {} ms without one)",
                    self.mcu.heartbeat_period_ms, self.mcu.firmware.heartbeat_timeout_ms
                ),
            );
        }
        if u64::from(self.mcu.firmware.heartbeat_timeout_ms) < 2 * self.mcu.heartbeat_period_ms {
            bad(
                "mcu.firmware.heartbeat-timeout-ms",
                "must be at least twice mcu.heartbeat-period-ms".into(),
            );
        }
        // The firmware's own validation of what the service will send it.
        if let Err(e) = control::Config::default()
            .with_mcu(&self.mcu.firmware)
            .validate()
        {
            bad("mcu.firmware", format!("the firmware would refuse it: {e}"));
        }
        let accel_ok = self.mcu.accel_mps2 > 0.0
            && self.mcu.accel_mps2 <= self.mcu.firmware.max_accel_mps2
            && self.mcu.accel_mps2.is_finite();
        if !accel_ok {
            bad(
                "mcu.accel-mps2",
                format!(
                    "{} is not in (0, mcu.firmware.max-accel-mps2 = {}]",
                    self.mcu.accel_mps2, self.mcu.firmware.max_accel_mps2
                ),
            );
        }
        if !(self.mcu.jerk_mps3 >= 0.0 && self.mcu.jerk_mps3.is_finite()) {
            bad(
                "mcu.jerk-mps3",
                format!("{} is not finite and >= 0", self.mcu.jerk_mps3),
            );
        }
        let run = &self.run;
        let speed_ok = run.max_speed_mps > 0.0
            && run.max_speed_mps <= self.mcu.firmware.max_speed_mps
            && run.max_speed_mps.is_finite();
        if !speed_ok {
            bad(
                "run.max-speed-mps",
                format!(
                    "{} is not in (0, mcu.firmware.max-speed-mps = {}]",
                    run.max_speed_mps, self.mcu.firmware.max_speed_mps
                ),
            );
        }
        if !(run.max_distance_m > 0.0 && run.max_distance_m <= MAX_DISTANCE_M) {
            bad(
                "run.max-distance-m",
                format!("{} is not in (0, {MAX_DISTANCE_M}] m", run.max_distance_m),
            );
        }
        for (key, us) in [
            ("run.checks-timeout-us", run.checks_timeout_us),
            ("run.stop-timeout-us", run.stop_timeout_us),
            ("run.progress-period-us", run.progress_period_us),
        ] {
            if us == 0 {
                bad(key, "must be above 0".into());
            }
        }
        if run.parked_us >= run.checks_timeout_us {
            bad(
                "run.parked-us",
                format!(
                    "{} us is not below run.checks-timeout-us ({} us): the checks would always \
                     time out",
                    run.parked_us, run.checks_timeout_us
                ),
            );
        }
        if accel_ok && speed_ok && self.mcu.jerk_mps3.is_finite() {
            let stop_s = self.stop_time_s();
            #[allow(clippy::cast_precision_loss)]
            let timeout_s = run.stop_timeout_us as f64 * 1e-6;
            if timeout_s < stop_s + STOP_MARGIN_S {
                bad(
                    "run.stop-timeout-us",
                    format!(
                        "{timeout_s} s is too short for a stop from run.max-speed-mps = {} at \
                         mcu.accel-mps2 = {} (about {stop_s:.1} s with the jerk limit and the \
                         firmware's hold, plus {STOP_MARGIN_S} s): raise it or the acceleration",
                        run.max_speed_mps, self.mcu.accel_mps2
                    ),
                );
            }
        }
        if self.lidar.alive_timeout_ms == 0 {
            bad("lidar.alive-timeout-ms", "must be above 0".into());
        }
        let cam = &self.camera;
        if cam.width == 0 || cam.height == 0 {
            bad(
                "camera.width/height",
                format!(
                    "{} x {} pixels: both must be above 0",
                    cam.width, cam.height
                ),
            );
        }
        if cam.fps == 0 || cam.fps > 300 {
            bad("camera.fps", format!("{} is not in 1..=300", cam.fps));
        }
        if cam.record_every == 0 {
            bad("camera.record-every", "must be at least 1".into());
        }
        if cam.alive_timeout_ms == 0 {
            bad("camera.alive-timeout-ms", "must be above 0".into());
        }
        let k = &cam.intrinsics;
        for (key, v) in [
            ("camera.intrinsics.fx", k.fx),
            ("camera.intrinsics.fy", k.fy),
            ("camera.intrinsics.depth-scale-m", k.depth_scale_m),
        ] {
            if !(v > 0.0 && v.is_finite()) {
                bad(key, format!("{v} is not finite and above 0"));
            }
        }
        for (key, v, size) in [
            ("camera.intrinsics.cx", k.cx, cam.width),
            ("camera.intrinsics.cy", k.cy, cam.height),
        ] {
            if !(v >= 0.0 && v <= f32::from(size)) {
                bad(
                    key,
                    format!("{v} is not inside the image (0..={size} pixels)"),
                );
            }
        }
        if self.preview.max_points == 0 {
            bad("preview.max-points", "must be above 0".into());
        }
        if !(self.preview.voxel_m > 0.0 && self.preview.voxel_m.is_finite()) {
            bad(
                "preview.voxel-m",
                format!("{} is not finite and above 0", self.preview.voxel_m),
            );
        }
        if self.processing.min_cloud_points == 0 {
            bad("processing.min-cloud-points", "must be above 0".into());
        }
        // The decoder's own check; named here by the config's key.
        let decoder = vlp16::DecoderConfig {
            range_offsets_m: self.processing.lidar_range_offsets_m,
            ..vlp16::DecoderConfig::default()
        };
        if let Err(vlp16::ConfigError::RangeOffset { laser, offset_m }) = decoder.check() {
            bad(
                "processing.lidar-range-offsets-m",
                format!(
                    "laser {laser}: {offset_m} m is not within +-{} m (a larger offset is a \
                     sensor to repair, not to calibrate)",
                    vlp16::MAX_RANGE_OFFSET_M
                ),
            );
        }
        let scale = self.processing.wheel_distance_scale;
        let (lo, hi) = pipeline::fusion::WHEEL_SCALE_RANGE;
        if !(lo..=hi).contains(&scale) {
            bad(
                "processing.wheel-distance-scale",
                format!(
                    "{scale} is not within {lo}..{hi} (wheels that far off are to repair, not \
                     to calibrate)"
                ),
            );
        }
        problems
    }

    /// Problems with the paired handhelds' key file (`check-config`; the service reads it at
    /// start). It must exist, be a regular file owned by root or by the user running the check
    /// (run it as the service user), grant nothing to others and at most read to the group
    /// (modes 0600, 0640, 0400, 0440), and hold at least one well-formed key.
    ///
    /// The device key (`signing.key-file`), when set, is held to the same rules and must hold
    /// one key of 64 hex digits.
    pub fn file_problems(&self) -> Vec<ConfigError> {
        let path = &self.radio.key_file;
        let mut problems: Vec<ConfigError> = check_secret_file(path, "radio.key-file")
            .and_then(|()| {
                link::keys::read(path)
                    .map(drop)
                    .map_err(|e| ConfigError::Invalid {
                        path: path.clone(),
                        key: "radio.key-file".into(),
                        problem: e.to_string(),
                    })
            })
            .err()
            .into_iter()
            .collect();
        if let Some(path) = &self.signing.key_file {
            problems.extend(read_device_key(path).err());
        }
        problems
    }

    /// The device key, if `signing.key-file` is set (checked as [`Self::file_problems`] does).
    pub fn device_key(&self) -> Result<Option<signing::DeviceKey>, ConfigError> {
        self.signing
            .key_file
            .as_deref()
            .map(read_device_key)
            .transpose()
    }
}

/// Reads the robot's device key (`signing.key-file`): a file that `check_secret_file` accepts,
/// holding a 32-byte seed as 64 hex digits. Every error names `signing.key-file` and the file.
pub fn read_device_key(path: &Path) -> Result<signing::DeviceKey, ConfigError> {
    const KEY: &str = "signing.key-file";
    check_secret_file(path, KEY)?;
    let invalid = |problem: String| ConfigError::Invalid {
        path: path.to_owned(),
        key: KEY.to_owned(),
        problem,
    };
    // A seed file is 65 bytes; anything much larger is not one, and is not read whole.
    let len = fs::metadata(path).map_or(0, |m| m.len());
    if len > 256 {
        return Err(invalid(format!(
            "is {len} bytes: a device key is 64 hex digits (`passangle-onboard device-key \
             --generate`)"
        )));
    }
    let text = fs::read_to_string(path).map_err(|e| invalid(e.to_string()))?;
    let seed = signing::from_hex::<{ signing::SEED_LEN }>(text.trim()).ok_or_else(|| {
        invalid(format!(
            "expected {} hex digits (a key written by `passangle-onboard device-key --generate`)",
            2 * signing::SEED_LEN
        ))
    })?;
    Ok(signing::DeviceKey::from_seed(&seed))
}

/// Writes a new device key seed (64 hex digits) readable by its owner only (mode 0600); refuses
/// to overwrite.
pub fn write_device_key(path: &Path, seed: &[u8; signing::SEED_LEN]) -> Result<(), ConfigError> {
    write_secret_hex(path, seed)
}

/// The longest drive `run.max-distance-m` may allow, m (a car park's length, far beyond any
/// vehicle).
const MAX_DISTANCE_M: f32 = 100.0;

/// Every float in the TOML text that is NaN or infinite, named by its dotted key. A text that
/// does not parse as TOML gives none (the typed parse reports it).
fn non_finite_values(text: &str, path: &Path) -> Vec<ConfigError> {
    fn walk(value: &toml::Value, key: &str, out: &mut Vec<String>) {
        match value {
            toml::Value::Float(f) if !f.is_finite() => out.push(format!("{key} = {f}")),
            toml::Value::Table(t) => {
                for (k, v) in t {
                    let key = if key.is_empty() {
                        k.clone()
                    } else {
                        format!("{key}.{k}")
                    };
                    walk(v, &key, out);
                }
            }
            toml::Value::Array(a) => {
                for (i, v) in a.iter().enumerate() {
                    walk(v, &format!("{key}[{i}]"), out);
                }
            }
            _ => {}
        }
    }
    let Ok(table) = text.parse::<toml::Table>() else {
        return Vec::new();
    };
    let mut found = Vec::new();
    for (k, v) in &table {
        walk(v, k, &mut found);
    }
    found
        .into_iter()
        .map(|entry| {
            let (key, value) = entry.split_once(" = ").unwrap_or((&entry, ""));
            ConfigError::Invalid {
                path: path.to_owned(),
                key: key.to_owned(),
                problem: format!("is {value}: every number must be finite"),
            }
        })
        .collect()
}

/// Checks that `path` (the value of `key`) is a regular file owned by root or the effective
/// user, with no permission for others and at most read for the group.
fn check_secret_file(path: &Path, key: &str) -> Result<(), ConfigError> {
    use std::os::unix::fs::MetadataExt;
    let invalid = |problem: String| ConfigError::Invalid {
        path: path.to_owned(),
        key: key.to_owned(),
        problem,
    };
    let meta = fs::metadata(path).map_err(|e| {
        if e.kind() == io::ErrorKind::NotFound {
            invalid("the file does not exist".into())
        } else {
            ConfigError::Io {
                path: path.to_owned(),
                source: e,
            }
        }
    })?;
    if !meta.is_file() {
        return Err(invalid("is not a regular file".into()));
    }
    let mode = meta.mode() & 0o7777;
    if mode & 0o7137 != 0 {
        return Err(invalid(format!(
            "mode {mode:04o} is too open: use 0600 (or 0640 for the service's group), \
             never readable by others"
        )));
    }
    let me = nix::unistd::geteuid().as_raw();
    if meta.uid() != 0 && meta.uid() != me {
        return Err(invalid(format!(
            "owned by uid {}: expected root or the user running this check (uid {me}); run \
             check-config as the service user",
            meta.uid()
        )));
    }
    Ok(())
}

/// Reads a pairing key file (64 hex digits, surrounding whitespace ignored).
pub fn read_key(path: &Path) -> Result<Key, ConfigError> {
    let text = fs::read_to_string(path).map_err(|source| ConfigError::Io {
        path: path.to_owned(),
        source,
    })?;
    parse_key(text.trim()).ok_or_else(|| ConfigError::Parse {
        path: path.to_owned(),
        message: format!(
            "expected {} hex digits (a key written by `passangle pair`)",
            2 * KEY_LEN
        ),
    })
}

fn parse_key(hex: &str) -> Option<Key> {
    if hex.len() != 2 * KEY_LEN || !hex.is_ascii() {
        return None;
    }
    let mut key = [0u8; KEY_LEN];
    for (i, b) in key.iter_mut().enumerate() {
        *b = u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).ok()?;
    }
    Some(Key(key))
}

/// Writes a new key file readable by its owner only (mode 0600); refuses to overwrite
/// ([`link::keys::write_key`] with the configuration's error).
pub fn write_key(path: &Path, key: &Key) -> Result<(), ConfigError> {
    write_secret_hex(path, &key.0)
}

/// Writes `secret` as hex and a newline to a new file of mode 0600; refuses to overwrite
/// ([`link::keys::write_secret_hex`]).
fn write_secret_hex(path: &Path, secret: &[u8]) -> Result<(), ConfigError> {
    link::keys::write_secret_hex(path, secret).map_err(|source| ConfigError::Io {
        path: path.to_owned(),
        source,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const MINIMAL: &str = "[radio]\nport = \"/dev/ttyUSB0\"\n[mcu]\nport = \"/dev/ttyACM0\"\n";

    #[test]
    fn minimal_config_takes_the_documented_defaults() {
        let c = OnboardConfig::parse(MINIMAL, Path::new("x.toml")).unwrap();
        assert_eq!(c.radio.baud, 57_600);
        assert_eq!(c.mcu.heartbeat_period_ms, 20);
        assert_eq!(c.run, RunConfig::default());
        assert_eq!(c.lidar.data_addr.port(), 2368);
        assert_eq!(c.camera.source, CameraSource::None);
    }

    #[test]
    fn the_shipped_example_is_valid_and_complete() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("onboard.example.toml");
        let c = OnboardConfig::load(&path).unwrap();
        // The example spells out every default: parsing it equals parsing the minimal file.
        let mut min = OnboardConfig::parse(MINIMAL, Path::new("x.toml")).unwrap();
        min.radio.port.clone_from(&c.radio.port);
        min.mcu.port.clone_from(&c.mcu.port);
        assert_eq!(c, min, "example and defaults disagree");
    }

    #[test]
    fn the_standards_of_result_json_are_configurable() {
        use angles::profiles::Standard;
        let c = OnboardConfig::parse(MINIMAL, Path::new("x.toml")).unwrap();
        assert_eq!(c.processing.standards.len(), 6, "all by default");
        let with = |line: &str| {
            let text = format!("{MINIMAL}[processing]\n{line}\n");
            OnboardConfig::parse(&text, Path::new("x.toml"))
        };
        let c = with("standards = [\"eu\", \"cfr\"]").unwrap();
        assert_eq!(
            c.processing.standards,
            [Standard::Cfr523Sae, Standard::Eu2018_858]
        );
        assert!(
            with("standards = []")
                .unwrap()
                .processing
                .standards
                .is_empty()
        );
        let e = with("standards = [\"sae\"]").unwrap_err().to_string();
        assert!(e.contains("`sae`"), "{e}");
    }

    #[test]
    fn the_parked_time_must_leave_the_checks_time_to_pass() {
        let e = OnboardConfig::parse(
            &format!("{MINIMAL}[run]\nparked-us = 6000000\n"),
            Path::new("c.toml"),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("run.parked-us") && e.contains("checks-timeout-us"),
            "{e}"
        );
    }

    #[test]
    fn the_wheel_distance_scale_is_read_and_checked() {
        let with = |line: &str| {
            OnboardConfig::parse(
                &format!("{MINIMAL}[processing]\n{line}\n"),
                Path::new("c.toml"),
            )
        };
        let c = with("wheel-distance-scale = 1.0129").unwrap();
        assert!((c.processing.wheel_distance_scale - 1.0129).abs() < 1e-12);
        assert!((with("").unwrap().processing.wheel_distance_scale - 1.0).abs() < 1e-12);
        for bad in ["0.7", "nan", "1.25"] {
            let e = with(&format!("wheel-distance-scale = {bad}"))
                .unwrap_err()
                .to_string();
            assert!(e.contains("processing.wheel-distance-scale"), "{bad}: {e}");
        }
    }

    #[test]
    fn lidar_range_offsets_are_read_and_checked() {
        let with = |line: &str| {
            OnboardConfig::parse(
                &format!("{MINIMAL}[processing]\n{line}\n"),
                Path::new("c.toml"),
            )
        };
        let offsets: Vec<String> = (0..16)
            .map(|l| format!("{:.3}", 0.001 * f64::from(l)))
            .collect();
        let c = with(&format!("lidar-range-offsets-m = [{}]", offsets.join(", "))).unwrap();
        assert!((c.processing.lidar_range_offsets_m[15] - 0.015).abs() < 1e-7);
        let mut bad = offsets.clone();
        bad[5] = "0.25".into();
        let e = with(&format!("lidar-range-offsets-m = [{}]", bad.join(", ")))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("processing.lidar-range-offsets-m") && e.contains("laser 5"),
            "{e}"
        );
        let e = with("lidar-range-offsets-m = [0.0, 0.0]")
            .unwrap_err()
            .to_string();
        assert!(e.contains("lidar-range-offsets-m"), "{e}");
    }

    #[test]
    fn unknown_keys_and_bad_values_are_named() {
        let e = OnboardConfig::parse(
            &format!("{MINIMAL}[run]\nmax-sped-mps = 1.0\n"),
            Path::new("a.toml"),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("a.toml") && e.contains("max-sped-mps") && e.contains("line 6"),
            "{e}"
        );
        let e = OnboardConfig::parse("[radio]\nport = \"x\"\n", Path::new("b.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("mcu"), "{e}");
        let e = OnboardConfig::parse(
            &MINIMAL.replace("[mcu]\n", "[mcu]\nheartbeat-period-ms = 200\n"),
            Path::new("c.toml"),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("`mcu.heartbeat-period-ms`"), "{e}");
        let e = OnboardConfig::parse(
            &format!("{MINIMAL}[run]\nmax-speed-mps = 3.0\n"),
            Path::new("d.toml"),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("`run.max-speed-mps`"), "{e}");
        // A gentle ramp must fit in the stop timeout: 0.5 m/s at 0.05 m/s^2 is a 10 s stop.
        let e = OnboardConfig::parse(
            &MINIMAL.replace("[mcu]\n", "[mcu]\naccel-mps2 = 0.05\n"),
            Path::new("e.toml"),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("`run.stop-timeout-us`") && e.contains("mcu.accel-mps2 = 0.05"),
            "{e}"
        );
        let c = OnboardConfig::parse(MINIMAL, Path::new("x.toml")).unwrap();
        assert!((c.stop_time_s() - (0.5 / 0.3 + 0.3 + 0.5)).abs() < 1e-6);
    }

    #[test]
    fn a_partial_firmware_table_keeps_the_firmware_defaults() {
        let c = OnboardConfig::parse(
            &format!("{MINIMAL}[mcu.firmware]\nwheel-radius-m = 0.05\nesc-ids = [4, 3, 2, 1]\n"),
            Path::new("f.toml"),
        )
        .unwrap();
        let expected = McuConfig {
            wheel_radius_m: 0.05,
            esc_ids: [4, 3, 2, 1],
            ..firmware_defaults()
        };
        assert_eq!(c.mcu.firmware, expected);
        let minimal = OnboardConfig::parse(MINIMAL, Path::new("x.toml")).unwrap();
        assert_eq!(minimal.mcu.firmware, firmware_defaults());
        let e = OnboardConfig::parse(
            &format!("{MINIMAL}[mcu.firmware]\nwheel-radius = 0.05\n"),
            Path::new("g.toml"),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("g.toml") && e.contains("wheel-radius"), "{e}");
    }

    #[test]
    fn every_problem_is_reported_non_finite_values_included() {
        let text = format!(
            "{MINIMAL}[run]\nmax-speed-mps = nan\nmax-distance-m = inf\n\
             [camera]\nwidth = 0\nheight = 0\n[processing.pipeline]\n"
        );
        let problems = OnboardConfig::parse_reporting_all(&text, Path::new("f.toml")).unwrap_err();
        let all: Vec<String> = problems.iter().map(ToString::to_string).collect();
        for needle in [
            "`run.max-speed-mps` is NaN: every number must be finite",
            "`run.max-distance-m` is inf: every number must be finite",
            "`run.max-speed-mps` NaN is not in (0,",
            "`run.max-distance-m` inf is not in (0, 100] m",
            "`camera.width/height` 0 x 0 pixels",
            "`camera.intrinsics.cx` 424 is not inside the image",
        ] {
            assert!(
                all.iter()
                    .any(|e| e.starts_with("f.toml: ") && e.contains(needle)),
                "{needle:?} missing from {all:#?}"
            );
        }
        // The service's own load stops at the first.
        assert!(OnboardConfig::parse(&text, Path::new("f.toml")).is_err());
        // A negative infinity in an array and a NaN deep in the pipeline section are named too.
        let text = format!("{MINIMAL}[processing.pipeline]\nvoxel-m = -inf\n");
        let e = OnboardConfig::parse_reporting_all(&text, Path::new("g.toml"))
            .unwrap_err()
            .remove(0)
            .to_string();
        assert!(e.contains("`processing.pipeline.voxel-m` is -inf"), "{e}");
    }

    #[test]
    fn the_key_file_is_checked() {
        use std::os::unix::fs::PermissionsExt;
        let dir = std::env::temp_dir().join(format!("passangle-cfgchk-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        fs::create_dir_all(&dir).unwrap();
        let key = dir.join("pairing.key");
        let text = MINIMAL.replace("[mcu]", &format!("key-file = \"{}\"\n[mcu]", key.display()));
        let config_path = dir.join("onboard.toml");
        fs::write(&config_path, &text).unwrap();
        let problems = |path: &Path| -> Vec<String> {
            OnboardConfig::check_file(path)
                .1
                .iter()
                .map(ToString::to_string)
                .collect()
        };
        let p = problems(&config_path);
        assert_eq!(p.len(), 1, "{p:#?}");
        assert!(
            p[0].contains("`radio.key-file` the file does not exist"),
            "{p:#?}"
        );
        link::keys::add(&key, &Key([7; KEY_LEN]), "handheld 1").unwrap();
        assert_eq!(problems(&config_path), Vec::<String>::new());
        // World-readable.
        fs::set_permissions(&key, fs::Permissions::from_mode(0o644)).unwrap();
        let p = problems(&config_path);
        assert!(p[0].contains("mode 0644 is too open"), "{p:#?}");
        // Not a key.
        fs::set_permissions(&key, fs::Permissions::from_mode(0o600)).unwrap();
        fs::write(&key, "twelve\n").unwrap();
        let p = problems(&config_path);
        assert!(
            p[0].contains("`radio.key-file`") && p[0].contains("line 1"),
            "{p:#?}"
        );
        // A directory where the key should be.
        fs::remove_file(&key).unwrap();
        fs::create_dir(&key).unwrap();
        let p = problems(&config_path);
        assert!(p[0].contains("is not a regular file"), "{p:#?}");
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn the_device_key_is_checked_when_configured() {
        use std::os::unix::fs::PermissionsExt;
        let dir = std::env::temp_dir().join(format!("passangle-devkey-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        fs::create_dir_all(&dir).unwrap();
        let pairing = dir.join("pairing.key");
        link::keys::add(&pairing, &Key([7; KEY_LEN]), "handheld 1").unwrap();
        let device = dir.join("device.key");
        let base = MINIMAL.replace(
            "[mcu]",
            &format!("key-file = \"{}\"\n[mcu]", pairing.display()),
        );
        let config_path = dir.join("onboard.toml");
        let problems = |text: &str| -> Vec<String> {
            fs::write(&config_path, text).unwrap();
            OnboardConfig::check_file(&config_path)
                .1
                .iter()
                .map(ToString::to_string)
                .collect()
        };
        // Not configured: nothing to check, nothing signed.
        assert_eq!(problems(&base), Vec::<String>::new());
        let c = OnboardConfig::parse(&base, &config_path).unwrap();
        assert!(c.device_key().unwrap().is_none());
        let signed = format!("{base}[signing]\nkey-file = \"{}\"\n", device.display());
        let p = problems(&signed);
        assert!(
            p.len() == 1 && p[0].contains("`signing.key-file` the file does not exist"),
            "{p:#?}"
        );
        write_device_key(&device, &[9; signing::SEED_LEN]).unwrap();
        assert_eq!(problems(&signed), Vec::<String>::new());
        let c = OnboardConfig::parse(&signed, &config_path).unwrap();
        assert_eq!(
            c.device_key().unwrap().unwrap().public(),
            signing::DeviceKey::from_seed(&[9; signing::SEED_LEN]).public()
        );
        assert!(
            write_device_key(&device, &[1; signing::SEED_LEN]).is_err(),
            "no overwrite"
        );
        fs::set_permissions(&device, fs::Permissions::from_mode(0o604)).unwrap();
        let p = problems(&signed);
        assert!(
            p.len() == 1 && p[0].contains("`signing.key-file` mode 0604 is too open"),
            "{p:#?}"
        );
        fs::set_permissions(&device, fs::Permissions::from_mode(0o600)).unwrap();
        fs::write(&device, "0123\n").unwrap();
        let p = problems(&signed);
        assert!(
            p.len() == 1
                && p[0].contains("`signing.key-file`")
                && p[0].contains("expected 64 hex digits"),
            "{p:#?}"
        );
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn handheld_key_files_round_trip() {
        use std::os::unix::fs::PermissionsExt;
        let dir = std::env::temp_dir().join(format!("passangle-cfg-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        fs::create_dir_all(&dir).unwrap();
        let p = dir.join("k");
        let key = Key([0xab; KEY_LEN]);
        write_key(&p, &key).unwrap();
        assert_eq!(read_key(&p).unwrap(), key);
        assert_eq!(
            fs::metadata(&p).unwrap().permissions().mode() & 0o777,
            0o600
        );
        assert!(write_key(&p, &key).is_err(), "never overwrites a key");
        fs::write(dir.join("bad"), "abc").unwrap();
        assert!(
            read_key(&dir.join("bad"))
                .unwrap_err()
                .to_string()
                .contains("64 hex digits")
        );
        fs::remove_dir_all(&dir).unwrap();
    }
}
