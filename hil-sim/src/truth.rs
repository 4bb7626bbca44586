//! True passing angles of a simulated vehicle, computed from its geometry by a deliberately simple
//! routine that shares nothing with the onboard angle calculator.
//!
//! # Method (brute force, side view)
//! Work in the vehicle's side view (x forward, z up, ground z = 0). A tyre of static loaded radius r
//! is the circle centred at `(x_axle, r)`. A *ramp line* tangent to the front tyre at slope `a`,
//! rising toward the front, is the set of points whose signed distance from the tyre centre along the
//! line's downward normal `n(a) = (sin a, -cos a)` equals r; a point P lies *on or below* the line
//! exactly when `n(a) . (P - centre) >= r`, i.e. `d sin a + (r - z) cos a >= r` with `d = x - x_axle`.
//!
//! * **Approach**: rotate the tangent line about the front tyre from a = 0 upward in steps of
//!   [`COARSE_STEP_RAD`]; the approach angle is the first slope at which any outline point in the
//!   zone ahead of the tyre touches the line, refined by bisection to [`TOLERANCE_RAD`].
//! * **Departure**: the same about the rear tyre, mirrored (the line rises toward the rear).
//! * **Breakover**: for every outline point P between the axles, rotate a line about each tyre until
//!   it reaches P (same stepping and bisection), giving `a_front(P)` and `a_rear(P)`; the breakover
//!   angle is the minimum of `a_front(P) + a_rear(P)`, the supplement of the largest crest angle
//!   (49 CFR 523.2 / EU ramp angle).
//!
//! Outline points come from [`Vehicle::outline_points`]; points inside a tyre circle (hidden in the
//! wheel) are skipped. Mesh parts contribute every vertex (a tangent line in the side view first
//! touches a polyhedron at one of its vertices, so vertices suffice for approach and departure) and
//! the lowest samples along their edges (a breakover crest can touch an edge between vertices); a
//! mesh part's `rigid` flag applies to all its points. The tests cross-check this stepping search against the closed form
//! `a = asin(r / hypot(d, r - z)) - atan2(r - z, d)` (docs/architecture.md section 6 step 8).

use crate::vehicle::{OutlinePoint, Vehicle};

/// Step of the brute-force rotation, radians (0.1 degree).
pub const COARSE_STEP_RAD: f64 = 0.1 * std::f64::consts::PI / 180.0;

/// Bisection tolerance, radians.
pub const TOLERANCE_RAD: f64 = 1e-9;

/// Which points count for approach and departure: the calculator's own zone type (one name per
/// concept), though the truth computes its angles independently of the calculator.
pub use angles::Zone;

/// Options of the true-angle computation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TruthOptions {
    /// Approach/departure zone.
    pub zone: Zone,
    /// Count flexible parts (CFR: any underside point) or only rigid ones (EU).
    pub include_flexible: bool,
    /// Outline sampling step, metres.
    pub spacing_m: f64,
}

impl Default for TruthOptions {
    fn default() -> Self {
        Self {
            zone: Zone::Tyre,
            include_flexible: true,
            spacing_m: 0.002,
        }
    }
}

/// One true angle and the outline point that limits it.
#[derive(Clone, Debug, PartialEq)]
pub struct TrueAngle {
    /// The angle, radians.
    pub angle_rad: f64,
    /// The limiting outline point (`None` if no point lies in the zone: the angle is then 90 degrees).
    pub witness: Option<OutlinePoint>,
}

/// The three true angles.
#[derive(Clone, Debug, PartialEq)]
pub struct TrueAngles {
    /// Approach angle.
    pub approach: TrueAngle,
    /// Departure angle.
    pub departure: TrueAngle,
    /// Ramp breakover angle (supplement of the crest angle).
    pub breakover: TrueAngle,
}

/// Compute the true angles of `vehicle` by brute-force rotation (see the module docs).
pub fn true_angles(vehicle: &Vehicle, options: &TruthOptions) -> TrueAngles {
    let points: Vec<OutlinePoint> = vehicle
        .outline_points(options.spacing_m)
        .into_iter()
        .filter(|p| options.include_flexible || p.rigid)
        .collect();
    let r = vehicle.tyre.radius_m;
    let front_x = 0.0;
    let rear_x = -vehicle.wheelbase_m;
    let zone_margin = match options.zone {
        Zone::Tyre => r,
        Zone::Axle => 0.0,
    };
    // Side-view distances measured away from each tyre, outward (approach, departure) or inward.
    let outside = |p: &OutlinePoint, d: f64| d > 0.0 && d.hypot(r - p.z_m) > r;
    let approach: Vec<(f64, &OutlinePoint)> = points
        .iter()
        .map(|p| (p.x_m - front_x, p))
        .filter(|(d, p)| *d > zone_margin && outside(p, *d))
        .collect();
    let departure: Vec<(f64, &OutlinePoint)> = points
        .iter()
        .map(|p| (rear_x - p.x_m, p))
        .filter(|(d, p)| *d > zone_margin && outside(p, *d))
        .collect();
    TrueAngles {
        approach: first_contact(&approach, r),
        departure: first_contact(&departure, r),
        breakover: breakover(&points, r, front_x, rear_x),
    }
}

/// Whether the point at distance `d` from the tyre, height `z`, is on or below the tangent line of
/// slope `a_rad` (the only geometric test the brute force uses).
fn touches(d: f64, z: f64, r: f64, a_rad: f64) -> bool {
    let (s, c) = a_rad.sin_cos();
    d * s + (r - z) * c >= r
}

/// Rotate the tangent line from 0 upward until the first of `points` touches it.
fn first_contact(points: &[(f64, &OutlinePoint)], r: f64) -> TrueAngle {
    let any_touch = |a: f64| points.iter().any(|(d, p)| touches(*d, p.z_m, r, a));
    let Some(a) = rotate_until(any_touch) else {
        return TrueAngle {
            angle_rad: std::f64::consts::FRAC_PI_2,
            witness: None,
        };
    };
    let witness = points
        .iter()
        .find(|(d, p)| touches(*d, p.z_m, r, a))
        .map(|(_, p)| (*p).clone());
    TrueAngle {
        angle_rad: a,
        witness,
    }
}

/// Step `a` from 0 to 90 degrees until `hit(a)`, then bisect to [`TOLERANCE_RAD`]; returns the
/// smallest slope found that hits (`None` if nothing hits below 90 degrees).
fn rotate_until(hit: impl Fn(f64) -> bool) -> Option<f64> {
    let steps = (std::f64::consts::FRAC_PI_2 / COARSE_STEP_RAD).ceil() as usize;
    let mut lo = 0.0;
    for k in 0..=steps {
        let a = (k as f64 * COARSE_STEP_RAD).min(std::f64::consts::FRAC_PI_2);
        if hit(a) {
            if k == 0 {
                return Some(0.0);
            }
            let mut hi = a;
            while hi - lo > TOLERANCE_RAD {
                let mid = 0.5 * (lo + hi);
                if hit(mid) { hi = mid } else { lo = mid }
            }
            return Some(hi);
        }
        lo = a;
    }
    None
}

fn breakover(points: &[OutlinePoint], r: f64, front_x: f64, rear_x: f64) -> TrueAngle {
    let mut best = TrueAngle {
        angle_rad: std::f64::consts::PI,
        witness: None,
    };
    for p in points {
        let (d_front, d_rear) = (front_x - p.x_m, p.x_m - rear_x);
        let inside_either = d_front.hypot(r - p.z_m) <= r || d_rear.hypot(r - p.z_m) <= r;
        if d_front <= 0.0 || d_rear <= 0.0 || inside_either {
            continue;
        }
        let a_front = rotate_until(|a| touches(d_front, p.z_m, r, a));
        let a_rear = rotate_until(|a| touches(d_rear, p.z_m, r, a));
        if let (Some(f), Some(b)) = (a_front, a_rear)
            && f + b < best.angle_rad
        {
            best = TrueAngle {
                angle_rad: f + b,
                witness: Some(p.clone()),
            };
        }
    }
    best
}

/// The closed form of docs/architecture.md section 6 step 8, used only to cross-check the brute force: slope of
/// the plane tangent to a tyre of radius `r` through a point at horizontal distance `d` from the wheel
/// centre and height `z`.
pub fn closed_form_rad(d: f64, z: f64, r: f64) -> f64 {
    (r / d.hypot(r - z)).asin() - (r - z).atan2(d)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vehicle::tests::test_sedan;

    const TOL: f64 = 1e-7;

    fn opts() -> TruthOptions {
        TruthOptions {
            spacing_m: 0.005,
            ..TruthOptions::default()
        }
    }

    #[test]
    fn closed_form_sanity_values() {
        // z = r, d = 2r gives 30 degrees; z = 0 gives 0; r -> 0 gives atan(z/d).
        assert!((closed_form_rad(0.6, 0.3, 0.3).to_degrees() - 30.0).abs() < 1e-9);
        assert!(closed_form_rad(0.8, 0.0, 0.4).abs() < 1e-12);
        assert!((closed_form_rad(0.9, 0.3, 1e-9) - (0.3f64 / 0.9).atan()).abs() < 1e-6);
        // The architecture document's magnitude check: d = 800 mm, z = 350 mm, r = 400 mm -> 26.4 degrees.
        assert!((closed_form_rad(0.8, 0.35, 0.4).to_degrees() - 26.4).abs() < 0.05);
    }

    #[test]
    fn brute_force_matches_closed_form_at_single_points() {
        for &(d, z, r) in &[
            (0.6, 0.3, 0.3),
            (0.9, 0.31, 0.33),
            (1.5, 0.05, 0.4),
            (0.4, 0.6, 0.3),
        ] {
            let a = rotate_until(|a| touches(d, z, r, a)).expect("point is reachable");
            assert!((a - closed_form_rad(d, z, r)).abs() < TOL, "d={d} z={z}");
        }
    }

    #[test]
    fn approach_and_departure_match_closed_form_minimum_over_vertices() {
        // The line sweeps a region that grows monotonically, so the first contact with a polyline is
        // at a vertex: the closed form over vertices must equal the brute force over dense samples.
        let v = test_sedan();
        let t = true_angles(&v, &opts());
        let r = v.tyre.radius_m;
        let verts = v.outline_vertices();
        let min_over = |f: &dyn Fn(&OutlinePoint) -> Option<f64>| {
            verts.iter().filter_map(f).fold(f64::INFINITY, f64::min)
        };
        let approach = min_over(&|p| (p.x_m > r).then(|| closed_form_rad(p.x_m, p.z_m, r)));
        let rear_x = -v.wheelbase_m;
        let departure =
            min_over(&|p| (rear_x - p.x_m > r).then(|| closed_form_rad(rear_x - p.x_m, p.z_m, r)));
        assert!(
            (t.approach.angle_rad - approach).abs() < TOL,
            "{} vs {approach}",
            t.approach.angle_rad
        );
        assert!((t.departure.angle_rad - departure).abs() < TOL);
        assert_eq!(
            t.approach.witness.as_ref().map(|w| w.source.as_str()),
            Some("front overhang")
        );
        // The test vehicle's exhaust hangs below the rear overhang and limits the departure angle.
        assert_eq!(
            t.departure.witness.as_ref().map(|w| w.source.as_str()),
            Some("exhaust")
        );
    }

    #[test]
    fn breakover_matches_closed_form_over_the_same_samples() {
        let v = test_sedan();
        let t = true_angles(&v, &opts());
        let (r, wb) = (v.tyre.radius_m, v.wheelbase_m);
        let expected = v
            .outline_points(opts().spacing_m)
            .iter()
            .filter(|p| p.x_m < 0.0 && p.x_m > -wb)
            .filter(|p| (-p.x_m).hypot(r - p.z_m) > r && (p.x_m + wb).hypot(r - p.z_m) > r)
            .map(|p| closed_form_rad(-p.x_m, p.z_m, r) + closed_form_rad(p.x_m + wb, p.z_m, r))
            .fold(f64::INFINITY, f64::min);
        assert!((t.breakover.angle_rad - expected).abs() < 2.0 * TOL);
    }

    #[test]
    fn flat_floor_breakover_is_limited_at_mid_wheelbase() {
        let mut v = test_sedan();
        v.underside.as_mut().expect("prism body").between.points = vec![[-0.45, 0.2], [-2.35, 0.2]];
        let t = true_angles(
            &v,
            &TruthOptions {
                spacing_m: 0.001,
                ..opts()
            },
        );
        let (r, wb) = (v.tyre.radius_m, v.wheelbase_m);
        let expected = 2.0 * closed_form_rad(wb / 2.0, 0.2, r);
        assert!((t.breakover.angle_rad - expected).abs() < 1e-6);
        let w = t.breakover.witness.expect("witness");
        assert!((w.x_m + wb / 2.0).abs() < 0.002, "apex at {}", w.x_m);
    }

    #[test]
    fn flexible_parts_only_count_when_asked() {
        let mut v = test_sedan();
        v.parts.push(crate::vehicle::Part::Box {
            name: "air dam".into(),
            min_m: [0.7, -0.6, 0.08],
            max_m: [0.75, 0.6, 0.3],
            rigid: false,
        });
        let all = true_angles(&v, &opts());
        let rigid = true_angles(
            &v,
            &TruthOptions {
                include_flexible: false,
                ..opts()
            },
        );
        assert_eq!(
            all.approach.witness.as_ref().map(|w| w.source.as_str()),
            Some("air dam")
        );
        assert!(all.approach.angle_rad < rigid.approach.angle_rad);
    }
}
