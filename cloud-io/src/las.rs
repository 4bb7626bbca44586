//! ASPRS LAS 1.0-1.4 and LAZ (LASzip-compressed LAS) clouds, read through the `las` crate (LAZ
//! through its pure-Rust `laz` decoder, single-threaded).
//!
//! Coordinates: every record's integer x, y, z times the header's scale plus its offset. Units:
//! LAS coordinates are in the units of the file's coordinate reference system. The reader reads
//! the CRS (GeoTIFF keys or WKT) and
//! - converts feet to metres: GeoTIFF linear-unit codes 9002 (international foot, 0.3048 m) and
//!   9003 (US survey foot, 1200/3937 m), or a WKT `UNIT`/`LENGTHUNIT` with its own metres-per-unit
//!   factor; the horizontal unit scales x and y, the vertical unit (GeoTIFF `VerticalUnitsGeoKey`,
//!   WKT `VERT_CS`/`VERTCRS`) scales z, and z takes the horizontal unit when no vertical one is
//!   given;
//! - refuses a geographic CRS (longitude/latitude in degrees) and a geocentric one (ECEF, z not
//!   up): reproject to a metric projected CRS first;
//! - refuses CRS records it cannot read (units unknown);
//! - takes coordinates as metres when the file has no CRS, and says so in a note.
//!
//! Hostile input: before the crate sees the bytes, the header's point count is checked against
//! [`ParseLimits`], an uncompressed file's point records must fit in the file, an extended VLR
//! must fit in the file (the crate allocates its declared 64-bit length), and a LAZ chunk table
//! may not declare more chunks than points (the decoder reserves one entry per declared chunk).
//! Points are decoded in batches of at most 1 MiB of records.

use std::io::Cursor;

use las::{Reader, Transform};

use super::{ParseError, ParseLimits, RawCloud};

/// The LAS file signature.
pub(super) const SIGNATURE: &[u8; 4] = b"LASF";
/// Size of the LAS 1.0-1.2 public header block, the smallest there is.
const MIN_HEADER_LEN: usize = 227;
/// Size of an extended VLR's header.
const EVLR_HEADER_LEN: u64 = 60;
/// Bytes of point records decoded per batch.
const BATCH_BYTES: usize = 1 << 20;

/// Points read, and what the reader converted or assumed.
pub(super) struct LasCloud {
    pub(super) raw: RawCloud,
    pub(super) notes: Vec<String>,
}

fn err(message: impl Into<String>) -> ParseError {
    ParseError::Container(message.into())
}

fn field<const N: usize>(bytes: &[u8], at: usize) -> Option<[u8; N]> {
    bytes.get(at..at + N)?.try_into().ok()
}
fn u16_at(b: &[u8], at: usize) -> u64 {
    field::<2>(b, at).map_or(0, |a| u64::from(u16::from_le_bytes(a)))
}
fn u32_at(b: &[u8], at: usize) -> u64 {
    field::<4>(b, at).map_or(0, |a| u64::from(u32::from_le_bytes(a)))
}
fn u64_at(b: &[u8], at: usize) -> u64 {
    field::<8>(b, at).map_or(0, u64::from_le_bytes)
}
fn i64_at(b: &[u8], at: usize) -> Option<i64> {
    field::<8>(b, at).map(i64::from_le_bytes)
}

/// The header fields the checks need, read from the raw bytes.
struct RawHeader {
    minor: u8,
    offset_to_points: u64,
    compressed: bool,
    record_len: u64,
    points: u64,
    evlr_start: u64,
    evlr_count: u64,
}

impl RawHeader {
    fn read(bytes: &[u8]) -> Result<Self, ParseError> {
        if bytes.len() < MIN_HEADER_LEN || !bytes.starts_with(SIGNATURE) {
            return Err(err(format!(
                "not a LAS file: needs the `LASF` signature and a header of at least \
                 {MIN_HEADER_LEN} bytes"
            )));
        }
        let (major, minor) = (bytes[24], bytes[25]);
        // As the `las` crate reads them: LAS 1.4 headers (whatever their declared size) carry
        // the extended VLR and 64-bit count fields, and a non-zero legacy count wins.
        let extended = (major, minor) >= (1, 4);
        let legacy_points = u32_at(bytes, 107);
        let points = if extended && legacy_points == 0 {
            u64_at(bytes, 247)
        } else {
            legacy_points
        };
        let format_id = bytes[104];
        Ok(Self {
            minor,
            offset_to_points: u32_at(bytes, 96),
            // LASzip marks a compressed point format by setting bit 7 (and sometimes bit 6).
            compressed: format_id & 0xC0 != 0,
            record_len: u16_at(bytes, 105),
            points,
            evlr_start: if extended { u64_at(bytes, 235) } else { 0 },
            evlr_count: if extended { u32_at(bytes, 243) } else { 0 },
        })
    }

    /// Every check of a declared size against the file and the limits.
    fn check(&self, bytes: &[u8], limits: &ParseLimits) -> Result<(), ParseError> {
        let len = bytes.len() as u64;
        limits.check_points(usize::try_from(self.points).unwrap_or(usize::MAX))?;
        if self.evlr_start > 0 && self.evlr_count > 0 {
            let length = self
                .evlr_start
                .checked_add(20)
                .and_then(|at| usize::try_from(at).ok())
                .map(|at| u64_at(bytes, at));
            let end = length.and_then(|l| {
                self.evlr_start
                    .checked_add(EVLR_HEADER_LEN)
                    .and_then(|h| h.checked_add(l))
            });
            if end.is_none_or(|end| end > len) {
                return Err(err(format!(
                    "LAS 1.{}: the first extended VLR (at byte {}, {} bytes of data) ends beyond \
                     the file's {len} bytes",
                    self.minor,
                    self.evlr_start,
                    length.unwrap_or(0)
                )));
            }
        }
        if self.offset_to_points > len {
            return Err(err(format!(
                "LAS: point data starts at byte {}, beyond the file's {len} bytes",
                self.offset_to_points
            )));
        }
        if self.compressed {
            self.check_chunk_table(bytes)
        } else {
            let room = (len - self.offset_to_points) / self.record_len.max(1);
            if room < self.points {
                return Err(ParseError::Truncated {
                    what: "LAS point records",
                    declared: usize::try_from(self.points).unwrap_or(usize::MAX),
                    complete: usize::try_from(room).unwrap_or(usize::MAX),
                });
            }
            Ok(())
        }
    }

    /// The LAZ chunk table's declared chunk count, found the way LASzip finds it (an offset at
    /// the start of the point data, or, when that was never updated, in the last 8 bytes).
    fn check_chunk_table(&self, bytes: &[u8]) -> Result<(), ParseError> {
        let data_start = self.offset_to_points;
        let Some(mut table) = usize::try_from(data_start)
            .ok()
            .and_then(|at| i64_at(bytes, at))
        else {
            return Ok(());
        };
        if table <= data_start as i64 {
            match i64_at(bytes, bytes.len().saturating_sub(8)) {
                Some(t) if t > data_start as i64 => table = t,
                _ => return Ok(()),
            }
        }
        let chunks = usize::try_from(table)
            .ok()
            .and_then(|at| at.checked_add(4))
            .map_or(0, |at| u32_at(bytes, at));
        if chunks > self.points.saturating_add(1) {
            return Err(err(format!(
                "LAZ: the chunk table at byte {table} declares {chunks} chunks for {} points",
                self.points
            )));
        }
        Ok(())
    }
}

/// Metres per unit for x, y (horizontal) and z (vertical), and a note saying what was found.
struct Units {
    horizontal: f64,
    vertical: f64,
    note: String,
}

pub(super) fn parse(bytes: Vec<u8>, limits: &ParseLimits) -> Result<LasCloud, ParseError> {
    let raw = RawHeader::read(&bytes)?;
    raw.check(&bytes, limits)?;
    let kind = if raw.compressed { "LAZ" } else { "LAS" };
    let mut reader = Reader::new(Cursor::new(bytes)).map_err(|e| err(format!("{kind}: {e}")))?;
    let header = reader.header().clone();
    for (axis, t) in [
        ("x", header.transforms().x),
        ("y", header.transforms().y),
        ("z", header.transforms().z),
    ] {
        check_transform(axis, t)?;
    }
    let units = units(&header)?;
    let declared = header.number_of_points();
    let record_len = usize::from(header.point_format().len()).max(1);
    let batch = (BATCH_BYTES / record_len).max(1) as u64;
    // Within `max_points` (checked before the crate ran): reserved once.
    let mut points = Vec::with_capacity(usize::try_from(declared).unwrap_or(0));
    let mut data = las::PointDataBuilder::new().for_header(&header).build();
    let mut read = 0u64;
    while read < declared {
        let n = reader
            .fill_points(batch.min(declared - read), &mut data)
            .map_err(|e| {
                err(format!(
                    "{kind}: reading point {} of {declared}: {e}",
                    read + 1
                ))
            })?;
        if n == 0 {
            break;
        }
        read += n;
        points.extend(data.x().zip(data.y()).zip(data.z()).map(|((x, y), z)| {
            [
                x * units.horizontal,
                y * units.horizontal,
                z * units.vertical,
            ]
        }));
    }
    if read < declared {
        return Err(ParseError::Truncated {
            what: "LAS point records",
            declared: usize::try_from(declared).unwrap_or(usize::MAX),
            complete: usize::try_from(read).unwrap_or(usize::MAX),
        });
    }
    let version = header.version();
    Ok(LasCloud {
        raw: RawCloud {
            points,
            encoding: if raw.compressed {
                "LAZ"
            } else {
                "uncompressed"
            },
        },
        notes: vec![
            format!(
                "{kind} {}.{}, point format {}",
                version.major,
                version.minor,
                header.point_format().to_u8().unwrap_or(0)
            ),
            units.note,
        ],
    })
}

fn check_transform(axis: &str, t: Transform) -> Result<(), ParseError> {
    if !(t.scale.is_finite() && t.scale > 0.0 && t.offset.is_finite()) {
        return Err(err(format!(
            "LAS header: {axis} scale {} and offset {}: the scale must be finite and above 0, the \
             offset finite",
            t.scale, t.offset
        )));
    }
    Ok(())
}

/// GeoTIFF key ids (GeoTIFF 1.1).
const GT_MODEL_TYPE: u16 = 1024;
const PROJ_LINEAR_UNITS: u16 = 3076;
const VERTICAL_UNITS: u16 = 4099;

fn unit_code(code: u16, key: &str) -> Result<(f64, &'static str), ParseError> {
    match code {
        9001 => Ok((1.0, "metre")),
        9002 => Ok((0.3048, "foot")),
        9003 => Ok((1200.0 / 3937.0, "US survey foot")),
        other => Err(err(format!(
            "LAS CRS: {key} is unit code {other}, not metre (9001), foot (9002) or US survey \
             foot (9003); convert the file to metres"
        ))),
    }
}

fn units(header: &las::Header) -> Result<Units, ParseError> {
    if let Some(wkt) = header.get_wkt_crs_bytes() {
        return wkt_units(&String::from_utf8_lossy(wkt));
    }
    let crs = header.get_geotiff_crs().map_err(|e| {
        err(format!(
            "LAS CRS: the GeoTIFF keys cannot be read ({e}), so the units are unknown"
        ))
    })?;
    let Some(crs) = crs else {
        return Ok(Units {
            horizontal: 1.0,
            vertical: 1.0,
            note: "no coordinate reference system in the file: coordinates taken as metres".into(),
        });
    };
    let key = |id: u16| {
        crs.entries
            .iter()
            .find(|e| e.id == id)
            .and_then(|e| match e.data {
                las::crs::GeoTiffData::U16(v) => Some(v),
                _ => None,
            })
    };
    match key(GT_MODEL_TYPE) {
        Some(2) => {
            return Err(err(
                "LAS CRS: geographic (longitude/latitude in degrees); reproject the file to a \
                 metric projected CRS first",
            ));
        }
        Some(3) => {
            return Err(err(
                "LAS CRS: geocentric (ECEF: z is not up); reproject the file to a metric \
                 projected CRS first",
            ));
        }
        _ => {}
    }
    let (horizontal, h_name) = match key(PROJ_LINEAR_UNITS) {
        Some(code) => unit_code(code, "ProjLinearUnitsGeoKey")?,
        None => (1.0, "metre (no ProjLinearUnitsGeoKey: assumed)"),
    };
    let (vertical, v_name) = match key(VERTICAL_UNITS) {
        Some(code) => unit_code(code, "VerticalUnitsGeoKey")?,
        None => (horizontal, "as horizontal"),
    };
    Ok(Units {
        horizontal,
        vertical,
        note: units_note("GeoTIFF", horizontal, h_name, vertical, v_name),
    })
}

fn units_note(source: &str, h: f64, h_name: &str, v: f64, v_name: &str) -> String {
    let converted = if (h - 1.0).abs() < 1e-12 && (v - 1.0).abs() < 1e-12 {
        "coordinates in metres"
    } else {
        "converted to metres"
    };
    format!("{source} CRS units: horizontal {h_name}, vertical {v_name}; {converted}")
}

/// The linear units of a WKT (1 or 2) CRS: each `UNIT["name", metres per unit]` or
/// `LENGTHUNIT[...]` that is not an angle unit; the one inside a vertical CRS applies to z.
fn wkt_units(wkt: &str) -> Result<Units, ParseError> {
    let upper = wkt.trim_start().to_ascii_uppercase();
    let geographic = ["GEOGCS", "GEOGCRS", "GEOGRAPHICCRS"];
    let geocentric = ["GEOCCS", "GEODCRS", "GEODETICCRS"];
    if geographic.iter().any(|g| upper.starts_with(g)) {
        return Err(err(
            "LAS CRS (WKT): geographic (longitude/latitude in degrees); reproject the file to a \
             metric projected CRS first",
        ));
    }
    if geocentric.iter().any(|g| upper.starts_with(g)) {
        return Err(err(
            "LAS CRS (WKT): geocentric (ECEF: z is not up); reproject the file to a metric \
             projected CRS first",
        ));
    }
    let vertical_at = ["VERT_CS", "VERTCRS", "VERTICALCRS"]
        .iter()
        .filter_map(|k| upper.find(k))
        .min()
        .unwrap_or(usize::MAX);
    let mut horizontal = None;
    let mut vertical = None;
    for (at, _) in upper.match_indices("UNIT[") {
        // WKT2's SCALEUNIT and TIMEUNIT are not lengths.
        let before = &upper[..at];
        if before.ends_with("SCALE") || before.ends_with("TIME") {
            continue;
        }
        let Some((name, factor)) = wkt_unit(&upper[at + 5..]) else {
            continue;
        };
        let angle = ["DEGREE", "GRAD", "RADIAN", "ARC"]
            .iter()
            .any(|a| name.contains(a));
        if angle {
            continue;
        }
        if !(factor.is_finite() && factor > 0.0) {
            return Err(err(format!(
                "LAS CRS (WKT): unit `{name}` has the factor {factor}"
            )));
        }
        let slot = if at > vertical_at {
            &mut vertical
        } else {
            &mut horizontal
        };
        if slot.is_none() {
            *slot = Some((factor, name));
        }
    }
    let (h, h_name) = horizontal.unwrap_or((1.0, "metre (no linear unit: assumed)".into()));
    let (v, v_name) = vertical.unwrap_or((h, "as horizontal".into()));
    Ok(Units {
        horizontal: h,
        vertical: v,
        note: units_note(
            "WKT",
            h,
            &h_name.to_ascii_lowercase(),
            v,
            &v_name.to_ascii_lowercase(),
        ),
    })
}

/// `"NAME", FACTOR` at the start of `s` (after `UNIT[`).
fn wkt_unit(s: &str) -> Option<(String, f64)> {
    let s = s.trim_start().strip_prefix('"')?;
    let end = s.find('"')?;
    let name = s[..end].to_owned();
    let rest = s[end + 1..].trim_start().strip_prefix(',')?;
    let number: String = rest
        .trim_start()
        .chars()
        .take_while(|c| c.is_ascii_digit() || matches!(c, '.' | 'E' | 'e' | '-' | '+'))
        .collect();
    Some((name, number.parse().ok()?))
}

/// Writes `points` as LAS 1.4 point format 0 (LAZ when `compressed`), x, y, z rounded to
/// `resolution_m` about an offset at the centre of their bounding box, no CRS (metres).
pub(super) fn write<W: std::io::Write + std::io::Seek + Send + Sync + 'static>(
    out: W,
    points: &[[f64; 3]],
    resolution_m: f64,
    compressed: bool,
) -> las::Result<W> {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in points {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let centre = |k: usize| {
        if lo[k].is_finite() {
            f64::midpoint(lo[k], hi[k]).round()
        } else {
            0.0
        }
    };
    let mut builder = las::Builder::from((1, 4));
    builder.point_format = las::point::Format::new(0)?;
    builder.point_format.is_compressed = compressed;
    "passangle".clone_into(&mut builder.generating_software);
    builder.transforms = las::Vector {
        x: Transform {
            scale: resolution_m,
            offset: centre(0),
        },
        y: Transform {
            scale: resolution_m,
            offset: centre(1),
        },
        z: Transform {
            scale: resolution_m,
            offset: centre(2),
        },
    };
    let mut writer = las::Writer::new(out, builder.into_header()?)?;
    for p in points {
        writer.write_point(las::Point {
            x: p[0],
            y: p[1],
            z: p[2],
            ..las::Point::default()
        })?;
    }
    writer.into_inner()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wkt_units_convert_feet_and_refuse_degrees() {
        let ft = r#"PROJCS["NAD83 / Oregon GIC Lambert (ft)",GEOGCS["NAD83",DATUM["North_American_Datum_1983"],UNIT["degree",0.0174532925199433]],PROJECTION["Lambert_Conformal_Conic_2SP"],UNIT["foot",0.3048,AUTHORITY["EPSG","9002"]]]"#;
        let u = wkt_units(ft).unwrap();
        assert_eq!((u.horizontal, u.vertical), (0.3048, 0.3048), "{}", u.note);
        let compound = r#"COMPD_CS["x",PROJCS["p",GEOGCS["g",UNIT["degree",0.01745]],UNIT["US survey foot",0.304800609601219]],VERT_CS["NAVD88",VERT_DATUM["d",2005],UNIT["metre",1]]]"#;
        let u = wkt_units(compound).unwrap();
        assert!(
            (u.horizontal - 0.304_800_609_601_219).abs() < 1e-15,
            "{}",
            u.note
        );
        assert!((u.vertical - 1.0).abs() < 1e-15, "{}", u.note);
        let e = wkt_units(r#"GEOGCS["WGS 84",UNIT["degree",0.0174532925199433]]"#)
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("geographic"), "{e}");
        let m = wkt_units(r#"PROJCRS["WGS 84 / UTM 32N",LENGTHUNIT["metre",1]]"#).unwrap();
        assert_eq!((m.horizontal, m.vertical), (1.0, 1.0));
        assert!(m.note.contains("in metres"), "{}", m.note);
    }
}
