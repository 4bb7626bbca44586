//! Measurement uncertainty of the angles and the clearance (GUM, first-order propagation).
//!
//! Every angle is a function of a few measured inputs: the witness's height `z` and position `x`
//! (vehicle frame), the axle's position and its static loaded radius `r`, through
//! [`crate::tangent_slope`]. Each input gets a standard uncertainty from this run's own data;
//! the angle's sensitivity to each is a central difference of the same function the angle came
//! from; the contributions add in quadrature and the expanded uncertainty is `U = 2 u` (coverage
//! factor k = 2, about 95 % for a normal distribution).
//!
//! The inputs' standard uncertainties:
//! - **witness height**: the noise sigma normal to the underside ([`crate::AnglesResult::noise_sigma_m`]):
//!   the lowest mode of an envelope bin is located to about one noise sigma;
//! - **witness position**: a uniform distribution over the envelope bin, `bin / sqrt(12)`;
//! - **loaded radius and axle position**: the tyre fits' covariances (short arcs give large
//!   variances), the axle's mean over its tyres, or half the difference between the two tyres if
//!   that is larger (a one-degree-of-freedom check that the fits agree), plus one noise sigma for the
//!   silhouette's outward bias (a slice's outermost point is the largest of noisy samples);
//! - **ground**: the floor's own noise sigma about its plane (flatness and range noise), as an
//!   offset of the witness's height above the floor;
//! - **end reach** (approach and departure, with the scanner's view): the witness's part may
//!   go on beyond it, among returns at its height or unseen, up to the first place at its height
//!   the scanner saw empty (`visibility`), which would make the angle lower by up to `span`:
//!   half of `span`, so that `U` reaches the far end (the reported angle stays the witness's);
//! - **trajectory**: the scan's error along the path, `trajectory_x_sigma_per_m` times the
//!   distance between the witness and the axle (the robot travelled that far between seeing the
//!   two). Zero for a cloud from another scanner, whose own uncertainty the caller must add.
//!
//! What this does not cover, and the held-out evaluation measures: a part the scan missed
//! entirely and not joined to a seen one at the witness's height (then the angle is wrong by more than any local statistic says) and systematic
//! errors the model above does not name.

use crate::{Axle, tangent_slope};

/// The expanded uncertainty of one result and its budget: standard uncertainties of the result
/// (radians for an angle, metres for a clearance) from each source.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Uncertainty {
    /// Expanded uncertainty `U` (k = 2).
    pub expanded: f64,
    /// From the witness's height (range noise at the lowest edge).
    pub witness_height: f64,
    /// From the witness's position along the vehicle (the envelope bin).
    pub witness_position: f64,
    /// From the static loaded radii (tyre fits).
    pub tyre_radius: f64,
    /// From the axles' positions (tyre fits).
    pub axle_position: f64,
    /// From the floor (its flatness and noise about the fitted plane).
    pub ground: f64,
    /// From the stretch beyond an approach or departure witness where its part may go on
    /// (`visibility`): half the angle's change over it; 0 for the breakover, the clearance, and
    /// without the scanner's view.
    pub end_reach: f64,
    /// From the scan's trajectory along the path.
    pub trajectory: f64,
}

impl Uncertainty {
    fn from_parts(parts: [f64; 7]) -> Self {
        let u = parts.iter().map(|p| p * p).sum::<f64>().sqrt();
        Self {
            expanded: 2.0 * u,
            witness_height: parts[0],
            witness_position: parts[1],
            tyre_radius: parts[2],
            axle_position: parts[3],
            ground: parts[4],
            trajectory: parts[5],
            end_reach: parts[6],
        }
    }

    /// This budget with the end reach's term: `angle_span` (radians) is how much lower the
    /// angle would be at the far end of the stretch. The truth lies anywhere in
    /// `[angle - span, angle]`, one-sided about the reported angle; a term of `span / 2` makes
    /// `U = 2 u` reach the far end when it dominates (conservative: a uniform distribution over
    /// the stretch has a standard deviation of `span / sqrt(12)` about its middle, but the
    /// reported angle is its end).
    pub(crate) fn with_end_reach(self, angle_span: f64) -> Self {
        let mut parts = self.parts();
        parts[6] = 0.5 * angle_span.abs();
        Self::from_parts(parts)
    }
}

/// Standard uncertainties of the inputs shared by every result of a run (metres).
#[derive(Debug, Clone, Copy)]
#[allow(clippy::struct_field_names)] // every field is a length; the suffix names the unit
pub(crate) struct Inputs {
    /// Noise sigma normal to the underside.
    pub noise_m: f64,
    /// Envelope bin width.
    pub bin_m: f64,
    /// The floor's noise sigma about its plane.
    pub ground_m: f64,
    /// Trajectory error along the path per metre travelled.
    pub trajectory_per_m: f64,
}

/// Step of the central differences (metres).
const STEP_M: f64 = 1e-4;

/// Central difference of `f` at `x`; 0 where either side is undefined (a witness within
/// `STEP_M` of the tyre's side-view disc, where no tangent plane reaches it from one side, so the
/// input has no first-order effect there).
fn slope(f: impl Fn(f64) -> Option<f64>, x: f64) -> f64 {
    match (f(x + STEP_M), f(x - STEP_M)) {
        (Some(a), Some(b)) => (a - b) / (2.0 * STEP_M),
        _ => 0.0,
    }
}

/// Approach (`front` true) or departure: the angle `tangent_slope(d, z, r)` with `d` the
/// witness's distance outboard of the axle.
pub(crate) fn of_overhang(
    witness: [f64; 2],
    axle: &Axle,
    front: bool,
    inputs: Inputs,
) -> Uncertainty {
    let [x, z] = witness;
    let d = if front { x - axle.x_m } else { axle.x_m - x };
    let r = axle.loaded_radius_m;
    let dd = slope(|d| tangent_slope(d, z, r), d);
    let dz = slope(|z| tangent_slope(d, z, r), z);
    let dr = slope(|r| tangent_slope(d, z, r), r);
    Uncertainty::from_parts([
        dz * inputs.noise_m,
        dd * inputs.bin_m / 12f64.sqrt(),
        dr * axle.u_loaded_radius_m,
        dd * axle.u_x_m,
        dz * inputs.ground_m,
        dd * inputs.trajectory_per_m * d.abs(),
        0.0,
    ])
    .abs()
}

/// Breakover: `tangent_slope(x_front - x, z, r_front) + tangent_slope(x - x_rear, z, r_rear)`.
pub(crate) fn of_breakover(
    witness: [f64; 2],
    (front, rear): (&Axle, &Axle),
    inputs: Inputs,
) -> Uncertainty {
    let [x, z] = witness;
    let angle = |x: f64, z: f64, xf: f64, rf: f64, xr: f64, rr: f64| {
        Some(tangent_slope(xf - x, z, rf)? + tangent_slope(x - xr, z, rr)?)
    };
    let (xf, rf, xr, rr) = (
        front.x_m,
        front.loaded_radius_m,
        rear.x_m,
        rear.loaded_radius_m,
    );
    let dx = slope(|x| angle(x, z, xf, rf, xr, rr), x);
    let dz = slope(|z| angle(x, z, xf, rf, xr, rr), z);
    let dxf = slope(|xf| angle(x, z, xf, rf, xr, rr), xf);
    let dxr = slope(|xr| angle(x, z, xf, rf, xr, rr), xr);
    let drf = slope(|rf| angle(x, z, xf, rf, xr, rr), rf);
    let drr = slope(|rr| angle(x, z, xf, rf, xr, rr), rr);
    let per_m = inputs.trajectory_per_m;
    Uncertainty::from_parts([
        dz * inputs.noise_m,
        dx * inputs.bin_m / 12f64.sqrt(),
        (drf * front.u_loaded_radius_m).hypot(drr * rear.u_loaded_radius_m),
        (dxf * front.u_x_m).hypot(dxr * rear.u_x_m),
        dz * inputs.ground_m,
        (dxf * per_m * (xf - x)).hypot(dxr * per_m * (x - xr)),
        0.0,
    ])
    .abs()
}

/// Ground clearance: the witness's height above the floor.
pub(crate) fn of_clearance(inputs: Inputs) -> Uncertainty {
    Uncertainty::from_parts([inputs.noise_m, 0.0, 0.0, 0.0, inputs.ground_m, 0.0, 0.0])
}

impl Uncertainty {
    fn parts(self) -> [f64; 7] {
        [
            self.witness_height,
            self.witness_position,
            self.tyre_radius,
            self.axle_position,
            self.ground,
            self.trajectory,
            self.end_reach,
        ]
    }

    /// Every part as a magnitude (sensitivities may be negative).
    fn abs(self) -> Self {
        Self::from_parts(self.parts().map(f64::abs))
    }
}

/// The standard uncertainty of the mean of an axle's tyres' values `(value, variance)`: the
/// propagated variance of the mean, or, when the tyres disagree by more, half their spread.
pub(crate) fn axle_mean_u(values: &[(f64, f64)]) -> f64 {
    let n = values.len().max(1) as f64;
    let propagated = values.iter().map(|(_, v)| v).sum::<f64>() / (n * n);
    let spread = match values {
        [(a, _), (b, _)] => 0.25 * (a - b).powi(2),
        _ => 0.0,
    };
    propagated.max(spread).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn axle(x_m: f64, u: f64) -> Axle {
        Axle {
            x_m,
            loaded_radius_m: 0.3,
            free_radius_m: 0.32,
            u_x_m: u,
            u_loaded_radius_m: u,
        }
    }

    const INPUTS: Inputs = Inputs {
        noise_m: 0.003,
        bin_m: 0.005,
        ground_m: 0.002,
        trajectory_per_m: 0.0,
    };

    #[test]
    fn the_witness_height_term_matches_the_closed_form_derivative() {
        // tangent_slope(d, z, r) = asin(r / hypot(d, r - z)) - atan2(r - z, d): check d/dz by a
        // finer difference.
        let a = axle(1.5, 0.0);
        let u = of_overhang([2.3, 0.35], &a, true, INPUTS);
        let f = |z: f64| tangent_slope(0.8, z, 0.3).unwrap();
        let dz = (f(0.35 + 1e-6) - f(0.35 - 1e-6)) / 2e-6;
        assert!((u.witness_height - dz.abs() * 0.003).abs() < 1e-9, "{u:?}");
        assert!(u.expanded > 0.0 && u.trajectory == 0.0);
    }

    #[test]
    fn a_worse_tyre_fit_and_a_drifting_trajectory_give_a_larger_uncertainty() {
        let good = of_overhang([2.3, 0.35], &axle(1.5, 0.002), true, INPUTS);
        let bad = of_overhang([2.3, 0.35], &axle(1.5, 0.02), true, INPUTS);
        assert!(bad.expanded > good.expanded);
        // The trajectory's term: the sensitivity to d times the drift over the lever arm d.
        let drifting = Inputs {
            trajectory_per_m: 0.01,
            ..INPUTS
        };
        let u = of_overhang([2.3, 0.35], &axle(1.5, 0.0), true, drifting);
        let f = |d: f64| tangent_slope(d, 0.35, 0.3).unwrap();
        let dd = (f(0.8 + 1e-6) - f(0.8 - 1e-6)) / 2e-6;
        assert!((u.trajectory - dd.abs() * 0.01 * 0.8).abs() < 1e-9, "{u:?}");
    }

    #[test]
    fn breakover_budget_is_symmetric_for_a_symmetric_vehicle() {
        let (front, rear) = (axle(1.4, 0.003), axle(-1.4, 0.003));
        let u = of_breakover([0.0, 0.25], (&front, &rear), INPUTS);
        // At the midpoint the witness's position does not move the sum to first order.
        assert!(u.witness_position < 1e-6, "{u:?}");
        assert!(u.tyre_radius > 0.0 && u.axle_position > 0.0 && u.witness_height > 0.0);
    }

    #[test]
    fn axle_uncertainty_takes_the_larger_of_fit_and_disagreement() {
        assert!((axle_mean_u(&[(0.30, 1e-6), (0.30, 1e-6)]) - (0.5e-6f64).sqrt()).abs() < 1e-12);
        assert!((axle_mean_u(&[(0.30, 1e-8), (0.32, 1e-8)]) - 0.01).abs() < 1e-12);
        assert!((axle_mean_u(&[(0.30, 4e-6)]) - 0.002).abs() < 1e-12);
    }
}
