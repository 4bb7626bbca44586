//! The calculator's own geometry on top of passangle-geom's vectors and operations: the vehicle
//! frame, a least-squares plane, a circle fit with its covariance, and the median.

pub use passangle_geom::V3;

/// Unit vector along `a`, or `None` for a (near) zero vector.
pub(crate) fn unit(a: V3) -> Option<V3> {
    let n = a.dot(&a).sqrt();
    (n > 1e-12 && n.is_finite()).then(|| a * (1.0 / n))
}

/// A right-handed orthonormal frame given in cloud coordinates: the vehicle frame (x forward,
/// y left, z up, origin on the ground) or an intermediate frame while it is being estimated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VehicleFrame {
    /// The frame's origin, in cloud coordinates (metres).
    pub origin_in_cloud: V3,
    /// Unit x axis (vehicle forward) in cloud coordinates.
    pub x_axis_in_cloud: V3,
    /// Unit y axis (vehicle left) in cloud coordinates.
    pub y_axis_in_cloud: V3,
    /// Unit z axis (ground normal, up) in cloud coordinates.
    pub z_axis_in_cloud: V3,
}

impl VehicleFrame {
    /// A frame with z along `up` (unit) and x along `forward` projected onto the plane normal to `up`.
    pub(crate) fn from_up_forward(origin_in_cloud: V3, up: V3, forward: V3) -> Option<Self> {
        let z = unit(up)?;
        let x = unit(forward - (z * forward.dot(&z)))?;
        let y = z.cross(&x);
        Some(Self {
            origin_in_cloud,
            x_axis_in_cloud: x,
            y_axis_in_cloud: y,
            z_axis_in_cloud: z,
        })
    }

    /// Coordinates of a cloud point in this frame.
    pub fn vehicle_from_cloud(&self, p_in_cloud: V3) -> V3 {
        let d = p_in_cloud - self.origin_in_cloud;
        V3::new(
            d.dot(&self.x_axis_in_cloud),
            d.dot(&self.y_axis_in_cloud),
            d.dot(&self.z_axis_in_cloud),
        )
    }

    /// Cloud coordinates of a point given in this frame.
    pub fn cloud_from_vehicle(&self, p_in_vehicle: V3) -> V3 {
        self.origin_in_cloud
            + (((self.x_axis_in_cloud * p_in_vehicle[0])
                + (self.y_axis_in_cloud * p_in_vehicle[1]))
                + (self.z_axis_in_cloud * p_in_vehicle[2]))
    }

    /// The same axes rotated by `yaw_rad` about z, origin moved to `origin_in_frame` (given in this frame).
    pub(crate) fn yawed(&self, yaw_rad: f64, origin_in_frame: V3) -> Self {
        let (s, c) = yaw_rad.sin_cos();
        let x = (self.x_axis_in_cloud * c) + (self.y_axis_in_cloud * s);
        let y = self.z_axis_in_cloud.cross(&x);
        Self {
            origin_in_cloud: self.cloud_from_vehicle(origin_in_frame),
            x_axis_in_cloud: x,
            y_axis_in_cloud: y,
            z_axis_in_cloud: self.z_axis_in_cloud,
        }
    }
}

/// Solve a 3x3 linear system by Gaussian elimination with partial pivoting.
pub(crate) fn solve3(mut a: [[f64; 3]; 3], mut b: [f64; 3]) -> Option<[f64; 3]> {
    for col in 0..3 {
        let pivot = (col..3).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        if a[pivot][col].abs() < 1e-300 {
            return None;
        }
        a.swap(col, pivot);
        b.swap(col, pivot);
        for row in col + 1..3 {
            let f = a[row][col] / a[col][col];
            let pivot_row = a[col];
            for (k, v) in a[row].iter_mut().enumerate().skip(col) {
                *v -= f * pivot_row[k];
            }
            b[row] -= f * b[col];
        }
    }
    let mut x = [0.0; 3];
    for row in (0..3).rev() {
        let s: f64 = (row + 1..3).map(|k| a[row][k] * x[k]).sum();
        x[row] = (b[row] - s) / a[row][row];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// Least-squares plane `z = a x + b y + c` through points (centred for conditioning); returns the
/// upward unit normal and a point on the plane. Suited to near-horizontal planes (tilt well under 45 degrees).
pub(crate) fn fit_plane(points: impl Iterator<Item = V3> + Clone) -> Option<(V3, V3)> {
    let (mut n, mut centre) = (0.0, V3::zeros());
    for p in points.clone() {
        n += 1.0;
        centre += p;
    }
    if n < 3.0 {
        return None;
    }
    let centre = centre * (1.0 / n);
    let (mut sxx, mut sxy, mut syy, mut sxz, mut syz) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for p in points {
        let d = p - centre;
        sxx += d[0] * d[0];
        sxy += d[0] * d[1];
        syy += d[1] * d[1];
        sxz += d[0] * d[2];
        syz += d[1] * d[2];
    }
    let det = sxx * syy - sxy * sxy;
    if det.abs() < 1e-18 {
        return None;
    }
    let a = (sxz * syy - syz * sxy) / det;
    let b = (syz * sxx - sxz * sxy) / det;
    Some((unit(V3::new(-a, -b, 1.0))?, centre))
}

/// A circle in a plane: centre `(u, v)` and radius.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Circle {
    pub u: f64,
    pub v: f64,
    pub r: f64,
}

/// Geometric least-squares circle fit (algebraic Kasa start, then Gauss-Newton on the orthogonal
/// distances). Returns `None` for fewer than 3 points or a degenerate configuration.
pub(crate) fn fit_circle(points: &[[f64; 2]]) -> Option<Circle> {
    if points.len() < 3 {
        return None;
    }
    let n = points.len() as f64;
    let (mu, mv) = points
        .iter()
        .fold((0.0, 0.0), |(a, b), p| (a + p[0], b + p[1]));
    let (mu, mv) = (mu / n, mv / n);
    // Kasa: minimise sum (u^2 + v^2 + D u + E v + F)^2 in centred coordinates.
    let mut m = [[0.0; 3]; 3];
    let mut rhs = [0.0; 3];
    for p in points {
        let (u, v) = (p[0] - mu, p[1] - mv);
        let row = [u, v, 1.0];
        let w = -(u * u + v * v);
        for i in 0..3 {
            for j in 0..3 {
                m[i][j] += row[i] * row[j];
            }
            rhs[i] += row[i] * w;
        }
    }
    let [d, e, f] = solve3(m, rhs)?;
    let (mut cu, mut cv) = (-d / 2.0, -e / 2.0);
    let mut r = (cu * cu + cv * cv - f).max(0.0).sqrt();
    // Gauss-Newton on residual_i = |p_i - c| - r.
    for _ in 0..20 {
        let mut jtj = [[0.0; 3]; 3];
        let mut jtr = [0.0; 3];
        for p in points {
            let (du, dv) = (p[0] - mu - cu, p[1] - mv - cv);
            let dist = du.hypot(dv);
            if dist < 1e-12 {
                continue;
            }
            let res = dist - r;
            let jac = [-du / dist, -dv / dist, -1.0];
            for i in 0..3 {
                for j in 0..3 {
                    jtj[i][j] += jac[i] * jac[j];
                }
                jtr[i] -= jac[i] * res;
            }
        }
        let step = solve3(jtj, jtr)?;
        cu += step[0];
        cv += step[1];
        r += step[2];
        if step.iter().map(|s| s.abs()).fold(0.0, f64::max) < 1e-12 {
            break;
        }
    }
    (r.is_finite() && r > 0.0).then_some(Circle {
        u: cu + mu,
        v: cv + mv,
        r,
    })
}

/// Covariance of a geometric circle fit's `(u, v, r)`: `sigma^2 (J^T J)^-1` with `J` the
/// Jacobian of the orthogonal distances `|p - c| - r` at `circle`, the first-order propagation
/// of independent residuals of standard deviation `sigma_m` (Gauss-Markov). A short arc makes
/// `J^T J` nearly singular along the direction that trades the centre's height against the
/// radius, and that shows as a large variance of `v` and `r`. `None` for fewer than 4 points or
/// a singular fit.
pub(crate) fn circle_covariance(
    points: &[[f64; 2]],
    circle: Circle,
    sigma_m: f64,
) -> Option<[[f64; 3]; 3]> {
    if points.len() < 4 {
        return None;
    }
    let mut jtj = [[0.0; 3]; 3];
    for p in points {
        let (du, dv) = (p[0] - circle.u, p[1] - circle.v);
        let dist = du.hypot(dv);
        if dist < 1e-12 {
            continue;
        }
        let jac = [-du / dist, -dv / dist, -1.0];
        for i in 0..3 {
            for j in 0..3 {
                jtj[i][j] += jac[i] * jac[j];
            }
        }
    }
    let mut cov = [[0.0; 3]; 3];
    for k in 0..3 {
        let mut e = [0.0; 3];
        e[k] = 1.0;
        let col = solve3(jtj, e)?;
        for i in 0..3 {
            cov[i][k] = col[i] * sigma_m * sigma_m;
        }
    }
    (0..3)
        .all(|i| cov[i][i].is_finite() && cov[i][i] >= 0.0)
        .then_some(cov)
}

/// Median of a slice (sorts it). `None` when empty.
pub(crate) fn median(values: &mut [f64]) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    values.sort_unstable_by(f64::total_cmp);
    let mid = values.len() / 2;
    Some(if values.len() % 2 == 1 {
        values[mid]
    } else {
        0.5 * (values[mid - 1] + values[mid])
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn circle_fit_recovers_an_arc() {
        let pts: Vec<[f64; 2]> = (0..50)
            .map(|i| {
                let t = -2.0 + f64::from(i) * 0.05;
                [1.5 + 0.4 * t.cos(), 0.35 + 0.4 * t.sin()]
            })
            .collect();
        let c = fit_circle(&pts).unwrap();
        assert!(
            (c.u - 1.5).abs() < 1e-9 && (c.v - 0.35).abs() < 1e-9 && (c.r - 0.4).abs() < 1e-9,
            "{c:?}"
        );
    }

    #[test]
    fn a_short_arc_has_a_larger_covariance_than_a_long_one() {
        let arc = |from: f64, to: f64| -> Vec<[f64; 2]> {
            (0..=40)
                .map(|i| {
                    let t = from + (to - from) * f64::from(i) / 40.0;
                    [0.3 * t.cos(), 0.28 + 0.3 * t.sin()]
                })
                .collect()
        };
        let c = Circle {
            u: 0.0,
            v: 0.28,
            r: 0.3,
        };
        // The lower third of a tyre against its lower two thirds.
        let short = circle_covariance(&arc(-2.4, -0.74), c, 0.003).unwrap();
        let long = circle_covariance(&arc(-3.0, -0.14), c, 0.003).unwrap();
        assert!(short[1][1] > 4.0 * long[1][1], "{short:?} {long:?}");
        // Along the whole circle: the centre to sigma / sqrt(n / 2), the radius to sigma / sqrt(n).
        let full: Vec<[f64; 2]> = (0..100)
            .map(|i| {
                let t = std::f64::consts::TAU * f64::from(i) / 100.0;
                [0.3 * t.cos(), 0.28 + 0.3 * t.sin()]
            })
            .collect();
        let cov = circle_covariance(&full, c, 0.01).unwrap();
        assert!(
            (cov[0][0].sqrt() - 0.01 / 50f64.sqrt()).abs() < 1e-6,
            "{cov:?}"
        );
        assert!((cov[2][2].sqrt() - 0.01 / 10.0).abs() < 1e-6, "{cov:?}");
    }

    #[test]
    fn plane_fit_recovers_a_tilted_plane() {
        let pts: Vec<V3> = (0..100)
            .map(|i| {
                let (x, y) = (f64::from(i % 10), f64::from(i / 10));
                V3::new(x, y, 0.1 * x - 0.05 * y + 2.0)
            })
            .collect();
        let (n, p) = fit_plane(pts.iter().copied()).unwrap();
        let expect = unit(V3::new(-0.1, 0.05, 1.0)).unwrap();
        assert!(n.dot(&expect) > 1.0 - 1e-12);
        assert!((p[2] - (0.1 * p[0] - 0.05 * p[1] + 2.0)).abs() < 1e-12);
    }

    #[test]
    fn frame_round_trips() {
        let f = VehicleFrame::from_up_forward(
            V3::new(1.0, 2.0, 3.0),
            V3::new(0.05, -0.02, 1.0),
            V3::new(1.0, 0.3, 0.0),
        )
        .unwrap()
        .yawed(0.2, V3::new(0.5, -0.1, 0.0));
        let p = V3::new(3.0, -1.0, 0.7);
        let q = f.cloud_from_vehicle(f.vehicle_from_cloud(p));
        assert!((p - q).iter().all(|d| d.abs() < 1e-12));
    }
}
