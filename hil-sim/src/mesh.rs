//! Triangle meshes for vehicle parts: loaders for Wavefront OBJ, STL (ASCII and binary) and PLY
//! (ascii and `binary_little_endian`), a bounding-volume hierarchy, Möller–Trumbore ray casting and
//! an exact point-to-mesh distance.
//!
//! Mesh files are untrusted input: the loaders never panic, never allocate more than the file's size
//! allows (every declared count is checked against the bytes that remain before anything is
//! reserved), reject non-finite coordinates and out-of-range indices, and every error names the
//! file, the line (text formats) or byte offset (binary formats) and what is wrong.
//!
//! The BVH splits triangles at the median of their centroids along the longest axis of the
//! centroids' bounds, down to [`LEAF_TRIANGLES`] per leaf; each node carries the box of its
//! triangles. The median split keeps the depth at about log2 of the triangle count whatever the
//! input, so traversal uses a small explicit stack.

use std::path::{Path, PathBuf};

use crate::geometry::{Normalized, Vec3};

/// Largest mesh file the loaders read, bytes (a vehicle part is far smaller).
pub const MAX_MESH_FILE_BYTES: u64 = 256 * 1024 * 1024;

/// Most triangles in one BVH leaf.
pub const LEAF_TRIANGLES: usize = 4;

/// Why a mesh file was rejected.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    /// The file could not be read.
    #[error("cannot read mesh file {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The IO error.
        source: std::io::Error,
    },
    /// The content is malformed.
    #[error("mesh file {path}: {location}: {reason}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// Where: `line N`, `byte N`, `header` or `whole file`.
        location: String,
        /// What is wrong.
        reason: String,
    },
}

/// An axis-aligned bounding box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bounds {
    /// Minimum corner.
    pub min: Vec3,
    /// Maximum corner.
    pub max: Vec3,
}

impl Bounds {
    const EMPTY: Self = Self {
        min: Vec3::new(f64::INFINITY, f64::INFINITY, f64::INFINITY),
        max: Vec3::new(f64::NEG_INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY),
    };

    fn grow(&mut self, p: Vec3) {
        self.min = Vec3::new(
            self.min.x.min(p.x),
            self.min.y.min(p.y),
            self.min.z.min(p.z),
        );
        self.max = Vec3::new(
            self.max.x.max(p.x),
            self.max.y.max(p.y),
            self.max.z.max(p.z),
        );
    }

    /// Whether the ray enters the box before `t_max` ([`Bounds::entry`]).
    pub(crate) fn hit(&self, o: Vec3, inv: Vec3, t_max: f64) -> bool {
        self.entry(o, inv, t_max).is_some()
    }

    /// Entry distance of the ray into the box if it enters before `t_max` (slab test, `inv` is the
    /// component-wise inverse direction).
    fn entry(&self, o: Vec3, inv: Vec3, t_max: f64) -> Option<f64> {
        let (mut t0, mut t1) = (0.0f64, t_max);
        for (o, inv, lo, hi) in [
            (o.x, inv.x, self.min.x, self.max.x),
            (o.y, inv.y, self.min.y, self.max.y),
            (o.z, inv.z, self.min.z, self.max.z),
        ] {
            let (a, b) = ((lo - o) * inv, (hi - o) * inv);
            let (a, b) = if a < b { (a, b) } else { (b, a) };
            // NaN (0 * inf when the origin lies on a slab plane) keeps the previous bound.
            t0 = if a > t0 { a } else { t0 };
            t1 = if b < t1 { b } else { t1 };
        }
        (t0 <= t1).then_some(t0)
    }

    /// Euclidean distance from `p` to the box (0 inside).
    fn distance(&self, p: Vec3) -> f64 {
        let dx = (self.min.x - p.x).max(p.x - self.max.x).max(0.0);
        let dy = (self.min.y - p.y).max(p.y - self.max.y).max(0.0);
        let dz = (self.min.z - p.z).max(p.z - self.max.z).max(0.0);
        Vec3::new(dx, dy, dz).norm()
    }
}

#[derive(Clone, Debug, PartialEq)]
struct Node {
    bounds: Bounds,
    /// Leaf: first index into `order`; inner node: index of the left child (the right is next).
    first: u32,
    /// Leaf: number of triangles; inner node: 0.
    count: u32,
}

/// A triangle mesh with its BVH (the default is the empty mesh, which nothing hits).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    vertices: Vec<Vec3>,
    triangles: Vec<[u32; 3]>,
    nodes: Vec<Node>,
    /// Triangle indices in BVH leaf order.
    order: Vec<u32>,
}

impl Mesh {
    /// A mesh from vertices and triangles; the error says which vertex has a non-finite
    /// coordinate, which triangle uses an out-of-range index, or that there are no triangles.
    pub fn new(vertices: Vec<Vec3>, triangles: Vec<[u32; 3]>) -> Result<Self, String> {
        if let Some(i) = vertices
            .iter()
            .position(|v| !(v.x.is_finite() && v.y.is_finite() && v.z.is_finite()))
        {
            return Err(format!("vertex {i} has a non-finite coordinate"));
        }
        if triangles.is_empty() {
            return Err("the mesh has no triangles".to_owned());
        }
        if triangles.len() > u32::MAX as usize / 2 {
            return Err("too many triangles".to_owned());
        }
        if let Some((t, &i)) = triangles.iter().enumerate().find_map(|(t, tri)| {
            tri.iter()
                .find(|&&i| i as usize >= vertices.len())
                .map(|i| (t, i))
        }) {
            return Err(format!(
                "triangle {t} uses vertex {i}, but there are only {} vertices",
                vertices.len()
            ));
        }
        let mut mesh = Self {
            vertices,
            triangles,
            nodes: Vec::new(),
            order: Vec::new(),
        };
        mesh.build_bvh();
        Ok(mesh)
    }

    /// The vertices.
    pub fn vertices(&self) -> &[Vec3] {
        &self.vertices
    }

    /// The triangles (indices into [`Mesh::vertices`]).
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    /// The exact box around the vertices (`None` for a mesh without vertices).
    pub fn vertex_bounds(&self) -> Option<Bounds> {
        let mut b = Bounds::EMPTY;
        for &v in &self.vertices {
            b.grow(v);
        }
        (!self.vertices.is_empty()).then_some(b)
    }

    /// The box around every triangle, padded by about a nanometre (see the BVH).
    pub fn bounds(&self) -> Bounds {
        self.nodes.first().map_or(Bounds::EMPTY, |n| n.bounds)
    }

    /// The mesh with every vertex mapped to `p * scale + offset`.
    #[must_use]
    pub fn transformed(&self, scale: f64, offset: Vec3) -> Self {
        let vertices = self.vertices.iter().map(|&v| v * scale + offset).collect();
        let mut mesh = Self {
            vertices,
            triangles: self.triangles.clone(),
            nodes: Vec::new(),
            order: Vec::new(),
        };
        mesh.build_bvh();
        mesh
    }

    fn corners(&self, t: u32) -> [Vec3; 3] {
        let [a, b, c] = self.triangles[t as usize];
        [
            self.vertices[a as usize],
            self.vertices[b as usize],
            self.vertices[c as usize],
        ]
    }

    fn build_bvh(&mut self) {
        let n = self.triangles.len();
        if n == 0 {
            self.nodes.clear();
            self.order.clear();
            return;
        }
        let centroids: Vec<Vec3> = (0..n as u32)
            .map(|t| {
                let [a, b, c] = self.corners(t);
                (a + b + c) * (1.0 / 3.0)
            })
            .collect();
        self.order = (0..n as u32).collect();
        self.nodes = vec![Node {
            bounds: Bounds::EMPTY,
            first: 0,
            count: 0,
        }];
        // (node index, range in `order`)
        let mut stack = vec![(0usize, 0usize, n)];
        while let Some((node, lo, hi)) = stack.pop() {
            let mut bounds = Bounds::EMPTY;
            let mut cb = Bounds::EMPTY;
            for &t in &self.order[lo..hi] {
                for p in self.corners(t) {
                    bounds.grow(p);
                }
                cb.grow(centroids[t as usize]);
            }
            // Padding keeps the slab test conservative for flat (axis-aligned) leaves, whose
            // zero-thickness boxes rounding could otherwise miss.
            let pad = 1e-9 * (1.0 + (bounds.max - bounds.min).norm());
            bounds.min -= Vec3::new(pad, pad, pad);
            bounds.max += Vec3::new(pad, pad, pad);
            self.nodes[node].bounds = bounds;
            if hi - lo <= LEAF_TRIANGLES {
                self.nodes[node].first = lo as u32;
                self.nodes[node].count = (hi - lo) as u32;
                continue;
            }
            let ext = cb.max - cb.min;
            let key: fn(Vec3) -> f64 = if ext.x >= ext.y && ext.x >= ext.z {
                |v| v.x
            } else if ext.y >= ext.z {
                |v| v.y
            } else {
                |v| v.z
            };
            let mid = lo + (hi - lo) / 2;
            self.order[lo..hi].select_nth_unstable_by(mid - lo, |&a, &b| {
                key(centroids[a as usize]).total_cmp(&key(centroids[b as usize]))
            });
            let left = self.nodes.len();
            self.nodes[node].first = left as u32;
            self.nodes[node].count = 0;
            for _ in 0..2 {
                self.nodes.push(Node {
                    bounds: Bounds::EMPTY,
                    first: 0,
                    count: 0,
                });
            }
            stack.push((left, lo, mid));
            stack.push((left + 1, mid, hi));
        }
    }

    /// The nearest hit of the ray from `o` along the unit vector `d` closer than `t_max`: its
    /// distance and the unit normal of the triangle hit, turned to face the ray's origin.
    pub fn cast(&self, o: Vec3, d: Vec3, t_max: f64) -> Option<(f64, Vec3)> {
        let inv = Vec3::new(1.0 / d.x, 1.0 / d.y, 1.0 / d.z);
        let mut best: Option<(f64, u32)> = None;
        let mut limit = t_max;
        if self.nodes.is_empty() {
            return None;
        }
        let mut stack: Vec<u32> = Vec::with_capacity(64);
        stack.push(0);
        while let Some(i) = stack.pop() {
            let node = &self.nodes[i as usize];
            if node.bounds.entry(o, inv, limit).is_none() {
                continue;
            }
            if node.count == 0 {
                stack.push(node.first);
                stack.push(node.first + 1);
                continue;
            }
            let (lo, hi) = (node.first as usize, (node.first + node.count) as usize);
            for &t in &self.order[lo..hi] {
                if let Some(dist) = moller_trumbore(self.corners(t), o, d)
                    && dist < limit
                {
                    limit = dist;
                    best = Some((dist, t));
                }
            }
        }
        best.map(|(dist, t)| {
            let [a, b, c] = self.corners(t);
            let n = (b - a).cross(&(c - a)).normalized();
            (dist, if n.dot(&d) > 0.0 { -n } else { n })
        })
    }

    /// Euclidean distance from `p` to the nearest point of any triangle.
    pub fn distance(&self, p: Vec3) -> f64 {
        let mut best = f64::INFINITY;
        if self.nodes.is_empty() {
            return f64::INFINITY;
        }
        let mut stack: Vec<u32> = Vec::with_capacity(64);
        stack.push(0);
        while let Some(i) = stack.pop() {
            let node = &self.nodes[i as usize];
            if node.bounds.distance(p) >= best {
                continue;
            }
            if node.count == 0 {
                stack.push(node.first);
                stack.push(node.first + 1);
                continue;
            }
            let (lo, hi) = (node.first as usize, (node.first + node.count) as usize);
            for &t in &self.order[lo..hi] {
                best = best.min(point_triangle_distance(p, self.corners(t)));
            }
        }
        best
    }
}

/// Möller–Trumbore: distance along `d` at which the ray from `o` crosses the triangle (both faces,
/// edges included), if positive.
fn moller_trumbore([a, b, c]: [Vec3; 3], o: Vec3, d: Vec3) -> Option<f64> {
    let (e1, e2) = (b - a, c - a);
    let p = d.cross(&e2);
    let det = e1.dot(&p);
    // Parallel to the plane, or a degenerate triangle.
    if det.abs() <= 1e-14 * e1.norm() * e2.norm() || det == 0.0 {
        return None;
    }
    let inv = 1.0 / det;
    let s = o - a;
    let u = s.dot(&p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(&e1);
    let v = d.dot(&q) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let t = e2.dot(&q) * inv;
    (t > 0.0).then_some(t)
}

/// Distance from `p` to the closest point of the triangle (Ericson, Real-Time Collision Detection
/// 5.1.5, by Voronoi regions).
fn point_triangle_distance(p: Vec3, [a, b, c]: [Vec3; 3]) -> f64 {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(&ap), ac.dot(&ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return ap.norm();
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(&bp), ac.dot(&bp));
    if d3 >= 0.0 && d4 <= d3 {
        return bp.norm();
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (p - (a + ab * v)).norm();
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(&cp), ac.dot(&cp));
    if d6 >= 0.0 && d5 <= d6 {
        return cp.norm();
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (p - (a + ac * w)).norm();
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (p - (b + (c - b) * w)).norm();
    }
    let denom = va + vb + vc;
    if denom.abs() < f64::MIN_POSITIVE || !denom.is_finite() {
        // Degenerate (zero-area) triangle: the nearest of its edges.
        return [(a, b), (b, c), (c, a)]
            .iter()
            .map(|&(s, e)| point_segment_distance(p, s, e))
            .fold(f64::INFINITY, f64::min);
    }
    let (v, w) = (vb / denom, vc / denom);
    (p - (a + ab * v + ac * w)).norm()
}

fn point_segment_distance(p: Vec3, a: Vec3, b: Vec3) -> f64 {
    let ab = b - a;
    let len2 = ab.dot(&ab);
    let t = if len2 > 0.0 {
        ((p - a).dot(&ab) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p - (a + ab * t)).norm()
}

// ---------------------------------------------------------------------------------------------
// Loaders

/// Which file format to read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// Wavefront OBJ.
    Obj,
    /// STL, ASCII or binary.
    Stl,
    /// PLY, ascii or `binary_little_endian`.
    Ply,
}

impl Format {
    /// The format named by the file's extension (case-insensitive), if any.
    pub fn from_path(path: &Path) -> Option<Self> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        match ext.as_str() {
            "obj" => Some(Self::Obj),
            "stl" => Some(Self::Stl),
            "ply" => Some(Self::Ply),
            _ => None,
        }
    }
}

/// Read a mesh file; the format comes from its extension (`.obj`, `.stl`, `.ply`).
pub fn load(path: &Path) -> Result<Mesh, MeshError> {
    let invalid = |location: &str, reason: String| MeshError::Invalid {
        path: path.to_owned(),
        location: location.to_owned(),
        reason,
    };
    let format = Format::from_path(path).ok_or_else(|| {
        invalid(
            "file name",
            "the extension must be .obj, .stl or .ply".to_owned(),
        )
    })?;
    let io = |source| MeshError::Io {
        path: path.to_owned(),
        source,
    };
    let size = std::fs::metadata(path).map_err(io)?.len();
    if size > MAX_MESH_FILE_BYTES {
        return Err(invalid(
            "whole file",
            format!("{size} bytes exceeds the {MAX_MESH_FILE_BYTES}-byte limit"),
        ));
    }
    let bytes = std::fs::read(path).map_err(io)?;
    parse(format, &bytes, path)
}

/// Parse mesh bytes of the given format; `path` is only used in error messages.
pub fn parse(format: Format, bytes: &[u8], path: &Path) -> Result<Mesh, MeshError> {
    let (vertices, triangles) = match format {
        Format::Obj => parse_obj(bytes),
        Format::Stl => parse_stl(bytes),
        Format::Ply => parse_ply(bytes),
    }
    .map_err(|(location, reason)| MeshError::Invalid {
        path: path.to_owned(),
        location,
        reason,
    })?;
    Mesh::new(vertices, triangles).map_err(|reason| MeshError::Invalid {
        path: path.to_owned(),
        location: "whole file".to_owned(),
        reason,
    })
}

type Parsed = Result<(Vec<Vec3>, Vec<[u32; 3]>), (String, String)>;

fn at_line(n: usize, reason: impl Into<String>) -> (String, String) {
    (format!("line {n}"), reason.into())
}

fn at_byte(n: usize, reason: impl Into<String>) -> (String, String) {
    (format!("byte {n}"), reason.into())
}

fn finite_vertex(x: f64, y: f64, z: f64) -> Option<Vec3> {
    (x.is_finite() && y.is_finite() && z.is_finite()).then(|| Vec3::new(x, y, z))
}

/// Fan-triangulate a polygon given as vertex indices.
fn fan(poly: &[u32], out: &mut Vec<[u32; 3]>) {
    for k in 1..poly.len().saturating_sub(1) {
        out.push([poly[0], poly[k], poly[k + 1]]);
    }
}

fn text_lines(bytes: &[u8]) -> impl Iterator<Item = (usize, Result<&str, (String, String)>)> {
    bytes.split(|&b| b == b'\n').enumerate().map(|(i, line)| {
        let n = i + 1;
        (
            n,
            std::str::from_utf8(line)
                .map(|s| s.trim_end_matches('\r'))
                .map_err(|_| at_line(n, "not UTF-8 text")),
        )
    })
}

fn parse_float(token: Option<&str>, n: usize, what: &str) -> Result<f64, (String, String)> {
    let token = token.ok_or_else(|| at_line(n, format!("missing {what}")))?;
    token
        .parse::<f64>()
        .map_err(|_| at_line(n, format!("{what} `{token}` is not a number")))
}

fn parse_xyz<'a>(
    tokens: &mut impl Iterator<Item = &'a str>,
    n: usize,
) -> Result<Vec3, (String, String)> {
    let x = parse_float(tokens.next(), n, "x")?;
    let y = parse_float(tokens.next(), n, "y")?;
    let z = parse_float(tokens.next(), n, "z")?;
    finite_vertex(x, y, z).ok_or_else(|| at_line(n, "non-finite vertex coordinate"))
}

/// Wavefront OBJ: `v x y z [w]` and `f i j k ...` with `i`, `i/t`, `i//n` or `i/t/n` corners,
/// 1-based or negative (relative to the vertices read so far); other statements are ignored.
fn parse_obj(bytes: &[u8]) -> Parsed {
    let mut vertices = Vec::new();
    let mut triangles = Vec::new();
    let mut poly = Vec::new();
    for (n, line) in text_lines(bytes) {
        let line = line?;
        let line = line.split('#').next().unwrap_or("");
        let mut tokens = line.split_whitespace();
        match tokens.next() {
            Some("v") => vertices.push(parse_xyz(&mut tokens, n)?),
            Some("f") => {
                poly.clear();
                for corner in tokens {
                    let index = corner.split('/').next().unwrap_or("");
                    let i: i64 = index.parse().map_err(|_| {
                        at_line(n, format!("face corner `{corner}` has no vertex index"))
                    })?;
                    let count = vertices.len() as i64;
                    let resolved = match i {
                        1.. if i <= count => i - 1,
                        ..=-1 if -i <= count => count + i,
                        _ => {
                            return Err(at_line(
                                n,
                                format!(
                                    "vertex index {i} is out of range ({count} vertices so far)"
                                ),
                            ));
                        }
                    };
                    poly.push(
                        u32::try_from(resolved)
                            .map_err(|_| at_line(n, "vertex index too large"))?,
                    );
                }
                if poly.len() < 3 {
                    return Err(at_line(n, "a face needs at least 3 vertices"));
                }
                fan(&poly, &mut triangles);
            }
            _ => {}
        }
    }
    Ok((vertices, triangles))
}

/// STL: binary when the size matches the 84-byte header plus 50 bytes per declared triangle, else
/// ASCII if it starts with `solid`.
fn parse_stl(bytes: &[u8]) -> Parsed {
    if bytes.len() >= 84 {
        let count = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as usize;
        if count.checked_mul(50).and_then(|b| b.checked_add(84)) == Some(bytes.len()) {
            return parse_stl_binary(&bytes[84..], count);
        }
    }
    let starts_solid = bytes
        .iter()
        .position(|b| !b.is_ascii_whitespace())
        .is_some_and(|i| bytes[i..].starts_with(b"solid"));
    if starts_solid {
        return parse_stl_ascii(bytes);
    }
    if bytes.len() < 84 {
        return Err(at_byte(
            bytes.len(),
            "truncated binary STL (shorter than its 84-byte header)",
        ));
    }
    let count = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]);
    Err(at_byte(
        80,
        format!(
            "binary STL declares {count} triangles ({} bytes) but the file has {} bytes",
            u64::from(count) * 50 + 84,
            bytes.len()
        ),
    ))
}

fn parse_stl_binary(body: &[u8], count: usize) -> Parsed {
    let mut vertices = Vec::with_capacity(3 * count);
    let mut triangles = Vec::with_capacity(count);
    for (t, record) in body.chunks_exact(50).enumerate() {
        let f = |k: usize| {
            let o = 12 + 4 * k;
            f64::from(f32::from_le_bytes([
                record[o],
                record[o + 1],
                record[o + 2],
                record[o + 3],
            ]))
        };
        for v in 0..3 {
            let p = finite_vertex(f(3 * v), f(3 * v + 1), f(3 * v + 2)).ok_or_else(|| {
                at_byte(
                    84 + 50 * t + 12 + 12 * v,
                    format!("triangle {t}: non-finite vertex coordinate"),
                )
            })?;
            vertices.push(p);
        }
        let base = (3 * t) as u32;
        triangles.push([base, base + 1, base + 2]);
    }
    Ok((vertices, triangles))
}

fn parse_stl_ascii(bytes: &[u8]) -> Parsed {
    let mut vertices = Vec::new();
    let mut triangles = Vec::new();
    let mut in_loop: Option<(usize, Vec<u32>)> = None;
    let mut last_line = 0;
    for (n, line) in text_lines(bytes) {
        last_line = n;
        let line = line?;
        let mut tokens = line.split_whitespace();
        match (tokens.next(), &mut in_loop) {
            (Some("outer"), None) => in_loop = Some((n, Vec::new())),
            (Some("outer"), Some(_)) => return Err(at_line(n, "`outer loop` inside a loop")),
            (Some("vertex"), Some((_, poly))) => {
                let index =
                    u32::try_from(vertices.len()).map_err(|_| at_line(n, "too many vertices"))?;
                vertices.push(parse_xyz(&mut tokens, n)?);
                poly.push(index);
            }
            (Some("vertex"), None) => return Err(at_line(n, "`vertex` outside `outer loop`")),
            (Some("endloop"), Some((_, poly))) => {
                if poly.len() < 3 {
                    return Err(at_line(n, "a facet needs at least 3 vertices"));
                }
                fan(poly, &mut triangles);
                in_loop = None;
            }
            (Some("endloop"), None) => return Err(at_line(n, "`endloop` without `outer loop`")),
            _ => {}
        }
    }
    if let Some((start, _)) = in_loop {
        return Err(at_line(
            last_line,
            format!("truncated: the loop opened on line {start} never ends"),
        ));
    }
    Ok((vertices, triangles))
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(name: &str) -> Option<Self> {
        Some(match name {
            "char" | "int8" => Self::I8,
            "uchar" | "uint8" => Self::U8,
            "short" | "int16" => Self::I16,
            "ushort" | "uint16" => Self::U16,
            "int" | "int32" => Self::I32,
            "uint" | "uint32" => Self::U32,
            "float" | "float32" => Self::F32,
            "double" | "float64" => Self::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Self::I8 | Self::U8 => 1,
            Self::I16 | Self::U16 => 2,
            Self::I32 | Self::U32 | Self::F32 => 4,
            Self::F64 => 8,
        }
    }

    fn read_le(self, b: &[u8]) -> f64 {
        match self {
            Self::I8 => f64::from(i8::from_le_bytes([b[0]])),
            Self::U8 => f64::from(b[0]),
            Self::I16 => f64::from(i16::from_le_bytes([b[0], b[1]])),
            Self::U16 => f64::from(u16::from_le_bytes([b[0], b[1]])),
            Self::I32 => f64::from(i32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            Self::U32 => f64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            Self::F32 => f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            Self::F64 => f64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]),
        }
    }
}

#[derive(Clone, Debug)]
struct Property {
    name: String,
    /// `Some(count type)` for a list property.
    list: Option<Scalar>,
    value: Scalar,
}

#[derive(Clone, Debug)]
struct Element {
    name: String,
    count: usize,
    properties: Vec<Property>,
}

// `slice::split` passes each byte by reference.
#[allow(clippy::trivially_copy_pass_by_ref)]
fn is_newline(b: &u8) -> bool {
    *b == b'\n'
}

/// One record's values: scalars as one-element slices, lists as their items.
type Record = Vec<Vec<f64>>;

/// PLY: the header, then every element's records; `vertex` gives x y z, `face` a `vertex_indices`
/// (or `vertex_index`) list; other elements and properties are read and ignored.
fn parse_ply(bytes: &[u8]) -> Parsed {
    let (elements, binary, body_start, body_line) = parse_ply_header(bytes)?;
    let mut reader = if binary {
        PlyReader::Binary {
            bytes,
            pos: body_start,
        }
    } else {
        PlyReader::Ascii {
            lines: bytes[body_start..].split(is_newline as fn(&u8) -> bool),
            line: body_line,
        }
    };
    let mut vertices: Vec<Vec3> = Vec::new();
    let mut triangles = Vec::new();
    let mut have_vertices = false;
    let mut poly = Vec::new();
    for element in &elements {
        // Each record takes at least one byte per property (binary) or two (ascii "0 "), so a
        // count the remaining bytes cannot hold is rejected before anything is reserved.
        let min_bytes = element.properties.len().max(1);
        let remaining = bytes.len().saturating_sub(reader.position_hint(body_start));
        if element.count > remaining / min_bytes {
            return Err((
                "header".to_owned(),
                format!(
                    "element `{}` declares {} records but only {remaining} bytes follow",
                    element.name, element.count
                ),
            ));
        }
        let xyz = ["x", "y", "z"].map(|c| {
            element
                .properties
                .iter()
                .position(|p| p.name == c && p.list.is_none())
        });
        let list = element.properties.iter().position(|p| {
            p.list.is_some() && (p.name == "vertex_indices" || p.name == "vertex_index")
        });
        match element.name.as_str() {
            "vertex" => {
                let [Some(ix), Some(iy), Some(iz)] = xyz else {
                    return Err((
                        "header".to_owned(),
                        "element `vertex` lacks a scalar x, y or z property".to_owned(),
                    ));
                };
                vertices.reserve(element.count);
                for k in 0..element.count {
                    let (location, record) = reader.record(element)?;
                    let v = finite_vertex(record[ix][0], record[iy][0], record[iz][0])
                        .ok_or_else(|| (location, format!("vertex {k}: non-finite coordinate")))?;
                    vertices.push(v);
                }
                have_vertices = true;
            }
            "face" => {
                if !have_vertices {
                    return Err((
                        "header".to_owned(),
                        "element `face` must come after element `vertex`".to_owned(),
                    ));
                }
                let Some(il) = list else {
                    return Err((
                        "header".to_owned(),
                        "element `face` lacks a `vertex_indices` list".to_owned(),
                    ));
                };
                triangles.reserve(element.count);
                for k in 0..element.count {
                    let (location, record) = reader.record(element)?;
                    poly.clear();
                    for &i in &record[il] {
                        if !(i >= 0.0 && i < vertices.len() as f64 && i.fract() == 0.0) {
                            return Err((
                                location,
                                format!(
                                    "face {k}: vertex index {i} is out of range ({} vertices)",
                                    vertices.len()
                                ),
                            ));
                        }
                        poly.push(i as u32);
                    }
                    if poly.len() < 3 {
                        return Err((location, format!("face {k}: needs at least 3 vertices")));
                    }
                    fan(&poly, &mut triangles);
                }
            }
            _ => {
                for _ in 0..element.count {
                    reader.record(element)?;
                }
            }
        }
    }
    Ok((vertices, triangles))
}

/// The PLY header: its elements, whether the body is binary, the body's byte offset and the line
/// number of its first line.
type PlyHeader = (Vec<Element>, bool, usize, usize);

/// Parse the PLY header (see [`PlyHeader`]).
fn parse_ply_header(bytes: &[u8]) -> Result<PlyHeader, (String, String)> {
    let mut elements: Vec<Element> = Vec::new();
    let mut binary = None;
    let mut pos = 0;
    let mut n = 0;
    loop {
        n += 1;
        let Some(len) = bytes[pos..].iter().position(|&b| b == b'\n') else {
            return Err(at_line(n, "truncated header (no `end_header`)"));
        };
        let line = std::str::from_utf8(&bytes[pos..pos + len])
            .map_err(|_| at_line(n, "header is not UTF-8 text"))?
            .trim_end_matches('\r');
        pos += len + 1;
        let tokens: Vec<&str> = line.split_whitespace().collect();
        match tokens.as_slice() {
            ["ply"] if n == 1 => {}
            _ if n == 1 => return Err(at_line(1, "not a PLY file (first line must be `ply`)")),
            ["format", "ascii", _] => binary = Some(false),
            ["format", "binary_little_endian", _] => binary = Some(true),
            ["format", other, ..] => {
                return Err(at_line(n, format!("unsupported format `{other}`")));
            }
            ["comment" | "obj_info", ..] | [] => {}
            ["element", name, count] => {
                let count = count
                    .parse()
                    .map_err(|_| at_line(n, format!("element count `{count}` is not a count")))?;
                elements.push(Element {
                    name: (*name).to_owned(),
                    count,
                    properties: Vec::new(),
                });
            }
            ["property", "list", count, value, name] => {
                let element = elements
                    .last_mut()
                    .ok_or_else(|| at_line(n, "property before any element"))?;
                let (Some(c), Some(v)) = (Scalar::parse(count), Scalar::parse(value)) else {
                    return Err(at_line(n, "unknown property type"));
                };
                if matches!(c, Scalar::F32 | Scalar::F64) {
                    return Err(at_line(n, "a list count must be an integer type"));
                }
                element.properties.push(Property {
                    name: (*name).to_owned(),
                    list: Some(c),
                    value: v,
                });
            }
            ["property", value, name] => {
                let element = elements
                    .last_mut()
                    .ok_or_else(|| at_line(n, "property before any element"))?;
                let v = Scalar::parse(value)
                    .ok_or_else(|| at_line(n, format!("unknown property type `{value}`")))?;
                element.properties.push(Property {
                    name: (*name).to_owned(),
                    list: None,
                    value: v,
                });
            }
            ["end_header"] => break,
            _ => return Err(at_line(n, format!("unrecognised header line `{line}`"))),
        }
    }
    let binary = binary.ok_or_else(|| ("header".to_owned(), "no `format` line".to_owned()))?;
    Ok((elements, binary, pos, n + 1))
}

enum PlyReader<'a> {
    Binary {
        bytes: &'a [u8],
        pos: usize,
    },
    Ascii {
        lines: std::slice::Split<'a, u8, fn(&u8) -> bool>,
        line: usize,
    },
}

impl PlyReader<'_> {
    /// Byte offset reached (binary) or the body start (ascii, where the check is looser).
    fn position_hint(&self, body_start: usize) -> usize {
        match self {
            Self::Binary { pos, .. } => *pos,
            Self::Ascii { .. } => body_start,
        }
    }

    /// Read one record of `element`; returns its location (for errors) and values.
    fn record(&mut self, element: &Element) -> Result<(String, Record), (String, String)> {
        match self {
            Self::Binary { bytes, pos } => {
                let location = format!("byte {pos}");
                let mut record = Vec::with_capacity(element.properties.len());
                let take = |size: usize, pos: &mut usize| -> Result<usize, (String, String)> {
                    if bytes.len() - *pos < size {
                        return Err(at_byte(
                            *pos,
                            format!("truncated: element `{}` needs more bytes", element.name),
                        ));
                    }
                    let at = *pos;
                    *pos += size;
                    Ok(at)
                };
                for p in &element.properties {
                    if let Some(c) = p.list {
                        let at = take(c.size(), pos)?;
                        let count = c.read_le(&bytes[at..]);
                        let size = p.value.size();
                        if !(count >= 0.0 && count * size as f64 <= (bytes.len() - *pos) as f64) {
                            return Err(at_byte(
                                at,
                                format!("list `{}` count {count} overruns the file", p.name),
                            ));
                        }
                        let count = count as usize;
                        let mut items = Vec::with_capacity(count);
                        for _ in 0..count {
                            let at = take(size, pos)?;
                            items.push(p.value.read_le(&bytes[at..]));
                        }
                        record.push(items);
                    } else {
                        let at = take(p.value.size(), pos)?;
                        record.push(vec![p.value.read_le(&bytes[at..])]);
                    }
                }
                Ok((location, record))
            }
            Self::Ascii { lines, line } => {
                let text = loop {
                    let n = *line;
                    *line += 1;
                    let raw = lines.next().ok_or_else(|| {
                        at_line(
                            n,
                            format!("truncated: element `{}` needs more lines", element.name),
                        )
                    })?;
                    let text =
                        std::str::from_utf8(raw).map_err(|_| at_line(n, "not UTF-8 text"))?;
                    if !text.trim().is_empty() {
                        break (n, text);
                    }
                };
                let (n, text) = text;
                let mut tokens = text.split_whitespace();
                let mut record = Vec::with_capacity(element.properties.len());
                for p in &element.properties {
                    if p.list.is_some() {
                        let count = parse_float(tokens.next(), n, &format!("`{}` count", p.name))?;
                        if !(count >= 0.0 && count.fract() == 0.0 && count <= text.len() as f64) {
                            return Err(at_line(
                                n,
                                format!("list `{}` count {count} is impossible", p.name),
                            ));
                        }
                        let mut items = Vec::with_capacity(count as usize);
                        for _ in 0..count as usize {
                            items.push(parse_float(
                                tokens.next(),
                                n,
                                &format!("`{}` item", p.name),
                            )?);
                        }
                        record.push(items);
                    } else {
                        record.push(vec![parse_float(
                            tokens.next(),
                            n,
                            &format!("`{}`", p.name),
                        )?]);
                    }
                }
                Ok((format!("line {n}"), record))
            }
        }
    }
}

/// An axis-aligned box as a closed 12-triangle mesh (for tests and generated parts).
pub fn box_mesh(min: Vec3, max: Vec3) -> Mesh {
    let v = (0..8)
        .map(|k| {
            Vec3::new(
                if k & 1 == 0 { min.x } else { max.x },
                if k & 2 == 0 { min.y } else { max.y },
                if k & 4 == 0 { min.z } else { max.z },
            )
        })
        .collect();
    let quads: [[u32; 4]; 6] = [
        [0, 2, 3, 1],
        [4, 5, 7, 6],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 4, 6, 2],
        [1, 3, 7, 5],
    ];
    let mut t = Vec::new();
    for q in quads {
        fan(&q, &mut t);
    }
    let mut mesh = Mesh {
        vertices: v,
        triangles: t,
        nodes: Vec::new(),
        order: Vec::new(),
    };
    mesh.build_bvh();
    mesh
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn obj(text: &str) -> Result<Mesh, String> {
        parse(Format::Obj, text.as_bytes(), Path::new("t.obj")).map_err(|e| e.to_string())
    }

    fn stl(bytes: &[u8]) -> Result<Mesh, String> {
        parse(Format::Stl, bytes, Path::new("t.stl")).map_err(|e| e.to_string())
    }

    fn ply(bytes: &[u8]) -> Result<Mesh, String> {
        parse(Format::Ply, bytes, Path::new("t.ply")).map_err(|e| e.to_string())
    }

    const CUBE_OBJ: &str = "# unit cube\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n\
        f 1 4 3 2\nf 5/1 6/2 7/3 8/4\nf 1//1 2//1 6//1 5//1\nf -5 -1 -2 -6\nf 1/1/1 5/1/1 8/1/1 4/1/1\nf 2 3 7 6\n";

    #[test]
    fn obj_cube_fan_triangulates_all_index_forms() {
        let m = obj(CUBE_OBJ).expect("valid");
        assert_eq!(m.vertices().len(), 8);
        assert_eq!(m.triangles().len(), 12);
        // `f -5 -1 -2 -6` after 8 vertices is 4 8 7 3.
        assert_eq!(m.triangles()[6], [3, 7, 6]);
        let hit = m
            .cast(Vec3::new(0.5, 0.5, -1.0), Vec3::new(0.0, 0.0, 1.0), 10.0)
            .expect("hits the bottom");
        assert!((hit.0 - 1.0).abs() < 1e-12);
        assert_eq!(hit.1, Vec3::new(0.0, 0.0, -1.0));
    }

    #[test]
    fn obj_hostile_inputs_are_errors_naming_the_line() {
        for (text, needle) in [
            ("v 0 0 0\nv 1 0 0\nf 1 2 3\n", "line 3"),
            ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "out of range"),
            ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -4 1 2\n", "out of range"),
            ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n", "at least 3"),
            ("v 0 NaN 0\n", "line 1: non-finite"),
            ("v 0 inf 0\n", "non-finite"),
            ("v 0 0\n", "missing z"),
            ("v 0 0 zz\n", "not a number"),
            ("v 0 0 0\nf a b c\n", "no vertex index"),
            (
                "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99999999999999999999\n",
                "line 4",
            ),
            ("", "no triangles"),
        ] {
            let e = obj(text).expect_err(text);
            assert!(e.contains("t.obj") && e.contains(needle), "{text:?}: {e}");
        }
        let invalid_utf8 = parse(Format::Obj, b"v 0 0 0\n\xff\xfe\n", Path::new("t.obj"));
        assert!(invalid_utf8.is_err_and(|e| e.to_string().contains("line 2")));
    }

    fn binary_stl(tris: &[[[f32; 3]; 3]], declared: u32) -> Vec<u8> {
        let mut b = vec![b' '; 80];
        b.extend_from_slice(&declared.to_le_bytes());
        for t in tris {
            b.extend_from_slice(&[0; 12]);
            for v in t {
                for c in v {
                    b.extend_from_slice(&c.to_le_bytes());
                }
            }
            b.extend_from_slice(&[0; 2]);
        }
        b
    }

    #[test]
    fn stl_ascii_and_binary_read_the_same_triangle() {
        let ascii = "solid t\n facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n   vertex 1 0 0\n   vertex 0 1 0\n  endloop\n endfacet\nendsolid t\n";
        let a = stl(ascii.as_bytes()).expect("ascii");
        let b = stl(&binary_stl(
            &[[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]],
            1,
        ))
        .expect("binary");
        assert_eq!(a.vertices(), b.vertices());
        assert_eq!(a.triangles(), b.triangles());
        // A binary file whose header happens to begin with "solid" is still binary.
        let mut tricky = binary_stl(&[[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]], 1);
        tricky[..5].copy_from_slice(b"solid");
        assert_eq!(stl(&tricky).expect("binary").triangles().len(), 1);
    }

    #[test]
    fn stl_hostile_inputs_are_errors() {
        let tri = [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let huge = binary_stl(&[tri], u32::MAX);
        let e = stl(&huge).expect_err("huge count");
        assert!(e.contains("byte 80") && e.contains("4294967295"), "{e}");
        let mut nan = binary_stl(&[tri], 1);
        nan[84 + 12 + 4..84 + 12 + 8].copy_from_slice(&f32::NAN.to_le_bytes());
        let e = stl(&nan).expect_err("NaN");
        assert!(e.contains("byte 96") && e.contains("non-finite"), "{e}");
        let e = stl(&binary_stl(&[tri], 2)).expect_err("truncated");
        assert!(e.contains("declares 2"), "{e}");
        assert!(stl(b"").is_err());
        assert!(stl(&[0; 83]).expect_err("short").contains("header"));
        let e = stl(b"solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n")
            .expect_err("truncated ascii");
        assert!(e.contains("never ends"), "{e}");
        let e = stl(b"solid t\nouter loop\nvertex 0 0 0\nvertex 1 0 nan\nvertex 0 1 0\nendloop\n")
            .expect_err("nan ascii");
        assert!(e.contains("line 4"), "{e}");
        let e =
            stl(b"solid t\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nendloop\n").expect_err("two");
        assert!(e.contains("line 5") && e.contains("at least 3"), "{e}");
    }

    const PLY_HEADER: &str = "ply\nformat ascii 1.0\ncomment test\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";

    #[test]
    fn ply_ascii_and_binary_read_the_same_quad() {
        let ascii = format!("{PLY_HEADER}0 0 0 1\n1 0 0 2\n1 1 0 3\n0 1 0 4\n4 0 1 2 3\n");
        let a = ply(ascii.as_bytes()).expect("ascii");
        assert_eq!(a.triangles(), &[[0, 1, 2], [0, 2, 3]]);
        let mut bin = PLY_HEADER
            .replace("ascii", "binary_little_endian")
            .into_bytes();
        for (x, y) in [(0.0f32, 0.0f32), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)] {
            for c in [x, y, 0.0] {
                bin.extend_from_slice(&c.to_le_bytes());
            }
            bin.push(7);
        }
        bin.push(4);
        for i in 0i32..4 {
            bin.extend_from_slice(&i.to_le_bytes());
        }
        let b = ply(&bin).expect("binary");
        assert_eq!(a.vertices(), b.vertices());
        assert_eq!(a.triangles(), b.triangles());
        // Truncating the binary body anywhere is an error, never a panic.
        for cut in PLY_HEADER.len()..bin.len() {
            let e = ply(&bin[..cut]).expect_err("truncated");
            assert!(e.contains("t.ply"), "{e}");
        }
    }

    #[test]
    fn ply_hostile_inputs_are_errors() {
        let body = "0 0 0 1\n1 0 0 2\n1 1 0 3\n0 1 0 4\n";
        for (text, needle) in [
            (
                format!("{PLY_HEADER}{body}4 0 1 2 9\n"),
                "line 16: face 0: vertex index 9",
            ),
            (format!("{PLY_HEADER}{body}4 0 1 -2 3\n"), "out of range"),
            (format!("{PLY_HEADER}{body}"), "truncated"),
            (
                format!("{PLY_HEADER}0 0 nan 1\n1 0 0 2\n1 1 0 3\n0 1 0 4\n3 0 1 2\n"),
                "line 12: vertex 0: non-finite",
            ),
            (
                PLY_HEADER.replace("vertex 4", "vertex 18446744073709551615") + body,
                "declares 18446744073709551615",
            ),
            (
                PLY_HEADER.replace("vertex 4", "vertex 99999999999999999999999"),
                "line 4",
            ),
            (
                PLY_HEADER.replace("ascii", "binary_big_endian"),
                "unsupported",
            ),
            (PLY_HEADER.replace("end_header\n", ""), "no `end_header`"),
            ("plx\n".to_owned(), "not a PLY"),
            (
                PLY_HEADER.replace("vertex_indices", "corners") + body + "3 0 1 2\n",
                "lacks a `vertex_indices`",
            ),
            (format!("{PLY_HEADER}{body}200 0 1 2\n"), "impossible"),
            (format!("{PLY_HEADER}{body}5 0 1 2\n"), "item"),
        ] {
            let e = ply(text.as_bytes()).expect_err(&text);
            assert!(e.contains(needle), "{text:?}: {e}");
        }
        // A binary list count larger than the rest of the file.
        let mut bin = PLY_HEADER
            .replace("ascii", "binary_little_endian")
            .replace("list uchar int", "list uint int")
            .into_bytes();
        bin.extend_from_slice(&[0; 4 * 13]);
        bin.extend_from_slice(&u32::MAX.to_le_bytes());
        let e = ply(&bin).expect_err("huge list");
        assert!(e.contains("overruns"), "{e}");
    }

    #[test]
    fn random_bytes_never_panic() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let seeds: [&[u8]; 3] = [
            CUBE_OBJ.as_bytes(),
            PLY_HEADER.as_bytes(),
            b"solid x\nouter loop\nvertex 0 0 0\n",
        ];
        for _ in 0..3000 {
            let mut b = seeds[rng.random_range(0..3)].to_vec();
            for _ in 0..rng.random_range(1..8) {
                let i = rng.random_range(0..b.len());
                b[i] = rng.random();
            }
            for f in [Format::Obj, Format::Stl, Format::Ply] {
                let _ = parse(f, &b, Path::new("r"));
            }
        }
    }

    fn random_ray(rng: &mut impl Rng) -> (Vec3, Vec3) {
        let o = Vec3::new(
            rng.random_range(-2.0..2.0),
            rng.random_range(-2.0..2.0),
            rng.random_range(-2.0..2.0),
        );
        let d = Vec3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        )
        .normalized();
        (o, d)
    }

    #[test]
    fn bvh_cast_equals_brute_force_and_hits_lie_on_the_mesh() {
        // A bumpy surface of many triangles, so the BVH has several levels.
        let n = 24;
        let mut v = Vec::new();
        for i in 0..=n {
            for j in 0..=n {
                let (x, y) = (f64::from(i) / 6.0 - 2.0, f64::from(j) / 6.0 - 2.0);
                v.push(Vec3::new(x, y, 0.2 * (3.0 * x).sin() * (2.0 * y).cos()));
            }
        }
        let mut t = Vec::new();
        let id = |i: u32, j: u32| i * (n + 1) + j;
        for i in 0..n {
            for j in 0..n {
                fan(
                    &[id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)],
                    &mut t,
                );
            }
        }
        let m = Mesh::new(v, t).expect("valid");
        assert!(m.nodes.len() > 100);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let mut hits = 0;
        for _ in 0..5000 {
            let (o, d) = random_ray(&mut rng);
            let brute = (0..m.triangles.len() as u32)
                .filter_map(|t| moller_trumbore(m.corners(t), o, d))
                .fold(f64::INFINITY, f64::min);
            match m.cast(o, d, 100.0) {
                Some((dist, normal)) => {
                    hits += 1;
                    assert_eq!(dist.to_bits(), brute.to_bits());
                    assert!(m.distance(o + d * dist) < 1e-12);
                    assert!(normal.dot(&d) <= 0.0);
                    assert!((normal.norm() - 1.0).abs() < 1e-12);
                }
                None => assert!(brute.is_infinite()),
            }
        }
        assert!(hits > 1000, "{hits}");
    }

    #[test]
    fn distance_matches_the_analytic_box() {
        let (min, max) = (Vec3::new(-0.3, -0.2, 0.1), Vec3::new(0.4, 0.5, 0.3));
        let m = box_mesh(min, max);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        for _ in 0..5000 {
            let (p, _) = random_ray(&mut rng);
            let c = (min + max) * 0.5;
            let h = (max - min) * 0.5;
            let q = p - c;
            let e = Vec3::new(q.x.abs() - h.x, q.y.abs() - h.y, q.z.abs() - h.z);
            let expected = if e.x <= 0.0 && e.y <= 0.0 && e.z <= 0.0 {
                -(e.x.max(e.y).max(e.z))
            } else {
                Vec3::new(e.x.max(0.0), e.y.max(0.0), e.z.max(0.0)).norm()
            };
            assert!((m.distance(p) - expected).abs() < 1e-12, "{p:?}");
        }
    }
}
