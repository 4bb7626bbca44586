//! How far the sensor travelled between two parked captures, from the walls both see: the
//! reference for the wheels' distance scale. Pure: returns in, a distance out.
//!
//! # Why
//! Mecanum wheels report a distance off by a nearly constant factor on one floor (roller wear,
//! load, the floor's grip: up to a few per cent). Under a vehicle the laser fixes the travel only
//! partly, so the trajectory, and the distance between the parts it places (an axle and a mud
//! flap behind it), keep much of that factor (decision record 043). A wall seen from two parked
//! positions gives the travel between them to a millimetre.
//!
//! # Model
//! A wall is a plane `n . x = d` in the sensor frame, `d` its distance. Parked at the start and
//! again after driving by `t` (start frame), the same wall lies at `d' = d - n . t`; a turn of
//! the sensor about its own origin leaves `d'` unchanged. The robot drives on its floor, so `t`
//! lies in the sensor's x-y plane: walls ahead or behind and walls beside the path give both of
//! its components by weighted least squares (weights `1 / var(d - d')`), and the travel is its
//! length. With walls ahead or behind alone, the sideways part is taken as zero (the robot
//! drives straight) and the travel is the part along the wheels' direction. The wheels'
//! direction is not used otherwise: their heading drifts by a degree or two over a drive, and
//! its cosine would put 0.05 % into the scale.
//!
//! # Steps
//! 1. Each capture's walls: the near-vertical planes of [`super::calibration`]'s search (same
//!    range limits, inlier band and size), each refitted (total least squares), with its residual
//!    sigma; a plane scattering more than [`super::calibration::MAX_PLANE_SIGMA_RATIO`] times the
//!    median is not one flat surface and is left out; a median sigma above the data sheet's range
//!    accuracy is refused (the sensor moved).
//! 2. Matching: a start wall and an end wall whose normals lie within [`MAX_TURN_RAD`] of each
//!    other and whose distances differ by what the expected travel predicts within
//!    [`MATCH_TOLERANCE`] of it (the wheels' distance is known to a few per cent); the nearest
//!    such pair. At least one matched wall must face the travel (`|n . u|` at least
//!    [`MIN_FACING`]).
//! 3. Standard error: each distance's `sigma / sqrt(returns)` propagated, or, with more walls
//!    than unknowns, the residuals' scatter if that is larger (a wall that is not flat, a
//!    sideways drift the model neglects). Approximate: returns taken as independent.

use passangle_geom::{V3, solve_spd};
use thiserror::Error;

use super::calibration::{
    CalibrationError, MAX_PLANE_SIGMA_RATIO, MAX_RANGE_M, MIN_PLANE_RETURNS, MIN_RANGE_M,
    PlaneSummary, Return, find_planes, fit_plane, median,
};
use super::decoder::RANGE_ACCURACY_M;

/// Least `|n . u|` of at least one matched wall: one within 60 degrees of facing the travel.
pub const MIN_FACING: f64 = 0.5;
/// Largest turn of a wall's normal between the captures (radians): the robot drives straight.
pub const MAX_TURN_RAD: f64 = 0.087;
/// A start and an end wall pair up when their distances differ by the expected travel within
/// this fraction of it (the wheels' scale error is a few per cent at most).
pub const MATCH_TOLERANCE: f64 = 0.1;

/// The travel between two captures.
#[derive(Debug, Clone, PartialEq)]
pub struct Travel {
    /// Distance along the direction of travel, metres.
    pub distance_m: f64,
    /// Its standard error, metres.
    pub standard_error_m: f64,
    /// The walls used: (start, end) and each one's estimate of the distance, metres.
    pub walls: Vec<(PlaneSummary, PlaneSummary, f64)>,
}

/// Why two captures give no travel.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum TravelError {
    /// The start capture's walls.
    #[error("the capture before the drive: {0}")]
    Start(CalibrationError),
    /// The end capture's walls.
    #[error("the capture after the drive: {0}")]
    End(CalibrationError),
    /// No wall facing the travel is seen from both positions.
    #[error(
        "no wall facing the direction of travel is seen from both ends of the drive: drive toward or away from a wall within {MAX_RANGE_M} m"
    )]
    NoCommonWall,
}

/// The walls of one parked capture, given as positions in the sensor frame (metres), each
/// with its normal pointing away from the sensor (step 1 of the module docs).
pub fn walls_of(points: &[V3]) -> Result<Vec<PlaneSummary>, CalibrationError> {
    // The planes are fitted to the points as they are: each return's ray from the sensor's
    // centre (the lasers' vertical offsets move a return by under 3 cm along a wall, not off it).
    let returns: Vec<Return> = points
        .iter()
        .filter_map(|p| {
            let range_m = p.norm();
            (MIN_RANGE_M..=MAX_RANGE_M)
                .contains(&range_m)
                .then(|| Return {
                    laser: 0,
                    ray: p / range_m,
                    range_m,
                    azimuth_rad: p[0].atan2(p[1]),
                })
        })
        .collect();
    if returns.len() < MIN_PLANE_RETURNS {
        return Err(CalibrationError::TooFewReturns {
            found: returns.len(),
        });
    }
    let mut out: Vec<PlaneSummary> = find_planes(&returns, false)
        .into_iter()
        .filter(|(_, usable)| *usable)
        .filter_map(|(members, _)| {
            let at = |i: &usize| returns[*i].at(0.0, false);
            let mut plane = fit_plane(members.iter().map(at))?;
            if plane.distance < 0.0 {
                plane.normal = -plane.normal;
                plane.distance = -plane.distance;
            }
            let ss: f64 = members.iter().map(|i| plane.residual(at(i)).powi(2)).sum();
            Some(PlaneSummary {
                normal: plane.normal.into(),
                distance_m: plane.distance,
                returns: members.len(),
                residual_sigma_m: (ss / members.len() as f64).sqrt(),
            })
        })
        .collect();
    if out.is_empty() {
        return Err(CalibrationError::NoPlanes);
    }
    let sigmas: Vec<f64> = out.iter().map(|p| p.residual_sigma_m).collect();
    let typical = median(&sigmas);
    if typical > RANGE_ACCURACY_M {
        return Err(CalibrationError::NotStill {
            sigma_mm: typical * 1e3,
        });
    }
    out.retain(|p| p.residual_sigma_m <= MAX_PLANE_SIGMA_RATIO * typical);
    Ok(out)
}

/// The travel from the `start` walls' position to the `end` walls', expected along
/// `direction` (a unit vector in the start capture's sensor frame, the wheels') by about
/// `expected_m` (the wheels' distance); steps 2-3 of the module docs.
pub fn travel_between(
    start: &[PlaneSummary],
    end: &[PlaneSummary],
    direction: [f64; 3],
    expected_m: f64,
) -> Result<Travel, TravelError> {
    let u = V3::from(direction);
    let mut matched: Vec<Matched> = Vec::new();
    for a in start {
        let na = V3::from(a.normal);
        let predicted = a.distance_m - na.dot(&u) * expected_m;
        let best = end
            .iter()
            .filter(|b| na.dot(&V3::from(b.normal)) >= MAX_TURN_RAD.cos())
            .map(|b| (b, (b.distance_m - predicted).abs()))
            .filter(|(_, miss)| *miss <= MATCH_TOLERANCE * expected_m.abs())
            .min_by(|x, y| x.1.total_cmp(&y.1));
        if let Some((b, _)) = best {
            let n = (na + V3::from(b.normal)).normalize();
            let variance = |p: &PlaneSummary| p.residual_sigma_m.powi(2) / p.returns.max(1) as f64;
            let weight = 1.0 / (variance(a) + variance(b)).max(1e-12);
            matched.push((*a, *b, n, a.distance_m - b.distance_m, weight));
        }
    }
    if !matched.iter().any(|m| m.2.dot(&u).abs() >= MIN_FACING) {
        return Err(TravelError::NoCommonWall);
    }
    let Solve {
        t,
        information,
        dof,
    } = solve_travel(&matched, u);
    let distance_m = t.norm();
    let along = t / distance_m.max(1e-12);
    // Each wall's residual against the solved travel, for the scatter.
    let chi2: f64 = matched
        .iter()
        .map(|m| m.4 * (m.2.dot(&t) - m.3).powi(2))
        .sum();
    let propagated = information.recip().sqrt();
    let scatter = if dof > 0 {
        (chi2 / dof as f64 / information).sqrt()
    } else {
        0.0
    };
    let walls = matched
        .iter()
        .filter(|m| m.2.dot(&along).abs() >= MIN_FACING)
        .map(|m| (m.0, m.1, m.3 / m.2.dot(&along)))
        .collect();
    Ok(Travel {
        distance_m,
        standard_error_m: propagated.max(scatter),
        walls,
    })
}

/// A matched wall: (start, end, mean normal, change of distance `d - d'`, weight).
type Matched = (PlaneSummary, PlaneSummary, V3, f64, f64);

/// The weighted least squares of `n . t = d - d'` over the matched walls (module docs), solved
/// once.
struct Solve {
    /// The travel, sensor frame, in the plane of the sensor's x and y.
    t: V3,
    /// Information (inverse variance) on the travel's length, along `t`.
    information: f64,
    /// Walls beyond the unknowns.
    dof: usize,
}

/// The travel `t` (in the plane of the sensor's x and y: the robot drives on its floor) by
/// weighted least squares over the matched walls: both components where the walls determine
/// them (walls ahead or behind and walls beside the path: the weaker direction holds at least a
/// hundredth of the stronger's information), else only the part along `u` (walls ahead or
/// behind alone: the sideways part is the wheels', zero).
fn solve_travel(matched: &[Matched], u: V3) -> Solve {
    let mut ata = [[0.0; 2]; 2];
    let mut atb = [0.0; 2];
    for (_, _, n, dd, w) in matched {
        let a = [n[0], n[1]];
        for i in 0..2 {
            atb[i] += w * a[i] * dd;
            for j in 0..2 {
                ata[i][j] += w * a[i] * a[j];
            }
        }
    }
    let det = ata[0][0] * ata[1][1] - ata[0][1] * ata[1][0];
    let trace = ata[0][0] + ata[1][1];
    if det > 1e-2 * (0.5 * trace).powi(2)
        && let Some([tx, ty]) = solve_spd(&ata, &atb)
    {
        let t = V3::new(tx, ty, 0.0);
        let along = t / t.norm().max(1e-12);
        // var(along . t) = along^T (A^T W A)^-1 along.
        let variance = solve_spd(&ata, &[along[0], along[1]])
            .map_or(f64::INFINITY, |x| x[0] * along[0] + x[1] * along[1]);
        return Solve {
            t,
            information: variance.recip(),
            dof: matched.len().saturating_sub(2),
        };
    }
    let (num, den) = matched
        .iter()
        .fold((0.0, 0.0), |(num, den), (_, _, n, dd, w)| {
            let f = n.dot(&u);
            (num + w * f * dd, den + w * f * f)
        });
    Solve {
        t: u * (num / den),
        information: den,
        dof: matched.len().saturating_sub(1),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn wall(normal: [f64; 3], distance_m: f64) -> PlaneSummary {
        PlaneSummary {
            normal,
            distance_m,
            returns: 20_000,
            residual_sigma_m: 0.01,
        }
    }

    #[test]
    fn the_walls_ahead_and_behind_give_the_travel() {
        // Driving 3.03 m along -x: the wall at +x recedes, the wall at -x comes nearer.
        let start = [wall([1.0, 0.0, 0.0], 8.0), wall([-1.0, 0.0, 0.0], 4.0)];
        let end = [wall([1.0, 0.0, 0.0], 11.03), wall([-1.0, 0.0, 0.0], 0.97)];
        let t = travel_between(&start, &end, [-1.0, 0.0, 0.0], 2.95).unwrap();
        assert!((t.distance_m - 3.03).abs() < 1e-9, "{t:?}");
        assert_eq!(t.walls.len(), 2);
        assert!(
            t.standard_error_m > 0.0 && t.standard_error_m < 1e-3,
            "{t:?}"
        );
    }

    #[test]
    fn a_wall_beside_the_path_gives_the_travels_sideways_part() {
        // The robot drives 3 m at 3 degrees off the wheels' direction (their heading drifted):
        // the walls ahead and behind see only the part along x, the side wall the rest.
        let theta = 3.0_f64.to_radians();
        let t = [-3.0 * theta.cos(), 3.0 * theta.sin(), 0.0];
        let moved = |normal: [f64; 3], d: f64| {
            let n = V3::from(normal);
            wall(normal, d - n.dot(&V3::from(t)))
        };
        let normals = [[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let start: Vec<_> = normals.iter().map(|&n| wall(n, 6.0)).collect();
        let end: Vec<_> = normals.iter().map(|&n| moved(n, 6.0)).collect();
        let got = travel_between(&start, &end, [-1.0, 0.0, 0.0], 2.9).unwrap();
        assert!((got.distance_m - 3.0).abs() < 1e-9, "{got:?}");
        // Walls ahead and behind alone: the part along the wheels' direction.
        let alone = travel_between(&start[..2], &end[..2], [-1.0, 0.0, 0.0], 2.9).unwrap();
        assert!(
            (alone.distance_m - 3.0 * theta.cos()).abs() < 1e-9,
            "{alone:?}"
        );
    }

    #[test]
    fn walls_along_the_travel_and_far_from_the_expected_distance_are_not_used() {
        let start = [wall([0.0, 1.0, 0.0], 3.0), wall([1.0, 0.0, 0.0], 8.0)];
        // The side wall stays put; the end wall moved by 1 m, not the 3 m expected.
        let end = [wall([0.0, 1.0, 0.0], 3.0), wall([1.0, 0.0, 0.0], 9.0)];
        let e = travel_between(&start, &end, [-1.0, 0.0, 0.0], 3.0).unwrap_err();
        assert_eq!(e, TravelError::NoCommonWall);
        assert!(e.to_string().contains("no wall facing"), "{e}");
    }

    #[test]
    fn two_walls_that_disagree_widen_the_standard_error() {
        let start = [wall([1.0, 0.0, 0.0], 8.0), wall([-1.0, 0.0, 0.0], 6.0)];
        let end = [wall([1.0, 0.0, 0.0], 11.00), wall([-1.0, 0.0, 0.0], 2.98)];
        let t = travel_between(&start, &end, [-1.0, 0.0, 0.0], 3.0).unwrap();
        assert!((t.distance_m - 3.01).abs() < 1e-9, "{t:?}");
        assert!((t.standard_error_m - 0.01).abs() < 1e-9, "{t:?}");
    }
}
