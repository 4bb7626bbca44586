//! The lab report of a recorded run: one self-contained HTML file (inline CSS and SVG, no script,
//! nothing fetched) that prints cleanly to PDF. The robot writes it, signed, when a run closes
//! ([`write_on_robot`]); `passangle report RUN_DIR` writes it from a copy of the run.
//!
//! The results are the run's recorded (and, with a device key, signed) `result.json`; a quantity
//! it did not measure shows its reason, never a number. The witnesses, tyre fits, side view and
//! floor flatness come from running the calculator again on the run's `cloud.ply` and
//! `scan.toml` (the scan path; [`crate::scan_file`]) with the service's settings; where that
//! recomputation differs from `result.json`, the report says so.
//! Provenance: robot key id, software version and git hash, the config's hash and the SHA-256 of
//! every file of the run, with each signature's status when trusted keys are given.
//!
//! [`gather`] reads the files into a [`Report`]; [`render`] turns it into HTML without any IO.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use angles::profiles::{
    Classification, DECISION_RULE, Measure, ProfileQuantity, ProfileResult, QuantityKind, Standard,
    Thresholds, classify_all, compute_profiles,
};
use angles::{
    AngleFinding, AnglesConfig, AnglesResult, Quantity, V3, Zone, compute_angles, side_view_svg,
};
use anyhow::Context;
use cloud_io::read_cloud;
use link::record::ProfileRecord;
use serde::Deserialize;
use sha2::{Digest, Sha256};

use crate::recorder::{RecordedOutcome, Recording, ResultRecord, RunMeta};
use crate::scan_file::ScanRecord;
use crate::signed::{self, Check};

/// The recomputed angles may differ from `result.json` by this much before the report says so
/// (degrees): `result.json` holds f32 values rounded for people.
const ANGLE_TOLERANCE_DEG: f64 = 0.01;
/// Likewise for the ground clearance, metres.
const CLEARANCE_TOLERANCE_M: f64 = 0.0005;
/// A witness's close-up: this far either side of the witness along the vehicle, metres.
const CLOSE_UP_HALF_X_M: f64 = 0.3;
/// A close-up's height above the floor, metres (raised for a witness higher than this less 0.1 m).
const CLOSE_UP_Z_M: f64 = 0.6;
/// At most this many points are drawn in a close-up (evenly thinned beyond).
const CLOSE_UP_MAX_POINTS: usize = 6000;
/// The close-ups' scale, pixels per metre.
const CLOSE_UP_PX_PER_M: f64 = 600.0;
/// A close-up's point: a square this wide, pixels.
const CLOSE_UP_DOT_PX: f64 = 1.6;

/// `[lab]` of the lab file.
#[derive(Debug, Clone, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct LabSection {
    /// The lab's name.
    pub name: Option<String>,
    /// Its address.
    pub address: Option<String>,
    /// Its accreditation (body and number).
    pub accreditation: Option<String>,
    /// Who ran the measurement.
    pub operator: Option<String>,
}

/// `[customer]` of the lab file.
#[derive(Debug, Clone, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct CustomerSection {
    /// The customer's name.
    pub name: Option<String>,
    /// The customer's order or reference.
    pub reference: Option<String>,
}

/// `[vehicle]` of the lab file.
#[derive(Debug, Clone, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct VehicleSection {
    /// Make.
    pub make: Option<String>,
    /// Model.
    pub model: Option<String>,
    /// Vehicle identification number.
    pub vin: Option<String>,
    /// Load state (e.g. "unladen, driver 75 kg").
    pub load_state: Option<String>,
    /// Tyre pressures as set (e.g. "front 2.3 bar, rear 2.5 bar").
    pub tyre_pressures: Option<String>,
    /// Suspension mode (e.g. "air suspension, normal height").
    pub suspension_mode: Option<String>,
}

/// The lab file (`--lab`): every field optional, an unknown key an error.
#[derive(Debug, Clone, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct LabFile {
    /// Pass/fail decisions to state (`decide = ["cfr523.5", "eu-offroad"]`, a top-level key
    /// before the first table): each against its standard's profile, by guarded acceptance with
    /// the expanded uncertainty. Empty: no statement of conformity.
    #[serde(default)]
    pub decide: Vec<String>,
    /// The lab.
    #[serde(default)]
    pub lab: LabSection,
    /// The customer.
    #[serde(default)]
    pub customer: CustomerSection,
    /// The vehicle.
    #[serde(default)]
    pub vehicle: VehicleSection,
}

impl LabFile {
    /// Parses the lab file's text.
    pub fn parse(text: &str) -> anyhow::Result<Self> {
        let lab: Self = toml::from_str(text).map_err(|e| anyhow::anyhow!("{e}"))?;
        lab.thresholds()?;
        Ok(lab)
    }

    /// Parses a lab file's bytes (UTF-8), as they come from a file or over the radio.
    ///
    /// # Errors
    /// Bytes that are not UTF-8; what [`Self::parse`] refuses.
    pub fn parse_bytes(bytes: &[u8]) -> anyhow::Result<Self> {
        Self::parse(std::str::from_utf8(bytes).context("not UTF-8")?)
    }

    /// The threshold sets of `decide`.
    ///
    /// # Errors
    /// Names an unknown id.
    pub fn thresholds(&self) -> anyhow::Result<Vec<Thresholds>> {
        self.decide
            .iter()
            .map(|id| {
                Thresholds::parse(id).ok_or_else(|| {
                    anyhow::anyhow!("decide: unknown `{id}`: expected cfr523.5 or eu-offroad")
                })
            })
            .collect()
    }
}

/// One file of the run directory.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FileEntry {
    /// Path inside the run directory, `/`-separated.
    pub name: String,
    /// Bytes.
    pub size: u64,
    /// SHA-256, hex.
    pub sha256: String,
    /// Its signature's status, in words.
    pub signature: String,
    /// The signature was checked and does not hold (or the file is not signed when it should be).
    pub signature_failed: bool,
}

/// The calculator run again on `cloud.ply`.
#[derive(Debug, Clone)]
pub struct Recomputed {
    /// What it found.
    pub angles: AnglesResult,
    /// The cloud, in its own (cloud) frame.
    pub points_m: Vec<V3>,
    /// The calculator's settings used.
    pub config: AnglesConfig,
}

impl Recomputed {
    /// The recomputation had the scan path (from the run's `scan.toml`, as the service had it);
    /// false: the run has none, and the recomputation went without.
    pub fn scan_known(&self) -> bool {
        !self.config.scan_path_in_cloud.is_empty()
    }
}

/// Everything the report shows, gathered from the run directory.
#[derive(Debug, Clone)]
pub struct Report {
    /// The report id ([`report_id`]).
    pub id: String,
    /// The run directory's name.
    pub run_name: String,
    /// When the report was written, UTC.
    pub written_utc: String,
    /// Who wrote it.
    pub writer: Writer,
    /// The lab file, and where it came from (`None`: no lab file given).
    pub lab: LabFile,
    /// The lab file's path.
    pub lab_path: Option<String>,
    /// `meta.json`.
    pub meta: RunMeta,
    /// The run's `INCOMPLETE` marker is present.
    pub incomplete: bool,
    /// `result.json` (`None`: the run has none).
    pub result: Option<ResultRecord>,
    /// The service's `processing.enter-at-front` (from the run's `config.toml`).
    pub enter_at_front: bool,
    /// The lidar's per-laser range offsets the run was built with
    /// (`processing.lidar-range-offsets-m`; zeros: none).
    pub lidar_range_offsets_m: [f32; 16],
    /// The wheels' distance scale the run was built with (`processing.wheel-distance-scale`;
    /// 1: none).
    pub wheel_distance_scale: f64,
    /// The recomputation, or why there is none.
    pub recomputed: Result<Recomputed, String>,
    /// SHA-256 of `config.toml` (`None`: not in the run).
    pub config_sha256: Option<String>,
    /// The robot, as far as the run says: meta.json's `robot_id`, else the id of the key that
    /// signed result.json.
    pub robot_id: Option<String>,
    /// Every file of the run directory.
    pub files: Vec<FileEntry>,
    /// The trusted keys' ids the signatures were checked against (empty: not checked).
    pub checked_with: Vec<String>,
    /// `passangle`'s version.
    pub version: String,
    /// The git commit it was built from.
    pub git_hash: String,
    /// The standards' profiles: from `result.json`, or recomputed from `cloud.ply` when the
    /// record predates them.
    pub profiles: Vec<ProfileResult>,
    /// Where the profiles come from, in words.
    pub profiles_source: &'static str,
    /// The decisions the lab file asks for.
    pub decisions: Vec<Classification>,
}

/// A profile of `result.json` as the calculator's type (`None`: an id this build does not know).
fn profile_of_record(p: &ProfileRecord) -> Option<ProfileResult> {
    let standard = Standard::ALL.into_iter().find(|s| s.id() == p.standard)?;
    let quantities = p
        .quantities
        .iter()
        .filter_map(|q| {
            let kind = QuantityKind::ALL.into_iter().find(|k| k.id() == q.id)?;
            let measure = match (q.value, q.u) {
                (Some(value), Some(u)) => Measure::Value {
                    value,
                    u,
                    // result.json does not keep the witness.
                    witness_in_vehicle: V3::repeat(f64::NAN),
                },
                _ => Measure::NotMeasured(
                    q.not_measured
                        .clone()
                        .unwrap_or_else(|| "no reason recorded".to_owned()),
                ),
            };
            Some(ProfileQuantity {
                kind,
                name: standard.term(kind),
                measure,
            })
        })
        .collect();
    Some(ProfileResult {
        standard,
        quantities,
        notes: standard.notes(),
    })
}

/// The report id: the first 16 hex digits of SHA-256 over `result.json`'s bytes, a newline and
/// the run directory's name. The same run gives the same id however often it is reported; a
/// changed result gives another.
pub fn report_id(result_json: &[u8], run_name: &str) -> String {
    let d = Sha256::new()
        .chain_update(result_json)
        .chain_update(b"\n")
        .chain_update(run_name.as_bytes())
        .finalize();
    signing::to_hex(&d)[..16].to_owned()
}

/// The lab file a run directory may carry: the one the handheld sent with the run's start.
pub const LAB_FILE: &str = "lab.toml";

/// The report's file in a run directory (the robot writes it, signed, when the run closes).
pub const REPORT_FILE: &str = "report.html";

/// Who writes the report.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Writer {
    /// The robot, when the run closes; signed by its device key when it has one (the key the
    /// run's signatures are checked against, [`Report::checked_with`]).
    Robot,
    /// `passangle report` on a copy of the run directory: not signed.
    Handheld,
}

/// What a report is written from, besides the run directory.
#[derive(Debug, Clone)]
pub struct Inputs<'a> {
    /// The run directory (meta.json, result.json, cloud.ply, config.toml, ...).
    pub run_dir: &'a Path,
    /// The lab file and where it came from; `None`: the run directory's [`LAB_FILE`], if any.
    pub lab: Option<(LabFile, String)>,
    /// The report's own path (left out of the file list when it lies in the run directory).
    pub out: &'a Path,
    /// The keys the run's signatures are checked against (empty: not checked).
    pub trusted: &'a [signing::PublicKey],
    /// When the report is written, Unix seconds (the caller's clock).
    pub written_unix_s: u64,
    /// Who writes it.
    pub writer: Writer,
}

/// Reads the run directory (and the lab file) into a [`Report`].
///
/// # Errors
/// Names the file that cannot be read or parsed: the run directory's `meta.json`, its lab file,
/// any file listed.
pub fn gather(inputs: &Inputs<'_>) -> anyhow::Result<Report> {
    let dir = inputs.run_dir;
    let recording = Recording::open(dir).with_context(|| format!("opening {}", dir.display()))?;
    let run_name = dir
        .canonicalize()
        .unwrap_or_else(|_| dir.to_path_buf())
        .file_name()
        .map_or_else(
            || dir.display().to_string(),
            |n| n.to_string_lossy().into_owned(),
        );
    let result_bytes = std::fs::read(dir.join("result.json")).unwrap_or_default();
    let (lab, lab_path) = if let Some((lab, source)) = &inputs.lab {
        (lab.clone(), Some(source.clone()))
    } else {
        let p = dir.join(LAB_FILE);
        match std::fs::read_to_string(&p) {
            Ok(text) => (
                LabFile::parse(&text).with_context(|| format!("{}: lab file", p.display()))?,
                Some(format!("{LAB_FILE} of the run (sent by the handheld)")),
            ),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => (LabFile::default(), None),
            Err(e) => return Err(e).with_context(|| format!("reading {}", p.display())),
        }
    };
    let config = std::fs::read(dir.join("config.toml")).ok();
    // The run's own settings; a run without a readable config.toml is taken as the defaults.
    let processing = crate::process::ProcessConfig::of_run(dir)
        .ok()
        .flatten()
        .unwrap_or_default();
    let enter_at_front = processing.enter_at_front;
    let recomputed = recompute(dir, &recording.meta, enter_at_front);
    let trusted = inputs.trusted;
    let files = list_files(dir, inputs.out, trusted)?;
    // The robot as meta.json names it; a run whose meta.json has no `robot_id` is named by the
    // key that signed its result.json, if any.
    let robot_id = recording.meta.robot_id.clone().or_else(|| {
        signed::read_sidecar(&dir.join("result.json.sig"))
            .ok()
            .map(|s| s.public_key.id())
    });
    let recorded: Vec<ProfileResult> = recording
        .result
        .as_ref()
        .map(|r| r.profiles.iter().filter_map(profile_of_record).collect())
        .unwrap_or_default();
    let (profiles, profiles_source) = match &recomputed {
        _ if !recorded.is_empty() => (recorded, "as recorded by the robot in result.json"),
        Ok(rc) => (
            compute_profiles(&rc.points_m, &rc.config, None, &Standard::ALL),
            if rc.scan_known() {
                "recomputed from cloud.ply and scan.toml (this result.json predates the profiles)"
            } else {
                "recomputed from cloud.ply (this result.json predates the profiles; without the \
                 scan path, so the coverage check is the cloud's own)"
            },
        ),
        Err(_) => (Vec::new(), "not available"),
    };
    let decisions = classify_all(&profiles, &lab.thresholds()?);
    Ok(Report {
        id: report_id(&result_bytes, &run_name),
        run_name,
        written_utc: utc(inputs.written_unix_s),
        writer: inputs.writer,
        lab,
        lab_path,
        incomplete: recording.incomplete,
        result: recording.result,
        meta: recording.meta,
        enter_at_front,
        lidar_range_offsets_m: processing.lidar_range_offsets_m,
        wheel_distance_scale: processing.wheel_distance_scale,
        recomputed,
        config_sha256: config.map(|c| sha256_hex(&c)),
        robot_id,
        files,
        checked_with: trusted.iter().map(|k| k.id()).collect(),
        version: env!("CARGO_PKG_VERSION").to_owned(),
        git_hash: env!("PASSANGLE_GIT_HASH").to_owned(),
        profiles,
        profiles_source,
        decisions,
    })
}

/// Writes the run's report as the robot does when the run closes: [`REPORT_FILE`] in the run
/// directory, with the run's own [`LAB_FILE`] (if the handheld sent one), the run's signatures
/// checked against this robot's key, and signed by it (`REPORT_FILE.sig`) when it has one.
/// Returns the report id.
///
/// # Errors
/// What could not be read, parsed or written, naming the file.
pub fn write_on_robot(
    run_dir: &Path,
    signer: &signed::Signer,
    written_unix_s: u64,
) -> anyhow::Result<String> {
    let out = run_dir.join(REPORT_FILE);
    let trusted: Vec<signing::PublicKey> = signer
        .key()
        .map(signing::DeviceKey::public)
        .into_iter()
        .collect();
    let report = gather(&Inputs {
        run_dir,
        lab: None,
        out: &out,
        trusted: &trusted,
        written_unix_s,
        writer: Writer::Robot,
    })?;
    signed::write_signed(&out, render(&report).as_bytes(), signer)?;
    Ok(report.id)
}

/// The calculator on `cloud.ply` with the service's settings (`onboard::process`) and, where the
/// run has its `scan.toml`, the scan path and the trajectory's error the service gave it.
fn recompute(dir: &Path, meta: &RunMeta, enter_at_front: bool) -> Result<Recomputed, String> {
    let path = dir.join("cloud.ply");
    if !path.exists() {
        return Err("the run has no cloud.ply".to_owned());
    }
    let (cloud, _) = read_cloud(&path).map_err(|e| format!("cloud.ply: {e:#}"))?;
    let scan = ScanRecord::read(dir)?;
    let config = AnglesConfig {
        front_is_positive_x: !enter_at_front,
        zone: if meta.zone == "axle" {
            Zone::Axle
        } else {
            Zone::Tyre
        },
        range_accuracy_m: Some(vlp16::RANGE_ACCURACY_M),
        scanner_view: Some(angles::ScannerView::VLP16),
        scan_path_in_cloud: scan
            .as_ref()
            .map(|s| s.path_m.iter().map(|&p| V3::from(p)).collect())
            .unwrap_or_default(),
        trajectory_x_sigma_per_m: scan.as_ref().map_or(0.0, |s| s.trajectory_x_sigma_per_m),
        ..AnglesConfig::default()
    };
    let points_m: Vec<V3> = cloud.points_m.into_iter().map(V3::from).collect();
    let angles = compute_angles(&points_m, &config).map_err(|e| format!("angles: {e}"))?;
    Ok(Recomputed {
        angles,
        points_m,
        config,
    })
}

fn sha256_hex(bytes: &[u8]) -> String {
    signing::to_hex(&Sha256::digest(bytes))
}

fn sha256_file(path: &Path) -> anyhow::Result<(u64, String)> {
    let mut f = std::fs::File::open(path).with_context(|| format!("reading {}", path.display()))?;
    let mut h = Sha256::new();
    let size =
        std::io::copy(&mut f, &mut h).with_context(|| format!("reading {}", path.display()))?;
    Ok((size, signing::to_hex(&h.finalize())))
}

/// Every file under `dir` (sorted, `out` left out) with its size, hash and signature status.
fn list_files(
    dir: &Path,
    out: &Path,
    trusted: &[signing::PublicKey],
) -> anyhow::Result<Vec<FileEntry>> {
    let mut paths = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).with_context(|| format!("reading {}", d.display()))? {
            let p = e?.path();
            if p.is_dir() {
                stack.push(p);
            } else {
                paths.push(p);
            }
        }
    }
    let out = out.canonicalize().ok();
    paths.retain(|p| p.canonicalize().ok() != out || out.is_none());
    paths.sort();
    let any_sig = paths
        .iter()
        .any(|p| p.to_string_lossy().ends_with(signing::SIDECAR_SUFFIX));
    let mut files = Vec::new();
    for p in &paths {
        let name = p
            .strip_prefix(dir)
            .unwrap_or(p)
            .components()
            .map(|c| c.as_os_str().to_string_lossy())
            .collect::<Vec<_>>()
            .join("/");
        let (size, sha256) = sha256_file(p)?;
        let mut sig = p.clone().into_os_string();
        sig.push(signing::SIDECAR_SUFFIX);
        let sig = PathBuf::from(sig);
        let (signature, signature_failed) = if name.ends_with(signing::SIDECAR_SUFFIX) {
            ("a signature".to_owned(), false)
        } else if sig.exists() {
            if trusted.is_empty() {
                ("signed; not checked (no key given)".to_owned(), false)
            } else {
                match signed::check_file(p, &sig, trusted)? {
                    Check::Verified { key_id } => (format!("verified: {key_id}"), false),
                    Check::Changed {
                        key_id, changes, ..
                    } => (
                        format!(
                            "CHANGED after {key_id} signed it: {}",
                            changes
                                .iter()
                                .take(5)
                                .cloned()
                                .collect::<Vec<_>>()
                                .join("; ")
                        ),
                        true,
                    ),
                    Check::Untrusted(e) => (format!("FAILED: {e}"), true),
                    Check::Unsigned(e) => (format!("FAILED: no usable signature: {e}"), true),
                }
            }
        } else if signed::SIGNED_IN_A_RUN.contains(&name.as_str()) && any_sig {
            ("NOT SIGNED (the robot signs this file)".to_owned(), true)
        } else {
            ("not signed".to_owned(), false)
        };
        files.push(FileEntry {
            name,
            size,
            sha256,
            signature,
            signature_failed,
        });
    }
    Ok(files)
}

/// `YYYY-MM-DD hh:mm:ss UTC` of seconds since the Unix epoch.
pub fn utc(secs: u64) -> String {
    let days = (secs / 86_400) as i64;
    let rem = secs % 86_400;
    // Civil date from days since 1970-01-01 (H. Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!(
        "{y:04}-{m:02}-{d:02} {:02}:{:02}:{:02} UTC",
        rem / 3600,
        rem / 60 % 60,
        rem % 60
    )
}

/// Escapes text for HTML (and SVG) content and attribute values.
pub fn esc(s: &str) -> String {
    let mut o = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' => o.push_str("&quot;"),
            '\'' => o.push_str("&#39;"),
            c => o.push(c),
        }
    }
    o
}

fn given(v: Option<&String>) -> String {
    match v.map(|s| s.trim()).filter(|s| !s.is_empty()) {
        Some(s) => esc(s),
        None => r#"<span class="missing">not given</span>"#.to_owned(),
    }
}

const CSS: &str = r"
body { font-family: 'DejaVu Sans', Helvetica, Arial, sans-serif; font-size: 10.5pt; color: #111;
  max-width: 1100px; margin: 1.5em auto; padding: 0 1em; line-height: 1.35; }
h1 { font-size: 18pt; margin: 0 0 0.2em; }
h2 { font-size: 13pt; border-bottom: 1px solid #888; margin: 1.4em 0 0.5em; padding-bottom: 2px;
  break-after: avoid; page-break-after: avoid; }
h3 { font-size: 11pt; margin: 0.8em 0 0.3em; break-after: avoid; }
table { border-collapse: collapse; margin: 0.3em 0 0.6em; }
th, td { border: 1px solid #bbb; padding: 2px 6px; text-align: left; vertical-align: top; }
th { background: #eee; }
td.num { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
table.kv th { width: 14em; }
thead { display: table-header-group; }
tr { break-inside: avoid; page-break-inside: avoid; }
.hash { font-family: 'DejaVu Sans Mono', monospace; font-size: 8pt; word-break: break-all; }
.missing { color: #888; font-style: italic; }
.notmeasured { color: #a00; }
.fail { color: #a00; font-weight: bold; }
.note { background: #fff6d8; border-left: 4px solid #e0b000; padding: 4px 8px; margin: 0.5em 0; }
.small { font-size: 9pt; color: #444; }
svg { max-width: 100%; height: auto; }
.closeups { display: flex; flex-wrap: wrap; gap: 12px; }
.closeup { border: 1px solid #ccc; padding: 6px; width: 48%; box-sizing: border-box;
  break-inside: avoid; page-break-inside: avoid; }
section { margin-bottom: 0.5em; }
.sideview { break-inside: avoid; page-break-inside: avoid; }
@page { size: A4; margin: 14mm 12mm; }
@media print {
  body { max-width: none; margin: 0; padding: 0; font-size: 9.5pt; }
  .pagebreak { break-before: page; page-break-before: always; }
  .closeup { width: 48%; }
  a { color: inherit; text-decoration: none; }
}
";

/// The report as one HTML document. Pure: no IO.
pub fn render(r: &Report) -> String {
    let mut h = String::new();
    let _ = write!(
        h,
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
         <title>passangle report {id}: {run}</title>\n<style>{CSS}</style>\n</head>\n<body>\n",
        id = esc(&r.id),
        run = esc(&r.run_name)
    );
    header(&mut h, r);
    lab_section(&mut h, r);
    method_section(&mut h, r);
    results_section(&mut h, r);
    standards_section(&mut h, r);
    recomputed_sections(&mut h, r);
    provenance_section(&mut h, r);
    h.push_str("</body>\n</html>\n");
    h
}

fn header(h: &mut String, r: &Report) {
    let outcome = match &r.meta.outcome {
        RecordedOutcome::Running => "running or cut short".to_owned(),
        RecordedOutcome::Completed => "completed".to_owned(),
        RecordedOutcome::Aborted(why) => format!("aborted: {why}"),
        RecordedOutcome::Failed(why) => format!("failed: {why}"),
    };
    let _ = write!(
        h,
        "<header>\n<h1>Passing angles: measurement report</h1>\n\
         <table class=\"kv\">\n\
         <tr><th>Report id</th><td><b class=\"hash\" style=\"font-size:11pt\">{id}</b><br>\
         <span class=\"small\">The first 16 hex digits of SHA-256 over result.json's bytes, a \
         newline and the run directory's name: the same run always gives the same id.</span></td></tr>\n\
         <tr><th>Run</th><td>{run} (run id {run_id}), {outcome}{incomplete}</td></tr>\n\
         <tr><th>Vehicle id (as entered)</th><td>{vid}</td></tr>\n\
         <tr><th>Date of measurement</th><td>{date}</td></tr>\n\
         <tr><th>Report written</th><td>{written}</td></tr>\n\
         </table>\n</header>\n",
        id = esc(&r.id),
        run = esc(&r.run_name),
        run_id = r.meta.run_id,
        outcome = esc(&outcome),
        incomplete = if r.incomplete {
            " <span class=\"fail\">(marked INCOMPLETE: the run did not finish cleanly)</span>"
        } else {
            ""
        },
        vid = given(Some(&r.meta.vehicle_id)),
        date = esc(&utc(r.meta.started_unix_us / 1_000_000)),
        written = esc(&r.written_utc),
    );
}

fn lab_section(h: &mut String, r: &Report) {
    let (l, c, v) = (&r.lab.lab, &r.lab.customer, &r.lab.vehicle);
    let _ = write!(h, "<section>\n<h2>Lab, customer and vehicle</h2>\n");
    match &r.lab_path {
        None => h.push_str(
            "<p class=\"small\">No lab file was given (<code>passangle measure --lab \
             lab.toml</code>, or <code>passangle report --lab</code>): the fields below are not \
             given.</p>\n",
        ),
        Some(source) => {
            let _ = writeln!(h, "<p class=\"small\">From {}.</p>", esc(source));
        }
    }
    h.push_str("<table class=\"kv\">\n");
    for (k, val) in [
        ("Lab", l.name.as_ref()),
        ("Address", l.address.as_ref()),
        ("Accreditation", l.accreditation.as_ref()),
        ("Operator", l.operator.as_ref()),
        ("Customer", c.name.as_ref()),
        ("Customer reference", c.reference.as_ref()),
        ("Vehicle make", v.make.as_ref()),
        ("Vehicle model", v.model.as_ref()),
        ("VIN", v.vin.as_ref()),
        ("Load state", v.load_state.as_ref()),
        ("Tyre pressures", v.tyre_pressures.as_ref()),
        ("Suspension mode", v.suspension_mode.as_ref()),
    ] {
        let _ = writeln!(h, "<tr><th>{k}</th><td>{}</td></tr>", given(val));
    }
    h.push_str("</table>\n</section>\n");
}

fn zone_of(r: &Report) -> Zone {
    match &r.recomputed {
        Ok(c) => c.angles.zone,
        Err(_) if r.meta.zone == "axle" => Zone::Axle,
        Err(_) => Zone::Tyre,
    }
}

fn method_section(h: &mut String, r: &Report) {
    let zone = match zone_of(r) {
        Zone::Tyre => {
            "tyre: approach and departure ramps tangent to the tyres, the zone ahead of the front \
             tyre and behind the rear tyre (49 CFR 523.2; SAE J1100)"
        }
        Zone::Axle => {
            "axle: approach and departure ramps tangent to the tyres, the zone ahead of the front \
             axle and behind the rear axle (EU 2018/858, Annex I)"
        }
    };
    let _ = write!(
        h,
        "<section>\n<h2>Method and profile</h2>\n<table class=\"kv\">\n\
         <tr><th>Method</th><td>The robot drives under the parked vehicle at constant speed and \
         builds a point cloud of the underside and tyres from its VLP-16 lidar, depth camera and \
         wheel odometry. The calculator fits the floor and the tyres, takes the lower envelope of \
         the body in the band between the inner tyre faces, and finds the steepest ramp planes \
         and the ramp breakover that touch the body without lifting the tyres. Expanded \
         uncertainties U are for k&nbsp;=&nbsp;2 (docs: the uncertainty budget).</td></tr>\n\
         <tr><th>Zone (profile)</th><td>{zone}</td></tr>\n\
         <tr><th>Breakover, clearance</th><td>Ramp breakover: the angle between two planes \
         tangent to the front and rear tyres that meet on the body between the axles (SAE J1100, \
         49 CFR 523.2). Ground clearance: the lowest body point between the axles in the \
         band.</td></tr>\n\
         <tr><th>Run parameters</th><td>speed {speed:.2} m/s, distance {dist:.2} m; the robot \
         enters under the vehicle's {end}; {lidar}; {wheels}</td></tr>\n\
         </table>\n</section>\n",
        speed = r.meta.speed_mps,
        dist = r.meta.distance_m,
        end = if r.enter_at_front {
            "front bumper"
        } else {
            "rear bumper"
        },
        lidar = lidar_calibration_text(&r.lidar_range_offsets_m),
        wheels = wheel_calibration_text(r.wheel_distance_scale),
    );
}

/// The lidar's range calibration as the report states it.
fn lidar_calibration_text(offsets_m: &[f32; 16]) -> String {
    let set: Vec<f32> = offsets_m.iter().copied().filter(|o| *o != 0.0).collect();
    if set.is_empty() {
        return "lidar ranges as the sensor reports them (no range calibration applied)".to_owned();
    }
    let largest = set.iter().fold(0.0_f32, |m, o| m.max(o.abs()));
    format!(
        "lidar range calibration applied: offsets on {} of 16 lasers, largest {:.1} mm \
         (processing.lidar-range-offsets-m in config.toml)",
        set.len(),
        largest * 1e3
    )
}

/// The wheels' distance calibration as the report states it.
fn wheel_calibration_text(scale: f64) -> String {
    if (scale - 1.0).abs() < f64::EPSILON {
        return "wheel distances as the wheels report them (no distance calibration applied)"
            .to_owned();
    }
    format!(
        "wheel distance calibration applied: scale {scale:.5} (processing.wheel-distance-scale \
         in config.toml)"
    )
}

/// A recorded value: the number with U, or "not measured: reason".
fn recorded_cell(
    res: &ResultRecord,
    key: &str,
    value: f32,
    u: f32,
    unit: &str,
    digits: usize,
) -> String {
    match res.not_measured.get(key) {
        Some(n) => format!(
            "<td colspan=\"2\" class=\"notmeasured\">not measured: {}</td>",
            esc(&n.reason)
        ),
        None if !value.is_finite() => {
            "<td colspan=\"2\" class=\"notmeasured\">not measured: no reason recorded</td>"
                .to_owned()
        }
        None => {
            let u = if u.is_finite() {
                format!("{u:.digits$} {unit}")
            } else {
                "<span class=\"missing\">not recorded</span>".to_owned()
            };
            format!("<td class=\"num\">{value:.digits$} {unit}</td><td class=\"num\">{u}</td>")
        }
    }
}

fn results_section(h: &mut String, r: &Report) {
    h.push_str("<section>\n<h2>Results</h2>\n");
    let Some(res) = &r.result else {
        h.push_str(
            "<p class=\"fail\">The run has no result.json: nothing was measured.</p>\n</section>\n",
        );
        return;
    };
    h.push_str(
        "<p class=\"small\">As recorded by the robot in result.json (the signed record).</p>\n\
         <table>\n<thead><tr><th>Quantity</th><th>Value</th><th>U (k = 2)</th>\
         <th>Supporting points</th></tr></thead>\n<tbody>\n",
    );
    for (name, key, v, u, support) in [
        (
            "Approach angle",
            "approach",
            res.approach_deg,
            res.approach_u_deg,
            Some(res.approach_support),
        ),
        (
            "Departure angle",
            "departure",
            res.departure_deg,
            res.departure_u_deg,
            Some(res.departure_support),
        ),
        (
            "Ramp breakover angle",
            "breakover",
            res.breakover_deg,
            res.breakover_u_deg,
            Some(res.breakover_support),
        ),
    ] {
        let _ = writeln!(
            h,
            "<tr><th>{name}</th>{}<td class=\"num\">{}</td></tr>",
            recorded_cell(res, key, v, u, "°", 2),
            // A quantity not measured has no supporting points worth a number.
            support
                .filter(|_| v.is_finite() && !res.not_measured.contains_key(key))
                .map_or(String::new(), |s| s.to_string())
        );
    }
    let _ = writeln!(
        h,
        "<tr><th>Ground clearance</th>{}<td></td></tr>",
        recorded_cell(
            res,
            "ground_clearance",
            res.ground_clearance_m,
            res.ground_clearance_u_m,
            "m",
            3
        )
    );
    let num = |v: f32| {
        if v.is_finite() {
            format!("{v:.3} m")
        } else {
            "<span class=\"missing\">not measured</span>".to_owned()
        }
    };
    let _ = write!(
        h,
        "</tbody>\n</table>\n<table class=\"kv\">\n\
         <tr><th>Wheelbase</th><td>{}</td></tr>\n<tr><th>Track</th><td>{}</td></tr>\n\
         <tr><th>Tyre fit RMS</th><td>{}</td></tr>\n<tr><th>Points in the cloud</th><td>{}</td></tr>\n\
         <tr><th>Warnings</th><td>{}</td></tr>\n\
         <tr><th>Decision rule</th><td>{}</td></tr>\n\
         </table>\n</section>\n",
        num(res.wheelbase_m),
        num(res.track_m),
        if res.tyre_fit_rms_m.is_finite() {
            format!("{:.1} mm", res.tyre_fit_rms_m * 1e3)
        } else {
            "<span class=\"missing\">not measured</span>".to_owned()
        },
        res.cloud_points,
        if res.warnings.is_empty() {
            "none".to_owned()
        } else {
            esc(&res.warnings.join(", "))
        },
        if r.lab.decide.is_empty() {
            "No pass/fail limits were given: the results are reported with their uncertainties \
             and no statement of conformity is made."
                .to_owned()
        } else {
            format!(
                "{} (decisions under Standards).",
                esc(&upper_first(DECISION_RULE))
            )
        },
    );
}

fn upper_first(s: &str) -> String {
    let mut c = s.chars();
    c.next()
        .map_or_else(String::new, |f| f.to_uppercase().chain(c).collect())
}

/// The standards side by side and the decisions the lab file asks for.
fn standards_section(h: &mut String, r: &Report) {
    h.push_str("<section>\n<h2>Standards</h2>\n");
    if r.profiles.is_empty() {
        let _ = writeln!(
            h,
            "<p class=\"missing\">No standard profiles: {}.</p>\n</section>",
            esc(r.profiles_source)
        );
        return;
    }
    let _ = writeln!(
        h,
        "<p class=\"small\">Each standard's quantities with its own zone, lateral band and \
         clearance region, {}; value ± U (k = 2). docs/method/standards.md says what each \
         profile measures, cannot measure and assumes.</p>",
        esc(r.profiles_source)
    );
    let (header, rows, footnotes) = angles::profiles::side_by_side(&r.profiles);
    h.push_str("<table>\n<thead><tr>");
    for c in &header {
        let _ = write!(h, "<th>{}</th>", esc(c));
    }
    h.push_str("</tr></thead>\n<tbody>\n");
    for row in &rows {
        let _ = write!(h, "<tr><th>{}</th>", esc(&row[0]));
        for c in &row[1..] {
            let class = if c.starts_with("not measured") {
                "missing"
            } else {
                "num"
            };
            let _ = write!(h, "<td class=\"{class}\">{}</td>", esc(c));
        }
        h.push_str("</tr>\n");
    }
    h.push_str("</tbody>\n</table>\n");
    for (i, f) in footnotes.iter().enumerate() {
        let _ = writeln!(h, "<p class=\"small\">[{}] {}</p>", i + 1, esc(f));
    }
    h.push_str("<details><summary>Profiles' notes</summary>\n");
    for p in &r.profiles {
        let _ = write!(
            h,
            "<p><b>{}</b> ({})</p>\n<ul>\n",
            esc(p.standard.title()),
            esc(p.standard.citation())
        );
        for n in &p.notes {
            let _ = writeln!(h, "<li>{}</li>", esc(n));
        }
        h.push_str("</ul>\n");
    }
    h.push_str("</details>\n");
    if !r.decisions.is_empty() {
        let _ = writeln!(
            h,
            "<h3>Decisions</h3>\n<p>Decision rule: {}.</p>",
            esc(DECISION_RULE)
        );
        for c in &r.decisions {
            let lines = angles::profiles::decision_lines(c);
            let _ = writeln!(h, "<p><b>{}</b></p>\n<ul>", esc(&lines[0]));
            for l in &lines[1..] {
                let _ = writeln!(h, "<li>{}</li>", esc(l.trim()));
            }
            let _ = writeln!(
                h,
                "</ul>\n<p class=\"small\">Source: {}</p>",
                esc(c.thresholds.source())
            );
        }
    }
    h.push_str("</section>\n");
}

/// The recomputation's disagreements with `result.json`, in words.
fn differences(res: &ResultRecord, a: &AnglesResult) -> Vec<String> {
    let mut out = Vec::new();
    let angle = |f: &Option<AngleFinding>| f.as_ref().map(|f| f.angle_rad.to_degrees());
    for (name, key, recorded, again, tol, unit) in [
        (
            "approach",
            "approach",
            res.approach_deg,
            angle(&a.approach),
            ANGLE_TOLERANCE_DEG,
            "°",
        ),
        (
            "departure",
            "departure",
            res.departure_deg,
            angle(&a.departure),
            ANGLE_TOLERANCE_DEG,
            "°",
        ),
        (
            "breakover",
            "breakover",
            res.breakover_deg,
            angle(&a.breakover),
            ANGLE_TOLERANCE_DEG,
            "°",
        ),
        (
            "ground clearance",
            "ground_clearance",
            res.ground_clearance_m,
            a.ground_clearance.as_ref().map(|c| c.height_m),
            CLEARANCE_TOLERANCE_M,
            " m",
        ),
    ] {
        let recorded = (recorded.is_finite() && !res.not_measured.contains_key(key))
            .then_some(f64::from(recorded));
        match (recorded, again) {
            (Some(x), Some(y)) if (x - y).abs() > tol => out.push(format!(
                "{name}: recorded {x:.3}{unit}, recomputed {y:.3}{unit}"
            )),
            (Some(x), None) => out.push(format!(
                "{name}: recorded {x:.3}{unit}, recomputed: not measured"
            )),
            (None, Some(y)) => out.push(format!(
                "{name}: recorded not measured, recomputed {y:.3}{unit}"
            )),
            _ => {}
        }
    }
    out
}

fn recomputed_sections(h: &mut String, r: &Report) {
    let rc = match &r.recomputed {
        Ok(rc) => rc,
        Err(e) => {
            let _ = write!(
                h,
                "<section>\n<h2>Side view, witnesses, tyres and floor</h2>\n<p class=\"fail\">\
                 Not available: {}</p>\n</section>\n",
                esc(e)
            );
            return;
        }
    };
    let a = &rc.angles;
    h.push_str(
        "<section class=\"pagebreak\">\n<h2>Side view</h2>\n<p class=\"small\">The witnesses, \
         tyres, side view and floor below come from running the calculator again on the run's \
         cloud.ply (and scan.toml, where the run has it) with the service's settings.</p>\n",
    );
    if let Some(res) = &r.result {
        let diff = differences(res, a);
        if diff.is_empty() {
            let _ = writeln!(
                h,
                "<p class=\"small\">The recomputation agrees with result.json (angles within \
                 {ANGLE_TOLERANCE_DEG}°, clearance within {:.1} mm).</p>",
                CLEARANCE_TOLERANCE_M * 1e3
            );
        } else {
            let why = if rc.scan_known() {
                "It had the run's cloud.ply and scan.toml, as the service did: a difference \
                 means another calculator version, or files changed since the run."
            } else {
                "The service passes the robot's scan path to the calculator (which faces it saw \
                 across its path, the returns' rays, and the trajectory's error along it); this \
                 run has no scan.toml to carry it, so the recomputation can pick another witness \
                 or find what the service left out."
            };
            let _ = writeln!(
                h,
                "<div class=\"note\"><b>The recomputation differs from result.json</b>: {}. \
                 {why} The results above are the recorded ones.</div>",
                esc(&diff.join("; "))
            );
        }
    }
    let _ = writeln!(
        h,
        "<div class=\"sideview\">{}</div>\n</section>",
        side_view_svg(a)
    );

    witnesses_section(h, rc);
    tyres_section(h, a);
    floor_section(h, a);
}

/// Each witness named, with its close-up.
fn witnesses_section(h: &mut String, rc: &Recomputed) {
    let a = &rc.angles;
    h.push_str("<section>\n<h2>Witnesses</h2>\n<p class=\"small\">Each limiting point (witness) in the vehicle frame: x forward from mid-wheelbase, y left of the centreline, z up from the floor. Close-ups: the cloud's points within ±0.3 m along the vehicle of the witness, 0 to 0.6 m above the floor, in the envelope's lateral band; front to the right; the witness in red, the ramp line through it in blue.</p>\n<div class=\"closeups\">\n");
    for (q, f) in [
        (Quantity::Approach, &a.approach),
        (Quantity::Departure, &a.departure),
        (Quantity::Breakover, &a.breakover),
    ] {
        let title = match q {
            Quantity::Approach => "Approach",
            Quantity::Departure => "Departure",
            _ => "Ramp breakover",
        };
        match f {
            Some(f) => {
                let w = f.witness_in_vehicle;
                let _ = writeln!(
                    h,
                    "<div class=\"closeup\"><h3>{title} witness: {:.2}° ± {:.2}°</h3>\
                     <p class=\"small\">x {:.3} m, y {:.3} m, z {:.3} m; {} supporting points</p>{}</div>",
                    f.angle_rad.to_degrees(),
                    f.uncertainty.expanded.to_degrees(),
                    w[0],
                    w[1],
                    w[2],
                    f.support,
                    close_up(rc, q, w, Some(f)),
                );
            }
            None => {
                let _ = writeln!(
                    h,
                    "<div class=\"closeup\"><h3>{title} witness</h3><p class=\"notmeasured\">not \
                     measured: {}</p></div>",
                    esc(a.not_measured_reason(q).unwrap_or("no reason given"))
                );
            }
        }
    }
    match &a.ground_clearance {
        Some(c) => {
            let w = c.witness_in_vehicle;
            let _ = writeln!(
                h,
                "<div class=\"closeup\"><h3>Ground clearance witness: {:.3} m ± {:.3} m</h3>\
                 <p class=\"small\">x {:.3} m, y {:.3} m, z {:.3} m</p>{}</div>",
                c.height_m,
                c.uncertainty.expanded,
                w[0],
                w[1],
                w[2],
                close_up(rc, Quantity::GroundClearance, w, None),
            );
        }
        None => {
            let _ = writeln!(
                h,
                "<div class=\"closeup\"><h3>Ground clearance witness</h3><p class=\"notmeasured\">\
                 not measured: {}</p></div>",
                esc(a
                    .not_measured_reason(Quantity::GroundClearance)
                    .unwrap_or("no reason given"))
            );
        }
    }
    h.push_str("</div>\n</section>\n");
}

/// The tyre fits.
fn tyres_section(h: &mut String, a: &AnglesResult) {
    h.push_str(
        "<section>\n<h2>Tyre fits</h2>\n<table>\n<thead><tr><th>Tyre</th><th>Centre x, y, z \
         (m)</th><th>Static loaded radius</th><th>u (k = 1)</th><th>Free radius</th>\
         <th>Width</th><th>Fit residual RMS</th><th>Points</th></tr></thead>\n<tbody>\n",
    );
    for t in &a.tyres {
        let c = t.centre_in_vehicle;
        let _ = writeln!(
            h,
            "<tr><th>{}</th><td class=\"num\">{:.3}, {:.3}, {:.3}</td><td class=\"num\">{:.4} m</td>\
             <td class=\"num\">{:.4} m</td><td class=\"num\">{:.4} m</td><td class=\"num\">{:.3} m</td>\
             <td class=\"num\">{:.1} mm</td><td class=\"num\">{}</td></tr>",
            esc(t.position.label()),
            c[0],
            c[1],
            c[2],
            t.loaded_radius_m,
            t.u_loaded_radius_m,
            t.free_radius_m,
            t.width_m,
            t.residual_rms_m * 1e3,
            t.fit_points
        );
    }
    if a.tyres.is_empty() {
        h.push_str("<tr><td colspan=\"8\" class=\"missing\">no tyre was fitted</td></tr>\n");
    }
    let _ = write!(
        h,
        "</tbody>\n</table>\n<p class=\"small\">Wheelbase {:.3} m{}; static loaded radius: the \
         fitted wheel centre's height above the floor.</p>\n</section>\n",
        a.wheelbase_m,
        a.track_m
            .map_or(String::new(), |t| format!(", track {t:.3} m"))
    );
}

/// The floor's flatness from the calculator's ground fit.
fn floor_section(h: &mut String, a: &AnglesResult) {
    let g = &a.ground;
    let _ = write!(
        h,
        "<section>\n<h2>Floor flatness</h2>\n<table class=\"kv\">\n\
         <tr><th>Spread about the plane</th><td>{:.1} mm (σ, robust: 1.4826 × median absolute \
         deviation of the floor points from the fitted plane)</td></tr>\n\
         <tr><th>Floor tilt</th><td>{:.2}° (the plane's normal against the cloud's vertical)</td></tr>\n\
         <tr><th>Floor points</th><td>{}</td></tr>\n</table>\n\
         <p class=\"small\">Measured from the same cloud: the floor under and around the vehicle \
         as the robot scanned it. The spread includes the lidar's range noise, so the floor itself \
         is at least this flat; a spread well above the sensor's noise means an uneven floor, \
         which the angles' uncertainty budget counts under \"ground\".</p>\n</section>\n",
        g.noise_sigma_m * 1e3,
        g.tilt_rad.to_degrees(),
        g.inliers
    );
    if !a.warnings.is_empty() {
        let _ = writeln!(
            h,
            "<p class=\"small\">Calculator warnings: {}</p>",
            esc(&a.warnings.join("; "))
        );
    }
}

/// A witness's neighbourhood in side view (front to the right) as an inline SVG: one drawing,
/// kept in one piece so its coordinates read top to bottom.
#[allow(clippy::too_many_lines)]
fn close_up(rc: &Recomputed, q: Quantity, w: V3, f: Option<&AngleFinding>) -> String {
    let a = &rc.angles;
    let (x0, x1) = (w[0] - CLOSE_UP_HALF_X_M, w[0] + CLOSE_UP_HALF_X_M);
    let (z0, z1) = (0.0, CLOSE_UP_Z_M.max(w[2] + 0.1));
    let (y0, y1) = a.band_y_m;
    let pts: Vec<[f64; 2]> = rc
        .points_m
        .iter()
        .map(|p| a.frame.vehicle_from_cloud(*p))
        .filter(|p| {
            p[0] >= x0 && p[0] <= x1 && p[2] >= z0 - 0.02 && p[2] <= z1 && p[1] >= y0 && p[1] <= y1
        })
        .map(|p| [p[0], p[2]])
        .collect();
    let step = pts.len().div_ceil(CLOSE_UP_MAX_POINTS).max(1);
    let k = CLOSE_UP_PX_PER_M;
    let (wpx, hpx) = ((x1 - x0) * k, (z1 - z0) * k);
    let (m, top) = (30.0, 10.0);
    let sx = |x: f64| m + (x - x0) * k;
    let sy = |z: f64| top + (z1 - z) * k;
    let mut s = String::new();
    let _ = write!(
        s,
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{tw:.0}\" height=\"{th:.0}\" \
         viewBox=\"0 0 {tw:.0} {th:.0}\" font-family=\"sans-serif\" font-size=\"11\">\
         <rect x=\"{m}\" y=\"{top}\" width=\"{wpx:.0}\" height=\"{hpx:.0}\" fill=\"#fafafa\" stroke=\"#999\"/>\
         <svg x=\"{m}\" y=\"{top}\" width=\"{wpx:.0}\" height=\"{hpx:.0}\" viewBox=\"{m} {top} {wpx:.0} {hpx:.0}\" overflow=\"hidden\">",
        tw = wpx + m + 10.0,
        th = hpx + top + 30.0,
    );
    // The floor.
    let _ = write!(
        s,
        "<line x1=\"{:.1}\" y1=\"{:.1}\" x2=\"{:.1}\" y2=\"{:.1}\" stroke=\"#7a5c3a\" stroke-width=\"2\"/>",
        sx(x0),
        sy(0.0),
        sx(x1),
        sy(0.0)
    );
    // One 1.6 px square per occupied 1.6 px cell (points closer than that would overlap), all in
    // one path: the drawing is the same as a square per point at a fraction of the bytes.
    let cells: std::collections::BTreeSet<(i64, i64)> = pts
        .iter()
        .step_by(step)
        .map(|p| {
            (
                (sx(p[0]) / CLOSE_UP_DOT_PX).floor() as i64,
                (sy(p[1]) / CLOSE_UP_DOT_PX).floor() as i64,
            )
        })
        .collect();
    // In units of one cell, so each dot is a few digits.
    let _ = write!(
        s,
        "<path fill=\"#555\" transform=\"scale({CLOSE_UP_DOT_PX})\" d=\""
    );
    for (cx, cy) in cells {
        let _ = write!(s, "M{cx} {cy}h1v1h-1z");
    }
    s.push_str("\"/>");
    // The ramp line(s) through the witness: z rises toward the front for the approach ramp,
    // toward the rear for the departure ramp; the breakover's two planes meet at the witness.
    let line = |s: &mut String, xa: f64, xb: f64, slope: f64| {
        let _ = write!(
            s,
            "<line x1=\"{:.1}\" y1=\"{:.1}\" x2=\"{:.1}\" y2=\"{:.1}\" stroke=\"#1f5fbf\" stroke-width=\"1.5\"/>",
            sx(xa),
            sy(w[2] + slope * (xa - w[0])),
            sx(xb),
            sy(w[2] + slope * (xb - w[0]))
        );
    };
    match (q, f) {
        (Quantity::Approach, Some(f)) => line(&mut s, x0, x1, f.angle_rad.tan()),
        (Quantity::Departure, Some(f)) => line(&mut s, x0, x1, -f.angle_rad.tan()),
        (Quantity::Breakover, Some(f)) => {
            if let Some((front, rear)) = f.parts_rad {
                line(&mut s, w[0], x1, -front.tan());
                line(&mut s, x0, w[0], rear.tan());
            }
        }
        _ => {
            let _ = write!(
                s,
                "<line x1=\"{x:.1}\" y1=\"{:.1}\" x2=\"{x:.1}\" y2=\"{:.1}\" stroke=\"#1f5fbf\" \
                 stroke-width=\"1.5\" stroke-dasharray=\"4 3\"/>",
                sy(0.0),
                sy(w[2]),
                x = sx(w[0])
            );
        }
    }
    let _ = write!(
        s,
        "<circle cx=\"{:.1}\" cy=\"{:.1}\" r=\"5\" fill=\"none\" stroke=\"#d00\" stroke-width=\"2\"/></svg>",
        sx(w[0]),
        sy(w[2])
    );
    // Axes: x ticks every 0.1 m (relative to the witness), z ticks every 0.1 m.
    for i in -3..=3 {
        let x = w[0] + f64::from(i) * 0.1;
        let _ = write!(
            s,
            "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\">{:+.1}</text>",
            sx(x),
            top + hpx + 14.0,
            f64::from(i) * 0.1
        );
    }
    let mut z = 0.0;
    while z <= z1 + 1e-9 {
        let _ = write!(
            s,
            "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"end\">{z:.1}</text>",
            m - 4.0,
            sy(z) + 4.0
        );
        z += 0.1;
    }
    let _ = write!(
        s,
        "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\" fill=\"#444\">x from the witness (m); z above the floor (m); {} points</text></svg>",
        m + wpx / 2.0,
        top + hpx + 27.0,
        pts.len()
    );
    s
}

fn provenance_section(h: &mut String, r: &Report) {
    let _ = write!(
        h,
        "<section class=\"pagebreak\">\n<h2>Provenance</h2>\n<table class=\"kv\">\n\
         <tr><th>Robot</th><td>{robot}</td></tr>\n\
         <tr><th>Software</th><td>passangle {ver}, git commit <span class=\"hash\">{git}</span> \
         ({who})</td></tr>\n\
         <tr><th>Config hash</th><td>{cfg}</td></tr>\n\
         <tr><th>Signatures</th><td>{sig}</td></tr>\n\
         </table>\n",
        robot = r.robot_id.as_ref().map_or_else(
            || "<span class=\"missing\">not recorded (the run is not signed)</span>".to_owned(),
            |id| format!(
                "device key <span class=\"hash\">{}</span> (the key that signs the run's files)",
                esc(id)
            )
        ),
        who = match r.writer {
            Writer::Robot => "the robot's, which wrote this report",
            Writer::Handheld => {
                "the handheld that wrote this report; the robot's own version is in its log"
            }
        },
        ver = esc(&r.version),
        git = esc(&r.git_hash),
        cfg = r.config_sha256.as_ref().map_or_else(
            || "<span class=\"missing\">no config.toml in the run</span>".to_owned(),
            |c| format!("SHA-256 of config.toml: <span class=\"hash\">{c}</span>")
        ),
        sig = if r.checked_with.is_empty() {
            "signatures not checked: no trusted key was given (<code>--public-key KEY</code> or \
             <code>--keys FILE</code>)"
                .to_owned()
        } else {
            let failed = r.files.iter().filter(|f| f.signature_failed).count();
            format!(
                "checked against the trusted key(s) {}: {}",
                esc(&r.checked_with.join(", ")),
                if failed == 0 {
                    "every signed file verifies".to_owned()
                } else {
                    format!("<span class=\"fail\">{failed} file(s) FAILED</span>")
                }
            )
        },
    );
    h.push_str(
        "<h3>Files of the run</h3>\n<table>\n<thead><tr><th>File</th><th>Bytes</th>\
         <th>SHA-256</th><th>Signature</th></tr></thead>\n<tbody>\n",
    );
    for f in &r.files {
        let _ = writeln!(
            h,
            "<tr><td>{}</td><td class=\"num\">{}</td><td class=\"hash\">{}</td><td{}>{}</td></tr>",
            esc(&f.name),
            f.size,
            f.sha256,
            if f.signature_failed {
                " class=\"fail\""
            } else {
                ""
            },
            esc(&f.signature)
        );
    }
    let written = match (r.writer, r.checked_with.first()) {
        (Writer::Robot, Some(id)) => format!(
            "Written by the robot when the run closed and signed by its device key <span \
             class=\"hash\">{}</span> ({REPORT_FILE}.sig beside this file; check it with \
             <code>passangle verify</code>).",
            esc(id)
        ),
        (Writer::Robot, None) => "Written by the robot when the run closed. This \
             robot has no device key: nothing of the run is signed."
            .to_owned(),
        (Writer::Handheld, _) => {
            "Written by <code>passangle report</code>. This file is not signed \
             by the robot; its result.json, cloud.ply and the other signed files are, and their \
             hashes above tie this report to them."
                .to_owned()
        }
    };
    let _ = write!(
        h,
        "</tbody>\n</table>\n<p class=\"small\">{written}</p>\n</section>\n"
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_lidar_calibration_is_stated() {
        assert!(lidar_calibration_text(&[0.0; 16]).contains("no range calibration"));
        let mut o = [0.0; 16];
        o[3] = -0.0159;
        o[8] = 0.004;
        let t = lidar_calibration_text(&o);
        assert!(t.contains("2 of 16 lasers, largest 15.9 mm"), "{t}");
    }

    #[test]
    fn the_wheel_calibration_is_stated() {
        assert!(wheel_calibration_text(1.0).contains("no distance calibration"));
        let t = wheel_calibration_text(1.012_94);
        assert!(t.contains("scale 1.01294"), "{t}");
    }

    #[test]
    fn dates_and_escapes() {
        assert_eq!(utc(0), "1970-01-01 00:00:00 UTC");
        assert_eq!(utc(1_790_000_000), "2026-09-21 14:13:20 UTC");
        assert_eq!(utc(951_782_400), "2000-02-29 00:00:00 UTC");
        assert_eq!(
            esc("<a href=\"x\">&'"),
            "&lt;a href=&quot;x&quot;&gt;&amp;&#39;"
        );
        assert_eq!(report_id(b"{}", "run-000001").len(), 16);
        assert_ne!(
            report_id(b"{}", "run-000001"),
            report_id(b"{}", "run-000002")
        );
    }

    #[test]
    fn lab_file_decisions_are_named_ids() {
        let l = LabFile::parse("decide = [\"cfr523.5\", \"eu-offroad\"]\n[lab]\nname = \"L\"\n")
            .unwrap();
        assert_eq!(
            l.thresholds().unwrap(),
            [Thresholds::Cfr523_5, Thresholds::EuOffRoad]
        );
        let e = format!("{:#}", LabFile::parse("decide = [\"eu\"]\n").unwrap_err());
        assert!(e.contains("`eu`"), "{e}");
        assert!(LabFile::parse("").unwrap().decide.is_empty());
    }

    proptest::proptest! {
        /// The lab file comes over the radio: any text parses or is refused, never panics.
        #[test]
        fn any_lab_text_parses_or_is_refused(text in "\\PC{0,400}") {
            let _ = LabFile::parse(&text);
        }

        /// Lines of lab-file shape with arbitrary keys and values.
        #[test]
        fn lab_shaped_text_parses_or_is_refused(
            lines in proptest::collection::vec(
                ("\\[?[a-z-]{1,12}\\]?", "[ =\"a-z0-9\\[\\],.-]{0,20}"),
                0..12,
            )
        ) {
            let mut text = String::new();
            for (k, v) in &lines {
                let _ = writeln!(text, "{k}{v}");
            }
            let _ = LabFile::parse(&text);
        }
    }

    #[test]
    fn lab_file_is_optional_and_names_unknown_keys() {
        let l = LabFile::parse("[vehicle]\nvin = \"WVW123\"\nload-state = \"unladen\"\n").unwrap();
        assert_eq!(l.vehicle.vin.as_deref(), Some("WVW123"));
        assert_eq!(l.lab, LabSection::default());
        let e = LabFile::parse("[vehicle]\ncolour = \"red\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("colour"), "{e}");
        let e = LabFile::parse("[garage]\n").unwrap_err().to_string();
        assert!(e.contains("garage"), "{e}");
    }
}
