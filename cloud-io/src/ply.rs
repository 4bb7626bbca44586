//! PLY reader (ascii, binary little and big endian). Only the `vertex` element's x, y, z are kept;
//! every other property and element is skipped according to its declared types.

use super::{ParseError, ParseLimits, RawCloud, Scalar, parse_f64, split_header};

#[derive(Debug)]
enum Property {
    Scalar { name: String, ty: Scalar },
    List { count_ty: Scalar, item_ty: Scalar },
}

#[derive(Debug)]
struct Element {
    name: String,
    count: usize,
    header_line: usize,
    properties: Vec<Property>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Encoding {
    Ascii,
    Binary { big_endian: bool },
}

fn scalar_type(name: &str) -> Option<Scalar> {
    Some(match name {
        "char" | "int8" => Scalar::I8,
        "uchar" | "uint8" => Scalar::U8,
        "short" | "int16" => Scalar::I16,
        "ushort" | "uint16" => Scalar::U16,
        "int" | "int32" => Scalar::I32,
        "uint" | "uint32" => Scalar::U32,
        "float" | "float32" => Scalar::F32,
        "double" | "float64" => Scalar::F64,
        _ => return None,
    })
}

fn header_err(line: usize, message: impl Into<String>) -> ParseError {
    ParseError::Header {
        line,
        message: message.into(),
    }
}

struct Header {
    encoding: Encoding,
    elements: Vec<Element>,
}

fn parse_header(lines: &[&str]) -> Result<Header, ParseError> {
    if lines.first().map(|l| l.trim()) != Some("ply") {
        return Err(header_err(1, "first line must be `ply`"));
    }
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    for (i, line) in lines.iter().enumerate().skip(1) {
        let n = i + 1;
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            [] | ["comment" | "obj_info", ..] | ["end_header"] => {}
            ["format", fmt, _version] => {
                encoding = Some(match *fmt {
                    "ascii" => Encoding::Ascii,
                    "binary_little_endian" => Encoding::Binary { big_endian: false },
                    "binary_big_endian" => Encoding::Binary { big_endian: true },
                    other => return Err(header_err(n, format!("unknown format `{other}`"))),
                });
            }
            ["element", name, count] => {
                let count = count
                    .parse()
                    .map_err(|_| header_err(n, format!("element `{name}`: bad count `{count}`")))?;
                elements.push(Element {
                    name: (*name).to_string(),
                    count,
                    header_line: n,
                    properties: Vec::new(),
                });
            }
            ["property", "list", count_ty, item_ty, _name] => {
                let element = elements
                    .last_mut()
                    .ok_or_else(|| header_err(n, "property before any element"))?;
                let count_ty = scalar_type(count_ty).ok_or_else(|| {
                    header_err(n, format!("unknown list count type `{count_ty}`"))
                })?;
                let item_ty = scalar_type(item_ty)
                    .ok_or_else(|| header_err(n, format!("unknown list item type `{item_ty}`")))?;
                element
                    .properties
                    .push(Property::List { count_ty, item_ty });
            }
            ["property", ty, name] => {
                let element = elements
                    .last_mut()
                    .ok_or_else(|| header_err(n, "property before any element"))?;
                let ty = scalar_type(ty)
                    .ok_or_else(|| header_err(n, format!("unknown property type `{ty}`")))?;
                element.properties.push(Property::Scalar {
                    name: (*name).to_string(),
                    ty,
                });
            }
            _ => return Err(header_err(n, format!("unrecognised header line `{line}`"))),
        }
    }
    let encoding = encoding.ok_or_else(|| header_err(2, "missing `format` line"))?;
    Ok(Header { encoding, elements })
}

/// Indices of x, y, z among the vertex element's properties.
fn xyz_indices(vertex: &Element) -> Result<[usize; 3], ParseError> {
    let find = |axis: &str| {
        vertex
            .properties
            .iter()
            .position(|p| matches!(p, Property::Scalar { name, .. } if name == axis))
            .ok_or_else(|| {
                header_err(
                    vertex.header_line,
                    format!("element `vertex` has no scalar property `{axis}`"),
                )
            })
    };
    Ok([find("x")?, find("y")?, find("z")?])
}

pub(super) fn parse(bytes: &[u8], limits: &ParseLimits) -> Result<RawCloud, ParseError> {
    let (lines, body_start) = split_header(bytes, |l| l.trim() == "end_header")?;
    let header = parse_header(&lines)?;
    let vertex_index = header
        .elements
        .iter()
        .position(|e| e.name == "vertex")
        .ok_or_else(|| header_err(lines.len(), "no `element vertex` in the header"))?;
    let xyz = xyz_indices(&header.elements[vertex_index])?;
    limits.check_points(header.elements[vertex_index].count)?;
    let body = bytes.get(body_start..).unwrap_or_default();
    match header.encoding {
        Encoding::Ascii => parse_ascii(body, lines.len(), &header.elements, vertex_index, xyz),
        Encoding::Binary { big_endian } => {
            parse_binary(body, big_endian, &header.elements, vertex_index, xyz)
        }
    }
}

fn parse_ascii(
    body: &[u8],
    header_lines: usize,
    elements: &[Element],
    vertex_index: usize,
    xyz: [usize; 3],
) -> Result<RawCloud, ParseError> {
    let text = String::from_utf8_lossy(body);
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + header_lines + 1, l))
        .filter(|(_, l)| !l.trim().is_empty());
    let mut points = Vec::new();
    for (ei, element) in elements.iter().enumerate() {
        if ei == vertex_index {
            points.reserve(element.count.min(body.len() / 6 + 1));
        }
        for item in 0..element.count {
            let Some((line_no, line)) = lines.next() else {
                return Err(ParseError::Truncated {
                    what: if ei == vertex_index {
                        "vertices"
                    } else {
                        "other element items"
                    },
                    declared: element.count,
                    complete: item,
                });
            };
            let values = ascii_item(line, line_no, element)?;
            if ei == vertex_index {
                points.push([values[xyz[0]], values[xyz[1]], values[xyz[2]]]);
            }
        }
        if ei == vertex_index {
            break;
        }
    }
    Ok(RawCloud {
        points,
        encoding: "ascii",
    })
}

/// Parse one ascii item; returns one value per property (lists give NaN placeholders).
fn ascii_item(line: &str, line_no: usize, element: &Element) -> Result<Vec<f64>, ParseError> {
    let mut tokens = line.split_whitespace();
    let mut values = Vec::with_capacity(element.properties.len());
    let data_err = |message: String| ParseError::Data {
        line: line_no,
        message,
    };
    for property in &element.properties {
        match property {
            Property::Scalar { name, .. } => {
                let token = tokens.next().ok_or_else(|| {
                    data_err(format!(
                        "element `{}`: missing value for `{name}`",
                        element.name
                    ))
                })?;
                let v = parse_f64(token).ok_or_else(|| {
                    data_err(format!(
                        "element `{}`: `{token}` is not a number for `{name}`",
                        element.name
                    ))
                })?;
                values.push(v);
            }
            Property::List { .. } => {
                let token = tokens
                    .next()
                    .ok_or_else(|| data_err("missing list count".into()))?;
                let n: usize = token
                    .parse()
                    .map_err(|_| data_err(format!("bad list count `{token}`")))?;
                for _ in 0..n {
                    tokens.next().ok_or_else(|| {
                        data_err(format!("list declares {n} items, fewer present"))
                    })?;
                }
                values.push(f64::NAN);
            }
        }
    }
    Ok(values)
}

fn parse_binary(
    body: &[u8],
    big_endian: bool,
    elements: &[Element],
    vertex_index: usize,
    xyz: [usize; 3],
) -> Result<RawCloud, ParseError> {
    let mut at = 0usize;
    let mut points = Vec::new();
    for (ei, element) in elements.iter().enumerate() {
        let is_vertex = ei == vertex_index;
        let what = if is_vertex {
            "vertices"
        } else {
            "other element items"
        };
        // The smallest record: every scalar, and every list's count with no items. The whole
        // element must fit at that size before anything is allocated for it, so the count a
        // header declares is bounded by the bytes present, list properties included.
        let smallest: usize = element
            .properties
            .iter()
            .map(|p| match p {
                Property::Scalar { ty, .. } => ty.size(),
                Property::List { count_ty, .. } => count_ty.size(),
            })
            .sum();
        if smallest == 0 {
            // No properties: the items hold no bytes (and the vertex element has x, y, z).
            continue;
        }
        let available = body.len().saturating_sub(at);
        if smallest
            .checked_mul(element.count)
            .is_none_or(|needed| needed > available)
        {
            return Err(ParseError::Truncated {
                what,
                declared: element.count,
                complete: available / smallest,
            });
        }
        if is_vertex {
            points.reserve(element.count);
        }
        for item in 0..element.count {
            let truncated = || ParseError::Truncated {
                what,
                declared: element.count,
                complete: item,
            };
            let mut xyz_values = [f64::NAN; 3];
            for (pi, property) in element.properties.iter().enumerate() {
                match property {
                    Property::Scalar { ty, .. } => {
                        let bytes = body.get(at..at + ty.size()).ok_or_else(truncated)?;
                        if let Some(k) = xyz.iter().position(|&i| is_vertex && i == pi) {
                            xyz_values[k] = ty.read(bytes, big_endian);
                        }
                        at += ty.size();
                    }
                    Property::List { count_ty, item_ty } => {
                        let bytes = body.get(at..at + count_ty.size()).ok_or_else(truncated)?;
                        let n = count_ty.read(bytes, big_endian);
                        if !(0.0..=1e9).contains(&n) {
                            return Err(ParseError::Data {
                                line: 0,
                                message: format!(
                                    "element `{}` item {item}: bad list count {n}",
                                    element.name
                                ),
                            });
                        }
                        at += count_ty.size() + n as usize * item_ty.size();
                        if at > body.len() {
                            return Err(truncated());
                        }
                    }
                }
            }
            if is_vertex {
                points.push(xyz_values);
            }
        }
        if is_vertex {
            break;
        }
    }
    Ok(RawCloud {
        points,
        encoding: if big_endian {
            "binary_big_endian"
        } else {
            "binary_little_endian"
        },
    })
}
