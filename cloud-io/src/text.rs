//! Delimited text clouds (`.xyz`, `.csv`, `.txt`): one point per line, values separated by
//! whitespace, commas or semicolons. Lines starting with `#` or `//` are comments. If the first data
//! line is not numeric it is a header, and the columns named `x`, `y`, `z` (any case) are used;
//! otherwise the first three columns are x, y, z. Extra columns are ignored.

use super::{ParseError, ParseLimits, RawCloud, parse_f64};

fn split(line: &str) -> impl Iterator<Item = &str> {
    line.split(|c: char| c == ',' || c == ';' || c.is_whitespace())
        .filter(|t| !t.is_empty())
}

pub(super) fn parse(bytes: &[u8], limits: &ParseLimits) -> Result<RawCloud, ParseError> {
    let text = String::from_utf8_lossy(bytes);
    let mut columns: Option<[usize; 3]> = None;
    let mut points = Vec::with_capacity(bytes.len() / 24 + 1);
    for (i, line) in text.lines().enumerate() {
        let line_no = i + 1;
        let trimmed = line.trim();
        if trimmed.is_empty() || trimmed.starts_with('#') || trimmed.starts_with("//") {
            continue;
        }
        let tokens: Vec<&str> = split(trimmed).collect();
        let cols = if let Some(c) = columns {
            c
        } else if tokens.first().and_then(|t| parse_f64(t)).is_some() {
            columns = Some([0, 1, 2]);
            [0, 1, 2]
        } else {
            columns = Some(header_columns(&tokens, line_no)?);
            continue;
        };
        let mut p = [0.0; 3];
        for (k, &c) in cols.iter().enumerate() {
            let token = tokens.get(c).ok_or_else(|| ParseError::Data {
                line: line_no,
                message: format!(
                    "{} columns, need column {} for {}",
                    tokens.len(),
                    c + 1,
                    ["x", "y", "z"][k]
                ),
            })?;
            p[k] = parse_f64(token).ok_or_else(|| ParseError::Data {
                line: line_no,
                message: format!(
                    "`{token}` is not a number (column {} = {})",
                    c + 1,
                    ["x", "y", "z"][k]
                ),
            })?;
        }
        limits.check_points(points.len() + 1)?;
        points.push(p);
    }
    Ok(RawCloud {
        points,
        encoding: "text",
    })
}

fn header_columns(tokens: &[&str], line_no: usize) -> Result<[usize; 3], ParseError> {
    let find = |axis: &str| {
        tokens
            .iter()
            .position(|t| {
                t.trim_matches(|c| c == '"' || c == '/')
                    .eq_ignore_ascii_case(axis)
            })
            .ok_or_else(|| ParseError::Data {
                line: line_no,
                message: format!(
                    "header line has no `{axis}` column (columns: {})",
                    tokens.join(", ")
                ),
            })
    };
    Ok([find("x")?, find("y")?, find("z")?])
}
