//! PCD reader (`DATA ascii`, `binary`, `binary_compressed`). Fields other than x, y, z are skipped.
//! `binary_compressed` is the PCL layout: `u32` compressed size, `u32` uncompressed size, then an
//! LZF block whose decoded bytes hold each field for all points in turn (structure of arrays).

use super::{ParseError, ParseLimits, RawCloud, Scalar, lzf, parse_f64, split_header};

#[derive(Debug)]
struct Field {
    name: String,
    ty: Scalar,
    count: usize,
}

impl Field {
    fn bytes(&self) -> usize {
        self.ty.size() * self.count
    }
}

fn header_err(line: usize, message: impl Into<String>) -> ParseError {
    ParseError::Header {
        line,
        message: message.into(),
    }
}

struct Header {
    fields: Vec<Field>,
    points: usize,
    data: String,
    data_line: usize,
}

#[allow(clippy::too_many_lines)]
fn parse_header(lines: &[&str]) -> Result<Header, ParseError> {
    let mut names: Option<(usize, Vec<String>)> = None;
    let mut sizes: Option<(usize, Vec<usize>)> = None;
    let mut types: Option<(usize, Vec<char>)> = None;
    let mut counts: Option<(usize, Vec<usize>)> = None;
    let (mut width, mut height, mut points) = (None, None, None);
    let mut data = None;
    for (i, line) in lines.iter().enumerate() {
        let n = i + 1;
        let mut words = line.split_whitespace();
        let Some(key) = words.next() else { continue };
        let rest: Vec<&str> = words.collect();
        let numbers = |what: &str| -> Result<Vec<usize>, ParseError> {
            rest.iter()
                .map(|w| {
                    w.parse()
                        .map_err(|_| header_err(n, format!("{what}: `{w}` is not a count")))
                })
                .collect()
        };
        let one = |what: &str| -> Result<usize, ParseError> {
            match numbers(what)?.as_slice() {
                [v] => Ok(*v),
                _ => Err(header_err(n, format!("{what} takes one number"))),
            }
        };
        match key {
            k if k.starts_with('#') => {}
            "VERSION" | "VIEWPOINT" => {}
            "FIELDS" | "COLUMNS" => {
                names = Some((n, rest.iter().map(|s| (*s).to_string()).collect()));
            }
            "SIZE" => sizes = Some((n, numbers("SIZE")?)),
            "TYPE" => {
                let t: Option<Vec<char>> = rest.iter().map(|w| w.chars().next()).collect();
                types = Some((n, t.ok_or_else(|| header_err(n, "TYPE: empty entry"))?));
            }
            "COUNT" => counts = Some((n, numbers("COUNT")?)),
            "WIDTH" => width = Some(one("WIDTH")?),
            "HEIGHT" => height = Some(one("HEIGHT")?),
            "POINTS" => points = Some(one("POINTS")?),
            "DATA" => {
                data = Some((
                    n,
                    rest.first().map(|s| (*s).to_string()).unwrap_or_default(),
                ));
            }
            other => return Err(header_err(n, format!("unknown header key `{other}`"))),
        }
    }
    let (data_line, data) = data.ok_or_else(|| header_err(lines.len(), "missing DATA line"))?;
    let (names_line, names) = names.ok_or_else(|| header_err(data_line, "missing FIELDS line"))?;
    let nf = names.len();
    let (size_line, sizes) = sizes.unwrap_or((names_line, vec![4; nf]));
    let (type_line, types) = types.unwrap_or((names_line, vec!['F'; nf]));
    let (count_line, counts) = counts.unwrap_or((names_line, vec![1; nf]));
    for (line, len, what) in [
        (size_line, sizes.len(), "SIZE"),
        (type_line, types.len(), "TYPE"),
        (count_line, counts.len(), "COUNT"),
    ] {
        if len != nf {
            return Err(header_err(
                line,
                format!("{what} has {len} entries, FIELDS has {nf}"),
            ));
        }
    }
    let mut fields = Vec::with_capacity(nf);
    for (k, name) in names.into_iter().enumerate() {
        let ty = match (types[k], sizes[k]) {
            ('I', 1) => Scalar::I8,
            ('U', 1) => Scalar::U8,
            ('I', 2) => Scalar::I16,
            ('U', 2) => Scalar::U16,
            ('I', 4) => Scalar::I32,
            ('U', 4) => Scalar::U32,
            ('I', 8) => Scalar::I64,
            ('U', 8) => Scalar::U64,
            ('F', 4) => Scalar::F32,
            ('F', 8) => Scalar::F64,
            (t, s) => {
                return Err(header_err(
                    type_line,
                    format!("field `{name}`: unsupported TYPE {t} with SIZE {s}"),
                ));
            }
        };
        if counts[k] == 0 || counts[k] > 1 << 16 {
            return Err(header_err(
                count_line,
                format!("field `{name}`: COUNT {} out of range", counts[k]),
            ));
        }
        fields.push(Field {
            name,
            ty,
            count: counts[k],
        });
    }
    let points = match (points, width, height) {
        (Some(p), _, _) => p,
        (None, Some(w), Some(h)) => w
            .checked_mul(h)
            .ok_or_else(|| header_err(data_line, "WIDTH x HEIGHT overflows"))?,
        _ => {
            return Err(header_err(
                data_line,
                "missing POINTS (or WIDTH and HEIGHT)",
            ));
        }
    };
    Ok(Header {
        fields,
        points,
        data,
        data_line,
    })
}

/// For x, y, z: (index of the field, byte offset of its first element within a record).
fn xyz_fields(header: &Header) -> Result<[(usize, usize); 3], ParseError> {
    let mut out = [(0, 0); 3];
    for (k, axis) in ["x", "y", "z"].into_iter().enumerate() {
        let mut offset = 0;
        let mut found = None;
        for (i, f) in header.fields.iter().enumerate() {
            if f.name == axis {
                found = Some((i, offset));
                break;
            }
            offset += f.bytes();
        }
        out[k] =
            found.ok_or_else(|| header_err(header.data_line, format!("FIELDS has no `{axis}`")))?;
    }
    Ok(out)
}

pub(super) fn parse(bytes: &[u8], limits: &ParseLimits) -> Result<RawCloud, ParseError> {
    let (lines, body_start) = split_header(bytes, |l| l.trim_start().starts_with("DATA"))?;
    let header = parse_header(&lines)?;
    let xyz = xyz_fields(&header)?;
    limits.check_points(header.points)?;
    let body = bytes.get(body_start..).unwrap_or_default();
    match header.data.as_str() {
        "ascii" => parse_ascii(body, lines.len(), &header, xyz),
        "binary" => parse_binary(body, &header, xyz),
        "binary_compressed" => parse_compressed(body, &header, xyz, limits),
        other => Err(header_err(
            header.data_line,
            format!("unknown DATA encoding `{other}`"),
        )),
    }
}

fn parse_ascii(
    body: &[u8],
    header_lines: usize,
    header: &Header,
    xyz: [(usize, usize); 3],
) -> Result<RawCloud, ParseError> {
    // Token index of each field's first element.
    let mut token_at = Vec::with_capacity(header.fields.len());
    let mut t = 0;
    for f in &header.fields {
        token_at.push(t);
        t += f.count;
    }
    let needed = t;
    let text = String::from_utf8_lossy(body);
    let mut points = Vec::with_capacity(header.points.min(body.len() / 6 + 1));
    for (i, line) in text.lines().enumerate() {
        if points.len() == header.points {
            break;
        }
        let line_no = header_lines + i + 1;
        if line.trim().is_empty() {
            continue;
        }
        let tokens: Vec<&str> = line.split_whitespace().collect();
        if tokens.len() < needed {
            return Err(ParseError::Data {
                line: line_no,
                message: format!("{} values, FIELDS/COUNT need {needed}", tokens.len()),
            });
        }
        let mut p = [0.0; 3];
        for (k, &(field, _)) in xyz.iter().enumerate() {
            let token = tokens[token_at[field]];
            p[k] = parse_f64(token).ok_or_else(|| ParseError::Data {
                line: line_no,
                message: format!(
                    "`{token}` is not a number for field `{}`",
                    header.fields[field].name
                ),
            })?;
        }
        points.push(p);
    }
    if points.len() < header.points {
        return Err(ParseError::Truncated {
            what: "points",
            declared: header.points,
            complete: points.len(),
        });
    }
    Ok(RawCloud {
        points,
        encoding: "ascii",
    })
}

fn parse_binary(
    body: &[u8],
    header: &Header,
    xyz: [(usize, usize); 3],
) -> Result<RawCloud, ParseError> {
    let record: usize = header.fields.iter().map(Field::bytes).sum();
    let complete = body.len().checked_div(record).unwrap_or(0);
    if complete < header.points {
        return Err(ParseError::Truncated {
            what: "points",
            declared: header.points,
            complete,
        });
    }
    let types = xyz.map(|(f, _)| header.fields[f].ty);
    let points = body
        .chunks_exact(record.max(1))
        .take(header.points)
        .map(|r| {
            let mut p = [0.0; 3];
            for k in 0..3 {
                p[k] = types[k].read(r.get(xyz[k].1..).unwrap_or_default(), false);
            }
            p
        })
        .collect();
    Ok(RawCloud {
        points,
        encoding: "binary",
    })
}

fn parse_compressed(
    body: &[u8],
    header: &Header,
    xyz: [(usize, usize); 3],
    limits: &ParseLimits,
) -> Result<RawCloud, ParseError> {
    let word = |at: usize| -> Result<usize, ParseError> {
        body.get(at..at + 4)
            .and_then(|b| b.try_into().ok())
            .map(|b| u32::from_le_bytes(b) as usize)
            .ok_or(ParseError::Truncated {
                what: "points",
                declared: header.points,
                complete: 0,
            })
    };
    let compressed_len = word(0)?;
    let uncompressed_len = word(4)?;
    let record: usize = header.fields.iter().map(Field::bytes).sum();
    let expected = record.checked_mul(header.points);
    if expected != Some(uncompressed_len) {
        return Err(ParseError::Compressed(format!(
            "block declares {uncompressed_len} decoded bytes, FIELDS x POINTS need {}",
            expected.map_or_else(|| "more than usize".to_string(), |e| e.to_string())
        )));
    }
    if uncompressed_len > limits.max_decoded_bytes {
        return Err(ParseError::OverLimit {
            what: "decoded bytes of the compressed block",
            declared: uncompressed_len,
            limit: limits.max_decoded_bytes,
        });
    }
    let block = body.get(8..8 + compressed_len).ok_or_else(|| {
        ParseError::Compressed(format!(
            "block declares {compressed_len} bytes, {} present",
            body.len().saturating_sub(8)
        ))
    })?;
    // No LZF block decodes to more than MAX_RATIO times its size (a 3-byte back reference of
    // 264 bytes): a larger claim is refused before decoding.
    if uncompressed_len > compressed_len.saturating_mul(lzf::MAX_RATIO) {
        return Err(ParseError::Compressed(format!(
            "{compressed_len} compressed bytes cannot decode to the declared {uncompressed_len}"
        )));
    }
    let decoded = lzf::decompress(block, uncompressed_len).map_err(ParseError::Compressed)?;
    // Structure of arrays: field k occupies [start_k, start_k + points * bytes_k).
    let mut starts = Vec::with_capacity(header.fields.len());
    let mut s = 0;
    for f in &header.fields {
        starts.push(s);
        s += f.bytes() * header.points;
    }
    let mut points = Vec::with_capacity(header.points);
    for i in 0..header.points {
        let mut p = [0.0; 3];
        for (k, &(field, _)) in xyz.iter().enumerate() {
            let f = &header.fields[field];
            let at = starts[field] + i * f.bytes();
            p[k] = f.ty.read(decoded.get(at..).unwrap_or_default(), false);
        }
        points.push(p);
    }
    Ok(RawCloud {
        points,
        encoding: "binary_compressed",
    })
}
