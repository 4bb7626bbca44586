//! ASTM E2807 (E57) clouds, as FARO, Leica, Trimble and Riegl terrestrial scanners export them,
//! read through the `e57` crate.
//!
//! An E57 file holds one or more scans (`data3D` entries), each with its own pose (a rotation
//! quaternion and a translation from the scan's own frame to the file's frame). Every scan is
//! read, its points brought into the file's frame by its pose, and all scans are merged into one
//! cloud. Coordinates may be Cartesian or spherical (range, azimuth, elevation; converted to
//! Cartesian); a point whose invalid-state flag says it has no valid position (state 1: a
//! direction without range, state 2: no position) is dropped and counted. E57 is metres by
//! definition, so no unit conversion applies.
//!
//! Hostile input: the header's XML length is checked against the file before the crate allocates
//! it, the scans' declared point counts are summed and checked against [`ParseLimits`] before
//! any point is read, a scan whose every field is a constant (zero bits per value, which makes
//! the crate's decoder produce points without end) is refused, and a pose that is not a finite
//! rotation is refused naming the scan. The quaternion is normalised before use (writers that
//! print few decimals leave a norm slightly off 1, which would otherwise scale the scan).

use std::io::Cursor;

use e57::{CartesianCoordinate, E57Reader, PointCloud, RecordDataType, RecordName, Transform};

use super::{ParseError, ParseLimits, RawCloud};

/// The E57 file signature (first 8 bytes).
pub(super) const SIGNATURE: &[u8; 8] = b"ASTM-E57";
/// Size of the binary header before the first page's data.
const HEADER_LEN: usize = 48;

/// Points read, plus how many the file flagged as having no valid position.
pub(super) struct E57Cloud {
    pub(super) raw: RawCloud,
    pub(super) flagged_invalid: usize,
    pub(super) notes: Vec<String>,
}

fn header_err(message: impl Into<String>) -> ParseError {
    ParseError::Container(message.into())
}

fn u64_at(bytes: &[u8], at: usize) -> Option<u64> {
    Some(u64::from_le_bytes(bytes.get(at..at + 8)?.try_into().ok()?))
}

pub(super) fn parse(bytes: &[u8], limits: &ParseLimits) -> Result<E57Cloud, ParseError> {
    if bytes.len() < HEADER_LEN || !bytes.starts_with(SIGNATURE) {
        return Err(header_err(format!(
            "not an E57 file: needs the `ASTM-E57` signature and a {HEADER_LEN}-byte header"
        )));
    }
    // The crate allocates the XML section's declared length before reading it.
    let xml_len = u64_at(bytes, 32).unwrap_or(u64::MAX);
    if xml_len > bytes.len() as u64 {
        return Err(header_err(format!(
            "E57 header declares an XML section of {xml_len} bytes, more than the file's {}",
            bytes.len()
        )));
    }
    let mut reader =
        E57Reader::new(Cursor::new(bytes)).map_err(|e| header_err(format!("E57: {e}")))?;
    let scans = reader.pointclouds();
    if scans.is_empty() {
        return Err(header_err(
            "E57: the file holds no point cloud (data3D is empty)",
        ));
    }
    let declared = scans
        .iter()
        .fold(0u64, |sum, s| sum.saturating_add(s.records));
    let declared = usize::try_from(declared).unwrap_or(usize::MAX);
    limits.check_points(declared)?;

    // Within `max_points` (checked): reserved once, so the cloud never holds twice its size
    // while growing.
    let mut points = Vec::with_capacity(declared);
    let mut flagged_invalid = 0;
    let mut spherical_scans = 0;
    let mut posed_scans = 0;
    for (i, scan) in scans.iter().enumerate() {
        let name = scan_name(i, scan);
        check_prototype(scan, &name)?;
        let world_from_scan = pose(scan.transform.as_ref(), &name)?;
        if scan.transform.is_some() {
            posed_scans += 1;
        }
        if !scan.has_cartesian() {
            spherical_scans += 1;
        }
        let mut iter = reader
            .pointcloud_simple(scan)
            .map_err(|e| header_err(format!("E57 {name}: {e}")))?;
        iter.spherical_to_cartesian(true);
        iter.apply_pose(false);
        iter.intensity_to_color(false);
        iter.normalize_color(false);
        iter.normalize_intensity(false);
        let mut k = 0usize;
        for p in iter {
            let p = match p {
                Ok(p) => p,
                // A data packet that completes no point (an index packet, or packed integers
                // waiting for the next packet's bits) surfaces as this error; the iterator has
                // consumed the packet and goes on with the next one, so the number of such
                // errors is bounded by the packets in the file.
                Err(e57::Error::Internal { desc, .. })
                    if desc.starts_with("Cannot read next point") =>
                {
                    continue;
                }
                Err(e) => {
                    return Err(header_err(format!("E57 {name}, point {}: {e}", k + 1)));
                }
            };
            k += 1;
            match p.cartesian {
                CartesianCoordinate::Valid { x, y, z } => {
                    points.push(world_from_scan.apply([x, y, z]));
                }
                CartesianCoordinate::Direction { .. } | CartesianCoordinate::Invalid => {
                    flagged_invalid += 1;
                }
            }
        }
    }
    let mut notes = Vec::new();
    if scans.len() > 1 {
        notes.push(format!(
            "E57: {} scans merged into the file's frame ({posed_scans} with a pose)",
            scans.len()
        ));
    }
    if spherical_scans > 0 {
        notes.push(format!(
            "E57: {spherical_scans} scans in spherical coordinates, converted to Cartesian"
        ));
    }
    Ok(E57Cloud {
        raw: RawCloud {
            points,
            encoding: if spherical_scans > 0 {
                "spherical"
            } else {
                "cartesian"
            },
        },
        flagged_invalid,
        notes,
    })
}

fn scan_name(i: usize, scan: &PointCloud) -> String {
    match &scan.name {
        Some(n) => format!(
            "scan {} (`{}`)",
            i + 1,
            n.chars().take(64).collect::<String>()
        ),
        None => format!("scan {}", i + 1),
    }
}

/// Refuses a scan without a position and one whose fields all have zero bits per value.
fn check_prototype(scan: &PointCloud, name: &str) -> Result<(), ParseError> {
    let has = |n: RecordName| scan.prototype.iter().any(|r| r.name == n);
    let cartesian = [
        RecordName::CartesianX,
        RecordName::CartesianY,
        RecordName::CartesianZ,
    ]
    .into_iter()
    .all(has);
    let spherical = [
        RecordName::SphericalRange,
        RecordName::SphericalAzimuth,
        RecordName::SphericalElevation,
    ]
    .into_iter()
    .all(has);
    if !(cartesian || spherical) {
        return Err(header_err(format!(
            "E57 {name}: neither cartesianX/Y/Z nor sphericalRange/Azimuth/Elevation fields"
        )));
    }
    let zero_bits = |t: &RecordDataType| match t {
        RecordDataType::Integer { min, max } | RecordDataType::ScaledInteger { min, max, .. } => {
            min == max
        }
        RecordDataType::Single { .. } | RecordDataType::Double { .. } => false,
    };
    if scan.records > 0 && scan.prototype.iter().all(|r| zero_bits(&r.data_type)) {
        return Err(header_err(format!(
            "E57 {name}: every field is a constant (minimum = maximum), so the data holds no \
             point boundaries"
        )));
    }
    Ok(())
}

/// A rigid transform `p -> R p + t`.
#[derive(Debug, Clone, Copy)]
struct Pose {
    rotation: [[f64; 3]; 3],
    translation_m: [f64; 3],
}

impl Pose {
    fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        let r = &self.rotation;
        let t = self.translation_m;
        [
            r[0][0] * p[0] + r[0][1] * p[1] + r[0][2] * p[2] + t[0],
            r[1][0] * p[0] + r[1][1] * p[1] + r[1][2] * p[2] + t[1],
            r[2][0] * p[0] + r[2][1] * p[1] + r[2][2] * p[2] + t[2],
        ]
    }
}

/// The scan's pose (file from scan), the identity when the scan has none.
fn pose(transform: Option<&Transform>, name: &str) -> Result<Pose, ParseError> {
    let Some(t) = transform else {
        return Ok(Pose {
            rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            translation_m: [0.0; 3],
        });
    };
    let q = &t.rotation;
    let tr = &t.translation;
    let norm = (q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z).sqrt();
    let finite = [q.w, q.x, q.y, q.z, tr.x, tr.y, tr.z]
        .iter()
        .all(|v| v.is_finite());
    // A quaternion far from unit length is not a rotation that lost digits but a wrong pose.
    if !finite || !(0.9..=1.1).contains(&norm) {
        return Err(header_err(format!(
            "E57 {name}: pose rotation ({}, {}, {}, {}) with translation ({}, {}, {}) is not a \
             finite unit quaternion (norm {norm})",
            q.w, q.x, q.y, q.z, tr.x, tr.y, tr.z
        )));
    }
    let (w, x, y, z) = (q.w / norm, q.x / norm, q.y / norm, q.z / norm);
    Ok(Pose {
        rotation: [
            [
                1.0 - 2.0 * (y * y + z * z),
                2.0 * (x * y - w * z),
                2.0 * (x * z + w * y),
            ],
            [
                2.0 * (x * y + w * z),
                1.0 - 2.0 * (x * x + z * z),
                2.0 * (y * z - w * x),
            ],
            [
                2.0 * (x * z - w * y),
                2.0 * (y * z + w * x),
                1.0 - 2.0 * (x * x + y * y),
            ],
        ],
        translation_m: [tr.x, tr.y, tr.z],
    })
}

/// Writes `points` as one E57 scan: `double` Cartesian x, y, z in metres, no pose.
pub(super) fn write<W: std::io::Read + std::io::Write + std::io::Seek>(
    out: W,
    points: &[[f64; 3]],
    guid: &str,
) -> e57::Result<()> {
    let mut writer = e57::E57Writer::new(out, guid)?;
    let prototype = vec![
        e57::Record::CARTESIAN_X_F64,
        e57::Record::CARTESIAN_Y_F64,
        e57::Record::CARTESIAN_Z_F64,
    ];
    let mut scan = writer.add_pointcloud(&format!("{guid}-scan"), prototype)?;
    scan.set_name(Some("passangle cloud".to_owned()));
    for p in points {
        scan.add_point(p.iter().map(|&v| e57::RecordValue::Double(v)).collect())?;
    }
    scan.finalize()?;
    writer.finalize()
}
