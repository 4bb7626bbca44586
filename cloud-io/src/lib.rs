//! Point clouds: the shared point type and PLY / PCD / XYZ / CSV input and output.
//!
//! A [`Cloud`] is a plain list of points in metres (`points_m`). The frame is whatever the producer
//! says it is; the angle calculator expects the vehicle-cloud frame of docs/architecture.md section 8 (z roughly
//! up, x roughly toward the vehicle front) but tolerates tilt, yaw and offsets.
//!
//! Reading is split the usual way: [`parse_cloud`] is a pure function over bytes (it never panics on
//! any input: every length and count is checked before it is used, see the `never panics` property
//! test and the `cloud_parse` fuzz target), and [`read_cloud`] is the thin file adapter that adds the
//! path to every error. Points whose x, y or z is not finite (NaN, inf) are dropped and counted in
//! [`ReadStats::dropped_non_finite`]; an empty result is an error ([`ParseError::Empty`]).
//!
//! Supported inputs:
//! - PLY: `ascii`, `binary_little_endian`, `binary_big_endian`; any numeric type for x, y, z; other
//!   properties, list properties and other elements (faces, before or after the vertices) are skipped.
//! - PCD (v0.7 and older headers): `ascii`, `binary`, `binary_compressed` (LZF, decoded here).
//! - `.xyz` / `.csv` / `.txt`: one point per line, separated by whitespace, commas or semicolons; `#`
//!   comments; an optional header line naming the `x`, `y`, `z` columns.
//! - E57 (ASTM E2807, terrestrial scanners): every scan, brought into the file's frame by its pose;
//!   Cartesian or spherical coordinates; points flagged invalid are dropped and counted in
//!   [`ReadStats::dropped_invalid`] (see `e57.rs`).
//! - LAS 1.0-1.4 and LAZ: scale and offset applied; feet converted to metres when the CRS says so,
//!   geographic and geocentric CRSs refused, no CRS taken as metres with a note in
//!   [`ReadStats::notes`] (see `las.rs`).
//!
//! Writers: [`write_ply`] (ascii or binary little endian, `double` x y z) and [`write_xyz`].
//!
//! Memory: every count in a header is checked against the bytes present before anything is
//! allocated for it (a binary record's smallest size, list properties included, times the declared
//! count must fit in the file), and against [`ParseLimits`]: at most `max_points` points (24 bytes
//! each) and, for PCD `binary_compressed`, a decoded block of at most `max_decoded_bytes` (which
//! must also equal FIELDS x POINTS and be reachable from the compressed size at LZF's best ratio).
//! So a parse allocates at most the file's size, plus `24 x max_points`, plus
//! `max_decoded_bytes`: with the defaults, 192 MB + 128 MiB beyond the file itself. E57 and LAS/LAZ
//! have their own checks before the crates that decode them allocate (`e57.rs`, `las.rs`); their
//! decoders work in bounded batches (an E57 data packet is at most 64 KiB, LAS/LAZ records are
//! decoded 1 MiB at a time), and `onboard/tests/hostile_inputs.rs` measures their peaks.

mod e57;
mod las;
mod lzf;
mod pcd;
mod ply;
mod text;

use std::fmt;
use std::io::{self, Write};
use std::path::{Path, PathBuf};

/// A point cloud: points in metres, in the frame the producer documents.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Cloud {
    /// Points `[x, y, z]` in metres.
    pub points_m: Vec<[f64; 3]>,
}

/// File formats the reader understands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CloudFormat {
    /// Stanford PLY.
    Ply,
    /// Point Cloud Library PCD.
    Pcd,
    /// Delimited text: whitespace, comma or semicolon separated x y z per line.
    Text,
    /// ASTM E2807 E57 (terrestrial laser scanners).
    E57,
    /// ASPRS LAS, plain or LASzip-compressed (LAZ).
    Las,
}

impl fmt::Display for CloudFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            CloudFormat::Ply => "PLY",
            CloudFormat::Pcd => "PCD",
            CloudFormat::Text => "text",
            CloudFormat::E57 => "E57",
            CloudFormat::Las => "LAS",
        })
    }
}

/// What the reader saw, for the user and the report.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ReadStats {
    /// The format that was parsed.
    pub format: CloudFormat,
    /// The encoding inside that format (`ascii`, `binary_little_endian`, `binary_compressed`, ...).
    pub encoding: &'static str,
    /// Points (records) present in the file, finite or not.
    pub points_in_file: usize,
    /// Points dropped because x, y or z was NaN or infinite.
    pub dropped_non_finite: usize,
    /// Points dropped because the file flags them as having no valid position (E57 invalid
    /// states); 0 for formats without such flags.
    pub dropped_invalid: usize,
    /// What the reader converted or assumed (scans merged, units), one sentence each.
    pub notes: Vec<String>,
}

/// A malformed or unsupported cloud. Line numbers are 1-based and count header lines too.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ParseError {
    /// The bytes are not a PLY, PCD, E57, LAS/LAZ or text cloud the reader recognises.
    #[error("unknown cloud format (expected PLY, PCD, E57, LAS/LAZ, or x y z text)")]
    UnknownFormat,
    /// A binary container (E57, LAS/LAZ) is malformed or unsupported; the message names the
    /// part (scan, point, record, CRS) and what is wrong.
    #[error("{0}")]
    Container(String),
    /// The header is malformed; the message names the field.
    #[error("header line {line}: {message}")]
    Header {
        /// 1-based header line.
        line: usize,
        /// What was wrong.
        message: String,
    },
    /// A text data line is malformed.
    #[error("line {line}: {message}")]
    Data {
        /// 1-based line in the file.
        line: usize,
        /// What was wrong.
        message: String,
    },
    /// Binary data ends before the header's point count.
    #[error(
        "truncated data: header declares {declared} {what}, the data holds only {complete} complete ones"
    )]
    Truncated {
        /// What was being read (`vertices`, `points`, `faces`).
        what: &'static str,
        /// Count declared in the header.
        declared: usize,
        /// Complete records present.
        complete: usize,
    },
    /// A header declares more than a [`ParseLimits`] bound allows; nothing was allocated for it.
    #[error("{what}: {declared} declared, above the limit of {limit}")]
    OverLimit {
        /// What was counted (`points`, `decoded bytes`).
        what: &'static str,
        /// What the header declares.
        declared: usize,
        /// The limit.
        limit: usize,
    },
    /// A compressed block could not be decoded.
    #[error("compressed data: {0}")]
    Compressed(String),
    /// The cloud holds no finite point.
    #[error(
        "empty cloud: {points_in_file} points in the file, {dropped_non_finite} dropped as NaN/inf, none left"
    )]
    Empty {
        /// Points in the file.
        points_in_file: usize,
        /// Points dropped as non-finite.
        dropped_non_finite: usize,
    },
}

/// Reading a cloud file failed.
#[derive(Debug, thiserror::Error)]
pub enum CloudError {
    /// The file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The IO error.
        source: io::Error,
    },
    /// The file's content is malformed.
    #[error("{path}: {source}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// What was wrong, and where.
        source: ParseError,
    },
}

/// Guess the format from the file extension, then from the first bytes.
pub fn detect_format(path: Option<&Path>, bytes: &[u8]) -> Option<CloudFormat> {
    let ext = path
        .and_then(Path::extension)
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("ply") => return Some(CloudFormat::Ply),
        Some("pcd") => return Some(CloudFormat::Pcd),
        Some("xyz" | "csv" | "txt" | "pts") => return Some(CloudFormat::Text),
        Some("e57") => return Some(CloudFormat::E57),
        Some("las" | "laz") => return Some(CloudFormat::Las),
        _ => {}
    }
    if bytes.starts_with(b"ply") {
        return Some(CloudFormat::Ply);
    }
    if bytes.starts_with(e57::SIGNATURE) {
        return Some(CloudFormat::E57);
    }
    if bytes.starts_with(las::SIGNATURE) {
        return Some(CloudFormat::Las);
    }
    let head = &bytes[..bytes.len().min(256)];
    let head = String::from_utf8_lossy(head);
    if head.starts_with("# .PCD") || head.starts_with("VERSION") || head.starts_with("FIELDS") {
        return Some(CloudFormat::Pcd);
    }
    let first = head.trim_start().chars().next()?;
    (first.is_ascii_digit()
        || matches!(first, '-' | '+' | '.' | '#')
        || first.is_ascii_alphabetic())
    .then_some(CloudFormat::Text)
}

/// Bounds on what one parse may allocate beyond the file's own size (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ParseLimits {
    /// Most points a cloud may declare (each costs 24 bytes).
    pub max_points: usize,
    /// Largest decoded `binary_compressed` PCD block, bytes.
    pub max_decoded_bytes: usize,
}

impl ParseLimits {
    /// Default `max_points`: eight times the pipeline's clouds of about a million points.
    pub const DEFAULT_MAX_POINTS: usize = 8_000_000;
    /// Default `max_decoded_bytes`: 8 M points of 16 bytes (x, y, z, intensity as `float`).
    pub const DEFAULT_MAX_DECODED_BYTES: usize = 128 << 20;

    pub(crate) fn check_points(&self, declared: usize) -> Result<(), ParseError> {
        if declared > self.max_points {
            return Err(ParseError::OverLimit {
                what: "points",
                declared,
                limit: self.max_points,
            });
        }
        Ok(())
    }
}

impl Default for ParseLimits {
    fn default() -> Self {
        Self {
            max_points: Self::DEFAULT_MAX_POINTS,
            max_decoded_bytes: Self::DEFAULT_MAX_DECODED_BYTES,
        }
    }
}

/// Parse a cloud from bytes with the default [`ParseLimits`]. Pure; never panics.
pub fn parse_cloud(bytes: &[u8], format: CloudFormat) -> Result<(Cloud, ReadStats), ParseError> {
    parse_cloud_with(bytes, format, &ParseLimits::default())
}

/// Parse a cloud from bytes within `limits`. Pure; never panics.
pub fn parse_cloud_with(
    bytes: &[u8],
    format: CloudFormat,
    limits: &ParseLimits,
) -> Result<(Cloud, ReadStats), ParseError> {
    match format {
        // The `las` crate reads from an owned buffer: a copy of the bytes, within the 4 x file
        // bound of the hostile-input test. `read_cloud_with` hands the file's own buffer over.
        CloudFormat::Las => parse_owned(bytes.to_vec(), format, limits),
        _ => parse_borrowed(bytes, format, limits),
    }
}

fn parse_borrowed(
    bytes: &[u8],
    format: CloudFormat,
    limits: &ParseLimits,
) -> Result<(Cloud, ReadStats), ParseError> {
    let (raw, dropped_invalid, notes) = match format {
        CloudFormat::Ply => (ply::parse(bytes, limits)?, 0, Vec::new()),
        CloudFormat::Pcd => (pcd::parse(bytes, limits)?, 0, Vec::new()),
        CloudFormat::Text => (text::parse(bytes, limits)?, 0, Vec::new()),
        CloudFormat::E57 => {
            let c = e57::parse(bytes, limits)?;
            (c.raw, c.flagged_invalid, c.notes)
        }
        CloudFormat::Las => return parse_owned(bytes.to_vec(), format, limits),
    };
    finish(raw, format, dropped_invalid, notes)
}

fn parse_owned(
    bytes: Vec<u8>,
    format: CloudFormat,
    limits: &ParseLimits,
) -> Result<(Cloud, ReadStats), ParseError> {
    if format == CloudFormat::Las {
        let c = las::parse(bytes, limits)?;
        finish(c.raw, format, 0, c.notes)
    } else {
        parse_borrowed(&bytes, format, limits)
    }
}

/// Read a cloud file with the default [`ParseLimits`]; the format comes from the extension, else
/// from the first bytes.
pub fn read_cloud(path: &Path) -> Result<(Cloud, ReadStats), CloudError> {
    read_cloud_with(path, &ParseLimits::default())
}

/// Read a cloud file within `limits`.
pub fn read_cloud_with(
    path: &Path,
    limits: &ParseLimits,
) -> Result<(Cloud, ReadStats), CloudError> {
    let bytes = std::fs::read(path).map_err(|source| CloudError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let parse_err = |source| CloudError::Parse {
        path: path.to_path_buf(),
        source,
    };
    let format =
        detect_format(Some(path), &bytes).ok_or_else(|| parse_err(ParseError::UnknownFormat))?;
    parse_owned(bytes, format, limits).map_err(parse_err)
}

/// PLY body encodings the writer can produce.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlyEncoding {
    /// Human-readable, one vertex per line.
    Ascii,
    /// Compact binary, little endian.
    BinaryLittleEndian,
}

/// Write a cloud as PLY with `double` x, y, z (read back bit-exactly by [`parse_cloud`]).
pub fn write_ply<W: Write>(mut out: W, cloud: &Cloud, encoding: PlyEncoding) -> io::Result<()> {
    let format = match encoding {
        PlyEncoding::Ascii => "ascii",
        PlyEncoding::BinaryLittleEndian => "binary_little_endian",
    };
    write!(
        out,
        "ply\nformat {format} 1.0\ncomment passangle cloud, metres\nelement vertex {}\n\
         property double x\nproperty double y\nproperty double z\nend_header\n",
        cloud.points_m.len()
    )?;
    for p in &cloud.points_m {
        match encoding {
            PlyEncoding::Ascii => writeln!(out, "{} {} {}", p[0], p[1], p[2])?,
            PlyEncoding::BinaryLittleEndian => {
                for v in p {
                    out.write_all(&v.to_le_bytes())?;
                }
            }
        }
    }
    out.flush()
}

/// Write a cloud as `x y z` text lines (shortest round-trip decimal form).
pub fn write_xyz<W: Write>(mut out: W, cloud: &Cloud) -> io::Result<()> {
    for p in &cloud.points_m {
        writeln!(out, "{} {} {}", p[0], p[1], p[2])?;
    }
    out.flush()
}

/// Write a cloud as E57: one scan of `double` Cartesian x, y, z in metres, without a pose.
/// `guid` names the file (E57 requires one; any unique string).
pub fn write_e57<W: io::Read + Write + io::Seek>(
    out: W,
    cloud: &Cloud,
    guid: &str,
) -> io::Result<()> {
    e57::write(out, &cloud.points_m, guid).map_err(io::Error::other)
}

/// Write a cloud as LAS 1.4 (point format 0), or LAZ when `compressed`: coordinates rounded to
/// `resolution_m` (the LAS scale) about an offset at the centre of the cloud's bounding box,
/// without a CRS (readers take it as metres). Returns the writer.
pub fn write_las<W: Write + io::Seek + Send + Sync + 'static>(
    out: W,
    cloud: &Cloud,
    resolution_m: f64,
    compressed: bool,
) -> io::Result<W> {
    las::write(out, &cloud.points_m, resolution_m, compressed).map_err(io::Error::other)
}

/// Points as parsed, before non-finite ones are dropped.
struct RawCloud {
    points: Vec<[f64; 3]>,
    encoding: &'static str,
}

fn finish(
    raw: RawCloud,
    format: CloudFormat,
    dropped_invalid: usize,
    notes: Vec<String>,
) -> Result<(Cloud, ReadStats), ParseError> {
    let points_in_file = raw.points.len() + dropped_invalid;
    let mut points_m = raw.points;
    points_m.retain(|p| p.iter().all(|v| v.is_finite()));
    let dropped_non_finite = points_in_file - dropped_invalid - points_m.len();
    if points_m.is_empty() && dropped_invalid > 0 {
        return Err(ParseError::Container(format!(
            "empty cloud: {points_in_file} points in the file, {dropped_invalid} flagged invalid \
             by the file, {dropped_non_finite} dropped as NaN/inf, none left"
        )));
    }
    if points_m.is_empty() {
        return Err(ParseError::Empty {
            points_in_file,
            dropped_non_finite,
        });
    }
    Ok((
        Cloud { points_m },
        ReadStats {
            format,
            encoding: raw.encoding,
            points_in_file,
            dropped_non_finite,
            dropped_invalid,
            notes,
        },
    ))
}

/// Scalar types shared by PLY and PCD binary bodies.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    I64,
    U64,
    F32,
    F64,
}

impl Scalar {
    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::I64 | Scalar::U64 | Scalar::F64 => 8,
        }
    }

    /// Decode one value; `bytes` must hold at least `size()` bytes (callers check), else NaN.
    fn read(self, bytes: &[u8], big_endian: bool) -> f64 {
        fn arr<const N: usize>(b: &[u8], be: bool) -> Option<[u8; N]> {
            let mut a: [u8; N] = b.get(..N)?.try_into().ok()?;
            if be {
                a.reverse();
            }
            Some(a)
        }
        let v = match self {
            Scalar::I8 => arr::<1>(bytes, false).map(|a| f64::from(i8::from_le_bytes(a))),
            Scalar::U8 => arr::<1>(bytes, false).map(|a| f64::from(a[0])),
            Scalar::I16 => arr::<2>(bytes, big_endian).map(|a| f64::from(i16::from_le_bytes(a))),
            Scalar::U16 => arr::<2>(bytes, big_endian).map(|a| f64::from(u16::from_le_bytes(a))),
            Scalar::I32 => arr::<4>(bytes, big_endian).map(|a| f64::from(i32::from_le_bytes(a))),
            Scalar::U32 => arr::<4>(bytes, big_endian).map(|a| f64::from(u32::from_le_bytes(a))),
            Scalar::I64 => arr::<8>(bytes, big_endian).map(|a| i64::from_le_bytes(a) as f64),
            Scalar::U64 => arr::<8>(bytes, big_endian).map(|a| u64::from_le_bytes(a) as f64),
            Scalar::F32 => arr::<4>(bytes, big_endian).map(|a| f64::from(f32::from_le_bytes(a))),
            Scalar::F64 => arr::<8>(bytes, big_endian).map(f64::from_le_bytes),
        };
        v.unwrap_or(f64::NAN)
    }
}

/// Split off the header: lines up to and including the one for which `is_last` holds.
/// Returns the header lines and the byte offset of the body. Header size is capped at 1 MiB.
fn split_header(
    bytes: &[u8],
    is_last: impl Fn(&str) -> bool,
) -> Result<(Vec<&str>, usize), ParseError> {
    const MAX_HEADER: usize = 1 << 20;
    let mut lines = Vec::new();
    let mut start = 0;
    loop {
        let rest = bytes.get(start..).unwrap_or_default();
        let Some(len) = rest.iter().position(|&b| b == b'\n') else {
            return Err(ParseError::Header {
                line: lines.len() + 1,
                message: "header ends before its last line (end_header / DATA)".into(),
            });
        };
        if start + len > MAX_HEADER {
            return Err(ParseError::Header {
                line: lines.len() + 1,
                message: "header longer than 1 MiB".into(),
            });
        }
        let line = std::str::from_utf8(&rest[..len]).map_err(|_| ParseError::Header {
            line: lines.len() + 1,
            message: "header line is not UTF-8 text".into(),
        })?;
        let line = line.trim_end_matches('\r');
        start += len + 1;
        lines.push(line);
        if is_last(line) {
            return Ok((lines, start));
        }
    }
}

fn parse_f64(token: &str) -> Option<f64> {
    token.parse::<f64>().ok()
}

#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_formats;
