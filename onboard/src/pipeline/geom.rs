//! Small fixed-size geometry and linear algebra for the pipeline: 3-vectors, rotation matrices,
//! rigid poses with a 6-vector increment, symmetric eigen-decomposition, Cholesky solves, and a
//! voxel hash index for nearest-neighbour queries. Written by hand (no nalgebra) because every
//! system here is at most 6x6 and the per-frame budget is a few milliseconds.
//!
//! Increments are `[rx, ry, rz, tx, ty, tz]`: a rotation vector (radians, axis times angle) and a
//! translation (metres). [`Pose::from_increment`] maps one to `(exp(r), t)`; robot-frame names
//! follow DESIGN.md section 8 (x forward, y left, z up), so `rx` is roll, `ry` pitch, `rz` yaw.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

/// A 3-vector in metres (or a direction), `[x, y, z]`.
pub type V3 = [f64; 3];
/// A 3x3 matrix, row-major.
pub type M3 = [[f64; 3]; 3];
/// A 6-vector `[rx, ry, rz, tx, ty, tz]` (rotation vector in radians, translation in metres).
pub type Twist6 = [f64; 6];

/// `a + b`.
pub fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
/// `a - b`.
pub fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
/// `s * a`.
pub fn scale(a: V3, s: f64) -> V3 {
    [a[0] * s, a[1] * s, a[2] * s]
}
/// Dot product.
pub fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
/// Cross product.
pub fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
/// Euclidean norm.
pub fn norm(a: V3) -> f64 {
    dot(a, a).sqrt()
}
/// Squared distance.
pub fn dist2(a: V3, b: V3) -> f64 {
    let d = sub(a, b);
    dot(d, d)
}

/// The identity matrix.
pub const IDENTITY: M3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// `m v`.
pub fn mat_vec(m: &M3, v: V3) -> V3 {
    [dot(m[0], v), dot(m[1], v), dot(m[2], v)]
}
/// `a b`.
pub fn mat_mul(a: &M3, b: &M3) -> M3 {
    let mut out = [[0.0; 3]; 3];
    for (i, row) in out.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    out
}
/// `m^T`.
pub fn transpose(m: &M3) -> M3 {
    [
        [m[0][0], m[1][0], m[2][0]],
        [m[0][1], m[1][1], m[2][1]],
        [m[0][2], m[1][2], m[2][2]],
    ]
}

/// Rotation matrix of a rotation vector (Rodrigues).
pub fn exp_so3(r: V3) -> M3 {
    let theta = norm(r);
    let k = [[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]];
    let (a, b) = if theta < 1e-9 {
        (1.0, 0.5)
    } else {
        (theta.sin() / theta, (1.0 - theta.cos()) / (theta * theta))
    };
    let k2 = mat_mul(&k, &k);
    let mut out = IDENTITY;
    for i in 0..3 {
        for j in 0..3 {
            out[i][j] += a * k[i][j] + b * k2[i][j];
        }
    }
    out
}

/// Rotation vector of a rotation matrix (inverse of [`exp_so3`] for angles below pi).
pub fn log_so3(m: &M3) -> V3 {
    let c = ((m[0][0] + m[1][1] + m[2][2] - 1.0) / 2.0).clamp(-1.0, 1.0);
    let theta = c.acos();
    let w = [m[2][1] - m[1][2], m[0][2] - m[2][0], m[1][0] - m[0][1]];
    let s = if theta < 1e-9 {
        0.5
    } else {
        theta / (2.0 * theta.sin())
    };
    scale(w, s)
}

/// Rotation from roll, pitch, yaw (radians): `Rz(yaw) Ry(pitch) Rx(roll)`.
pub fn rot_from_rpy(roll_rad: f64, pitch_rad: f64, yaw_rad: f64) -> M3 {
    let rx = exp_so3([roll_rad, 0.0, 0.0]);
    let ry = exp_so3([0.0, pitch_rad, 0.0]);
    let rz = exp_so3([0.0, 0.0, yaw_rad]);
    mat_mul(&rz, &mat_mul(&ry, &rx))
}

/// Roll, pitch, yaw (radians) of a rotation built by [`rot_from_rpy`].
pub fn rpy_of(m: &M3) -> V3 {
    let pitch = (-m[2][0]).clamp(-1.0, 1.0).asin();
    [m[2][1].atan2(m[2][2]), pitch, m[1][0].atan2(m[0][0])]
}

/// A rigid transform `b_from_a`: `p_b = rotation p_a + translation`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Rotation matrix.
    pub rotation: M3,
    /// Translation, metres.
    pub translation: V3,
}

impl Default for Pose {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Pose {
    /// The identity transform.
    pub const IDENTITY: Self = Self {
        rotation: IDENTITY,
        translation: [0.0; 3],
    };

    /// From a translation and roll, pitch, yaw.
    pub fn from_xyz_rpy(xyz_m: V3, rpy_rad: V3) -> Self {
        Self {
            rotation: rot_from_rpy(rpy_rad[0], rpy_rad[1], rpy_rad[2]),
            translation: xyz_m,
        }
    }

    /// `(exp(r), t)` of an increment `[rx, ry, rz, tx, ty, tz]`.
    pub fn from_increment(d: Twist6) -> Self {
        Self {
            rotation: exp_so3([d[0], d[1], d[2]]),
            translation: [d[3], d[4], d[5]],
        }
    }

    /// Inverse of [`Pose::from_increment`].
    pub fn to_increment(&self) -> Twist6 {
        let r = log_so3(&self.rotation);
        let t = self.translation;
        [r[0], r[1], r[2], t[0], t[1], t[2]]
    }

    /// Transform a point.
    pub fn apply(&self, p: V3) -> V3 {
        add(mat_vec(&self.rotation, p), self.translation)
    }

    /// Rotate a direction.
    pub fn apply_vector(&self, v: V3) -> V3 {
        mat_vec(&self.rotation, v)
    }

    /// `self * other` (`c_from_a = c_from_b * b_from_a`).
    #[must_use]
    pub fn compose(&self, other: &Self) -> Self {
        Self {
            rotation: mat_mul(&self.rotation, &other.rotation),
            translation: self.apply(other.translation),
        }
    }

    /// The inverse transform.
    #[must_use]
    pub fn inverse(&self) -> Self {
        let rt = transpose(&self.rotation);
        Self {
            rotation: rt,
            translation: scale(mat_vec(&rt, self.translation), -1.0),
        }
    }

    /// Roll, pitch, yaw of the rotation, radians.
    pub fn rpy(&self) -> V3 {
        rpy_of(&self.rotation)
    }

    /// Interpolate between `self` (s = 0) and `other` (s = 1): translation linearly, rotation
    /// along the geodesic.
    #[must_use]
    pub fn interpolate(&self, other: &Self, s: f64) -> Self {
        let delta = mat_mul(&transpose(&self.rotation), &other.rotation);
        let r = scale(log_so3(&delta), s);
        Self {
            rotation: mat_mul(&self.rotation, &exp_so3(r)),
            translation: add(
                self.translation,
                scale(sub(other.translation, self.translation), s),
            ),
        }
    }
}

/// Solve the symmetric positive definite system `a x = b` (n <= 6) by Cholesky. `None` when `a`
/// is not positive definite.
pub fn solve_spd<const N: usize>(a: &[[f64; N]; N], b: &[f64; N]) -> Option<[f64; N]> {
    let mut l = [[0.0; N]; N];
    for i in 0..N {
        for j in 0..=i {
            let s: f64 = a[i][j] - (0..j).map(|k| l[i][k] * l[j][k]).sum::<f64>();
            if i == j {
                if !(s > 1e-15) {
                    return None;
                }
                l[i][i] = s.sqrt();
            } else {
                l[i][j] = s / l[j][j];
            }
        }
    }
    let mut y = [0.0; N];
    for i in 0..N {
        y[i] = (b[i] - (0..i).map(|k| l[i][k] * y[k]).sum::<f64>()) / l[i][i];
    }
    let mut x = [0.0; N];
    for i in (0..N).rev() {
        x[i] = (y[i] - (i + 1..N).map(|k| l[k][i] * x[k]).sum::<f64>()) / l[i][i];
    }
    Some(x)
}

/// Eigenvalues (ascending) and eigenvectors (as columns: `vectors[k][i]` is component k of vector
/// i) of a symmetric matrix, by cyclic Jacobi rotations.
pub fn symmetric_eigen<const N: usize>(m: &[[f64; N]; N]) -> ([f64; N], [[f64; N]; N]) {
    let mut a = *m;
    let mut v = [[0.0; N]; N];
    for (i, row) in v.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    for _sweep in 0..50 {
        let off: f64 = (0..N)
            .flat_map(|i| (0..N).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| a[i][j] * a[i][j])
            .sum();
        if off < 1e-24 {
            break;
        }
        for p in 0..N {
            for q in p + 1..N {
                if a[p][q].abs() < 1e-300 {
                    continue;
                }
                let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..N {
                    let akp = a[k][p];
                    let akq = a[k][q];
                    a[k][p] = c * akp - s * akq;
                    a[k][q] = s * akp + c * akq;
                }
                for k in 0..N {
                    let apk = a[p][k];
                    let aqk = a[q][k];
                    a[p][k] = c * apk - s * aqk;
                    a[q][k] = s * apk + c * aqk;
                }
                for row in &mut v {
                    let vkp = row[p];
                    let vkq = row[q];
                    row[p] = c * vkp - s * vkq;
                    row[q] = s * vkp + c * vkq;
                }
            }
        }
    }
    let mut order: [usize; N] = [0; N];
    for (i, o) in order.iter_mut().enumerate() {
        *o = i;
    }
    order.sort_by(|&i, &j| a[i][i].total_cmp(&a[j][j]));
    let mut values = [0.0; N];
    let mut vectors = [[0.0; N]; N];
    for (new, &old) in order.iter().enumerate() {
        values[new] = a[old][old];
        for k in 0..N {
            vectors[k][new] = v[k][old];
        }
    }
    (values, vectors)
}

/// Centroid and covariance of points; `None` for an empty set.
pub fn centroid_covariance(points: impl Iterator<Item = V3> + Clone) -> Option<(V3, M3)> {
    let mut n = 0.0;
    let mut c = [0.0; 3];
    for p in points.clone() {
        c = add(c, p);
        n += 1.0;
    }
    if n == 0.0 {
        return None;
    }
    c = scale(c, 1.0 / n);
    let mut cov = [[0.0; 3]; 3];
    for p in points {
        let d = sub(p, c);
        for i in 0..3 {
            for j in 0..3 {
                cov[i][j] += d[i] * d[j] / n;
            }
        }
    }
    Some((c, cov))
}

/// A fast, non-cryptographic hasher for voxel keys (FxHash's multiply-rotate).
#[derive(Default, Clone, Copy)]
pub struct FxHasher(u64);

impl Hasher for FxHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(u64::from(b));
        }
    }
    fn write_i32(&mut self, i: i32) {
        self.write_u64(u64::from(i.cast_unsigned()));
    }
    fn write_u64(&mut self, i: u64) {
        self.0 = (self.0.rotate_left(5) ^ i).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }
}

/// A hash map keyed by voxel, with [`FxHasher`].
pub type VoxelMap<T> = HashMap<[i32; 3], T, BuildHasherDefault<FxHasher>>;

/// The voxel holding `p` for voxels of `size_m`.
pub fn voxel_of(p: V3, size_m: f64) -> [i32; 3] {
    [
        (p[0] / size_m).floor() as i32,
        (p[1] / size_m).floor() as i32,
        (p[2] / size_m).floor() as i32,
    ]
}

/// A static nearest-neighbour index over a point set: points bucketed by voxel; queries scan the
/// 27 voxels around the query, so results are exact for radii up to the voxel size.
#[derive(Debug, Clone)]
pub struct VoxelIndex {
    voxel_m: f64,
    cells: VoxelMap<Vec<u32>>,
    points: Vec<V3>,
    /// A caller-defined tag per point (the pipeline's scan-line id).
    tags: Vec<u32>,
}

impl VoxelIndex {
    /// Index `points` with voxels of `voxel_m` (the largest query radius you will use).
    pub fn new(points: Vec<V3>, voxel_m: f64) -> Self {
        let tags = vec![0; points.len()];
        Self::new_tagged(points, tags, voxel_m)
    }

    /// Like [`VoxelIndex::new`] with a tag per point (`tags` shorter than `points` pads with 0).
    pub fn new_tagged(points: Vec<V3>, mut tags: Vec<u32>, voxel_m: f64) -> Self {
        tags.resize(points.len(), 0);
        let mut cells: VoxelMap<Vec<u32>> = VoxelMap::default();
        for (i, &p) in points.iter().enumerate() {
            cells
                .entry(voxel_of(p, voxel_m))
                .or_default()
                .push(i as u32);
        }
        Self {
            voxel_m,
            cells,
            points,
            tags,
        }
    }

    /// The tag of point `i` (0 if out of range).
    pub fn tag(&self, i: u32) -> u32 {
        self.tags.get(i as usize).copied().unwrap_or(0)
    }

    /// Add `p` unless its voxel already holds `cap` points; returns whether it was added.
    pub fn insert_capped(&mut self, p: V3, tag: u32, cap: usize) -> bool {
        let cell = self.cells.entry(voxel_of(p, self.voxel_m)).or_default();
        if cell.len() >= cap {
            return false;
        }
        cell.push(self.points.len() as u32);
        self.points.push(p);
        self.tags.push(tag);
        true
    }

    /// The indexed points.
    pub fn points(&self) -> &[V3] {
        &self.points
    }

    /// Up to `K` nearest points within `radius_m` (<= the voxel size) of `q`, nearest first, as
    /// `(squared distance, index)`; returns how many were found.
    pub fn nearest<const K: usize>(
        &self,
        q: V3,
        radius_m: f64,
        out: &mut [(f64, u32); K],
    ) -> usize {
        let r2 = radius_m * radius_m;
        let mut n = 0;
        let c = voxel_of(q, self.voxel_m);
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let Some(cell) = self.cells.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) else {
                        continue;
                    };
                    for &i in cell {
                        let d2 = dist2(self.points[i as usize], q);
                        if d2 > r2 || (n == K && d2 >= out[K - 1].0) {
                            continue;
                        }
                        let mut j = if n < K {
                            n += 1;
                            n - 1
                        } else {
                            K - 1
                        };
                        while j > 0 && out[j - 1].0 > d2 {
                            out[j] = out[j - 1];
                            j -= 1;
                        }
                        out[j] = (d2, i);
                    }
                }
            }
        }
        n
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol
    }

    #[test]
    fn exp_log_round_trip() {
        for r in [[0.1, -0.2, 0.3], [0.0, 0.0, 1e-12], [1.5, 0.2, -0.7]] {
            let back = log_so3(&exp_so3(r));
            for k in 0..3 {
                assert!(close(back[k], r[k], 1e-9), "{r:?} -> {back:?}");
            }
        }
    }

    #[test]
    fn rpy_round_trip_and_pose_inverse() {
        let pose = Pose::from_xyz_rpy([1.0, -2.0, 0.5], [0.05, -0.1, 2.0]);
        let rpy = pose.rpy();
        assert!(close(rpy[0], 0.05, 1e-12) && close(rpy[1], -0.1, 1e-12));
        assert!(close(rpy[2], 2.0, 1e-12));
        let id = pose.compose(&pose.inverse());
        assert!(norm(id.translation) < 1e-12);
        let p = [0.3, 0.4, -0.2];
        let q = pose.inverse().apply(pose.apply(p));
        assert!(dist2(p, q) < 1e-24);
    }

    #[test]
    fn cholesky_solves_and_rejects_indefinite() {
        let a = [[4.0, 1.0, 0.0], [1.0, 3.0, 0.5], [0.0, 0.5, 2.0]];
        let x = solve_spd(&a, &[1.0, 2.0, 3.0]).unwrap();
        for (i, row) in a.iter().enumerate() {
            let bi: f64 = row.iter().zip(&x).map(|(a, x)| a * x).sum();
            assert!(close(bi, [1.0, 2.0, 3.0][i], 1e-12));
        }
        assert!(solve_spd(&[[1.0, 2.0], [2.0, 1.0]], &[1.0, 1.0]).is_none());
    }

    #[test]
    fn eigen_of_known_matrix() {
        let m = [[2.0, 1.0, 0.0], [1.0, 2.0, 0.0], [0.0, 0.0, 5.0]];
        let (values, vectors) = symmetric_eigen(&m);
        assert!(close(values[0], 1.0, 1e-12) && close(values[1], 3.0, 1e-12));
        assert!(close(values[2], 5.0, 1e-12));
        // First eigenvector is (1, -1, 0) / sqrt 2 up to sign.
        assert!(close(
            vectors[0][0].abs(),
            std::f64::consts::FRAC_1_SQRT_2,
            1e-9
        ));
        assert!(close(vectors[0][0], -vectors[1][0], 1e-9));
    }

    #[test]
    fn voxel_index_matches_brute_force() {
        let points: Vec<V3> = (0..500)
            .map(|i| {
                let f = f64::from(i);
                [(f * 0.37).sin(), (f * 0.11).cos(), (f * 0.05).sin() * 0.5]
            })
            .collect();
        let index = VoxelIndex::new(points.clone(), 0.3);
        let q = [0.1, 0.2, 0.0];
        let mut out = [(0.0, 0); 5];
        let n = index.nearest(q, 0.3, &mut out);
        let mut brute: Vec<(f64, u32)> = points
            .iter()
            .enumerate()
            .map(|(i, &p)| (dist2(p, q), i as u32))
            .filter(|(d, _)| *d <= 0.09)
            .collect();
        brute.sort_by(|a, b| a.0.total_cmp(&b.0));
        brute.truncate(5);
        assert_eq!(&out[..n], &brute[..]);
    }
}
