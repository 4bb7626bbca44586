//! Per-laser range offsets from a recording in a room: the user calibration of the range biases
//! a VLP-16 keeps after the factory's (a few millimetres per laser, up to centimetres on a worn
//! unit). Pure: returns in, offsets out.
//!
//! # Why
//! A laser's range bias moves every return of that laser along its ray. The tyres are seen
//! nearly head-on from ahead and behind, mostly by the upper lasers, so a biased laser moves a
//! tyre's outline along the path, and the fitted wheel centre's height (the static loaded
//! radius) with it: on simulated passes with 1 cm per-laser biases the loaded radii read up to
//! 3 cm off on true-pose clouds (decision record 042).
//!
//! # Model
//! A return of laser `l` with measured range `r` along the unit ray `u` (sensor frame, from the
//! laser's origin `o_l`, its vertical offset) lies at `o_l + (r - b_l) u`, `b_l` being the
//! laser's range bias. On a plane `n . x = d` every return of it satisfies
//! `n . u r + n . o_l = d + b_l (n . u)`. With the planes' normals fixed this is linear in the
//! planes' distances and the biases. Each plane's distance and a small tilt of it are eliminated
//! (Schur complement), leaving a 16 x 16 normal system for `b`: lasers hit a wall at heights
//! that grow with their elevation, so a tilted wall would otherwise pass for a pattern of
//! biases. A bias and a plane's distance separate because `n . u` changes across the plane (a
//! wall is seen over many azimuths); a laser with too few returns on the planes is left
//! uncalibrated (offset 0) and named.
//!
//! # Steps
//! 1. Candidates: returns [`MIN_RANGE_M`]-[`MAX_RANGE_M`] from the sensor, every
//!    [`SUBSAMPLE`]-th for the search.
//! 2. Planes: near-vertical (walls, pillar faces, cabinets; `|n_z|` at most [`MAX_NORMAL_Z`]: the
//!    sensor tilted by up to 5 degrees),
//!    found by a seeded RANSAC, largest first, with an inlier band of [`RANSAC_BAND_M`] (the
//!    data sheet's +-3 cm noise plus as much bias). The floor is not used: seen at grazing
//!    incidence, a millimetre of unevenness is centimetres along the ray. A plane needs
//!    [`MIN_PLANE_RETURNS`] returns (of all, not the subsample) over [`MIN_AZIMUTH_SPAN_RAD`].
//! 3. Rounds: each plane refitted (total least squares) to its returns with the current
//!    offsets; the biases solved; a plane whose residual sigma exceeds [`MAX_PLANE_SIGMA_RATIO`]
//!    times the median plane's left out (it is not one flat surface) and the rounds started
//!    over; each plane's returns chosen afresh from all returns: within 4 robust sigma (median
//!    absolute deviation) of it and not within that of another plane (where two surfaces meet,
//!    the other surface's returns lie on one side of the plane). [`ROUNDS`] settled rounds.
//! 4. Standard errors: the residual sigma times the square root of the normal matrix's inverse
//!    diagonal. A residual sigma above the data sheet's range accuracy (3 cm) is refused: the
//!    sensor moved, or the walls are not flat. The standard errors assume independent returns;
//!    a wall's unevenness is shared by a laser's returns on it and is not in them
//!    (approximate: flat walls assumed).
//!
//! The recording must be static (the robot parked, the sensor still): frames are pooled in the
//! sensor frame without deskewing.

use passangle_geom::{V3, centroid_covariance, solve_spd, symmetric_eigen3};
use thiserror::Error;

use super::decoder::{DecoderConfig, Point, RANGE_ACCURACY_M, VERTICAL_OFFSET_MM};
use super::packet::LASERS;

/// Nearest return used, metres: the robot's own body and the vehicle's nearest parts are not
/// walls.
pub const MIN_RANGE_M: f64 = 1.5;
/// Farthest return used, metres.
pub const MAX_RANGE_M: f64 = 40.0;
/// One return in this many is searched for planes: a prime, so that the search takes every
/// laser in turn from returns in firing order (a stride of 16 would take one laser only).
pub const SUBSAMPLE: usize = 17;
/// Largest vertical component of a usable plane's normal.
pub const MAX_NORMAL_Z: f64 = 0.1;
/// RANSAC inlier band, metres.
pub const RANSAC_BAND_M: f64 = 0.06;
/// Fewest returns on a usable plane.
pub const MIN_PLANE_RETURNS: usize = 2_000;
/// Narrowest azimuth span of a usable plane, radians (15 degrees): over a narrower one the
/// plane's distance and a bias hardly separate.
pub const MIN_AZIMUTH_SPAN_RAD: f64 = 0.26;
/// Half-width of a RANSAC triple's neighbourhood, in searched returns (about 10 degrees of
/// azimuth in one revolution).
pub const NEIGHBOURHOOD: usize = 50;
/// Most planes searched for.
pub const MAX_PLANES: usize = 8;
/// RANSAC hypotheses per plane.
pub const HYPOTHESES: usize = 400;
/// Refinement rounds.
pub const ROUNDS: usize = 4;
/// Floor of the robust sigma in the pruning band, metres (a noiseless recording's residuals
/// are rounding).
pub const MIN_SIGMA_M: f64 = 0.001;
/// A plane whose residual sigma exceeds the planes' median by this factor is not one flat
/// surface and is left out. Range noise alone gives every plane nearly the same sigma (the
/// simulated hall's walls at 3-11 m: 11.5-13.9 mm).
pub const MAX_PLANE_SIGMA_RATIO: f64 = 1.5;
/// Fewest plane returns for a laser to be calibrated.
pub const MIN_LASER_RETURNS: usize = 300;

/// One return as the calibration sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Return {
    /// Laser id in the firing order.
    pub laser: usize,
    /// Unit ray from the laser's origin, sensor frame.
    pub ray: V3,
    /// Range as decoded (with the decoder's offsets applied), metres.
    pub range_m: f64,
    /// Azimuth, radians.
    pub azimuth_rad: f64,
}

impl Return {
    /// The return behind a decoded point: its range and ray, from the point less the laser's
    /// vertical offset when `config` adds it.
    pub fn of_point(p: &Point, config: &DecoderConfig) -> Self {
        let laser = usize::from(p.laser_id) % LASERS;
        let q = V3::new(f64::from(p.x_m), f64::from(p.y_m), f64::from(p.z_m))
            - origin(laser, config.vertical_offset);
        let range_m = q.norm();
        let ray = if range_m > 0.0 { q / range_m } else { V3::z() };
        Self {
            laser,
            ray,
            range_m,
            azimuth_rad: f64::from(p.azimuth_rad),
        }
    }

    fn origin(&self, vertical_offset: bool) -> V3 {
        origin(self.laser, vertical_offset)
    }

    /// The return's position with `offset_m` taken off its range.
    pub(crate) fn at(&self, offset_m: f64, vertical_offset: bool) -> V3 {
        self.origin(vertical_offset) + self.ray * (self.range_m - offset_m)
    }
}

/// A laser's origin in the sensor frame: its vertical offset when the decoder adds it.
fn origin(laser: usize, vertical_offset: bool) -> V3 {
    if vertical_offset {
        V3::new(0.0, 0.0, f64::from(VERTICAL_OFFSET_MM[laser]) * 1e-3)
    } else {
        V3::zeros()
    }
}

/// The estimate.
#[derive(Debug, Clone, PartialEq)]
pub struct RangeCalibration {
    /// Each laser id's range offset, metres, to be added to the decoder's current offsets
    /// (zero for a laser not calibrated).
    pub offsets_m: [f64; LASERS],
    /// Standard error of each offset, metres (`None`: not calibrated, too few returns on planes).
    pub standard_error_m: [Option<f64>; LASERS],
    /// Returns on planes per laser in the last round.
    pub returns: [usize; LASERS],
    /// The planes used.
    pub planes: Vec<PlaneSummary>,
    /// Residual sigma along the planes' normals, metres.
    pub residual_sigma_m: f64,
}

/// One plane the calibration used, sensor frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlaneSummary {
    /// Unit normal.
    pub normal: [f64; 3],
    /// Distance from the sensor, metres.
    pub distance_m: f64,
    /// Returns on it.
    pub returns: usize,
    /// Its residual sigma with the offsets applied, metres.
    pub residual_sigma_m: f64,
}

impl RangeCalibration {
    /// Laser ids not calibrated.
    pub fn uncalibrated(&self) -> Vec<usize> {
        (0..LASERS)
            .filter(|&l| self.standard_error_m[l].is_none())
            .collect()
    }
}

/// Why a recording does not calibrate.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum CalibrationError {
    /// Too few returns in the usable range.
    #[error(
        "only {found} returns lie {MIN_RANGE_M}-{MAX_RANGE_M} m from the sensor; a calibration needs a room with walls in view"
    )]
    TooFewReturns {
        /// Returns found.
        found: usize,
    },
    /// No usable plane.
    #[error(
        "no wall-like plane found ({MIN_PLANE_RETURNS}+ returns, {:.0}+ degrees wide, near vertical): park the sensor where it sees walls",
        MIN_AZIMUTH_SPAN_RAD.to_degrees()
    )]
    NoPlanes,
    /// The planes' returns scatter more than the data sheet's range accuracy: the sensor moved
    /// during the capture, or the walls are not flat.
    #[error(
        "the walls' returns scatter by {sigma_mm:.0} mm, more than the VLP-16's {:.0} mm range accuracy: the sensor must stand still during the capture, facing flat walls",
        RANGE_ACCURACY_M * 1e3
    )]
    NotStill {
        /// The residual sigma, millimetres.
        sigma_mm: f64,
    },
    /// The normal system is singular: no laser sees a plane over a usable span.
    #[error(
        "no laser sees a flat wall well enough to separate its bias from the wall's distance: the sensor must stand still during the capture, facing walls over a wide arc"
    )]
    Unresolved,
}

/// Estimate the range offsets from a static recording's points (see the module docs).
/// `config` is the decoder's that produced them.
pub fn estimate_range_offsets(
    points: &[Point],
    config: &DecoderConfig,
) -> Result<RangeCalibration, CalibrationError> {
    let vo = config.vertical_offset;
    let returns: Vec<Return> = points
        .iter()
        .map(|p| Return::of_point(p, config))
        .filter(|r| (MIN_RANGE_M..=MAX_RANGE_M).contains(&r.range_m))
        .collect();
    if returns.len() < MIN_PLANE_RETURNS {
        return Err(CalibrationError::TooFewReturns {
            found: returns.len(),
        });
    }
    let surfaces = find_planes(&returns, vo);
    let mut usable: Vec<bool> = surfaces.iter().map(|(_, u)| *u).collect();
    if !usable.iter().any(|&u| u) {
        return Err(CalibrationError::NoPlanes);
    }
    let mut offsets = [0.0; LASERS];
    let mut members: Vec<Vec<usize>> = surfaces.into_iter().map(|(m, _)| m).collect();
    let mut result = None;
    let at = |i: usize, offsets: &[f64; LASERS]| returns[i].at(offsets[returns[i].laser], vo);
    let mut settled = 0;
    for _ in 0..3 * ROUNDS {
        if settled == ROUNDS {
            break;
        }
        let used: Vec<usize> = (0..members.len()).filter(|&k| usable[k]).collect();
        let fitted: Vec<(Plane, Vec<usize>)> = used
            .iter()
            .filter_map(|&k| {
                let m = &members[k];
                fit_plane(m.iter().map(|&i| at(i, &offsets))).map(|p| (p, m.clone()))
            })
            .collect();
        if fitted.len() != used.len() {
            return Err(CalibrationError::Unresolved);
        }
        let solved = solve_offsets(&returns, &fitted, vo).ok_or(CalibrationError::Unresolved)?;
        // A plane whose returns scatter more than the others' is not one surface (a car's
        // front, a row of cabinets, two walls at a step): it leaves, and the rounds start over.
        let sigmas: Vec<f64> = solved.planes.iter().map(|p| p.residual_sigma_m).collect();
        let typical = median(&sigmas);
        let mut rejected = false;
        for (&k, &sigma) in used.iter().zip(&sigmas) {
            if sigma > MAX_PLANE_SIGMA_RATIO * typical {
                usable[k] = false;
                rejected = true;
            }
        }
        if rejected {
            settled = 0;
            if !usable.iter().any(|&u| u) {
                return Err(CalibrationError::NoPlanes);
            }
            continue;
        }
        settled += 1;
        offsets = solved.offsets_m;
        result = Some(solved);
        members = reselect(&returns, &members, &offsets, vo);
    }
    let result = result.ok_or(CalibrationError::Unresolved)?;
    if result.residual_sigma_m > RANGE_ACCURACY_M {
        return Err(CalibrationError::NotStill {
            sigma_mm: result.residual_sigma_m * 1e3,
        });
    }
    Ok(result)
}

/// Each plane refitted to its returns under `offsets`, then its returns chosen afresh from all:
/// those within 4 robust sigma of it and not within that of another plane (a corner's returns
/// belong to either, and another surface's returns in a plane's band all lie on one side of
/// it). Chosen from all returns, not the search's, so that no laser's tail stays cut by the
/// search band drawn before the offsets were known.
fn reselect(
    returns: &[Return],
    members: &[Vec<usize>],
    offsets: &[f64; LASERS],
    vo: bool,
) -> Vec<Vec<usize>> {
    let at = |i: usize| returns[i].at(offsets[returns[i].laser], vo);
    let bands: Vec<Option<(Plane, f64)>> = members
        .iter()
        .map(|m| {
            let plane = fit_plane(m.iter().map(|&i| at(i)))?;
            let res: Vec<f64> = m.iter().map(|&i| plane.residual(at(i))).collect();
            Some((plane, 4.0 * robust_sigma(&res).max(MIN_SIGMA_M)))
        })
        .collect();
    // A surface that cannot be refitted keeps no returns (and excludes none).
    let mut out = vec![Vec::new(); members.len()];
    for i in 0..returns.len() {
        let p = at(i);
        let distances: Vec<Option<(f64, f64)>> = bands
            .iter()
            .map(|b| {
                b.as_ref()
                    .map(|(plane, band)| (plane.residual(p).abs(), *band))
            })
            .collect();
        let Some(k) = distances
            .iter()
            .position(|d| d.is_some_and(|(r, band)| r <= band))
        else {
            continue;
        };
        let clear = distances
            .iter()
            .enumerate()
            .all(|(j, d)| j == k || d.is_none_or(|(r, band)| r > band));
        if clear {
            out[k].push(i);
        }
    }
    out
}

/// A plane `n . x = d` with a unit normal.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Plane {
    pub(crate) normal: V3,
    pub(crate) distance: f64,
}

impl Plane {
    pub(crate) fn residual(&self, p: V3) -> f64 {
        self.normal.dot(&p) - self.distance
    }
}

/// Total least squares plane through the points.
pub(crate) fn fit_plane(points: impl Iterator<Item = V3> + Clone) -> Option<Plane> {
    let (c, cov) = centroid_covariance(points)?;
    let (values, vectors) = symmetric_eigen3(&cov)?;
    let k = (0..3)
        .min_by(|&a, &b| values[a].total_cmp(&values[b]))
        .unwrap_or(0);
    let normal = vectors.column(k).try_normalize(0.0)?;
    Some(Plane {
        normal,
        distance: normal.dot(&c),
    })
}

/// Near-vertical planes, largest first: each the indices of its returns.
pub(crate) fn find_planes(returns: &[Return], vo: bool) -> Vec<(Vec<usize>, bool)> {
    let mut free: Vec<bool> = vec![true; returns.len()];
    let mut rng = SplitMix64(0x5eed_ca1b);
    let mut planes = Vec::new();
    for _ in 0..2 * MAX_PLANES {
        if planes.len() == MAX_PLANES {
            break;
        }
        let sample: Vec<usize> = (0..returns.len())
            .step_by(SUBSAMPLE)
            .filter(|&i| free[i])
            .collect();
        if sample.len() < 3 {
            break;
        }
        let count = |plane: &Plane| {
            sample
                .iter()
                .filter(|&&i| plane.residual(returns[i].at(0.0, vo)).abs() <= RANSAC_BAND_M)
                .count()
        };
        let mut best: Option<(usize, Plane)> = None;
        for _ in 0..HYPOTHESES {
            // Three returns near each other in the recording's order (the firing order: near in
            // azimuth), so that most triples lie on one surface.
            let first = rng.below(sample.len());
            let lo = first.saturating_sub(NEIGHBOURHOOD);
            let hi = (first + NEIGHBOURHOOD).min(sample.len() - 1);
            let pick = [
                first,
                lo + rng.below(hi - lo + 1),
                lo + rng.below(hi - lo + 1),
            ];
            let [a, b, c] = pick.map(|k| returns[sample[k]].at(0.0, vo));
            let Some(normal) = (b - a).cross(&(c - a)).try_normalize(1e-6) else {
                continue;
            };
            let plane = Plane {
                normal,
                distance: normal.dot(&a),
            };
            let n = count(&plane);
            if best.as_ref().is_none_or(|(m, _)| n > *m) {
                best = Some((n, plane));
            }
        }
        let Some((_, mut plane)) = best else { break };
        // Two least-squares refits on the sample's inliers: a triple's normal carries its
        // returns' noise over their short baseline.
        for _ in 0..2 {
            let inliers = sample
                .iter()
                .filter(|&&i| plane.residual(returns[i].at(0.0, vo)).abs() <= RANSAC_BAND_M)
                .map(|&i| returns[i].at(0.0, vo));
            match fit_plane(inliers) {
                Some(p) => plane = p,
                None => break,
            }
        }
        let members: Vec<usize> = (0..returns.len())
            .filter(|&i| free[i] && plane.residual(returns[i].at(0.0, vo)).abs() <= RANSAC_BAND_M)
            .collect();
        if members.len() < MIN_PLANE_RETURNS {
            continue;
        }
        for &i in &members {
            free[i] = false;
        }
        let usable = plane.normal[2].abs() <= MAX_NORMAL_Z
            && azimuth_span(members.iter().map(|&i| returns[i].azimuth_rad))
                >= MIN_AZIMUTH_SPAN_RAD;
        planes.push((plane, members, usable));
    }
    // A return within the band of two planes (a corner) belongs to either: it is left out, as
    // the other surface's returns caught in a plane's band all lie on one side of it.
    let all: Vec<Plane> = planes.iter().map(|(p, _, _)| *p).collect();
    planes
        .into_iter()
        .enumerate()
        .map(|(k, (_, members, usable))| {
            let members = members
                .into_iter()
                .filter(|&i| {
                    let p = returns[i].at(0.0, vo);
                    all.iter()
                        .enumerate()
                        .all(|(j, other)| j == k || other.residual(p).abs() > RANSAC_BAND_M)
                })
                .collect();
            (members, usable)
        })
        .collect()
}

/// The biases by least squares with each plane's distance and tilt free.
///
/// Row `i` on plane `k`: `y_i = n_k . (o_l + r_i u_i) = d_k + b_l (n_k . u_i) + x_i . theta_k`,
/// `x_i` the return's position along two directions in the plane (a small turn `theta_k` of the
/// plane's normal). The plane's own unknowns `[d, theta]` are eliminated (Schur complement), so
/// that a per-laser pattern a tilted plane would explain as well (lasers hit a wall at
/// heights that grow with their elevation) is not taken for bias, and the standard errors say
/// how well the two separate.
fn solve_offsets(
    returns: &[Return],
    planes: &[(Plane, Vec<usize>)],
    vo: bool,
) -> Option<RangeCalibration> {
    let mut counts = [0usize; LASERS];
    let mut ata = [[0.0; LASERS]; LASERS];
    let mut aty = [0.0; LASERS];
    let mut per_plane = Vec::with_capacity(planes.len());
    for (plane, members) in planes {
        let s = PlaneSums::of(returns, plane, members, vo, &mut counts);
        // A = sum (G'G - G'X (X'X)^-1 X'G), c = sum (G'y - G'X (X'X)^-1 X'y).
        let xx_inv_xy = solve_spd(&s.xx, &s.xy)?;
        let xx_inv_xg: Vec<[f64; 3]> = (0..LASERS)
            .map(|l| solve_spd(&s.xx, &s.gx[l]))
            .collect::<Option<_>>()?;
        for p in 0..LASERS {
            ata[p][p] += s.gg[p];
            aty[p] += s.gy[p] - dot3(s.gx[p], xx_inv_xy);
            for (q, v) in xx_inv_xg.iter().enumerate() {
                ata[p][q] -= dot3(s.gx[p], *v);
            }
        }
        per_plane.push(s);
    }
    // Lasers with too few rows are held at zero (their rows and columns replaced by identity).
    let calibrated: [bool; LASERS] = std::array::from_fn(|l| counts[l] >= MIN_LASER_RETURNS);
    if !calibrated.iter().any(|&c| c) {
        return None;
    }
    for l in (0..LASERS).filter(|&l| !calibrated[l]) {
        for row in &mut ata {
            row[l] = 0.0;
        }
        ata[l] = [0.0; LASERS];
        ata[l][l] = 1.0;
        aty[l] = 0.0;
    }
    let offsets = solve_spd(&ata, &aty)?;
    // Residuals: each plane's own unknowns refitted with the biases held.
    let (mut rss, mut rows) = (0.0, 0usize);
    let mut summaries = Vec::with_capacity(planes.len());
    for ((plane, members), s) in planes.iter().zip(&per_plane) {
        let rhs: [f64; 3] = std::array::from_fn(|a| {
            s.xy[a] - (0..LASERS).map(|l| s.gx[l][a] * offsets[l]).sum::<f64>()
        });
        let own = solve_spd(&s.xx, &rhs)?;
        let plane_rss: f64 = members
            .iter()
            .map(|&i| {
                let ret = &returns[i];
                let (g, x, y) = s.row(plane, ret, vo);
                (y - g * offsets[ret.laser] - dot3(x, own)).powi(2)
            })
            .sum();
        rss += plane_rss;
        rows += members.len();
        summaries.push(PlaneSummary {
            normal: plane.normal.into(),
            distance_m: plane.distance.abs(),
            returns: members.len(),
            residual_sigma_m: (plane_rss / members.len().max(1) as f64).sqrt(),
        });
    }
    let dof = rows.saturating_sub(3 * planes.len() + LASERS).max(1);
    let sigma = (rss / dof as f64).sqrt();
    let mut standard_error_m = [None; LASERS];
    for l in (0..LASERS).filter(|&l| calibrated[l]) {
        let mut e = [0.0; LASERS];
        e[l] = 1.0;
        let col = solve_spd(&ata, &e)?;
        standard_error_m[l] = Some(sigma * col[l].max(0.0).sqrt());
    }
    Some(RangeCalibration {
        offsets_m: std::array::from_fn(|l| if calibrated[l] { offsets[l] } else { 0.0 }),
        standard_error_m,
        returns: counts,
        planes: summaries,
        residual_sigma_m: sigma,
    })
}

/// One plane's sums for [`solve_offsets`]: `g = n . u` per laser, the plane's own regressors
/// `x = [1, t1 . p, t2 . p]` and the observation `y = n . p`.
struct PlaneSums {
    tangents: [V3; 2],
    gg: [f64; LASERS],
    gx: [[f64; 3]; LASERS],
    xx: [[f64; 3]; 3],
    gy: [f64; LASERS],
    xy: [f64; 3],
}

impl PlaneSums {
    fn of(
        returns: &[Return],
        plane: &Plane,
        members: &[usize],
        vo: bool,
        counts: &mut [usize; LASERS],
    ) -> Self {
        let mut s = Self {
            tangents: tangents(plane.normal),
            gg: [0.0; LASERS],
            gx: [[0.0; 3]; LASERS],
            xx: [[0.0; 3]; 3],
            gy: [0.0; LASERS],
            xy: [0.0; 3],
        };
        for &i in members {
            let ret = &returns[i];
            let (g, x, y) = s.row(plane, ret, vo);
            let l = ret.laser;
            counts[l] += 1;
            s.gg[l] += g * g;
            s.gy[l] += g * y;
            for a in 0..3 {
                s.gx[l][a] += g * x[a];
                s.xy[a] += x[a] * y;
                for b in 0..3 {
                    s.xx[a][b] += x[a] * x[b];
                }
            }
        }
        s
    }

    /// A return's `(g, x, y)`.
    fn row(&self, plane: &Plane, ret: &Return, vo: bool) -> (f64, [f64; 3], f64) {
        let p = ret.at(0.0, vo);
        let x = [1.0, self.tangents[0].dot(&p), self.tangents[1].dot(&p)];
        (plane.normal.dot(&ret.ray), x, plane.normal.dot(&p))
    }
}

/// Two unit vectors spanning the plane orthogonal to `n`.
fn tangents(n: V3) -> [V3; 2] {
    let helper = if n[2].abs() < 0.9 { V3::z() } else { V3::x() };
    let a = n.cross(&helper).normalize();
    [a, n.cross(&a)]
}

fn dot3(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// The median (the upper one of an even count).
pub(crate) fn median(values: &[f64]) -> f64 {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(0.0)
}

/// Sigma from the median absolute deviation (0 for no values).
fn robust_sigma(values: &[f64]) -> f64 {
    let centre = median(values);
    let deviations: Vec<f64> = values.iter().map(|x| (x - centre).abs()).collect();
    1.4826 * median(&deviations)
}

/// The smallest arc holding all the azimuths, radians.
fn azimuth_span(azimuths: impl Iterator<Item = f64>) -> f64 {
    const BINS: usize = 360;
    let mut seen = [false; BINS];
    for a in azimuths {
        let k =
            (a.rem_euclid(std::f64::consts::TAU) / std::f64::consts::TAU * BINS as f64) as usize;
        seen[k.min(BINS - 1)] = true;
    }
    if !seen.contains(&true) {
        return 0.0;
    }
    // The longest run of empty bins (cyclic) is the gap; the span is the rest.
    let mut longest = 0;
    let mut run = 0;
    for k in 0..2 * BINS {
        if seen[k % BINS] {
            run = 0;
        } else {
            run += 1;
            longest = longest.max(run.min(BINS));
        }
    }
    (BINS - longest) as f64 / BINS as f64 * std::f64::consts::TAU
}

/// A small seeded generator (splitmix64) for the plane search: the same points give the same
/// planes.
struct SplitMix64(u64);

impl SplitMix64 {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::decoder::{ELEVATION_DEG, ReturnKind};

    /// Returns of a static sensor in a box room (walls at `walls` along +x, -x, +y, -y), every
    /// laser every 0.05 degrees (four revolutions' worth), with `bias` per laser and a deterministic pseudo-noise.
    fn room(walls: [f64; 4], bias: [f64; LASERS], noise_m: f64) -> Vec<Point> {
        let mut rng = SplitMix64(7);
        let mut out = Vec::new();
        for step in 0..7200 {
            let az = f64::from(step) * 0.05_f64.to_radians();
            for laser in 0..LASERS {
                let w = f64::from(ELEVATION_DEG[laser]).to_radians();
                // Manual frame: x = r cos w sin a, y = r cos w cos a.
                let u = [w.cos() * az.sin(), w.cos() * az.cos(), w.sin()];
                let z0 = f64::from(VERTICAL_OFFSET_MM[laser]) * 1e-3;
                let mut t = f64::INFINITY;
                for (k, &d) in walls.iter().enumerate() {
                    let (axis, sign) = (k / 2, if k % 2 == 0 { 1.0 } else { -1.0 });
                    let c = u[axis] * sign;
                    if c > 1e-9 {
                        t = t.min(d / c);
                    }
                }
                // Floor 1.5 m below, ceiling 3 m above (not planes the calibration uses).
                if u[2] < 0.0 {
                    t = t.min((1.5 + z0) / -u[2]);
                } else if u[2] > 0.0 {
                    t = t.min((3.0 - z0) / u[2]);
                }
                let uniform = (rng.next() >> 11) as f64 / (1u64 << 53) as f64;
                let r = t + bias[laser] + noise_m * (2.0 * uniform - 1.0) * 3.0_f64.sqrt();
                out.push(Point {
                    x_m: (r * u[0]) as f32,
                    y_m: (r * u[1]) as f32,
                    z_m: (r * u[2] + z0) as f32,
                    time_us: 0.0,
                    azimuth_rad: az as f32,
                    intensity: 50,
                    ring: crate::decoder::ring_of_laser(laser),
                    laser_id: laser as u8,
                    return_kind: ReturnKind::Strongest,
                });
            }
        }
        out
    }

    fn planted() -> [f64; LASERS] {
        std::array::from_fn(|l| 0.004 * ((l as f64 * 1.7).sin() * 5.0).round())
    }

    #[test]
    fn recovers_planted_biases_in_a_room() {
        let bias = planted();
        let points = room([4.0, 5.0, 3.5, 6.0], bias, 0.015);
        let cal = estimate_range_offsets(&points, &DecoderConfig::default()).unwrap();
        assert!(cal.planes.len() >= 4, "{cal:?}");
        for (l, &b) in bias.iter().enumerate() {
            let se = cal.standard_error_m[l].unwrap();
            let err = cal.offsets_m[l] - b;
            // Within a millimetre: with 1.5 cm of range noise a common +0.5 mm is left (the
            // returns where the walls meet the floor, the ceiling and each other).
            assert!(
                err.abs() < 1e-3,
                "laser {l}: {} vs {b} (se {se})",
                cal.offsets_m[l]
            );
            assert!(se < 1e-3, "laser {l}: se {se}");
        }
    }

    #[test]
    fn applying_the_offsets_leaves_nothing_to_calibrate() {
        let bias = planted();
        let points = room([4.0, 5.0, 3.5, 6.0], bias, 0.0);
        let config = DecoderConfig::default();
        let cal = estimate_range_offsets(&points, &config).unwrap();
        // Decoding with the offsets is the same as moving each return back along its ray.
        let corrected: Vec<Point> = points
            .iter()
            .map(|p| {
                let r = Return::of_point(p, &config);
                let q = r.at(cal.offsets_m[r.laser], true);
                Point {
                    x_m: q[0] as f32,
                    y_m: q[1] as f32,
                    z_m: q[2] as f32,
                    ..*p
                }
            })
            .collect();
        let again = estimate_range_offsets(&corrected, &config).unwrap();
        for l in 0..LASERS {
            assert!(
                again.offsets_m[l].abs() < 5e-4,
                "laser {l}: {}",
                again.offsets_m[l]
            );
        }
    }

    #[test]
    fn a_scatter_beyond_the_data_sheet_is_refused() {
        // 3.5 cm RMS along the rays (uniform, up to 6 cm): more than the data sheet allows, as
        // a moving sensor's smeared walls are.
        let points = room([4.0, 5.0, 3.5, 6.0], [0.0; LASERS], 0.035);
        let err = estimate_range_offsets(&points, &DecoderConfig::default()).unwrap_err();
        assert!(matches!(err, CalibrationError::NotStill { .. }), "{err}");
        assert!(err.to_string().contains("stand still"), "{err}");
    }

    #[test]
    fn an_open_field_names_what_is_missing() {
        // Only the floor and the ceiling: no wall.
        let points = room([1e4, 1e4, 1e4, 1e4], [0.0; LASERS], 0.01);
        let err = estimate_range_offsets(&points, &DecoderConfig::default()).unwrap_err();
        assert!(
            matches!(
                err,
                CalibrationError::NoPlanes | CalibrationError::TooFewReturns { .. }
            ),
            "{err}"
        );
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]
        /// Any points (a capture of anything, including a few repeated returns) give offsets or
        /// an error, never a panic, and offsets are finite.
        #[test]
        fn arbitrary_points_never_panic(
            raw in proptest::collection::vec(
                (-50.0f32..50.0, -50.0f32..50.0, -10.0f32..10.0, 0u8..16, 0.0f32..6.3),
                0..3000,
            ),
            copies in 1usize..4,
        ) {
            let points: Vec<Point> = raw
                .iter()
                .flat_map(|&(x, y, z, laser, az)| {
                    std::iter::repeat_n(
                        Point {
                            x_m: x,
                            y_m: y,
                            z_m: z,
                            time_us: 0.0,
                            azimuth_rad: az,
                            intensity: 0,
                            ring: laser,
                            laser_id: laser,
                            return_kind: ReturnKind::Strongest,
                        },
                        copies,
                    )
                })
                .collect();
            if let Ok(cal) = estimate_range_offsets(&points, &DecoderConfig::default()) {
                proptest::prop_assert!(cal.offsets_m.iter().all(|o| o.is_finite()));
            }
        }
    }

    #[test]
    fn a_span_is_the_arc_holding_the_azimuths() {
        let deg = |d: f64| d.to_radians();
        let span = azimuth_span([deg(350.0), deg(355.0), deg(5.0), deg(10.0)].into_iter());
        assert!((span - deg(21.0)).abs() < deg(1.5), "{}", span.to_degrees());
    }
}
