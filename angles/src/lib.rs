//! Passing-angle calculator (docs/architecture.md section 6 step 8): approach, departure and ramp breakover
//! angles of a vehicle from a point cloud of its underside and tyres, per the standard definitions
//! (`notes/domain.md` part A) and the paper's section 3.6 / Algorithm 2.
//!
//! Pure: points and an [`AnglesConfig`] in, an [`AnglesResult`] out; no IO, no clock, seeded RANSAC.
//!
//! # Method
//! 1. **Ground** (`ground`): RANSAC plane (seeded, near-horizontal hypotheses only, penalising
//!    planes with many points far below them), least-squares refinement, noise sigma from the
//!    inliers (robust MAD). Refined again once the tyres are known, without their footprints.
//! 2. **Tyres** (`tyres`): compact clusters of points a few centimetres above the ground are the
//!    footprints; each tyre is a circle in the side view fitted to its silhouette. Static loaded
//!    radius = centre height above the ground; the fitted radius is the free tread radius.
//! 3. **Vehicle frame**: z = ground normal, x = from the rear axle's midpoint to the front axle's
//!    (so ground tilt and vehicle yaw in the cloud are removed), y left; origin on the ground,
//!    midway between the axles, on the centreline between the inner tyre faces. Steps 2-3 iterate.
//! 4. **Body** = points above 1.5 x the ground threshold (4.5 cm; more on a noisy floor) that are
//!    not tyre (and not in an exclusion box).
//!    Those inside the lateral band (default: the vehicle's width, [`Band::OUTER`]) are projected
//!    onto the median plane and reduced to a robust lower envelope (`envelope`; between the axles
//!    also per lateral strip); its front and rear
//!    ends are placed by counting the surface's points beyond a reference, not by the last bin
//!    that reaches a support threshold (`edge`).
//! 5. **Angles**: for an envelope sample at horizontal distance `d` from a wheel centre and height `z`,
//!    with static loaded radius `r`, the plane through it tangent to the tyre rises at
//!    `a = asin(r / hypot(d, r - z)) - atan2(r - z, d)` ([`tangent_slope`]). Approach = min `a`
//!    over samples ahead of the front tyres (zone [`Zone::Tyre`], CFR/SAE) or ahead of the front
//!    axle ([`Zone::Axle`], EU); departure likewise behind the rear; breakover = min over samples
//!    between the axles of `a_front + a_rear` (the supplement of the crest angle). Samples inside a
//!    tyre's side-view disc cannot be touched by a tangent plane and are skipped.
//!
//! 6. **Coverage** (`check_coverage`): a partial scan gives wrong angles, not missing ones (the
//!    underside the robot has not reached yet is seen only by the lidar's flat rings, so the
//!    envelope simply ends early). A quantity whose part of the vehicle was not covered is
//!    reported as not measured, with the reason ([`AnglesResult::not_measured`]), never as a
//!    number: the approach (departure) when the scan's path (if given,
//!    [`AnglesConfig::scan_path_in_cloud`]) stops short of the front (rear) end of the underside
//!    or, without a path, when the cloud itself ends there; the breakover and the clearance when
//!    the underside between the axles has a gap. When the path does not reach both axles nothing
//!    is measured ([`AnglesError::Incomplete`]).
//! 7. **Uncertainty** (`uncertainty`): every angle and the clearance carry an expanded
//!    uncertainty (k = 2) from a budget of this run's own data: noise at the witness, envelope
//!    bin, tyre fits' covariances, floor flatness, and the trajectory's stated error.
//!
//! Every angle comes with its witness (the limiting envelope sample) in the vehicle and the cloud
//! frame and the number of points supporting it; the result also carries the tyre fits, the
//! envelope (for the side-view report, [`side_view_svg`]), point counts and warnings.

mod edge;
mod envelope;
mod faces;
mod geom;
mod ground;
pub mod profiles;
mod svg;
mod tyres;
mod uncertainty;
mod visibility;

pub use envelope::EnvelopeSample;
pub use geom::{V3, VehicleFrame};
pub use svg::side_view_svg;
pub use uncertainty::Uncertainty;
pub use visibility::ScannerView;

use envelope::{EnvelopeParams, lower_envelope};
use geom::unit;
use ground::Plane;
use tyres::{Seed, TyreFit, TyreParams};

/// Which points count for the approach and departure angles.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Zone {
    /// Ahead of the front tyre / behind the rear tyre (49 CFR 523.2, SAE J1100).
    #[default]
    Tyre,
    /// Ahead of the front axle / behind the rearmost axle (EU 2018/858 Annex I).
    Axle,
}

/// The lateral band whose body points form the side-view envelope.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Band {
    /// Between the inner tyre faces, shrunk by `margin_m` on each side ([`Band::INNER`]: 1 cm).
    InnerFaces {
        /// Margin inside each inner face (metres).
        margin_m: f64,
    },
    /// Between the outer tyre faces, widened by `margin_m` on each side: the vehicle's whole
    /// width in the side view, as the standards define the angles (sills and mud flaps outboard
    /// of the inner faces count), and nothing of a neighbour beside it (default, [`Band::OUTER`]).
    OuterFaces {
        /// Margin outside each outer face (metres).
        margin_m: f64,
    },
    /// `|y| <= half_width_m` about the vehicle centreline.
    HalfWidth(f64),
    /// Every body point, whatever its y.
    Full,
}

impl Band {
    /// Between the inner tyre faces, 1 cm inside each.
    pub const INNER: Band = Band::InnerFaces { margin_m: 0.01 };
    /// Between the outer tyre faces, 10 cm outside each: a body's sides (sills, arches, mud flaps)
    /// reach past its tyres' outer faces by a few centimetres, a neighbour beside it is metres away.
    pub const OUTER: Band = Band::OuterFaces { margin_m: 0.10 };
}

/// An axis-aligned box in cloud coordinates whose points are ignored (tow hooks, steps, mud flaps).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExclusionBox {
    /// Minimum corner `[x0, y0, z0]` (metres, cloud frame).
    pub min_in_cloud: V3,
    /// Maximum corner `[x1, y1, z1]` (metres, cloud frame).
    pub max_in_cloud: V3,
}

impl ExclusionBox {
    fn contains(&self, p: V3) -> bool {
        (0..3).all(|k| p[k] >= self.min_in_cloud[k] && p[k] <= self.max_in_cloud[k])
    }
}

/// Calculator settings. `Default` gives the documented defaults.
#[derive(Debug, Clone, PartialEq)]
pub struct AnglesConfig {
    /// The vehicle's front is toward +x of the cloud (false: toward -x, the CLI's `--front -x`).
    pub front_is_positive_x: bool,
    /// Approach/departure zone.
    pub zone: Zone,
    /// Lateral band of the envelope.
    pub band: Band,
    /// Ignored boxes, cloud frame.
    pub exclude: Vec<ExclusionBox>,
    /// Static loaded radius to use for every tyre instead of the fitted centre height (metres).
    pub tyre_radius_m: Option<f64>,
    /// RANSAC inlier distance for the ground (0.03 m, paper 3.1); points below 1.5 x this height
    /// (or 4 noise sigma, if more) are ground, not underside (see `classify`).
    pub ground_threshold_m: f64,
    /// Largest ground tilt against the cloud's z accepted by RANSAC (20 degrees).
    pub max_ground_tilt_rad: f64,
    /// Tyre footprint slice: points between these heights seed the tyre search (0.025 m .. 0.08 m;
    /// the lower bound is raised to 5 noise sigma). Body parts must not reach below `seed_high_m`.
    pub seed_low_m: f64,
    /// Upper bound of the footprint slice (0.08 m).
    pub seed_high_m: f64,
    /// Radial gap that separates a tyre's silhouette from the wheel arch (0.025 m).
    pub tyre_gap_m: f64,
    /// Envelope bin width; `None`: 5 mm, doubled (up to 4 cm) while bins hold too few points.
    pub bin_m: Option<f64>,
    /// Range noise sigma; `None`: estimated from the ground and tyre fits.
    pub noise_m: Option<f64>,
    /// The scanner's stated range accuracy, metres (a bound on how far a surface's returns
    /// scatter from it, e.g. the VLP-16 data sheet's +-3 cm); `None`: not known. Returns within it
    /// of a fitted tyre are the tyre's: the scanner cannot tell a part there from the tread.
    pub range_accuracy_m: Option<f64>,
    /// Points an envelope bin's lowest mode needs (5): fewer are treated as outliers.
    pub min_support: usize,
    /// RANSAC seed.
    pub seed: u64,
    /// Leave the overhangs' points on faces across the path (a part's end cap, e.g. an exhaust
    /// silencer's) out of the envelope's lowest modes (true; see `envelope::across_path`). The
    /// body's ends are placed from all points either way.
    pub skip_faces_across_path: bool,
    /// Where the lidar's optical centre was during the scan (along the pipeline's trajectory),
    /// cloud coordinates, metres; empty: unknown. With it, the calculator refuses a scan whose
    /// path does not reach both axles and within [`PATH_REACH_M`] of both ends of the underside
    /// (see `check_coverage`).
    pub scan_path_in_cloud: Vec<V3>,
    /// Standard uncertainty of the scan's trajectory along the path per metre travelled
    /// (dimensionless; 0.01: 1 cm per metre). The pipeline states it for its own clouds; 0 for a
    /// cloud whose scanner's uncertainty is not known here (the results' uncertainties then
    /// leave it out, `uncertainty`).
    pub trajectory_x_sigma_per_m: f64,
    /// What the scanner could see from each position of [`Self::scan_path_in_cloud`]; `None`:
    /// not known. With it and the path, an approach or departure witness's part may reach beyond
    /// it only as far as the scanner did not see empty, and the angle and its uncertainty say so
    /// (`visibility`); and the envelope takes a part's lowest line across the path from the
    /// returns' ray angles (`envelope::cross_section_floor`).
    pub scanner_view: Option<ScannerView>,
}

impl Default for AnglesConfig {
    fn default() -> Self {
        Self {
            front_is_positive_x: true,
            zone: Zone::Tyre,
            band: Band::OUTER,
            exclude: Vec::new(),
            tyre_radius_m: None,
            ground_threshold_m: 0.03,
            max_ground_tilt_rad: 20f64.to_radians(),
            seed_low_m: 0.025,
            seed_high_m: 0.08,
            tyre_gap_m: 0.025,
            bin_m: None,
            noise_m: None,
            range_accuracy_m: None,
            min_support: 5,
            seed: 0x5eed,
            skip_faces_across_path: true,
            scan_path_in_cloud: Vec::new(),
            trajectory_x_sigma_per_m: 0.0,
            scanner_view: None,
        }
    }
}

/// Why no result could be computed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AnglesError {
    /// A setting is out of range; the message names it.
    #[error("invalid setting: {0}")]
    InvalidConfig(String),
    /// Too few usable points.
    #[error("only {0} usable points (after NaN removal and exclusion boxes); need at least 100")]
    TooFewPoints(usize),
    /// No near-horizontal plane with enough support.
    #[error(
        "no ground plane found (no plane within {max_tilt_deg:.0} degrees of horizontal has enough points)"
    )]
    NoGround {
        /// The tilt limit that was searched, degrees.
        max_tilt_deg: f64,
    },
    /// The tyres could not be found; the message says what was seen.
    #[error("tyres not found: {0}")]
    Tyres(String),
    /// The scan does not cover the vehicle (a partial scan); the message names what is missing.
    #[error("incomplete scan: {0}")]
    Incomplete(String),
}

/// Tyre position on the vehicle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TyrePosition {
    /// Front left.
    FrontLeft,
    /// Front right.
    FrontRight,
    /// Rear left.
    RearLeft,
    /// Rear right.
    RearRight,
}

impl TyrePosition {
    /// Short label (`FL`, `FR`, `RL`, `RR`).
    pub fn label(self) -> &'static str {
        match self {
            TyrePosition::FrontLeft => "FL",
            TyrePosition::FrontRight => "FR",
            TyrePosition::RearLeft => "RL",
            TyrePosition::RearRight => "RR",
        }
    }

    fn is_front(self) -> bool {
        matches!(self, TyrePosition::FrontLeft | TyrePosition::FrontRight)
    }
}

/// One fitted tyre, in the vehicle frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Tyre {
    /// Which tyre.
    pub position: TyrePosition,
    /// Wheel centre `[x, y, z]` in the vehicle frame (z = static loaded radius).
    pub centre_in_vehicle: V3,
    /// Wheel centre in cloud coordinates.
    pub centre_in_cloud: V3,
    /// Static loaded radius: the centre's height above the ground (metres).
    pub loaded_radius_m: f64,
    /// Fitted free tread radius (metres).
    pub free_radius_m: f64,
    /// Standard uncertainty of the centre's x (metres, from the fit's covariance).
    pub u_centre_x_m: f64,
    /// Standard uncertainty of the static loaded radius (metres, from the fit's covariance).
    pub u_loaded_radius_m: f64,
    /// Visible width between the inner and the outer face (metres).
    pub width_m: f64,
    /// y of the inner face (toward the centreline), vehicle frame.
    pub inner_face_y_m: f64,
    /// RMS distance of the silhouette points to the fitted circle (metres).
    pub residual_rms_m: f64,
    /// Silhouette points used by the fit.
    pub fit_points: usize,
}

/// One limiting angle and what limits it.
#[derive(Debug, Clone, PartialEq)]
pub struct AngleFinding {
    /// The angle (radians), at the witness.
    pub angle_rad: f64,
    /// For the breakover angle, the front and the rear tangent slopes that sum to it.
    pub parts_rad: Option<(f64, f64)>,
    /// The limiting envelope sample, vehicle frame (y = mean y of its supporting points).
    pub witness_in_vehicle: V3,
    /// The same point in cloud coordinates.
    pub witness_in_cloud: V3,
    /// Points supporting the limiting sample (its envelope bin's lowest mode).
    pub support: usize,
    /// Expanded uncertainty of the angle (radians) and its budget.
    pub uncertainty: Uncertainty,
}

/// Lowest body point between the axles.
#[derive(Debug, Clone, PartialEq)]
pub struct Clearance {
    /// Height above the ground (metres).
    pub height_m: f64,
    /// Where, vehicle frame.
    pub witness_in_vehicle: V3,
    /// Where, cloud frame.
    pub witness_in_cloud: V3,
    /// Expanded uncertainty of the height (metres) and its budget.
    pub uncertainty: Uncertainty,
}

/// A quantity the calculator measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Quantity {
    /// The approach angle.
    Approach,
    /// The departure angle.
    Departure,
    /// The ramp breakover angle.
    Breakover,
    /// The ground clearance between the axles.
    GroundClearance,
}

impl Quantity {
    /// The name used in reports and JSON (`approach`, `departure`, `breakover`,
    /// `ground_clearance`).
    pub fn name(self) -> &'static str {
        match self {
            Quantity::Approach => "approach",
            Quantity::Departure => "departure",
            Quantity::Breakover => "breakover",
            Quantity::GroundClearance => "ground_clearance",
        }
    }
}

/// Why a quantity was not measured, as a kind (the words are in [`NotMeasured::reason`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Absence {
    /// No part of the vehicle in the quantity's zone.
    NothingInZone,
    /// The scan did not cover the quantity's part of the vehicle.
    NotCovered,
}

/// A quantity that was not measured: the scan lacks what it needs. Reported instead of a number.
#[derive(Debug, Clone, PartialEq)]
pub struct NotMeasured {
    /// Which.
    pub quantity: Quantity,
    /// Why, as a kind.
    pub kind: Absence,
    /// What is missing, in words (names the part of the vehicle or the scan).
    pub reason: String,
}

/// Point bookkeeping.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PointCounts {
    /// Points given to the calculator.
    pub input: usize,
    /// Non-finite points ignored.
    pub non_finite: usize,
    /// Points inside exclusion boxes.
    pub excluded: usize,
    /// Ground points (within the ground threshold, or below the ground).
    pub ground: usize,
    /// Tyre points.
    pub tyre: usize,
    /// Body points (everything else).
    pub body: usize,
    /// Body points inside the lateral band (the envelope's input).
    pub body_in_band: usize,
    /// Band points below their bin's lowest supported mode, rejected as outliers.
    pub outliers_below_envelope: usize,
}

/// The ground fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GroundFit {
    /// Upward unit normal in cloud coordinates.
    pub normal_in_cloud: V3,
    /// Angle between the normal and the cloud's z (radians).
    pub tilt_rad: f64,
    /// Noise sigma of the ground inliers (robust MAD, metres).
    pub noise_sigma_m: f64,
    /// Inliers used by the final fit.
    pub inliers: usize,
}

/// Everything the calculator found.
#[derive(Debug, Clone, PartialEq)]
pub struct AnglesResult {
    /// Approach angle, if any body point lies in the front zone.
    pub approach: Option<AngleFinding>,
    /// Departure angle, if any body point lies in the rear zone.
    pub departure: Option<AngleFinding>,
    /// Ramp breakover angle, if any body point lies between the axles.
    pub breakover: Option<AngleFinding>,
    /// Lowest envelope point between the axles (inclusive).
    pub ground_clearance: Option<Clearance>,
    /// Distance between the axles (metres).
    pub wheelbase_m: f64,
    /// Mean centre-to-centre distance of left and right tyres (visible widths), if both sides were found.
    pub track_m: Option<f64>,
    /// Distance between the inner faces, if both sides were found.
    pub inner_track_m: Option<f64>,
    /// Tyre fits.
    pub tyres: Vec<Tyre>,
    /// Front axle: x, static loaded radius and free radius used for the angles.
    pub front_axle: Axle,
    /// Rear axle, likewise.
    pub rear_axle: Axle,
    /// Vehicle frame in cloud coordinates.
    pub frame: VehicleFrame,
    /// Vehicle heading against the cloud's x (front direction), radians.
    pub yaw_rad: f64,
    /// Ground fit.
    pub ground: GroundFit,
    /// Noise sigma used for the envelope window (metres).
    pub noise_sigma_m: f64,
    /// Envelope bin width used (metres).
    pub bin_m: f64,
    /// Lateral band used, `(y_min, y_max)` in the vehicle frame.
    pub band_y_m: (f64, f64),
    /// Side-view lower envelope, sorted by x.
    pub envelope: Vec<EnvelopeSample>,
    /// Point counts.
    pub points: PointCounts,
    /// The zone used.
    pub zone: Zone,
    /// The quantities above that are `None`, each with its reason.
    pub not_measured: Vec<NotMeasured>,
    /// Things a person should check.
    pub warnings: Vec<String>,
}

impl AnglesResult {
    /// Why `quantity` was not measured (`None` when it was).
    pub fn not_measured_reason(&self, quantity: Quantity) -> Option<&str> {
        self.not_measured
            .iter()
            .find(|n| n.quantity == quantity)
            .map(|n| n.reason.as_str())
    }
}

/// An axle as used by the angles.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Axle {
    /// Wheel centre x in the vehicle frame (mean of the axle's tyres).
    pub x_m: f64,
    /// Static loaded radius used (fitted centre height, or the override).
    pub loaded_radius_m: f64,
    /// Free tread radius (fitted), which bounds the tyre zone.
    pub free_radius_m: f64,
    /// Standard uncertainty of `x_m` (metres): the tyres' fits, or half their disagreement.
    pub u_x_m: f64,
    /// Standard uncertainty of `loaded_radius_m` (metres): the tyres' fits or half their
    /// disagreement, plus one noise sigma for the silhouette's outward bias; 0 with the user's
    /// override (whose own uncertainty the user states).
    pub u_loaded_radius_m: f64,
}

/// Slope (radians) of the plane through a point at horizontal distance `d_m` (> 0, away from the
/// wheel) and height `z_m` that is tangent to a tyre of static loaded radius `r_m` standing on the
/// ground with its centre at height `r_m`: `asin(r / hypot(d, r - z)) - atan2(r - z, d)`.
/// `None` if the point is not outboard (`d <= 0`) or lies inside the tyre's side-view disc.
pub fn tangent_slope(d_m: f64, z_m: f64, r_m: f64) -> Option<f64> {
    let dist = d_m.hypot(r_m - z_m);
    (d_m > 0.0 && dist > r_m).then(|| (r_m / dist).asin() - (r_m - z_m).atan2(d_m))
}

impl AnglesConfig {
    fn validate(&self) -> Result<(), AnglesError> {
        let bad = |s: &str| Err(AnglesError::InvalidConfig(s.to_string()));
        let pos = |v: f64| v.is_finite() && v > 0.0;
        if !pos(self.ground_threshold_m) {
            return bad("ground threshold must be > 0");
        }
        if !(pos(self.seed_low_m) && pos(self.seed_high_m) && self.seed_high_m > self.seed_low_m) {
            return bad("tyre seed slice must satisfy 0 < low < high");
        }
        if !pos(self.tyre_gap_m) || !pos(self.max_ground_tilt_rad) {
            return bad("tyre gap and ground tilt limit must be > 0");
        }
        if self.tyre_radius_m.is_some_and(|r| !pos(r)) {
            return bad("tyre radius must be > 0");
        }
        if self.bin_m.is_some_and(|b| !pos(b))
            || self.noise_m.is_some_and(|n| !(n.is_finite() && n >= 0.0))
            || self
                .range_accuracy_m
                .is_some_and(|a| !(a.is_finite() && a >= 0.0))
        {
            return bad("bin width must be > 0, noise and range accuracy >= 0");
        }
        match self.band {
            Band::HalfWidth(w) if !pos(w) => return bad("band half width must be > 0"),
            Band::InnerFaces { margin_m } | Band::OuterFaces { margin_m }
                if !margin_m.is_finite() =>
            {
                return bad("band margin must be finite");
            }
            _ => {}
        }
        if self.min_support == 0 {
            return bad("min support must be >= 1");
        }
        if let Some(i) = self
            .scan_path_in_cloud
            .iter()
            .position(|p| !p.iter().all(|v| v.is_finite()))
        {
            return Err(AnglesError::InvalidConfig(format!(
                "scan path position {} of {} is not finite",
                i + 1,
                self.scan_path_in_cloud.len()
            )));
        }
        if self.scanner_view.is_some_and(|v| !v.is_valid()) {
            return bad(
                "scanner view: elevations must be finite with min < max, min range finite and >= 0",
            );
        }
        for (i, b) in self.exclude.iter().enumerate() {
            if (0..3).any(|k| b.min_in_cloud[k] > b.max_in_cloud[k] || b.min_in_cloud[k].is_nan()) {
                return Err(AnglesError::InvalidConfig(format!(
                    "exclusion box {}: each minimum must be <= its maximum",
                    i + 1
                )));
            }
        }
        Ok(())
    }
}

/// Compute the passing angles of the vehicle in `points_in_cloud` (metres, z roughly up).
pub fn compute_angles(
    points_in_cloud: &[V3],
    config: &AnglesConfig,
) -> Result<AnglesResult, AnglesError> {
    config.validate()?;
    let (points, mut counts) = usable_points(points_in_cloud, config);
    if points.len() < 100 {
        return Err(AnglesError::TooFewPoints(points.len()));
    }
    let mut warnings = Vec::new();
    let settled = settle_frame(&points, config, &mut warnings)?;
    let (frame, fits) = (settled.frame, settled.fits);
    let tyre_sigma = fits
        .iter()
        .map(|(_, f)| f.residual_rms_m)
        .fold(0.0, f64::max);
    let noise_m = config.noise_m.unwrap_or(settled.sigma.max(tyre_sigma));
    let (front, rear) = axles(&fits, config, noise_m);
    warnings.extend(left_out_warnings(&fits));
    let band_y_m = band(&fits, config.band, &mut warnings);
    // The overhangs, where faces across the path are left out of the envelope's modes.
    let (front_x, rear_x) = zone_limits(front, rear, Zone::Axle);
    let scan_path = path_in_frame(&frame, config);
    let body = classify(
        &settled.in_frame,
        &fits,
        (rear_x, front_x),
        config,
        config.scanner_view.and_then(|v| {
            envelope::ScanLine::new(&scan_path, (v.elevation_min_rad, v.elevation_max_rad))
        }),
        noise_m,
        band_y_m,
        &mut counts,
    );
    let mut body = body;
    let detached = drop_detached(&mut body.samples, front, rear);
    if detached > 0 {
        warnings.push(format!(
            "{detached} envelope samples lie beyond a gap of more than {DETACHED_GAP_M} m ahead of or behind the vehicle's body and were ignored (ground noise, kerbs or other objects)"
        ));
    }
    refine_ends(&mut body, front, rear, config.zone);
    let mut not_covered = check_coverage(
        &body.samples,
        (front, rear),
        &frame,
        &settled.in_frame,
        config,
    )?;
    let inputs = uncertainty::Inputs {
        noise_m: body.noise_sigma_m,
        bin_m: body.bin_m,
        ground_m: settled.sigma,
        trajectory_per_m: config.trajectory_x_sigma_per_m,
    };
    let mut findings = find_angles(&body.samples, front, rear, config.zone, &frame, inputs);
    if let Some(sight) = scan_sight(config, &frame, &settled.in_frame, &body, noise_m) {
        not_covered.extend(end_reaches(&mut findings, &sight, front, rear));
    }
    let not_measured = not_measured(&mut findings, not_covered);
    let plane = settled.plane;
    let heading = frame.x_axis_in_cloud;
    let sign = if config.front_is_positive_x {
        1.0
    } else {
        -1.0
    };
    let mut result = AnglesResult {
        approach: findings.approach,
        departure: findings.departure,
        breakover: findings.breakover,
        ground_clearance: findings.clearance,
        wheelbase_m: front.x_m - rear.x_m,
        track_m: track(&fits, |f| f.centre_y),
        inner_track_m: track(&fits, |f| f.inner_y),
        tyres: tyres_out(&fits, &frame),
        front_axle: front,
        rear_axle: rear,
        frame,
        yaw_rad: heading[1].atan2(heading[0].abs()) * sign,
        ground: GroundFit {
            normal_in_cloud: plane.normal,
            tilt_rad: plane.normal[2].clamp(-1.0, 1.0).acos(),
            noise_sigma_m: settled.sigma,
            inliers: settled.ground_inliers,
        },
        noise_sigma_m: body.noise_sigma_m,
        bin_m: body.bin_m,
        band_y_m,
        envelope: body.samples,
        points: counts,
        zone: config.zone,
        not_measured,
        warnings,
    };
    geometry_warnings(&mut result, config);
    finding_warnings(&mut result, body.unsupported_bins, body.ends, config);
    Ok(result)
}

/// Finite points outside the exclusion boxes, and the counts of the others.
fn usable_points(points_in_cloud: &[V3], config: &AnglesConfig) -> (Vec<V3>, PointCounts) {
    let mut counts = PointCounts {
        input: points_in_cloud.len(),
        ..PointCounts::default()
    };
    let mut points = Vec::with_capacity(points_in_cloud.len());
    for &p in points_in_cloud {
        if !p.iter().all(|v| v.is_finite()) {
            counts.non_finite += 1;
        } else if config.exclude.iter().any(|b| b.contains(p)) {
            counts.excluded += 1;
        } else {
            points.push(p);
        }
    }
    (points, counts)
}

/// The vehicle frame, the tyres in it and the ground, once they agree.
struct Settled {
    frame: VehicleFrame,
    plane: Plane,
    sigma: f64,
    ground_inliers: usize,
    fits: Vec<(TyrePosition, TyreFit)>,
    in_frame: Vec<V3>,
}

/// Ground, then three rounds of: tyres in the current frame, ground refit without the tyre
/// footprints, frame re-derived from the axles. A final tyre pass gives the fits, and the origin
/// moves to mid-wheelbase on the centreline.
fn settle_frame(
    points: &[V3],
    config: &AnglesConfig,
    warnings: &mut Vec<String>,
) -> Result<Settled, AnglesError> {
    let thr = config.ground_threshold_m;
    let no_ground = AnglesError::NoGround {
        max_tilt_deg: config.max_ground_tilt_rad.to_degrees(),
    };
    let plane0 = ground::ransac(points, thr, config.max_ground_tilt_rad, config.seed)
        .ok_or(no_ground.clone())?;
    let mut plane = ground::refine(points, plane0, thr, |_| true).unwrap_or(plane0);
    let forward = if config.front_is_positive_x {
        V3::new(1.0, 0.0, 0.0)
    } else {
        V3::new(-1.0, 0.0, 0.0)
    };
    let mut frame = frame_on(plane, points, forward).ok_or(no_ground)?;
    let (mut sigma, _) = ground::noise_sigma(points, plane, thr, |_| true);
    let mut local_sigma = ground::local_noise_sigma(points, plane, thr, |_| true);
    let mut ground_inliers = 0;
    for round in 0..4 {
        let in_frame: Vec<V3> = points
            .iter()
            .map(|&p| frame.vehicle_from_cloud(p))
            .collect();
        let noise = config.noise_m.unwrap_or(sigma);
        // The footprint band starts above the returns' own scatter on the floor, not the floor's
        // shape: on an undulating hall floor the plane's residuals are several times the
        // sensor's noise and would leave no band below `seed_high_m`. A floor bump inside the
        // band is wide, and seeds must be compact (`tyres::find_seeds`).
        let band_noise = config
            .noise_m
            .unwrap_or_else(|| local_sigma.map_or(sigma, |l| l.min(sigma)));
        let seed_low = config.seed_low_m.max(5.0 * band_noise);
        let (seeds, clusters) = tyres::find_seeds(&in_frame, seed_low, config.seed_high_m);
        let mut round_warnings = Vec::new();
        let mut fits = fit_tyres(
            &frame,
            &in_frame,
            &seeds,
            config,
            seed_low,
            noise,
            &mut round_warnings,
        )?;
        if clusters > fits.len() {
            round_warnings.push(format!(
                "{clusters} compact clusters near the ground; {} taken as tyres",
                fits.len()
            ));
        }
        if round == 3 {
            warnings.extend(round_warnings);
            // Move the origin to mid-wheelbase on the centreline.
            let (front, rear) = axles(&fits, config, sigma);
            let shift = V3::new(0.5 * (front.x_m + rear.x_m), centreline_y(&fits), 0.0);
            for (_, f) in &mut fits {
                f.centre_x -= shift[0];
                f.centre_y -= shift[1];
                f.inner_y -= shift[1];
                f.outer_y -= shift[1];
            }
            return Ok(Settled {
                frame: frame.yawed(0.0, shift),
                plane,
                sigma,
                ground_inliers,
                fits,
                in_frame: in_frame.into_iter().map(|p| p - shift).collect(),
            });
        }
        let footprints: Vec<TyreFit> = fits.iter().map(|(_, f)| f.clone()).collect();
        let off_tyres = |p: V3| {
            !footprints
                .iter()
                .any(|t| in_footprint(frame.vehicle_from_cloud(p), t))
        };
        if let Some(refined) = ground::refine(points, plane, thr, off_tyres) {
            plane = refined;
        }
        (sigma, ground_inliers) = ground::noise_sigma(points, plane, thr, off_tyres);
        local_sigma = ground::local_noise_sigma(points, plane, thr, off_tyres);
        let heading = axle_heading(&frame, &fits).unwrap_or(frame.x_axis_in_cloud);
        frame = frame_on(plane, points, heading)
            .ok_or(AnglesError::Tyres("degenerate axle heading".into()))?;
    }
    unreachable!("the loop returns in its last round")
}

/// The body's envelope and the figures that shaped it.
struct Body {
    samples: Vec<EnvelopeSample>,
    /// The band's body points (vehicle frame), the envelope's input.
    band_points: Vec<V3>,
    /// Per end of the band's points (rear, front): x of the end and the highest z within 3 cm of it.
    ends: [(f64, f64); 2],
    noise_sigma_m: f64,
    bin_m: f64,
    unsupported_bins: usize,
}

/// A warning for each tyre left out of its axle's position and radii ([`axle_members`]).
fn left_out_warnings(fits: &[(TyrePosition, TyreFit)]) -> impl Iterator<Item = String> + '_ {
    [true, false].into_iter().filter_map(|front| {
        axle_members(fits, front).1.map(|left_out| {
            format!(
                "tyre {} left out of its axle's position and radii: they disagree with the other \
                 three tyres, which agree with each other (a misfit)",
                left_out.label()
            )
        })
    })
}

/// Height (metres, vehicle frame) below which points are floor, not underside (`classify`).
fn body_floor_m(config: &AnglesConfig, noise_sigma_m: f64) -> f64 {
    (1.5 * config.ground_threshold_m).max(4.0 * noise_sigma_m)
}

/// Split points into ground, tyre and body; build the body's lower envelope inside the band,
/// seen from `scan_line` where it is known.
#[allow(clippy::too_many_arguments)]
fn classify(
    in_frame: &[V3],
    fits: &[(TyrePosition, TyreFit)],
    axles_x_m: (f64, f64),
    config: &AnglesConfig,
    scan_line: Option<envelope::ScanLine>,
    noise_sigma_m: f64,
    band_y_m: (f64, f64),
    counts: &mut PointCounts,
) -> Body {
    // A tyre's returns scatter about its outline by the range noise: 3 sigma of the estimated
    // noise, or the scanner's stated accuracy where it is known and larger. The estimate comes
    // from the floor and the tyre fits' silhouette points, which see the noise only across the
    // ray; the tread's front and back, seen head-on near the floor, see it along the ray.
    let tyre_tol = (3.0 * noise_sigma_m)
        .max(config.range_accuracy_m.unwrap_or(0.0))
        .max(0.01);
    // Points below 1.5 x the ground threshold (4.5 cm), or 4 noise sigma if more, are floor,
    // not underside. A noisy floor (a smeared cloud: 1 cm sigma) reaches above the threshold, and
    // so do arcs of floor hits that a frame's small tilt lifted just past the pipeline's own
    // per-frame ground band (the same 3 cm): on suv-offset seed 6 such an arc stood 3.1-3.5 cm
    // above the floor, 7 of its points fell into one envelope bin, and it became the breakover
    // witness (-16 degrees). No road vehicle's rigid underside comes that low, and the tyre
    // seeds above assume no body part below `seed_high_m` (8 cm) anyway.
    let ground_cut_m = body_floor_m(config, noise_sigma_m);
    let mut band_points = Vec::new();
    for p in in_frame {
        if p[2] < ground_cut_m {
            counts.ground += 1;
        } else if fits.iter().any(|(_, f)| is_tyre_point(*p, f, tyre_tol)) {
            counts.tyre += 1;
        } else {
            counts.body += 1;
            if p[1] >= band_y_m.0 && p[1] <= band_y_m.1 {
                band_points.push(*p);
            }
        }
    }
    counts.body_in_band = band_points.len();
    let ends = band_ends(&band_points);
    // Range noise seen by a low sensor is mostly along the underside; measure it on the body too.
    let body_sigma = envelope::surface_noise(&band_points).unwrap_or(0.0);
    let noise_sigma_m = config.noise_m.unwrap_or(noise_sigma_m.max(body_sigma));
    let bin_m = config
        .bin_m
        .unwrap_or_else(|| auto_bin(&band_points, config.min_support));
    // At least 0.4 bin: a surface sloping up to 0.8 keeps both of a bin's point columns in its mode.
    let half_window_m = (2.5 * noise_sigma_m).max(0.4 * bin_m);
    // Faces across the path (a part's end cap) stay out of the modes; the body's ends are
    // still placed from all points (`refine_ends`).
    // Without noise there is no smear to leave out, and a face's lowest points are the exact
    // end of the surface below it (the synthetic noiseless vehicles' bumpers; `edge` leaves
    // such ends alone by the same rule).
    let across = if config.skip_faces_across_path && noise_sigma_m >= edge::MIN_NOISE_BINS * bin_m {
        envelope::across_path(&band_points, axles_x_m)
    } else {
        vec![false; band_points.len()]
    };
    let mode_points: Vec<V3> = band_points
        .iter()
        .zip(&across)
        .filter(|&(_, &a)| !a)
        .map(|(p, _)| *p)
        .collect();
    let eparams = EnvelopeParams {
        bin_m,
        half_window_m,
        min_support: config.min_support,
        noise_m: noise_sigma_m,
        scan_line,
    };
    // Between the axles the underside is seen from below, its noise is vertical, and a lower
    // part beside a wider surface within the window (a sill 1 cm below the floor pan) must keep
    // its own mode: the whole band's envelope gains one per lateral strip there. In the overhangs
    // the rays graze the faces and smear them along x; there the whole band's support alone keeps
    // the smear out of the modes. The counts (bins without a mode, points below) are the band's.
    let (lo, hi) = (axles_x_m.0.min(axles_x_m.1), axles_x_m.0.max(axles_x_m.1));
    let between: Vec<V3> = mode_points
        .iter()
        .copied()
        .filter(|p| p[0] > lo && p[0] < hi)
        .collect();
    let env = lower_envelope(&mode_points, eparams).with_samples_of(
        envelope::lower_envelope_strips(&between, eparams, envelope::BETWEEN_AXLES_STRIP_M),
    );
    counts.outliers_below_envelope = env.outliers_below;
    let mut samples = env.samples;
    // The faces left out of the modes keep their lowest edges (a mud flap is its own witness).
    let free_edges = faces::face_bottoms(
        &band_points,
        &across,
        &samples,
        axles_x_m,
        noise_sigma_m,
        bin_m,
        config.min_support,
    );
    samples.extend(free_edges);
    samples.sort_by(|a, b| a.x_m.total_cmp(&b.x_m));
    Body {
        samples,
        band_points,
        ends,
        noise_sigma_m,
        bin_m,
        // Fringe bins are the expected smear of a surface's edge, not missing data: not warned.
        unsupported_bins: env.unsupported_bins,
    }
}

/// The approach and departure zones' limits along x: (front, rear).
fn zone_limits(front: Axle, rear: Axle, zone: Zone) -> (f64, f64) {
    match zone {
        Zone::Tyre => (
            front.x_m + front.free_radius_m,
            rear.x_m - rear.free_radius_m,
        ),
        Zone::Axle => (front.x_m, rear.x_m),
    }
}

/// Replace the last bins at the body's front and rear ends by an edge estimate ([`edge`]).
fn refine_ends(body: &mut Body, front: Axle, rear: Axle, zone: Zone) {
    let (front_limit, rear_limit) = zone_limits(front, rear, zone);
    for (outward, limit) in [(1.0, front_limit), (-1.0, rear_limit)] {
        edge::refine_end(
            &mut body.samples,
            &body.band_points,
            outward,
            limit,
            body.noise_sigma_m,
            body.bin_m,
        );
    }
}

/// A frame with z along the plane normal, x along `forward` projected onto the plane, origin at the
/// projection of the points' centroid.
fn frame_on(plane: Plane, points: &[V3], forward: V3) -> Option<VehicleFrame> {
    let n = points.len() as f64;
    let c = points.iter().fold(V3::zeros(), |a, p| a + *p);
    let c = c * (1.0 / n);
    let origin = c - (plane.normal * plane.height(c));
    VehicleFrame::from_up_forward(origin, plane.normal, forward)
}

/// Fit every seed, label front/rear and left/right.
fn fit_tyres(
    frame: &VehicleFrame,
    in_frame: &[V3],
    seeds: &[Seed],
    config: &AnglesConfig,
    seed_low: f64,
    noise: f64,
    warnings: &mut Vec<String>,
) -> Result<Vec<(TyrePosition, TyreFit)>, AnglesError> {
    let seeds: Vec<&Seed> = seeds.iter().take(tyres::CANDIDATE_SEEDS).collect();
    if seeds.len() < 2 {
        return Err(AnglesError::Tyres(format!(
            "{} footprint cluster(s) between {:.3} m and {:.3} m above the ground; need a front and a rear tyre",
            seeds.len(),
            seed_low,
            config.seed_high_m
        )));
    }
    // Which side of the vehicle a footprint is on: about the four largest, as a vehicle's
    // footprints are the largest clusters in most scans.
    let largest = &seeds[..seeds.len().min(4)];
    let centre_y = largest.iter().map(|s| s.y).sum::<f64>() / largest.len() as f64;
    let mut fitted = Vec::new();
    let mut unfitted = Vec::new();
    for (i, s) in seeds.iter().enumerate() {
        let params = TyreParams {
            h_lo: seed_low,
            h_hi: config.seed_high_m,
            gap_m: config.tyre_gap_m,
            noise_m: noise,
            inward_sign: if s.y < centre_y { 1.0 } else { -1.0 },
            band_edges: config.range_accuracy_m.is_some(),
            seed: config.seed,
        };
        match tyres::fit_tyre(in_frame, s, params) {
            Some(f) => fitted.push((f, s.count)),
            None if i < 4 => unfitted.push(format!("x {:.2} m, y {:.2} m", s.x, s.y)),
            None => {}
        }
    }
    let candidates: Vec<(f64, f64, usize)> = fitted
        .iter()
        .map(|(f, count)| (f.centre_x, f.centre_y, *count))
        .collect();
    let mut fits: Vec<TyreFit> = match tyres::vehicle_set(&candidates, &path_xy(frame, config)) {
        Some(set) => set.into_iter().map(|i| fitted[i].0.clone()).collect(),
        None => fitted.into_iter().take(4).map(|(f, _)| f).collect(),
    };
    if fits.len() < 4 {
        let ignored = |u: &String| format!("footprint at {u}: no consistent tyre circle, ignored");
        warnings.extend(unfitted.iter().map(ignored));
    }
    fits.sort_by(|a, b| a.centre_x.total_cmp(&b.centre_x));
    // Split front/rear at the largest gap in x.
    let split = (1..fits.len())
        .max_by(|&i, &j| {
            (fits[i].centre_x - fits[i - 1].centre_x)
                .total_cmp(&(fits[j].centre_x - fits[j - 1].centre_x))
        })
        .filter(|&i| fits[i].centre_x - fits[i - 1].centre_x > tyres::MIN_WHEELBASE_M)
        .ok_or_else(|| {
            let fitted: Vec<String> = fits
                .iter()
                .map(|f| {
                    format!(
                        "x {:.2} m, y {:.2} m (centre height {:.3} m)",
                        f.centre_x, f.centre_y, f.loaded_radius_m
                    )
                })
                .collect();
            let unfitted = if unfitted.is_empty() {
                String::new()
            } else {
                format!("; footprints without a circle at {}", unfitted.join(", "))
            };
            AnglesError::Tyres(format!(
                "{} tyre circle(s) fitted, but no front and rear axle more than {} m apart \
                 (circles at {}{unfitted})",
                fits.len(),
                tyres::MIN_WHEELBASE_M,
                fitted.join(", ")
            ))
        })?;
    let centre_y = fits.iter().map(|f| f.centre_y).sum::<f64>() / fits.len() as f64;
    let mut out = Vec::new();
    for (group, is_front) in [(&fits[split..], true), (&fits[..split], false)] {
        let mut group: Vec<&TyreFit> = group.iter().collect();
        if group.len() > 2 {
            warnings.push(format!(
                "{} tyre circles on one axle; the two best supported were kept",
                group.len()
            ));
            group.sort_by_key(|g| std::cmp::Reverse(g.silhouette_points));
            group.truncate(2);
        }
        if group.len() == 2 && (group[0].centre_y > centre_y) == (group[1].centre_y > centre_y) {
            warnings.push("two tyres on one side of the same axle; check the labels".into());
        }
        for f in group {
            let left = f.centre_y > centre_y;
            let pos = match (is_front, left) {
                (true, true) => TyrePosition::FrontLeft,
                (true, false) => TyrePosition::FrontRight,
                (false, true) => TyrePosition::RearLeft,
                (false, false) => TyrePosition::RearRight,
            };
            out.push((pos, f.clone()));
        }
    }
    Ok(out)
}

/// The scan path's positions in `frame`, sorted by x.
fn path_in_frame(frame: &VehicleFrame, config: &AnglesConfig) -> Vec<V3> {
    let mut path: Vec<V3> = config
        .scan_path_in_cloud
        .iter()
        .map(|&p| frame.vehicle_from_cloud(p))
        .collect();
    path.sort_by(|a, b| a[0].total_cmp(&b[0]));
    path
}

/// The scan path's positions in `frame`, `(x, y)`.
fn path_xy(frame: &VehicleFrame, config: &AnglesConfig) -> Vec<[f64; 2]> {
    config
        .scan_path_in_cloud
        .iter()
        .map(|&p| {
            let v = frame.vehicle_from_cloud(p);
            [v[0], v[1]]
        })
        .collect()
}

fn in_footprint(p: V3, t: &TyreFit) -> bool {
    let (lo, hi) = (
        t.inner_y.min(t.outer_y) - 0.03,
        t.inner_y.max(t.outer_y) + 0.03,
    );
    (p[0] - t.centre_x).abs() < t.free_radius_m + 0.03 && p[1] > lo && p[1] < hi
}

/// Whether `p` is the tyre's: inside its side-view disc (plus `tol`), and laterally from `tol`
/// inboard of its inner face outward without limit. Outboard of the inner face nothing of the
/// body lies inside a wheel's disc, while the tread's outermost returns scatter past the fitted
/// outer face (the 99 % quantile): the outer band ([`Band::OUTER`]) would take them for underside.
fn is_tyre_point(p: V3, t: &TyreFit, tol: f64) -> bool {
    let (lo, hi) = if t.outer_y > t.inner_y {
        (t.inner_y - tol, f64::INFINITY)
    } else {
        (f64::NEG_INFINITY, t.inner_y + tol)
    };
    p[1] > lo
        && p[1] < hi
        && (p[0] - t.centre_x).hypot(p[2] - t.loaded_radius_m) < t.free_radius_m + tol
}

/// Direction from the rear axle to the front one, in cloud coordinates: the mean of the
/// rear-to-front vectors of the sides with both tyres fitted, `None` without such a side.
///
/// Why per side, not from the axles' midpoints: with three tyres one axle's midpoint is a single
/// tyre's centre, half a track off the centreline, and the heading turns by atan(track / 2 /
/// wheelbase), 16 degrees on a city car (simulated, tuning cloud hall-a/1 with `passangle angles`'
/// defaults: a rear footprint without a circle; the frame then turned round after round and lost a
/// second tyre).
fn axle_heading(frame: &VehicleFrame, fits: &[(TyrePosition, TyreFit)]) -> Option<V3> {
    let at = |p: TyrePosition| {
        fits.iter()
            .find(|(q, _)| *q == p)
            .map(|(_, f)| frame.cloud_from_vehicle(V3::new(f.centre_x, f.centre_y, 0.0)))
    };
    let sides: Vec<V3> = [
        (TyrePosition::FrontLeft, TyrePosition::RearLeft),
        (TyrePosition::FrontRight, TyrePosition::RearRight),
    ]
    .into_iter()
    .filter_map(|(f, r)| Some(at(f)? - at(r)?))
    .collect();
    unit(sides.iter().fold(V3::zeros(), |a, v| a + v))
}

/// Largest left-right difference of one axle's static loaded radii that counts as agreement
/// (metres). The same vehicle's two tyres of one axle carry nearly the same load.
const AXLE_LOADED_TOL_M: f64 = 0.010;
/// Largest difference of free radii that counts as agreement (metres): one axle's tyres are the
/// same size.
const AXLE_FREE_TOL_M: f64 = 0.015;

fn tyres_agree(a: &TyreFit, b: &TyreFit) -> bool {
    (a.loaded_radius_m - b.loaded_radius_m).abs() <= AXLE_LOADED_TOL_M
        && (a.free_radius_m - b.free_radius_m).abs() <= AXLE_FREE_TOL_M
}

/// The fits an axle's position and radii come from, and the tyre left out, if any.
///
/// Both tyres, unless they disagree (loaded radii more than 10 mm or free radii more than 15 mm
/// apart) while the other axle's two agree with each other and exactly one of this axle's agrees
/// with both of them: then the other one is a misfit (a mud flap behind a pickup's rear tyre, a
/// partial silhouette of few points; measured on the simulator: the pickup's rear tyres on 4 of
/// 10 oracle clouds 4-9 cm off, the sedan's front left on one pipeline cloud 4.5 cm) and is left
/// out. With no such evidence the mean stays (a staggered set-up, uneven load), and the warnings
/// say the radii differ.
fn axle_members(
    fits: &[(TyrePosition, TyreFit)],
    front: bool,
) -> (Vec<&TyreFit>, Option<TyrePosition>) {
    let this: Vec<&(TyrePosition, TyreFit)> =
        fits.iter().filter(|(p, _)| p.is_front() == front).collect();
    let all = this.iter().map(|(_, f)| f).collect();
    let other: Vec<&TyreFit> = fits
        .iter()
        .filter(|(p, _)| p.is_front() != front)
        .map(|(_, f)| f)
        .collect();
    let ([a, b], [c, d]) = (this.as_slice(), other.as_slice()) else {
        return (all, None);
    };
    if tyres_agree(&a.1, &b.1) || !tyres_agree(c, d) {
        return (all, None);
    }
    let fits_other = |f: &TyreFit| tyres_agree(f, c) && tyres_agree(f, d);
    match (fits_other(&a.1), fits_other(&b.1)) {
        (true, false) => (vec![&a.1], Some(b.0)),
        (false, true) => (vec![&b.1], Some(a.0)),
        _ => (all, None),
    }
}

fn axles(fits: &[(TyrePosition, TyreFit)], config: &AnglesConfig, noise_m: f64) -> (Axle, Axle) {
    let axle = |front: bool| {
        let sel = axle_members(fits, front).0;
        let n = sel.len().max(1) as f64;
        let xs: Vec<(f64, f64)> = sel
            .iter()
            .map(|f| (f.centre_x, f.covariance[0][0]))
            .collect();
        let radii: Vec<(f64, f64)> = sel
            .iter()
            .map(|f| (f.loaded_radius_m, f.covariance[1][1]))
            .collect();
        Axle {
            x_m: sel.iter().map(|f| f.centre_x).sum::<f64>() / n,
            loaded_radius_m: config
                .tyre_radius_m
                .unwrap_or_else(|| sel.iter().map(|f| f.loaded_radius_m).sum::<f64>() / n),
            free_radius_m: sel.iter().map(|f| f.free_radius_m).sum::<f64>() / n,
            u_x_m: uncertainty::axle_mean_u(&xs),
            u_loaded_radius_m: if config.tyre_radius_m.is_some() {
                0.0
            } else {
                uncertainty::axle_mean_u(&radii).hypot(noise_m)
            },
        }
    };
    (axle(true), axle(false))
}

fn is_left(p: TyrePosition) -> bool {
    matches!(p, TyrePosition::FrontLeft | TyrePosition::RearLeft)
}

/// Midpoint between the left and right inner faces (or the mean tyre y if a side is missing).
fn centreline_y(fits: &[(TyrePosition, TyreFit)]) -> f64 {
    let left: Vec<f64> = fits
        .iter()
        .filter(|(p, _)| is_left(*p))
        .map(|(_, f)| f.inner_y)
        .collect();
    let right: Vec<f64> = fits
        .iter()
        .filter(|(p, _)| !is_left(*p))
        .map(|(_, f)| f.inner_y)
        .collect();
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    if left.is_empty() || right.is_empty() {
        fits.iter().map(|(_, f)| f.centre_y).sum::<f64>() / fits.len().max(1) as f64
    } else {
        0.5 * (mean(&left) + mean(&right))
    }
}

fn track(fits: &[(TyrePosition, TyreFit)], y: impl Fn(&TyreFit) -> f64) -> Option<f64> {
    let mean = |left: bool| {
        let v: Vec<f64> = fits
            .iter()
            .filter(|(p, _)| is_left(*p) == left)
            .map(|(_, f)| y(f))
            .collect();
        (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
    };
    Some(mean(true)? - mean(false)?)
}

fn band(fits: &[(TyrePosition, TyreFit)], band: Band, warnings: &mut Vec<String>) -> (f64, f64) {
    match band {
        Band::Full => (f64::NEG_INFINITY, f64::INFINITY),
        Band::HalfWidth(w) => (-w, w),
        Band::InnerFaces { margin_m } => {
            let left = fits
                .iter()
                .filter(|(p, _)| is_left(*p))
                .map(|(_, f)| f.inner_y)
                .fold(f64::INFINITY, f64::min);
            let right = fits
                .iter()
                .filter(|(p, _)| !is_left(*p))
                .map(|(_, f)| f.inner_y)
                .fold(f64::NEG_INFINITY, f64::max);
            if left.is_finite() && right.is_finite() && left - margin_m > right + margin_m {
                (right + margin_m, left - margin_m)
            } else {
                warnings.push(
                    "tyres on one side only: the envelope uses every body point (full band)".into(),
                );
                (f64::NEG_INFINITY, f64::INFINITY)
            }
        }
        Band::OuterFaces { margin_m } => {
            let left = fits
                .iter()
                .filter(|(p, _)| is_left(*p))
                .map(|(_, f)| f.outer_y)
                .fold(f64::NEG_INFINITY, f64::max);
            let right = fits
                .iter()
                .filter(|(p, _)| !is_left(*p))
                .map(|(_, f)| f.outer_y)
                .fold(f64::INFINITY, f64::min);
            if left.is_finite() && right.is_finite() && left > right {
                (right - margin_m, left + margin_m)
            } else {
                warnings.push(
                    "tyres on one side only: the envelope uses every body point (full band)".into(),
                );
                (f64::NEG_INFINITY, f64::INFINITY)
            }
        }
    }
}

/// The rear and front ends of the band's points: their x and the highest z within 3 cm of each.
fn band_ends(points: &[V3]) -> [(f64, f64); 2] {
    let x_min = points.iter().map(|p| p[0]).fold(f64::INFINITY, f64::min);
    let x_max = points
        .iter()
        .map(|p| p[0])
        .fold(f64::NEG_INFINITY, f64::max);
    let top = |x_end: f64| {
        points
            .iter()
            .filter(|p| (p[0] - x_end).abs() < 0.03)
            .map(|p| p[2])
            .fold(f64::NEG_INFINITY, f64::max)
    };
    [(x_min, top(x_min)), (x_max, top(x_max))]
}

/// 5 mm, doubled while the median occupied bin holds fewer than 3 x `min_support` points (max
/// [`envelope::MAX_BIN_M`]).
fn auto_bin(points: &[V3], min_support: usize) -> f64 {
    let mut bin = 0.005;
    while bin < envelope::MAX_BIN_M {
        let mut keys: Vec<i64> = points.iter().map(|p| (p[0] / bin).floor() as i64).collect();
        keys.sort_unstable();
        let mut sizes: Vec<f64> = keys
            .chunk_by(|a, b| a == b)
            .map(|c| c.len() as f64)
            .collect();
        if geom::median(&mut sizes).unwrap_or(0.0) >= 3.0 * min_support as f64 {
            break;
        }
        bin *= 2.0;
    }
    bin
}

/// Largest gap along x inside the vehicle's side-view envelope ahead of the front axle or behind
/// the rear one (metres); the first step from the axle may add the tyre's free radius.
const DETACHED_GAP_M: f64 = 0.5;

/// How far (metres) an end of the scanned underside may lie beyond the end of the scan's path.
/// The VLP-16's steepest rings (+11..+15 degrees) see an underside 0.1-0.15 m above the sensor
/// from 0.4-0.7 m away; what lies further beyond the robot's last position is seen only by the
/// flat rings, at grazing angles and in stripes, and ends where their reach ends rather than where
/// the vehicle does (measured: a van pass stopped after 12 s saw its rear underside to 2.7 m
/// behind the robot, 0.43 m short of the rear end, and read the departure 10 degrees high).
pub const PATH_REACH_M: f64 = 0.5;

/// Largest gap (metres, along x) between envelope samples between the axles (between the tyres'
/// treads) that still counts as covered: nothing hides in less (full passes: at most 0.05 m).
pub const MAX_UNDERSIDE_GAP_M: f64 = 0.3;

/// Without a scan path, the cloud must show ground at least this far (metres) beyond each end of
/// the underside: a cloud that ends where the underside ends was cut, not scanned past the end.
pub const GROUND_BEYOND_M: f64 = 0.3;

/// What the scan does not cover (module doc, step 6): an error when the axles themselves were
/// not covered (nothing can be measured), otherwise the quantities whose part of the vehicle was
/// not seen. `samples` is the envelope after [`drop_detached`], sorted by x; `in_frame` every
/// usable point in the vehicle frame.
fn check_coverage(
    samples: &[EnvelopeSample],
    (front, rear): (Axle, Axle),
    frame: &VehicleFrame,
    in_frame: &[V3],
    config: &AnglesConfig,
) -> Result<Vec<NotMeasured>, AnglesError> {
    let between_axles = |reason: String| {
        Ok(vec![
            NotMeasured {
                quantity: Quantity::Breakover,
                kind: Absence::NotCovered,
                reason: reason.clone(),
            },
            NotMeasured {
                quantity: Quantity::GroundClearance,
                kind: Absence::NotCovered,
                reason,
            },
        ])
    };
    // Between the tyres' treads: the breakover's zone.
    let (lo, hi) = (
        rear.x_m + rear.free_radius_m,
        front.x_m - front.free_radius_m,
    );
    let between: Vec<f64> = samples
        .iter()
        .map(|s| s.x_m)
        .filter(|x| *x > lo && *x < hi)
        .collect();
    let mut out = Vec::new();
    if between.is_empty() {
        out = between_axles(format!(
            "the underside between the axles was not seen (no body points between x {lo:.2} and {hi:.2} m, vehicle frame)"
        ))?;
    }
    if let Some(w) = between
        .windows(2)
        .max_by(|a, b| (a[1] - a[0]).total_cmp(&(b[1] - b[0])))
        .filter(|w| w[1] - w[0] > MAX_UNDERSIDE_GAP_M)
    {
        out = between_axles(format!(
            "the underside between the axles is not covered from x {:.2} to {:.2} m (vehicle frame; a gap of {:.2} m, at most {MAX_UNDERSIDE_GAP_M} m allowed)",
            w[0],
            w[1],
            w[1] - w[0]
        ))?;
    }
    let (Some(rear_end), Some(front_end)) = (samples.first(), samples.last()) else {
        return Ok(out);
    };
    let (rear_end, front_end) = (rear_end.x_m, front_end.x_m);
    if config.scan_path_in_cloud.is_empty() {
        out.extend(check_ground_beyond(
            in_frame,
            rear_end,
            front_end,
            config.ground_threshold_m,
        ));
        return Ok(out);
    }
    let xs = config
        .scan_path_in_cloud
        .iter()
        .map(|p| frame.vehicle_from_cloud(*p)[0]);
    let (path_lo, path_hi) = xs.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
        (a.min(x), b.max(x))
    });
    let path =
        format!("the scan's path runs from x {path_lo:.2} to {path_hi:.2} m (vehicle frame)");
    if path_lo > rear.x_m || path_hi < front.x_m {
        return Err(AnglesError::Incomplete(format!(
            "the underside between the axles was not covered: {path}, the axles are at x {:.2} and {:.2} m; a tyre pair seen only from afar is not measured",
            rear.x_m, front.x_m
        )));
    }
    if front_end > path_hi + PATH_REACH_M {
        out.push(NotMeasured {
            quantity: Quantity::Approach,
            kind: Absence::NotCovered,
            reason: format!(
                "the front overhang was not seen from below: {path}, the scanned underside reaches x {front_end:.2} m, more than {PATH_REACH_M} m beyond the path"
            ),
        });
    }
    if rear_end < path_lo - PATH_REACH_M {
        out.push(NotMeasured {
            quantity: Quantity::Departure,
            kind: Absence::NotCovered,
            reason: format!(
                "the rear overhang was not seen from below: {path}, the scanned underside reaches x {rear_end:.2} m, more than {PATH_REACH_M} m beyond the path"
            ),
        });
    }
    Ok(out)
}

/// Without a path: ground must be seen [`GROUND_BEYOND_M`] beyond each end of the underside, or
/// that end's angle is not measured.
fn check_ground_beyond(
    in_frame: &[V3],
    rear_end: f64,
    front_end: f64,
    ground_threshold_m: f64,
) -> Vec<NotMeasured> {
    let ground_x = in_frame
        .iter()
        .filter(|p| p[2].abs() < ground_threshold_m)
        .map(|p| p[0]);
    let (g_lo, g_hi) = ground_x.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
        (a.min(x), b.max(x))
    });
    let mut out = Vec::new();
    for (quantity, name, end, beyond) in [
        (Quantity::Approach, "front", front_end, g_hi - front_end),
        (Quantity::Departure, "rear", rear_end, rear_end - g_lo),
    ] {
        if beyond < GROUND_BEYOND_M {
            out.push(NotMeasured {
                quantity,
                kind: Absence::NotCovered,
                reason: format!(
                    "the {name} overhang may extend beyond the cloud: the cloud ends {:.2} m beyond the underside's end at x {end:.2} m (vehicle frame; at least {GROUND_BEYOND_M} m of ground beyond it expected)",
                    beyond.max(0.0)
                ),
            });
        }
    }
    out
}

/// Clear the findings the scan does not support (`not_covered`), and give every finding that is
/// absent its reason.
fn not_measured(findings: &mut Findings, mut not_covered: Vec<NotMeasured>) -> Vec<NotMeasured> {
    for n in &not_covered {
        match n.quantity {
            Quantity::Approach => findings.approach = None,
            Quantity::Departure => findings.departure = None,
            Quantity::Breakover => findings.breakover = None,
            Quantity::GroundClearance => findings.clearance = None,
        }
    }
    let absent = [
        (
            Quantity::Approach,
            findings.approach.is_none(),
            "no body points ahead of the front tyres (nothing in the zone)",
        ),
        (
            Quantity::Departure,
            findings.departure.is_none(),
            "no body points behind the rear tyres (nothing in the zone)",
        ),
        (
            Quantity::Breakover,
            findings.breakover.is_none(),
            "no body points between the axles",
        ),
        (
            Quantity::GroundClearance,
            findings.clearance.is_none(),
            "no body points between the axles",
        ),
    ];
    for (quantity, is_absent, reason) in absent {
        if is_absent && !not_covered.iter().any(|n| n.quantity == quantity) {
            not_covered.push(NotMeasured {
                quantity,
                kind: Absence::NothingInZone,
                reason: reason.to_owned(),
            });
        }
    }
    not_covered
}

/// Drop the envelope samples that are not connected to the vehicle: walking out from each axle,
/// the envelope ends at the first gap along x wider than [`DETACHED_GAP_M`] (the first step from
/// the axle may add the tyre's free radius). Whatever lies beyond is not the vehicle: on the
/// pickup's wheel-odometry cloud, ground 8 m behind the rear axle rose 3.3 cm above the fitted
/// plane and gave a departure angle of 0.2 degrees. Samples between the axles are all kept.
/// Returns how many were dropped. `samples` must be sorted by x.
fn drop_detached(samples: &mut Vec<EnvelopeSample>, front: Axle, rear: Axle) -> usize {
    let mut front_end = front.x_m + front.free_radius_m;
    for s in samples.iter().filter(|s| s.x_m > front.x_m) {
        if s.x_m - front_end > DETACHED_GAP_M {
            break;
        }
        front_end = front_end.max(s.x_m);
    }
    let mut rear_end = rear.x_m - rear.free_radius_m;
    for s in samples.iter().rev().filter(|s| s.x_m < rear.x_m) {
        if rear_end - s.x_m > DETACHED_GAP_M {
            break;
        }
        rear_end = rear_end.min(s.x_m);
    }
    let before = samples.len();
    samples.retain(|s| s.x_m >= rear_end && s.x_m <= front_end);
    before - samples.len()
}

struct Findings {
    approach: Option<AngleFinding>,
    departure: Option<AngleFinding>,
    breakover: Option<AngleFinding>,
    clearance: Option<Clearance>,
}

fn find_angles(
    samples: &[EnvelopeSample],
    front: Axle,
    rear: Axle,
    zone: Zone,
    frame: &VehicleFrame,
    inputs: uncertainty::Inputs,
) -> Findings {
    let (front_limit, rear_limit) = zone_limits(front, rear, zone);
    let finding = |s: &EnvelopeSample, angle_rad: f64, parts_rad: Option<(f64, f64)>| {
        let w = V3::new(s.x_m, s.y_m, s.z_m);
        AngleFinding {
            angle_rad,
            parts_rad,
            witness_in_vehicle: w,
            witness_in_cloud: frame.cloud_from_vehicle(w),
            support: s.support,
            uncertainty: Uncertainty::default(),
        }
    };
    let keep_min = |best: &mut Option<AngleFinding>, cand: AngleFinding| {
        if best.as_ref().is_none_or(|b| cand.angle_rad < b.angle_rad) {
            *best = Some(cand);
        }
    };
    let mut out = Findings {
        approach: None,
        departure: None,
        breakover: None,
        clearance: None,
    };
    for s in samples {
        let a_front = tangent_slope(s.x_m - front.x_m, s.z_m, front.loaded_radius_m);
        let a_rear = tangent_slope(rear.x_m - s.x_m, s.z_m, rear.loaded_radius_m);
        if s.x_m > front_limit
            && let Some(a) = a_front
        {
            keep_min(&mut out.approach, finding(s, a, None));
        }
        if s.x_m < rear_limit
            && let Some(a) = a_rear
        {
            keep_min(&mut out.departure, finding(s, a, None));
        }
        if s.x_m > rear.x_m && s.x_m < front.x_m {
            let af = tangent_slope(front.x_m - s.x_m, s.z_m, front.loaded_radius_m);
            let ar = tangent_slope(s.x_m - rear.x_m, s.z_m, rear.loaded_radius_m);
            if let (Some(af), Some(ar)) = (af, ar) {
                keep_min(&mut out.breakover, finding(s, af + ar, Some((af, ar))));
            }
        }
        if s.x_m >= rear.x_m
            && s.x_m <= front.x_m
            && out.clearance.as_ref().is_none_or(|c| s.z_m < c.height_m)
        {
            let w = V3::new(s.x_m, s.y_m, s.z_m);
            out.clearance = Some(Clearance {
                height_m: s.z_m,
                witness_in_vehicle: w,
                witness_in_cloud: frame.cloud_from_vehicle(w),
                uncertainty: uncertainty::of_clearance(inputs),
            });
        }
    }
    // The uncertainties of the limiting samples only (the minimum's, not every sample's).
    let xz = |f: &AngleFinding| [f.witness_in_vehicle[0], f.witness_in_vehicle[2]];
    if let Some(f) = &mut out.approach {
        f.uncertainty = uncertainty::of_overhang(xz(f), &front, true, inputs);
    }
    if let Some(f) = &mut out.departure {
        f.uncertainty = uncertainty::of_overhang(xz(f), &rear, false, inputs);
    }
    if let Some(f) = &mut out.breakover {
        f.uncertainty = uncertainty::of_breakover(xz(f), (&front, &rear), inputs);
    }
    out
}

/// What the scanner saw from its path (`visibility`), with its view and the path in `config`;
/// `None` without them. `noise_m` is the calculator's noise sigma, which sets the floor's cut-off
/// as in `classify`; the body's sets the tolerance.
fn scan_sight(
    config: &AnglesConfig,
    frame: &VehicleFrame,
    in_frame: &[V3],
    body: &Body,
    noise_m: f64,
) -> Option<visibility::Sight> {
    let path: Vec<V3> = config
        .scan_path_in_cloud
        .iter()
        .map(|p| frame.vehicle_from_cloud(*p))
        .collect();
    visibility::Sight::new(
        in_frame,
        body_floor_m(config, noise_m),
        &path,
        config.scanner_view?,
        3.0 * body.noise_sigma_m,
    )
}

/// How far the approach's and the departure's witness parts may go on beyond the witnesses
/// (`visibility`), into their uncertainties; a part the scan does not show ending within
/// [`visibility::MAX_REACH_M`] leaves its angle not measured (returned).
fn end_reaches(
    findings: &mut Findings,
    sight: &visibility::Sight,
    front: Axle,
    rear: Axle,
) -> Vec<NotMeasured> {
    let mut out = Vec::new();
    for (finding, quantity, axle, outward, name) in [
        (
            &mut findings.approach,
            Quantity::Approach,
            front,
            1.0,
            "front",
        ),
        (
            &mut findings.departure,
            Quantity::Departure,
            rear,
            -1.0,
            "rear",
        ),
    ] {
        let Some(f) = finding else { continue };
        let w = f.witness_in_vehicle;
        let Some(reach) = visibility::end_reach(sight, w, outward) else {
            out.push(NotMeasured {
                quantity,
                kind: Absence::NotCovered,
                reason: format!(
                    "the {name} overhang's lowest part (x {:.2}, z {:.2} m, vehicle frame) was not seen to end: no place at its height within {} m beyond it was in the lidar's view without returns",
                    w[0],
                    w[2],
                    visibility::MAX_REACH_M
                ),
            });
            continue;
        };
        let angle_at = |beyond: f64| {
            tangent_slope(
                outward * (w[0] - axle.x_m) + beyond,
                w[2],
                axle.loaded_radius_m,
            )
        };
        if let (Some(far), Some(seen)) = (angle_at(reach), angle_at(0.0)) {
            f.uncertainty = f.uncertainty.with_end_reach(seen - far);
        }
    }
    out
}

fn tyres_out(fits: &[(TyrePosition, TyreFit)], frame: &VehicleFrame) -> Vec<Tyre> {
    let mut out: Vec<Tyre> = fits
        .iter()
        .map(|(pos, f)| {
            let c = V3::new(f.centre_x, f.centre_y, f.loaded_radius_m);
            Tyre {
                position: *pos,
                centre_in_vehicle: c,
                centre_in_cloud: frame.cloud_from_vehicle(c),
                loaded_radius_m: f.loaded_radius_m,
                free_radius_m: f.free_radius_m,
                u_centre_x_m: f.covariance[0][0].sqrt(),
                u_loaded_radius_m: f.covariance[1][1].sqrt(),
                width_m: (f.outer_y - f.inner_y).abs(),
                inner_face_y_m: f.inner_y,
                residual_rms_m: f.residual_rms_m,
                fit_points: f.silhouette_points,
            }
        })
        .collect();
    out.sort_by_key(|t| t.position as u8);
    out
}

fn geometry_warnings(r: &mut AnglesResult, config: &AnglesConfig) {
    let w = &mut r.warnings;
    if r.ground.tilt_rad > 5f64.to_radians() {
        w.push(format!(
            "ground tilted {:.1} degrees from the cloud's z (expected <= 5)",
            r.ground.tilt_rad.to_degrees()
        ));
    }
    if r.yaw_rad.abs() > 10f64.to_radians() {
        w.push(format!(
            "vehicle yawed {:.1} degrees from the cloud's x (expected <= 10)",
            r.yaw_rad.to_degrees()
        ));
    }
    if r.tyres.len() < 4 {
        let found: Vec<&str> = r.tyres.iter().map(|t| t.position.label()).collect();
        w.push(format!(
            "only {} tyres fitted ({})",
            r.tyres.len(),
            found.join(", ")
        ));
    }
    for t in &r.tyres {
        if t.residual_rms_m > (2.0 * r.ground.noise_sigma_m).max(0.005) {
            w.push(format!(
                "tyre {}: circle fit residual {:.1} mm is high (noise {:.1} mm)",
                t.position.label(),
                t.residual_rms_m * 1e3,
                r.ground.noise_sigma_m * 1e3
            ));
        }
    }
    for pair in [
        (TyrePosition::FrontLeft, TyrePosition::FrontRight),
        (TyrePosition::RearLeft, TyrePosition::RearRight),
    ] {
        let get = |p| {
            r.tyres
                .iter()
                .find(|t| t.position == p)
                .map(|t| t.loaded_radius_m)
        };
        if let (Some(a), Some(b)) = (get(pair.0), get(pair.1))
            && (a - b).abs() > 0.01
        {
            w.push(format!(
                "{} and {} loaded radii differ by {:.0} mm (uneven load or fit problem)",
                pair.0.label(),
                pair.1.label(),
                (a - b).abs() * 1e3
            ));
        }
    }
    if config.tyre_radius_m.is_some() {
        w.push("static loaded radius overridden by the user".into());
    }
}

fn finding_warnings(
    r: &mut AnglesResult,
    unsupported_bins: usize,
    ends: [(f64, f64); 2],
    config: &AnglesConfig,
) {
    let w = &mut r.warnings;
    let [rear_end, front_end] = ends;
    for (name, f, (edge, end_top)) in [
        ("approach", &r.approach, front_end),
        ("departure", &r.departure, rear_end),
    ] {
        // A scan that ends mid-underside has no face rising at its end: the band's points near
        // the end are no higher than the witness.
        if let Some(f) = f
            && (f.witness_in_vehicle[0] - edge).abs() < 0.03
            && end_top < f.witness_in_vehicle[2] + 0.03
        {
            w.push(format!(
                "{name}: the limiting point is at the end of the scanned body with no face rising there; \
                 the vehicle may extend beyond the cloud"
            ));
        }
    }
    for (name, f) in [
        ("approach", &r.approach),
        ("departure", &r.departure),
        ("breakover", &r.breakover),
    ] {
        if let Some(f) = f
            && f.support < 2 * config.min_support
        {
            w.push(format!(
                "{name}: limiting feature supported by only {} points",
                f.support
            ));
        }
    }
    if unsupported_bins > 0 {
        w.push(format!(
            "{unsupported_bins} envelope bins were ignored (fewer than {} points in their lowest mode)",
            config.min_support
        ));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tyre(x: f64, loaded: f64, free: f64) -> TyreFit {
        TyreFit {
            centre_x: x,
            centre_y: 0.0,
            loaded_radius_m: loaded,
            free_radius_m: free,
            inner_y: 0.0,
            outer_y: 0.0,
            residual_rms_m: 0.003,
            silhouette_points: 60,
            covariance: [[1e-6, 0.0, 0.0], [0.0, 1e-6, 0.0], [0.0, 0.0, 1e-6]],
        }
    }

    #[test]
    fn three_tyres_give_the_heading_along_the_side_with_both() {
        use TyrePosition::{FrontLeft, FrontRight, RearRight};
        let frame = VehicleFrame::from_up_forward(V3::zeros(), V3::z(), V3::x()).expect("a frame");
        let at = |x: f64, y: f64| TyreFit {
            centre_y: y,
            ..tyre(x, 0.276, 0.289)
        };
        // A city car's front tyres and its rear right: the axles' midpoints would turn the
        // heading by atan(0.715 / 2.4), 16.6 degrees.
        let fits = vec![
            (FrontLeft, at(1.2, 0.715)),
            (FrontRight, at(1.2, -0.715)),
            (RearRight, at(-1.2, -0.715)),
        ];
        let h = axle_heading(&frame, &fits).expect("a heading");
        assert!((h - V3::x()).norm() < 1e-12, "{h:?}");
        // Diagonal tyres only: no side to take a heading from.
        assert!(axle_heading(&frame, &[fits[0].clone(), fits[2].clone()]).is_none());
    }

    #[test]
    fn a_tyre_the_other_three_disagree_with_is_left_out_of_its_axle() {
        use TyrePosition::{FrontLeft, FrontRight, RearLeft, RearRight};
        let config = AnglesConfig::default();
        // The sedan's pipeline seed 9: the front left circle 4.5 cm forward and 4.4 cm too big.
        let misfit = vec![
            (FrontLeft, tyre(1.518, 0.3349, 0.3923)),
            (FrontRight, tyre(1.473, 0.3266, 0.3478)),
            (RearLeft, tyre(-1.496, 0.3201, 0.3471)),
            (RearRight, tyre(-1.495, 0.3176, 0.3477)),
        ];
        let (front, rear) = axles(&misfit, &config, 0.003);
        assert!((front.x_m - 1.473).abs() < 1e-12, "{front:?}");
        assert!((front.loaded_radius_m - 0.3266).abs() < 1e-12);
        assert!(
            (rear.x_m + 1.4955).abs() < 1e-12,
            "the agreeing axle keeps its mean"
        );
        assert_eq!(axle_members(&misfit, true).1, Some(FrontLeft));
        // A staggered set-up (each axle consistent, the axles not): both kept.
        let staggered = vec![
            (FrontLeft, tyre(1.5, 0.31, 0.33)),
            (FrontRight, tyre(1.5, 0.312, 0.331)),
            (RearLeft, tyre(-1.5, 0.35, 0.37)),
            (RearRight, tyre(-1.5, 0.351, 0.372)),
        ];
        assert_eq!(axle_members(&staggered, true).1, None);
        assert_eq!(axle_members(&staggered, false).1, None);
        // One axle disagrees but so does the other: no evidence which is wrong, the mean stays.
        let both = vec![
            (FrontLeft, tyre(1.5, 0.30, 0.33)),
            (FrontRight, tyre(1.5, 0.33, 0.36)),
            (RearLeft, tyre(-1.5, 0.30, 0.33)),
            (RearRight, tyre(-1.5, 0.33, 0.36)),
        ];
        let (front, _) = axles(&both, &config, 0.003);
        assert!((front.loaded_radius_m - 0.315).abs() < 1e-12);
    }

    fn sample(x_m: f64) -> EnvelopeSample {
        EnvelopeSample {
            x_m,
            z_m: 0.3,
            y_m: 0.0,
            support: 10,
        }
    }

    #[test]
    fn a_non_finite_scan_path_position_is_refused_by_number() {
        let config = AnglesConfig {
            scan_path_in_cloud: vec![V3::new(0.0, 0.0, 0.1), V3::new(f64::NAN, 0.0, 0.1)],
            ..AnglesConfig::default()
        };
        let err = compute_angles(&[V3::zeros(); 200], &config).unwrap_err();
        assert!(
            err.to_string()
                .contains("scan path position 2 of 2 is not finite"),
            "{err}"
        );
    }

    #[test]
    fn envelope_beyond_a_gap_is_not_the_vehicle() {
        let axle = |x_m| Axle {
            x_m,
            loaded_radius_m: 0.33,
            free_radius_m: 0.34,
            u_x_m: 0.0,
            u_loaded_radius_m: 0.0,
        };
        let (front, rear) = (axle(1.5), axle(-1.5));
        // Body from 1 cm outside each tyre to 0.9 m beyond it, 2 cm steps; between the axles a
        // 0.8 m hole (kept: between the axles nothing is dropped); detached clusters 0.6 m beyond
        // each end of the body.
        let mut xs: Vec<f64> = (0..45).map(|i| 1.85 + 0.02 * f64::from(i)).collect();
        xs.extend(xs.clone().iter().map(|x| -x));
        xs.extend([-0.5, 0.3, 3.4, 3.45, -3.4]);
        xs.sort_by(f64::total_cmp);
        let mut samples: Vec<EnvelopeSample> = xs.iter().map(|&x| sample(x)).collect();
        assert_eq!(drop_detached(&mut samples, front, rear), 3);
        assert_eq!(samples.len(), 92);
        assert!(samples.iter().all(|s| s.x_m.abs() < 2.8));
        // A body that starts within the tyre's radius plus the gap is connected.
        let mut near: Vec<EnvelopeSample> = [2.3, 2.4, -2.3].map(sample).to_vec();
        near.sort_by(|a, b| a.x_m.total_cmp(&b.x_m));
        assert_eq!(drop_detached(&mut near, front, rear), 0);
    }
}
