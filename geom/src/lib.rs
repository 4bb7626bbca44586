//! The pipeline's geometry on nalgebra: 3-vectors and 3x3 matrices are nalgebra's fixed-size
//! types ([`V3`], [`M3`]); on them sit rigid poses with a 6-vector increment, Cholesky solves of
//! the small normal equations, a closed-form symmetric 3x3 eigen-decomposition, and a voxel hash
//! index for nearest-neighbour queries. The last three stay hand-written: nalgebra has no spatial
//! index, and its general eigen and Cholesky code is slower here or sums in another order
//! (docs/decisions/032-geometry-on-nalgebra.md).
//!
//! Increments are `[rx, ry, rz, tx, ty, tz]`: a rotation vector (radians, axis times angle) and a
//! translation (metres). [`Pose::from_increment`] maps one to `(exp(r), t)`; robot-frame names
//! follow docs/architecture.md section 8 (x forward, y left, z up), so `rx` is roll, `ry` pitch, `rz` yaw.

// `!(x > 0.0)` is deliberate throughout: it rejects NaN along with the out-of-range values.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
// Small fixed-size matrix code reads best with explicit indices.
#![allow(clippy::needless_range_loop)]

use std::collections::HashMap;
use std::hash::BuildHasherDefault;

pub use nalgebra;

/// A 3-vector in metres (or a direction): nalgebra's column vector, `v[0]`, `v.x` and the
/// operators read as usual.
pub type V3 = nalgebra::Vector3<f64>;
/// A 3x3 matrix (rotations, covariances); `m[(row, column)]`.
pub type M3 = nalgebra::Matrix3<f64>;
/// A 6-vector `[rx, ry, rz, tx, ty, tz]` (rotation vector in radians, translation in metres): the
/// unknowns of the 6x6 normal equations that [`solve_spd`] solves, kept as a plain array like them.
pub type Twist6 = [f64; 6];

// Code here and in the pipeline uses nalgebra's operators and methods (`a + b`, `a * s`,
// `a.dot(&b)`, `m * v`). nalgebra evaluates them in the order of the written-out formulas (a
// 3-vector's dot product is `(x x' + y y') + z z'`, a matrix product sums over k = 0, 1, 2 in
// turn), so results are bit for bit those formulas'. A division by a count is written
// `a * (1.0 / n)` where the formulas multiply by the reciprocal: `a / n` rounds differently.

/// The identity matrix.
pub const IDENTITY: M3 = M3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0);

/// Rotation matrix of a rotation vector: Rodrigues' `I + a K + b K^2` with `K` the cross-product
/// matrix of `r`, summed entry by entry as `I + (a K + b K^2)`. (nalgebra's
/// `Rotation3::from_scaled_axis` builds the same rotation from a different formula, which rounds
/// differently.)
pub fn exp_so3(r: V3) -> M3 {
    let theta = r.norm();
    let k = M3::new(0.0, -r[2], r[1], r[2], 0.0, -r[0], -r[1], r[0], 0.0);
    let (a, b) = if theta < 1e-9 {
        (1.0, 0.5)
    } else {
        (theta.sin() / theta, (1.0 - theta.cos()) / (theta * theta))
    };
    let k2 = k * k;
    IDENTITY + (k * a + k2 * b)
}

/// Rotation vector of a rotation matrix (inverse of [`exp_so3`] for angles below pi).
pub fn log_so3(m: &M3) -> V3 {
    let c = ((m[(0, 0)] + m[(1, 1)] + m[(2, 2)] - 1.0) / 2.0).clamp(-1.0, 1.0);
    let theta = c.acos();
    let w = V3::new(
        m[(2, 1)] - m[(1, 2)],
        m[(0, 2)] - m[(2, 0)],
        m[(1, 0)] - m[(0, 1)],
    );
    let s = if theta < 1e-9 {
        0.5
    } else {
        theta / (2.0 * theta.sin())
    };
    w * s
}

/// Rotation from roll, pitch, yaw (radians): `Rz(yaw) Ry(pitch) Rx(roll)`, each factor by
/// [`exp_so3`].
pub fn rot_from_rpy(roll_rad: f64, pitch_rad: f64, yaw_rad: f64) -> M3 {
    let rx = exp_so3(V3::new(roll_rad, 0.0, 0.0));
    let ry = exp_so3(V3::new(0.0, pitch_rad, 0.0));
    let rz = exp_so3(V3::new(0.0, 0.0, yaw_rad));
    rz * (ry * rx)
}

/// Roll, pitch, yaw (radians) of a rotation built by [`rot_from_rpy`].
pub fn rpy_of(m: &M3) -> V3 {
    let pitch = (-m[(2, 0)]).clamp(-1.0, 1.0).asin();
    V3::new(
        m[(2, 1)].atan2(m[(2, 2)]),
        pitch,
        m[(1, 0)].atan2(m[(0, 0)]),
    )
}

/// A rigid transform `b_from_a`: `p_b = rotation p_a + translation`. The same map as nalgebra's
/// [`nalgebra::IsometryMatrix3`] (see the `From` conversions), with the pipeline's constructors
/// and its increment and interpolation on top.
#[derive(Clone, Copy, PartialEq)]
pub struct Pose {
    /// Rotation matrix.
    pub rotation: M3,
    /// Translation, metres.
    pub translation: V3,
}

/// The rotation as its rows and the translation as `[x, y, z]`, as plain arrays: the text that
/// logs, reports and the pipeline's golden digests (`tests/golden/synthetic-runs.txt`) hold.
/// nalgebra's own `Debug` would print the matrix column by column.
impl std::fmt::Debug for Pose {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let rows: [[f64; 3]; 3] =
            std::array::from_fn(|i| std::array::from_fn(|j| self.rotation[(i, j)]));
        let translation: [f64; 3] = self.translation.into();
        f.debug_struct("Pose")
            .field("rotation", &rows)
            .field("translation", &translation)
            .finish()
    }
}

impl Default for Pose {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl From<Pose> for nalgebra::IsometryMatrix3<f64> {
    fn from(pose: Pose) -> Self {
        Self::from_parts(
            pose.translation.into(),
            nalgebra::Rotation3::from_matrix_unchecked(pose.rotation),
        )
    }
}

impl From<nalgebra::IsometryMatrix3<f64>> for Pose {
    fn from(iso: nalgebra::IsometryMatrix3<f64>) -> Self {
        Self {
            rotation: iso.rotation.into_inner(),
            translation: iso.translation.vector,
        }
    }
}

impl Pose {
    /// The identity transform.
    pub const IDENTITY: Self = Self {
        rotation: IDENTITY,
        translation: V3::new(0.0, 0.0, 0.0),
    };

    /// From a translation and roll, pitch, yaw (see [`rot_from_rpy`]); either may be given as an
    /// array (a configuration's `[x, y, z]`).
    pub fn from_xyz_rpy(xyz_m: impl Into<V3>, rpy_rad: impl Into<V3>) -> Self {
        let rpy_rad = rpy_rad.into();
        Self {
            rotation: rot_from_rpy(rpy_rad[0], rpy_rad[1], rpy_rad[2]),
            translation: xyz_m.into(),
        }
    }

    /// `(exp(r), t)` of an increment `[rx, ry, rz, tx, ty, tz]`.
    pub fn from_increment(d: Twist6) -> Self {
        Self {
            rotation: exp_so3(V3::new(d[0], d[1], d[2])),
            translation: V3::new(d[3], d[4], d[5]),
        }
    }

    /// Inverse of [`Pose::from_increment`].
    pub fn to_increment(&self) -> Twist6 {
        let r = log_so3(&self.rotation);
        let t = self.translation;
        [r[0], r[1], r[2], t[0], t[1], t[2]]
    }

    /// Transform a point.
    #[inline]
    pub fn apply(&self, p: V3) -> V3 {
        self.rotation * p + self.translation
    }

    /// Rotate a direction.
    #[inline]
    pub fn apply_vector(&self, v: V3) -> V3 {
        self.rotation * v
    }

    /// `self * other` (`c_from_a = c_from_b * b_from_a`).
    #[must_use]
    pub fn compose(&self, other: &Self) -> Self {
        Self {
            rotation: self.rotation * other.rotation,
            translation: self.apply(other.translation),
        }
    }

    /// The inverse transform.
    #[must_use]
    pub fn inverse(&self) -> Self {
        let rt = self.rotation.transpose();
        Self {
            rotation: rt,
            translation: -(rt * self.translation),
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
        let delta = self.rotation.transpose() * other.rotation;
        let r = log_so3(&delta) * s;
        Self {
            rotation: self.rotation * exp_so3(r),
            translation: self.translation + (other.translation - self.translation) * s,
        }
    }
}

/// Solve the symmetric positive definite system `a x = b` (n <= 6) by Cholesky. `None` when `a`
/// is not positive definite. Written out rather than nalgebra's `Cholesky`, which accumulates each
/// entry's sum in another order (and so rounds differently).
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
/// i) of a symmetric matrix given as rows (the 6x6 normal equations). 3x3 input takes the closed
/// form of [`symmetric_eigen3`]; other sizes, and 3x3 input with non-finite entries, take cyclic
/// Jacobi rotations ([`symmetric_eigen_jacobi`]).
pub fn symmetric_eigen<const N: usize>(m: &[[f64; N]; N]) -> ([f64; N], [[f64; N]; N]) {
    if N == 3 {
        let m3 = M3::from_fn(|i, j| m[i][j]);
        if let Some((values, vectors)) = symmetric_eigen3(&m3) {
            return (
                std::array::from_fn(|i| values[i]),
                std::array::from_fn(|i| std::array::from_fn(|j| vectors[(i, j)])),
            );
        }
    }
    symmetric_eigen_jacobi(m)
}

/// [`symmetric_eigen`] of a 3x3 matrix (a covariance): eigenvalues ascending, eigenvectors as the
/// columns of the matrix (`vectors.column(0)` belongs to the smallest). The closed form of
/// [`symmetric_eigen3`], or Jacobi for input with non-finite entries.
pub fn symmetric_eigen_m3(m: &M3) -> (V3, M3) {
    symmetric_eigen3(m).unwrap_or_else(|| {
        let rows: [[f64; 3]; 3] = std::array::from_fn(|i| std::array::from_fn(|j| m[(i, j)]));
        let (values, vectors) = symmetric_eigen_jacobi(&rows);
        (V3::from(values), M3::from_fn(|i, j| vectors[i][j]))
    })
}

/// Eigenvalues (ascending) and eigenvectors (as the columns of the matrix returned) of a 3x3
/// symmetric matrix without iteration (D. Eberly, "A Robust
/// Eigensolver for 3x3 Symmetric Matrices", Geometric Tools, 2014): the eigenvalues from the
/// trigonometric solution of the characteristic cubic of the shifted, scaled matrix; the
/// eigenvector of the eigenvalue farther from the other two from the largest cross product of
/// two rows of `A - lambda I`; the other two from the 2x2 problem in the plane orthogonal to it
/// (see `refine3`). Eigenvalues carry an absolute error of a few ulps of the largest entry
/// (Jacobi is more accurate for eigenvalues far below that, which nothing here needs);
/// eigenvectors an angle error of about that over the eigenvalue gap. `None` when an entry is not
/// finite. Kept beside nalgebra's iterative `SymmetricEigen` because it is faster on the
/// pipeline's covariances (docs/decisions/032-geometry-on-nalgebra.md).
pub fn symmetric_eigen3(m: &M3) -> Option<(V3, M3)> {
    if m.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let max = m.iter().fold(0.0_f64, |a, &v| a.max(v.abs()));
    if max == 0.0 {
        return Some((V3::zeros(), IDENTITY));
    }
    // Scale to entries in [-1, 1] so the cubic's terms neither overflow nor underflow.
    let a = m.map(|v| v / max);
    let off = a[(0, 1)] * a[(0, 1)] + a[(0, 2)] * a[(0, 2)] + a[(1, 2)] * a[(1, 2)];
    let (values, columns) = if off > 0.0 {
        refine3(&a, eigenvalues3(&a))
    } else {
        diagonal3(&a)
    };
    Some((values * max, M3::from_columns(&columns)))
}

/// Ascending eigenvalues of a scaled symmetric 3x3 matrix with a non-zero off-diagonal part.
fn eigenvalues3(a: &M3) -> V3 {
    let q = (a[(0, 0)] + a[(1, 1)] + a[(2, 2)]) / 3.0;
    let (b00, b11, b22) = (a[(0, 0)] - q, a[(1, 1)] - q, a[(2, 2)] - q);
    let (a01, a02, a12) = (a[(0, 1)], a[(0, 2)], a[(1, 2)]);
    let p = ((b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * (a01 * a01 + a02 * a02 + a12 * a12)) / 6.0)
        .sqrt();
    let c00 = b11 * b22 - a12 * a12;
    let c01 = a01 * b22 - a12 * a02;
    let c02 = a01 * a12 - b11 * a02;
    let det = (b00 * c00 - a01 * c01 + a02 * c02) / (p * p * p);
    let half_det = (0.5 * det).clamp(-1.0, 1.0);
    let (sin, cos) = (half_det.acos() / 3.0).sin_cos();
    let beta2 = 2.0 * cos;
    // 2 cos(angle + 2 pi / 3).
    let beta0 = -cos - 1.732_050_807_568_877_2 * sin;
    let beta1 = -(beta0 + beta2);
    V3::new(q + p * beta0, q + p * beta1, q + p * beta2)
}

/// Refined eigenvalues and unit eigenvectors (ascending) of a scaled symmetric 3x3 matrix from
/// its approximate eigenvalues `values`.
///
/// The trigonometric eigenvalues lose accuracy where two of them nearly coincide (the arc cosine
/// is steep next to +-1: a relative error up to about 1e-8). So only the eigenvalue farther from
/// the middle one is trusted to pick its eigenvector `w` (well conditioned: its gap is large); its
/// value becomes the Rayleigh quotient `w^T A w`, and the other two come from the closed-form 2x2
/// eigenproblem of `A` restricted to the plane orthogonal to `w`, which is accurate however close
/// they are.
fn refine3(a: &M3, values: V3) -> (V3, [V3; 3]) {
    let isolated = if values[2] - values[1] >= values[1] - values[0] {
        values[2]
    } else {
        values[0]
    };
    let w = eigenvector_isolated(a, isolated);
    let w_value = w.dot(&(a * w));
    let (u, v) = orthogonal_complement(w);
    let (au, av) = (a * u, a * v);
    let (m00, m01, m11) = (u.dot(&au), u.dot(&av), v.dot(&av));
    let mean = 0.5 * (m00 + m11);
    let half_diff = 0.5 * (m00 - m11);
    let radius = (half_diff * half_diff + m01 * m01).sqrt();
    // Eigenvector of the larger 2x2 eigenvalue, in the (u, v) basis, without cancellation.
    let (x, y) = if radius == 0.0 {
        (1.0, 0.0)
    } else if half_diff >= 0.0 {
        (half_diff + radius, m01)
    } else {
        (m01, radius - half_diff)
    };
    let len = (x * x + y * y).sqrt();
    let (x, y) = (x / len, y / len);
    let high = u * x + v * y;
    let low = u * -y + v * x;
    let mut pairs = [(w_value, w), (mean - radius, low), (mean + radius, high)];
    pairs.sort_by(|p, q| p.0.total_cmp(&q.0));
    (V3::from(pairs.map(|p| p.0)), pairs.map(|p| p.1))
}

/// The eigenvector of a simple eigenvalue: the longest cross product of two rows of
/// `A - value I` (the rows span the plane orthogonal to it).
fn eigenvector_isolated(a: &M3, value: f64) -> V3 {
    let r0 = V3::new(a[(0, 0)] - value, a[(0, 1)], a[(0, 2)]);
    let r1 = V3::new(a[(0, 1)], a[(1, 1)] - value, a[(1, 2)]);
    let r2 = V3::new(a[(0, 2)], a[(1, 2)], a[(2, 2)] - value);
    let candidates = [r0.cross(&r1), r0.cross(&r2), r1.cross(&r2)];
    let (best, len2) = candidates
        .iter()
        .map(|&c| (c, c.dot(&c)))
        .fold((V3::x(), 0.0), |acc, c| if c.1 > acc.1 { c } else { acc });
    if len2 > 0.0 {
        best * (1.0 / len2.sqrt())
    } else {
        best
    }
}

/// Two unit vectors completing the unit vector `w` to an orthonormal basis.
fn orthogonal_complement(w: V3) -> (V3, V3) {
    let u = if w[0].abs() > w[1].abs() {
        V3::new(-w[2], 0.0, w[0]) * (1.0 / (w[0] * w[0] + w[2] * w[2]).sqrt())
    } else {
        V3::new(0.0, w[2], -w[1]) * (1.0 / (w[1] * w[1] + w[2] * w[2]).sqrt())
    };
    (u, w.cross(&u))
}

/// Eigen-decomposition of a diagonal matrix: its entries, ascending, with the axes.
fn diagonal3(a: &M3) -> (V3, [V3; 3]) {
    let mut order = [0, 1, 2];
    order.sort_by(|&i, &j| a[(i, i)].total_cmp(&a[(j, j)]));
    let values = V3::from(order.map(|i| a[(i, i)]));
    let vectors = order.map(|i| IDENTITY.column(i).into_owned());
    (values, vectors)
}

/// Eigenvalues (ascending) and eigenvectors (as columns) of a symmetric matrix by cyclic Jacobi
/// rotations, to an off-diagonal sum of squares below 1e-24 (at most 50 sweeps).
pub fn symmetric_eigen_jacobi<const N: usize>(m: &[[f64; N]; N]) -> ([f64; N], [[f64; N]; N]) {
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
    let mut c = V3::zeros();
    for p in points.clone() {
        c += p;
        n += 1.0;
    }
    if n == 0.0 {
        return None;
    }
    c *= 1.0 / n;
    // The six distinct products, summed, then one division each (the matrix is symmetric).
    let mut s = [0.0; 6];
    for p in points {
        let d = p - c;
        s[0] += d[0] * d[0];
        s[1] += d[0] * d[1];
        s[2] += d[0] * d[2];
        s[3] += d[1] * d[1];
        s[4] += d[1] * d[2];
        s[5] += d[2] * d[2];
    }
    let s = s.map(|v| v / n);
    Some((
        c,
        M3::new(s[0], s[1], s[2], s[1], s[3], s[4], s[2], s[4], s[5]),
    ))
}

/// The hasher of the voxel maps: rustc's FxHash (`rustc-hash`), fast on small integer keys and
/// not DoS-resistant, which voxel keys from a sensor need not be.
pub use rustc_hash::FxHasher;

/// A hash map keyed by voxel, with [`FxHasher`].
pub type VoxelMap<T> = HashMap<[i32; 3], T, BuildHasherDefault<FxHasher>>;

/// The voxel holding `p` for voxels of `size_m`: `floor(p / size_m)` per axis, saturating at the
/// ends of `i32` (NaN gives 0).
#[inline]
pub fn voxel_of(p: V3, size_m: f64) -> [i32; 3] {
    [
        floor_i32(p.x / size_m),
        floor_i32(p.y / size_m),
        floor_i32(p.z / size_m),
    ]
}

/// `x.floor() as i32` without the libm call that `floor` becomes on targets without SSE4.1:
/// truncate (saturating, NaN to 0), then step down for negative non-integers.
#[inline]
fn floor_i32(x: f64) -> i32 {
    let t = x as i32;
    if f64::from(t) > x {
        t.saturating_sub(1)
    } else {
        t
    }
}

/// One indexed point, stored inline in its voxel's cell so a query reads each cell's points
/// from one contiguous block: the position, the point's index in insertion order and its tag (in
/// what was padding), so a query's caller needs neither the point list nor the tag list.
#[derive(Debug, Clone, Copy)]
struct Entry {
    p: V3,
    index: u32,
    tag: u32,
}

/// One neighbour found by [`VoxelIndex::neighbours`]: its squared distance to the query, its
/// index in insertion order, its tag and its position.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Neighbour {
    /// Squared distance to the query, square metres.
    pub d2: f64,
    /// The point's index in insertion order.
    pub index: u32,
    /// The point's tag ([`VoxelIndex::new_tagged`]).
    pub tag: u32,
    /// The point.
    pub p: V3,
}

/// A nearest-neighbour index over a point set: points bucketed by voxel, each voxel's points
/// stored contiguously in insertion order.
///
/// Queries are exact for any radius. A query visits only the voxels that intersect the box of
/// side `2 radius` around it: the query's own voxel first, then the others, each skipped without a
/// hash lookup when its nearest face is farther than the current search bound (the radius, or the
/// K-th best distance once K points were found). With a radius up to the voxel (the pipeline's
/// scan-to-map: 0.2 m voxels and radius) the 26 neighbours are visited by kind (face, edge,
/// corner), so the bound shrinks early and prunes most of them; with a radius well under the voxel
/// only one to eight voxels are visited. Ties in distance are broken by
/// the smaller index, so the result does not depend on the order in which voxels are visited.
#[derive(Debug, Clone)]
pub struct VoxelIndex {
    voxel_m: f64,
    cells: VoxelMap<Vec<Entry>>,
    points: Vec<V3>,
}

/// The 26 neighbours of a voxel: the 6 sharing a face, the 12 sharing an edge, the 8 sharing a
/// corner.
const SHELL: [[i32; 3]; 26] = [
    [-1, 0, 0],
    [1, 0, 0],
    [0, -1, 0],
    [0, 1, 0],
    [0, 0, -1],
    [0, 0, 1],
    [-1, -1, 0],
    [-1, 1, 0],
    [1, -1, 0],
    [1, 1, 0],
    [-1, 0, -1],
    [-1, 0, 1],
    [1, 0, -1],
    [1, 0, 1],
    [0, -1, -1],
    [0, -1, 1],
    [0, 1, -1],
    [0, 1, 1],
    [-1, -1, -1],
    [-1, -1, 1],
    [-1, 1, -1],
    [-1, 1, 1],
    [1, -1, -1],
    [1, -1, 1],
    [1, 1, -1],
    [1, 1, 1],
];

/// Slack on voxel bounds, metres: `voxel_of` divides and floors, so a point can sit a rounding
/// error outside the box its voxel number implies. Widening every bound by far more than that keeps
/// the voxel selection and the pruning conservative (they never skip a point within the radius).
const BOUND_SLACK_M: f64 = 1e-9;

impl VoxelIndex {
    /// Index `points` with voxels of `voxel_m`. Any query radius works; radii up to the voxel size
    /// visit at most the 27 voxels around the query.
    pub fn new(points: Vec<V3>, voxel_m: f64) -> Self {
        Self::new_tagged(points, Vec::new(), voxel_m)
    }

    /// Like [`VoxelIndex::new`] with a caller-defined tag per point (the pipeline's scan-line
    /// id), which queries return with the point ([`Neighbour`]); `tags` shorter than `points`
    /// pads with 0.
    pub fn new_tagged(points: Vec<V3>, tags: Vec<u32>, voxel_m: f64) -> Self {
        let tags = tags.into_iter().chain(std::iter::repeat(0));
        let mut cells: VoxelMap<Vec<Entry>> = VoxelMap::default();
        for (i, (&p, tag)) in points.iter().zip(tags).enumerate() {
            cells.entry(voxel_of(p, voxel_m)).or_default().push(Entry {
                p,
                index: i as u32,
                tag,
            });
        }
        Self {
            voxel_m,
            cells,
            points,
        }
    }

    /// Add `p` unless its voxel already holds `cap` points or one nearer than `spacing_m` (0: any
    /// distance); returns whether it was added.
    pub fn insert_capped(&mut self, p: V3, tag: u32, cap: usize, spacing_m: f64) -> bool {
        let cell = self.cells.entry(voxel_of(p, self.voxel_m)).or_default();
        let s2 = spacing_m * spacing_m;
        if cell.len() >= cap || cell.iter().any(|e| (e.p - p).norm_squared() < s2) {
            return false;
        }
        cell.push(Entry {
            p,
            index: self.points.len() as u32,
            tag,
        });
        self.points.push(p);
        true
    }

    /// The indexed points.
    pub fn points(&self) -> &[V3] {
        &self.points
    }

    /// The voxel size, metres.
    pub fn voxel_m(&self) -> f64 {
        self.voxel_m
    }

    /// Up to `K` nearest points within `radius_m` of `q`, nearest first (equal distances: smaller
    /// index first), as `(squared distance, index)`; returns how many were found.
    pub fn nearest<const K: usize>(
        &self,
        q: V3,
        radius_m: f64,
        out: &mut [(f64, u32); K],
    ) -> usize {
        let mut found = [Neighbour::default(); K];
        let n = self.neighbours(q, radius_m, &mut found);
        for (o, f) in out.iter_mut().zip(&found[..n]) {
            *o = (f.d2, f.index);
        }
        n
    }

    /// [`VoxelIndex::nearest`] with each neighbour's tag and position, read from the voxel's
    /// cell as it is scanned: a caller that fits them needs no lookups in the point and tag
    /// lists, which for the scan-to-map feature map are scattered reads from megabytes of memory.
    pub fn neighbours<const K: usize>(
        &self,
        q: V3,
        radius_m: f64,
        out: &mut [Neighbour; K],
    ) -> usize {
        if K == 0 || !(radius_m >= 0.0) {
            return 0;
        }
        let mut best = Best {
            out,
            n: 0,
            r2: radius_m * radius_m,
        };
        let centre = voxel_of(q, self.voxel_m);
        if radius_m <= self.voxel_m {
            self.nearest_in_shell(q, centre, &mut best);
            return best.n;
        }
        let Some((lo, hi)) = self.voxel_range(q, radius_m) else {
            // The box around the query spans more voxels than are occupied: scan them all.
            for cell in self.cells.values() {
                best.scan(cell, q);
            }
            return best.n;
        };
        if let Some(cell) = self.cells.get(&centre) {
            best.scan(cell, q);
        }
        for x in lo[0]..=hi[0] {
            let gx = self.gap2(q[0], x, centre[0]);
            for y in lo[1]..=hi[1] {
                let gxy = gx + self.gap2(q[1], y, centre[1]);
                if gxy > best.bound() {
                    continue;
                }
                for z in lo[2]..=hi[2] {
                    let key = [x, y, z];
                    if key == centre || gxy + self.gap2(q[2], z, centre[2]) > best.bound() {
                        continue;
                    }
                    if let Some(cell) = self.cells.get(&key) {
                        best.scan(cell, q);
                    }
                }
            }
        }
        best.n
    }

    /// [`VoxelIndex::nearest`] for radii up to the voxel size: the query's voxel, then its 26
    /// neighbours nearest-first by kind (6 sharing a face, 12 an edge, 8 a corner), so the
    /// K-th best distance shrinks early and prunes most of the rest before their hash lookup.
    fn nearest_in_shell<const K: usize>(&self, q: V3, centre: [i32; 3], best: &mut Best<'_, K>) {
        if let Some(cell) = self.cells.get(&centre) {
            best.scan(cell, q);
        }
        // Squared gap to the neighbour below, 0 (same voxel), and above, per axis.
        let gaps: [[f64; 3]; 3] = std::array::from_fn(|k| {
            [
                self.gap2(q[k], centre[k].wrapping_sub(1), centre[k]),
                0.0,
                self.gap2(q[k], centre[k].wrapping_add(1), centre[k]),
            ]
        });
        for offset in SHELL {
            let gap: f64 = (0..3).map(|k| gaps[k][(offset[k] + 1) as usize]).sum();
            if gap > best.bound() {
                continue;
            }
            let key = std::array::from_fn(|k| centre[k].wrapping_add(offset[k]));
            if let Some(cell) = self.cells.get(&key) {
                best.scan(cell, q);
            }
        }
    }

    /// Call `f(index, point)` for every point within `radius_m` of `q`, voxel by voxel in
    /// ascending `(x, y, z)` voxel order and in insertion order within a voxel (a fixed order, so
    /// sums over the neighbours are reproducible).
    pub fn for_each_within(&self, q: V3, radius_m: f64, mut f: impl FnMut(u32, V3)) {
        if !(radius_m >= 0.0) {
            return;
        }
        let r2 = radius_m * radius_m;
        let mut visit = |cell: &[Entry]| {
            for e in cell {
                if (e.p - q).norm_squared() <= r2 {
                    f(e.index, e.p);
                }
            }
        };
        let Some((lo, hi)) = self.voxel_range(q, radius_m) else {
            let mut keys: Vec<&[i32; 3]> = self.cells.keys().collect();
            keys.sort_unstable();
            for key in keys {
                visit(&self.cells[key]);
            }
            return;
        };
        let centre = voxel_of(q, self.voxel_m);
        for x in lo[0]..=hi[0] {
            let gx = self.gap2(q[0], x, centre[0]);
            for y in lo[1]..=hi[1] {
                let gxy = gx + self.gap2(q[1], y, centre[1]);
                if gxy > r2 {
                    continue;
                }
                for z in lo[2]..=hi[2] {
                    if gxy + self.gap2(q[2], z, centre[2]) > r2 {
                        continue;
                    }
                    if let Some(cell) = self.cells.get(&[x, y, z]) {
                        visit(cell);
                    }
                }
            }
        }
    }

    /// The voxels (inclusive corners) that the box `q +- radius_m` touches; `None` when they
    /// outnumber the occupied voxels (then a scan of every cell is cheaper and always terminates).
    fn voxel_range(&self, q: V3, radius_m: f64) -> Option<([i32; 3], [i32; 3])> {
        let reach = radius_m + BOUND_SLACK_M;
        let lo = voxel_of(q - V3::repeat(reach), self.voxel_m);
        let hi = voxel_of(q + V3::repeat(reach), self.voxel_m);
        let count: f64 = (0..3)
            .map(|k| f64::from(hi[k]) - f64::from(lo[k]) + 1.0)
            .product();
        (count <= 27.0 || count <= self.cells.len() as f64).then_some((lo, hi))
    }

    /// Squared distance from coordinate `qc` (in voxel `c`) to the nearest face of voxel `v`
    /// along one axis, shrunk by [`BOUND_SLACK_M`] so it never overestimates.
    fn gap2(&self, qc: f64, v: i32, c: i32) -> f64 {
        let gap = match v.cmp(&c) {
            std::cmp::Ordering::Less => qc - (f64::from(v) + 1.0) * self.voxel_m,
            std::cmp::Ordering::Greater => f64::from(v) * self.voxel_m - qc,
            std::cmp::Ordering::Equal => return 0.0,
        };
        let gap = (gap - BOUND_SLACK_M).max(0.0);
        gap * gap
    }
}

/// The K best neighbours so far, sorted by squared distance, then index.
struct Best<'a, const K: usize> {
    out: &'a mut [Neighbour; K],
    n: usize,
    r2: f64,
}

impl<const K: usize> Best<'_, K> {
    /// Squared distance a point must not exceed to enter.
    fn bound(&self) -> f64 {
        if self.n == K {
            self.out[K - 1].d2
        } else {
            self.r2
        }
    }

    #[inline]
    fn scan(&mut self, cell: &[Entry], q: V3) {
        let mut bound = self.bound();
        for e in cell {
            let d2 = (e.p - q).norm_squared();
            // One comparison per point on the common path; it also drops NaN.
            if !(d2 <= bound) {
                continue;
            }
            self.insert(Neighbour {
                d2,
                index: e.index,
                tag: e.tag,
                p: e.p,
            });
            bound = self.bound();
        }
    }

    /// Insert a candidate within the bound, keeping the list sorted and at most K long.
    fn insert(&mut self, candidate: Neighbour) {
        if self.n == K && !before(candidate, self.out[K - 1]) {
            return;
        }
        let mut j = if self.n < K {
            self.n += 1;
            self.n - 1
        } else {
            K - 1
        };
        while j > 0 && before(candidate, self.out[j - 1]) {
            self.out[j] = self.out[j - 1];
            j -= 1;
        }
        self.out[j] = candidate;
    }
}

/// Order of neighbours: by squared distance, then by index (distances here are never NaN).
#[allow(clippy::float_cmp)] // Equal distances are exactly the ties to break.
fn before(a: Neighbour, b: Neighbour) -> bool {
    a.d2 < b.d2 || (a.d2 == b.d2 && a.index < b.index)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol
    }

    #[test]
    fn exp_log_round_trip() {
        for r in [
            V3::new(0.1, -0.2, 0.3),
            V3::new(0.0, 0.0, 1e-12),
            V3::new(1.5, 0.2, -0.7),
        ] {
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
        assert!(id.translation.norm() < 1e-12);
        let p = V3::new(0.3, 0.4, -0.2);
        let q = pose.inverse().apply(pose.apply(p));
        assert!((p - q).norm_squared() < 1e-24);
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
                V3::new((f * 0.37).sin(), (f * 0.11).cos(), (f * 0.05).sin() * 0.5)
            })
            .collect();
        let index = VoxelIndex::new(points.clone(), 0.3);
        let q = V3::new(0.1, 0.2, 0.0);
        let mut out = [(0.0, 0); 5];
        let n = index.nearest(q, 0.3, &mut out);
        let mut brute: Vec<(f64, u32)> = points
            .iter()
            .enumerate()
            .map(|(i, &p)| ((p - q).norm_squared(), i as u32))
            .filter(|(d, _)| *d <= 0.09)
            .collect();
        brute.sort_by(|a, b| a.0.total_cmp(&b.0));
        brute.truncate(5);
        assert_eq!(&out[..n], &brute[..]);
    }

    /// A seeded random symmetric matrix: `R diag(values) R^T` with a random rotation.
    fn random_symmetric(rng: &mut rand_chacha::ChaCha8Rng, values: V3) -> M3 {
        use rand::Rng;
        let r = exp_so3(V3::new(
            rng.random_range(-3.0..3.0),
            rng.random_range(-3.0..3.0),
            rng.random_range(-3.0..3.0),
        ));
        let d = M3::from_diagonal(&values);
        let m = r * (d * r.transpose());
        // Exactly symmetric, as a covariance is.
        M3::from_fn(|i, j| 0.5 * (m[(i, j)] + m[(j, i)]))
    }

    #[test]
    fn closed_form_eigen_matches_jacobi_and_is_an_eigen_decomposition() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        for case in 0..2000 {
            // Spectra like the pipeline's covariances: planes (one tiny value), lines (one large),
            // blobs, repeated values and sign changes.
            let s = 10f64.powf(rng.random_range(-6.0..1.0));
            let values = match case % 5 {
                0 => [s * 1e-5, s * 0.3, s],
                1 => [s * 0.01, s * 0.02, s],
                2 => [s, s, s * 0.5],
                3 => [-s, 0.0, s * 1e-3],
                _ => [
                    s * rng.random_range(0.0..1.0),
                    s * rng.random_range(0.0..1.0),
                    s * rng.random_range(0.0..1.0),
                ],
            };
            let m = random_symmetric(&mut rng, V3::from(values));
            let (fast, fast_vectors) = symmetric_eigen3(&m).unwrap();
            let scale_m = m.iter().fold(0.0_f64, |a, v| a.max(v.abs()));
            // Jacobi stops on an absolute off-diagonal size: give it entries of order one.
            let rows = std::array::from_fn(|i| std::array::from_fn(|j| m[(i, j)] / scale_m));
            let (slow, slow_vectors) = symmetric_eigen_jacobi(&rows);
            let slow = V3::from(slow) * scale_m;
            for i in 0..3 {
                assert!(
                    close(fast[i], slow[i], 1e-13 * scale_m),
                    "{m:?}: {fast:?} {slow:?}"
                );
                let v: V3 = fast_vectors.column(i).into_owned();
                assert!(close(v.norm(), 1.0, 1e-12), "{m:?}: |v{i}| = {}", v.norm());
                let residual = m * v - v * fast[i];
                assert!(residual.norm() <= 1e-12 * scale_m, "{m:?}: {residual:?}");
                // Where the eigenvalue is simple, the vector is Jacobi's up to sign.
                let gap = (0..3)
                    .filter(|&j| j != i)
                    .map(|j| (slow[j] - slow[i]).abs())
                    .fold(f64::INFINITY, f64::min);
                if gap > 1e-3 * scale_m {
                    let w = V3::new(slow_vectors[0][i], slow_vectors[1][i], slow_vectors[2][i]);
                    assert!(close(v.dot(&w).abs(), 1.0, 1e-9), "{m:?}: {v:?} vs {w:?}");
                }
            }
            let (v0, v1) = (
                fast_vectors.column(0).into_owned(),
                fast_vectors.column(1).into_owned(),
            );
            assert!(v0.dot(&v1).abs() < 1e-12, "{m:?}");
        }
    }

    #[test]
    #[allow(clippy::float_cmp)] // Exact by construction: diagonal entries, copied points.
    fn eigen_of_diagonal_zero_and_non_finite_input() {
        let (values, vectors) =
            symmetric_eigen(&[[3.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 2.0]]);
        assert_eq!(values, [-1.0, 2.0, 3.0]);
        assert_eq!(vectors, [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
        assert_eq!(
            symmetric_eigen(&[[0.0; 3]; 3]),
            (
                [0.0; 3],
                [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
            )
        );
        assert_eq!(
            symmetric_eigen3(&M3::zeros()),
            Some((V3::zeros(), IDENTITY))
        );
        let nan = M3::new(f64::NAN, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
        assert!(symmetric_eigen3(&nan).is_none());
        // The 3x3 entry point falls back to Jacobi without panicking.
        let _ = symmetric_eigen_m3(&nan);
        // The generic entry point still answers (by Jacobi) without panicking.
        let _ = symmetric_eigen(&[[f64::INFINITY, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0; 3]]);
        // Other sizes take Jacobi.
        let (values, _) = symmetric_eigen(&[[2.0, 1.0], [1.0, 2.0]]);
        assert!(close(values[0], 1.0, 1e-12) && close(values[1], 3.0, 1e-12));
    }

    /// The K nearest within `r` by brute force, ordered by distance then index.
    fn brute_nearest(points: &[V3], q: V3, r: f64, k: usize) -> Vec<(f64, u32)> {
        let mut all: Vec<(f64, u32)> = points
            .iter()
            .enumerate()
            .map(|(i, &p)| ((p - q).norm_squared(), i as u32))
            .filter(|(d, _)| *d <= r * r)
            .collect();
        all.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        all.truncate(k);
        all
    }

    #[test]
    #[allow(clippy::float_cmp)] // Exact by construction: diagonal entries, copied points.
    fn voxel_index_matches_brute_force_for_any_radius_and_voxel() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        // Random points plus a grid (exact ties in distance) plus duplicates.
        let mut points: Vec<V3> = (0..1500)
            .map(|_| {
                V3::new(
                    rng.random_range(-2.0..2.0),
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-0.5..0.5),
                )
            })
            .collect();
        for i in 0..10 {
            for j in 0..10 {
                points.push(V3::new(f64::from(i) * 0.1, f64::from(j) * 0.1, 0.0));
            }
        }
        points.extend_from_within(0..50);
        for voxel_m in [0.05, 0.2, 0.5, 3.0] {
            let index = VoxelIndex::new(points.clone(), voxel_m);
            // The same points inserted one by one give the same index.
            let mut grown = VoxelIndex::new(Vec::new(), voxel_m);
            for &p in &points {
                assert!(grown.insert_capped(p, 0, usize::MAX, 0.0));
            }
            for case in 0..300 {
                let q = if case % 3 == 0 {
                    // On the grid: many equal distances.
                    V3::new(
                        f64::from(rng.random_range(0..10)) * 0.1,
                        f64::from(rng.random_range(0..10)) * 0.1,
                        0.0,
                    )
                } else {
                    V3::new(
                        rng.random_range(-2.2..2.2),
                        rng.random_range(-1.2..1.2),
                        rng.random_range(-0.6..0.6),
                    )
                };
                let r = [0.0, 0.05, 0.1, 0.2, 0.35, 1.0, 10.0][case % 7];
                let want = brute_nearest(&points, q, r, 5);
                let mut out = [(0.0, 0); 5];
                let n = index.nearest(q, r, &mut out);
                assert_eq!(&out[..n], &want[..], "voxel {voxel_m} q {q:?} r {r}");
                let n = grown.nearest(q, r, &mut out);
                assert_eq!(&out[..n], &want[..], "grown: voxel {voxel_m} q {q:?} r {r}");
                let mut one = [(0.0, 0); 1];
                let n = index.nearest(q, r, &mut one);
                assert_eq!(&one[..n], &want[..n.min(want.len())]);
                let mut within = Vec::new();
                index.for_each_within(q, r, |i, p| {
                    assert_eq!(p, points[i as usize]);
                    within.push(i);
                });
                within.sort_unstable();
                let mut all = brute_nearest(&points, q, r, usize::MAX)
                    .into_iter()
                    .map(|(_, i)| i)
                    .collect::<Vec<_>>();
                all.sort_unstable();
                assert_eq!(within, all, "within: voxel {voxel_m} q {q:?} r {r}");
            }
        }
        let mut out = [(0.0, 0); 3];
        assert_eq!(index_of_nothing().nearest(V3::zeros(), 1.0, &mut out), 0);
        let index = VoxelIndex::new(points, 0.2);
        assert_eq!(index.nearest(V3::repeat(f64::NAN), 1.0, &mut out), 0);
        assert_eq!(index.nearest(V3::zeros(), f64::NAN, &mut out), 0);
    }

    fn index_of_nothing() -> VoxelIndex {
        VoxelIndex::new(Vec::new(), 0.2)
    }

    #[test]
    fn for_each_within_visits_voxels_in_ascending_order() {
        let points = vec![
            V3::new(0.25, 0.0, 0.0),
            V3::new(-0.05, 0.0, 0.0),
            V3::new(0.05, 0.0, 0.0),
            V3::new(0.06, 0.01, 0.0),
        ];
        let index = VoxelIndex::new(points, 0.1);
        let mut seen = Vec::new();
        index.for_each_within(V3::zeros(), 0.2, |i, _| seen.push(i));
        // Voxel x = -1 first, then x = 0 in insertion order; the point 0.25 m away is left out.
        assert_eq!(seen, vec![1, 2, 3]);
    }

    #[test]
    fn floor_matches_the_standard_library() {
        for x in [
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            2.999_999,
            -2.000_001,
            1e10,
            -1e10,
            2_147_483_647.5,
            -2_147_483_648.5,
            -2_147_483_647.5,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ] {
            assert_eq!(floor_i32(x), x.floor() as i32, "{x}");
        }
        let p = V3::new(0.31, -0.01, -0.2);
        assert_eq!(voxel_of(p, 0.1), [3, -1, -2]);
    }
}
