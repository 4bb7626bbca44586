//! Standard profiles: every standard's quantities from one scan, side by side
//! (docs/method/standards.md).
//!
//! The standards define the passing angles and the ground clearance differently: which points count
//! for the approach and departure (ahead of the front tyre, 49 CFR 523.2 / SAE J1100, or ahead of
//! the front axle, EU 2018/858 Annex I), which parts count (any part of the underside, or rigid
//! parts only with steps excepted), and where the clearance is taken (the whole vehicle, between
//! and under the axles, or the central 80 % of the distance between the inner tyre faces). A
//! [`Standard`] names those settings; [`compute_profiles`] runs the calculator once per distinct
//! (zone, band) set-up the requested standards need and derives each standard's quantities, each
//! with its expanded uncertainty (k = 2) or the reason it was not measured.
//!
//! [`Thresholds`] classify a profile against 49 CFR 523.5 or the EU off-road criteria with a
//! guarded acceptance rule ([`decide`], [`DECISION_RULE`]).

use crate::{
    AngleFinding, AnglesConfig, AnglesError, AnglesResult, Axle, Band, EnvelopeSample, Quantity,
    Uncertainty, V3, Zone, compute_angles,
};

/// A standard whose definitions a profile applies.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Standard {
    /// US 49 CFR 523.2 definitions (the wording of SAE J1100): tyre zone, any part counts.
    Cfr523Sae,
    /// EU type approval, Regulation (EU) 2018/858 Annex I (off-road vehicle criteria): axle zone,
    /// rigid parts only with steps excepted, clearance between and under the axles.
    Eu2018_858,
    /// ISO 612:1978 terms: axle zone, clearance of the central part (80 % of the inner track).
    Iso612,
    /// China GB/T 12673-2019 (measurement method; terms per GB/T 3730.3).
    GbT12673,
    /// India: ARAI / IS 12218 and IS 9435 (based on ISO 612).
    IndiaArai,
    /// Australia: ADR definitions (clearance excluding tyres, hubs and flexible parts).
    AustraliaAdr,
}

/// The wording of the decision rule, printed with every decision.
pub const DECISION_RULE: &str = "guarded acceptance by the expanded uncertainty U (k = 2), \
     ILAC-G8:09/2019: pass when value - U >= limit, fail when value + U < limit, otherwise \
     inconclusive; a quantity that was not measured gives no decision";

impl Standard {
    /// Every standard, in the table's column order.
    pub const ALL: [Standard; 6] = [
        Standard::Cfr523Sae,
        Standard::Eu2018_858,
        Standard::Iso612,
        Standard::GbT12673,
        Standard::IndiaArai,
        Standard::AustraliaAdr,
    ];

    /// Identifier in JSON and on the command line's `--standard`.
    pub fn id(self) -> &'static str {
        match self {
            Standard::Cfr523Sae => "cfr",
            Standard::Eu2018_858 => "eu",
            Standard::Iso612 => "iso612",
            Standard::GbT12673 => "gbt",
            Standard::IndiaArai => "arai",
            Standard::AustraliaAdr => "adr",
        }
    }

    /// Short column heading.
    pub fn short(self) -> &'static str {
        match self {
            Standard::Cfr523Sae => "CFR/SAE",
            Standard::Eu2018_858 => "EU 2018/858",
            Standard::Iso612 => "ISO 612",
            Standard::GbT12673 => "GB/T 12673",
            Standard::IndiaArai => "India ARAI",
            Standard::AustraliaAdr => "ADR",
        }
    }

    /// Title.
    pub fn title(self) -> &'static str {
        match self {
            Standard::Cfr523Sae => "US 49 CFR 523.2 / SAE J1100 definitions",
            Standard::Eu2018_858 => "EU type approval: off-road vehicle criteria",
            Standard::Iso612 => "ISO 612 terms (dimensions of motor vehicles)",
            Standard::GbT12673 => "China GB/T 12673 measurement of main dimensions",
            Standard::IndiaArai => "India ARAI: IS 12218 angles, IS 9435 dimensions",
            Standard::AustraliaAdr => "Australian Design Rules: definitions",
        }
    }

    /// Where the definitions are.
    pub fn citation(self) -> &'static str {
        match self {
            Standard::Cfr523Sae => {
                "49 CFR 523.2 (approach angle, breakover angle, departure angle, running clearance, axle clearance); SAE J1100"
            }
            Standard::Eu2018_858 => {
                "Regulation (EU) 2018/858 Annex I Part A section 4 (formerly Directive 2007/46/EC Annex II, 87/403/EEC); Annex I Appendix 1"
            }
            Standard::Iso612 => {
                "ISO 612:1978 Road vehicles - Dimensions of motor vehicles and towed vehicles - Terms and definitions"
            }
            Standard::GbT12673 => {
                "GB/T 12673-2019 (methods of measurement of main dimensions of motor vehicles); GB/T 3730.3"
            }
            Standard::IndiaArai => {
                "IS 12218:2018 (approach, departure and ramp angles), IS 9435:2004 (based on ISO 612)"
            }
            Standard::AustraliaAdr => {
                "Vehicle Standard (Australian Design Rule - Definitions and Vehicle Categories) 2005"
            }
        }
    }

    /// Parse `all` or a comma-separated list of ids (`cfr`, `eu`, `iso612`, `gbt`, `arai`, `adr`).
    ///
    /// # Errors
    /// Names the unknown id.
    pub fn parse_list(s: &str) -> Result<Vec<Standard>, String> {
        let mut out = Vec::new();
        for part in s.split(',').map(str::trim).filter(|p| !p.is_empty()) {
            if part == "all" {
                out.extend(Standard::ALL);
                continue;
            }
            let std = Standard::ALL
                .into_iter()
                .find(|st| st.id() == part)
                .ok_or_else(|| {
                    format!(
                        "unknown standard `{part}`: expected all, cfr, eu, iso612, gbt, arai or adr"
                    )
                })?;
            out.push(std);
        }
        out.sort();
        out.dedup();
        if out.is_empty() {
            return Err("no standard given".into());
        }
        Ok(out)
    }

    /// Which points count for the approach and departure.
    pub fn zone(self) -> Zone {
        match self {
            Standard::Cfr523Sae | Standard::AustraliaAdr => Zone::Tyre,
            Standard::Eu2018_858 | Standard::Iso612 | Standard::GbT12673 | Standard::IndiaArai => {
                Zone::Axle
            }
        }
    }

    /// The lateral band of the angles: the standards are side views of the whole vehicle.
    pub fn angle_band(self) -> Band {
        Band::OUTER
    }

    /// The quantities this standard reports, in order.
    pub fn quantities(self) -> &'static [QuantityKind] {
        use QuantityKind as Q;
        match self {
            Standard::Cfr523Sae => &[
                Q::Approach,
                Q::Breakover,
                Q::Departure,
                Q::RunningClearance,
                Q::FrontAxleClearance,
                Q::RearAxleClearance,
            ],
            Standard::Eu2018_858 => &[
                Q::Approach,
                Q::Breakover,
                Q::Departure,
                Q::ClearanceBetweenAxles,
                Q::ClearanceUnderFrontAxle,
                Q::ClearanceUnderRearAxle,
            ],
            Standard::Iso612 | Standard::GbT12673 | Standard::IndiaArai => {
                &[Q::Approach, Q::Breakover, Q::Departure, Q::CentralClearance]
            }
            Standard::AustraliaAdr => &[
                Q::Approach,
                Q::Breakover,
                Q::Departure,
                Q::ClearanceExcludingWheels,
            ],
        }
    }

    /// The standard's own name of a quantity.
    pub fn term(self, q: QuantityKind) -> &'static str {
        use QuantityKind as Q;
        match (self, q) {
            (Standard::Cfr523Sae, Q::Breakover) => {
                "breakover angle (SAE J1100: ramp breakover angle)"
            }
            (Standard::AustraliaAdr, Q::Breakover) => "ramp breakover angle",
            (_, Q::Breakover) => "ramp angle",
            (Standard::GbT12673, Q::Approach) => "approach angle (接近角)",
            (Standard::GbT12673, Q::Departure) => "departure angle (离去角)",
            (Standard::GbT12673, Q::CentralClearance) => "minimum ground clearance (最小离地间隙)",
            (_, Q::Approach) => "approach angle",
            (_, Q::Departure) => "departure angle",
            (_, Q::RunningClearance) => "running clearance",
            (_, Q::FrontAxleClearance) => "axle clearance, front",
            (_, Q::RearAxleClearance) => "axle clearance, rear",
            (_, Q::ClearanceBetweenAxles) => "ground clearance between the axles",
            (_, Q::ClearanceUnderFrontAxle) => "ground clearance under the front axle",
            (_, Q::ClearanceUnderRearAxle) => "ground clearance under the rear axle",
            (_, Q::CentralClearance | Q::ClearanceExcludingWheels) => "ground clearance",
        }
    }

    /// What the profile measures, what it cannot and what it assumes.
    pub fn notes(self) -> Vec<&'static str> {
        let mut n = vec![
            "Load state: the vehicle as parked; the standard's load state (kerb, design or \
             maximum mass) must be set up before the scan.",
            "Angles over the whole width in the side view (between the outer tyre faces, 10 cm \
             outside each); static loaded radius = fitted wheel-centre height.",
        ];
        match self {
            Standard::Cfr523Sae => n.extend([
                "Approach/departure: points ahead of the front tyre / behind the rear tyre (tangent \
                 to the static loaded radius arc); every part of the underside counts. The \
                 operator's exclusion boxes still apply: give none for a strict 523.2 reading.",
                "Running clearance (lowest point excluding unsprung weight): the cloud cannot \
                 separate sprung from unsprung parts; measured is the lowest underside point of \
                 the whole vehicle outside the tyres, unsprung parts (axle housings, \
                 differentials, suspension arms) included, so it reads low (conservative) when \
                 an unsprung part is the lowest.",
                "Axle clearance (lowest point of the axle differential): the cloud cannot tell a \
                 differential from other parts; measured is the lowest point under each axle \
                 between the inner tyre faces, within one free tyre radius of the axle along x.",
            ]),
            Standard::Eu2018_858 => n.extend([
                "Approach/departure: no point ahead of the front axle / behind the rear axle \
                 below the plane tangent to the tyres; only rigid parts count, steps excepted. \
                 The cloud cannot tell rigid from flexible parts: flexible parts and steps count \
                 unless the operator excludes them with exclusion boxes.",
                "Ground clearance between the axles: lowest point between the axles over the \
                 whole width (fixed parts; flexible ones only through exclusion boxes).",
                "Ground clearance under an axle: the highest point of the arc through the centres \
                 of the axle's two tyre footprints that touches the lowest point between the \
                 wheels (2007/46/EC Annex II / 2018/858 Annex I wording as recalled, not read \
                 here: UNVERIFIED). Measured over the points between the inner tyre faces within \
                 one free tyre radius of the axle along x; a point's lateral position is the mean \
                 of its envelope bin's supporting points.",
            ]),
            Standard::Iso612 => n.extend([
                "ISO 612 defines terms only, no method or accuracy. Assumed (item numbers and \
                 wording UNVERIFIED, paywalled): approach/departure with points ahead of the \
                 front axle / behind the rear axle, as the EU text that derives from it.",
                "Ground clearance: lowest point of the central part, the middle 80 % of the \
                 distance between the inner tyre faces, over the whole length (assumed: the \
                 definition restricts the width only).",
            ]),
            Standard::GbT12673 => n.extend([
                "GB/T 12673-2019 text not read here (UNVERIFIED). Assumed: approach/departure \
                 with rigid parts fixed ahead of the front axle / behind the rear axle (as the \
                 Chinese consumer definition and the EU text), flexible parts and steps through \
                 the operator's exclusion boxes; ground clearance over the central 80 % of the \
                 inner track as ISO 612 (GB/T 3730.3 follows ISO 612).",
            ]),
            Standard::IndiaArai => n.extend([
                "IS 12218:2018 and IS 9435:2004 texts not read here (UNVERIFIED). Assumed: angles \
                 as ISO 612 (IS 9435 is based on it: axle zone); ground clearance over the \
                 central 80 % of the distance between the inner tyre faces, whole length.",
            ]),
            Standard::AustraliaAdr => n.extend([
                "ADR definitions text not read here (UNVERIFIED). Assumed: approach/departure \
                 tangent to the static loaded radius with points ahead of the front tyre / \
                 behind the rear tyre, as 49 CFR 523.2.",
                "Ground clearance excluding tyres, wheels, hubs, brake backing plates and \
                 flexible mud flaps: tyre points are never underside; points outboard of the \
                 inner tyre faces inside a wheel's side-view disc (hubs, backing plates) are \
                 left out; flexible parts only through the operator's exclusion boxes. Whole \
                 length (assumed).",
            ]),
        }
        n
    }
}

/// A quantity a profile reports; also the row of the side-by-side table.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum QuantityKind {
    /// Approach angle (degrees).
    Approach,
    /// Ramp breakover angle, the supplement of the crest angle (degrees).
    Breakover,
    /// Departure angle (degrees).
    Departure,
    /// Lowest underside point of the whole vehicle (CFR running clearance; metres).
    RunningClearance,
    /// Lowest point under the front axle between the inner tyre faces (CFR axle clearance).
    FrontAxleClearance,
    /// Lowest point under the rear axle between the inner tyre faces.
    RearAxleClearance,
    /// Lowest point between the axles over the whole width (EU).
    ClearanceBetweenAxles,
    /// EU arc clearance under the front axle.
    ClearanceUnderFrontAxle,
    /// EU arc clearance under the rear axle.
    ClearanceUnderRearAxle,
    /// Lowest point over the central 80 % of the inner track (ISO 612, GB/T, ARAI).
    CentralClearance,
    /// Lowest point excluding tyres, hubs and flexible parts (ADR).
    ClearanceExcludingWheels,
}

/// Unit of a quantity's value and U.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Unit {
    /// Degrees.
    Degree,
    /// Metres.
    Metre,
}

impl Unit {
    /// `deg` or `m`.
    pub fn symbol(self) -> &'static str {
        match self {
            Unit::Degree => "deg",
            Unit::Metre => "m",
        }
    }
}

impl QuantityKind {
    /// Every kind, in the table's row order.
    pub const ALL: [QuantityKind; 11] = [
        QuantityKind::Approach,
        QuantityKind::Breakover,
        QuantityKind::Departure,
        QuantityKind::RunningClearance,
        QuantityKind::ClearanceBetweenAxles,
        QuantityKind::CentralClearance,
        QuantityKind::ClearanceExcludingWheels,
        QuantityKind::FrontAxleClearance,
        QuantityKind::RearAxleClearance,
        QuantityKind::ClearanceUnderFrontAxle,
        QuantityKind::ClearanceUnderRearAxle,
    ];

    /// Identifier in JSON.
    pub fn id(self) -> &'static str {
        match self {
            QuantityKind::Approach => "approach",
            QuantityKind::Breakover => "breakover",
            QuantityKind::Departure => "departure",
            QuantityKind::RunningClearance => "running_clearance",
            QuantityKind::FrontAxleClearance => "front_axle_clearance",
            QuantityKind::RearAxleClearance => "rear_axle_clearance",
            QuantityKind::ClearanceBetweenAxles => "clearance_between_axles",
            QuantityKind::ClearanceUnderFrontAxle => "clearance_under_front_axle",
            QuantityKind::ClearanceUnderRearAxle => "clearance_under_rear_axle",
            QuantityKind::CentralClearance => "central_clearance",
            QuantityKind::ClearanceExcludingWheels => "clearance_excluding_wheels",
        }
    }

    /// Row label of the side-by-side table.
    pub fn label(self) -> &'static str {
        match self {
            QuantityKind::Approach => "approach angle",
            QuantityKind::Breakover => "ramp breakover angle",
            QuantityKind::Departure => "departure angle",
            QuantityKind::RunningClearance => "lowest point, whole vehicle",
            QuantityKind::FrontAxleClearance => "lowest point under front axle",
            QuantityKind::RearAxleClearance => "lowest point under rear axle",
            QuantityKind::ClearanceBetweenAxles => "clearance between axles",
            QuantityKind::ClearanceUnderFrontAxle => "arc clearance, front axle",
            QuantityKind::ClearanceUnderRearAxle => "arc clearance, rear axle",
            QuantityKind::CentralClearance => "clearance, central 80 %",
            QuantityKind::ClearanceExcludingWheels => "clearance excl. wheels, hubs",
        }
    }

    /// Unit of the value.
    pub fn unit(self) -> Unit {
        match self {
            QuantityKind::Approach | QuantityKind::Breakover | QuantityKind::Departure => {
                Unit::Degree
            }
            _ => Unit::Metre,
        }
    }
}

/// A value with its expanded uncertainty, or why there is none.
#[derive(Debug, Clone, PartialEq)]
pub enum Measure {
    /// Measured.
    Value {
        /// Degrees or metres ([`QuantityKind::unit`]).
        value: f64,
        /// Expanded uncertainty U (k = 2), same unit.
        u: f64,
        /// The limiting point, vehicle frame (metres).
        witness_in_vehicle: V3,
    },
    /// Not measured, with the reason.
    NotMeasured(String),
}

impl Measure {
    /// The value and U, if measured.
    pub fn value_u(&self) -> Option<(f64, f64)> {
        match self {
            Measure::Value { value, u, .. } => Some((*value, *u)),
            Measure::NotMeasured(_) => None,
        }
    }

    /// The reason, if not measured.
    pub fn reason(&self) -> Option<&str> {
        match self {
            Measure::Value { .. } => None,
            Measure::NotMeasured(r) => Some(r),
        }
    }
}

/// One quantity of a profile.
#[derive(Debug, Clone, PartialEq)]
pub struct ProfileQuantity {
    /// Which.
    pub kind: QuantityKind,
    /// The standard's own name.
    pub name: &'static str,
    /// Value and U, or why not measured.
    pub measure: Measure,
}

/// A standard's quantities from one scan.
#[derive(Debug, Clone, PartialEq)]
pub struct ProfileResult {
    /// Which standard.
    pub standard: Standard,
    /// The quantities, in the standard's order.
    pub quantities: Vec<ProfileQuantity>,
    /// What the profile measures, cannot measure and assumes.
    pub notes: Vec<&'static str>,
}

impl ProfileResult {
    /// The measure of `kind`, if this standard reports it.
    pub fn get(&self, kind: QuantityKind) -> Option<&Measure> {
        self.quantities
            .iter()
            .find(|q| q.kind == kind)
            .map(|q| &q.measure)
    }
}

/// A calculator set-up: the zone and lateral band; everything else from the caller's config.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Setup {
    zone: Zone,
    band: Band,
}

/// The calculator's runs, one per distinct set-up.
struct Runs<'a> {
    cloud: &'a [V3],
    base: &'a AnglesConfig,
    done: Vec<(Setup, Result<AnglesResult, AnglesError>)>,
    /// How many of `done` the caller gave rather than a run made.
    reused: usize,
}

impl Runs<'_> {
    fn get(&mut self, setup: Setup) -> Result<&AnglesResult, String> {
        let i = if let Some(i) = self.done.iter().position(|(s, _)| *s == setup) {
            i
        } else {
            let config = AnglesConfig {
                zone: setup.zone,
                band: setup.band,
                ..self.base.clone()
            };
            self.done.push((setup, compute_angles(self.cloud, &config)));
            self.done.len() - 1
        };
        self.done[i]
            .1
            .as_ref()
            .map_err(|e| format!("the calculator found no result: {e}"))
    }

    /// The distance between the inner tyre faces from any run that has it.
    fn inner_track(&self) -> Option<f64> {
        self.done
            .iter()
            .find_map(|(_, r)| r.as_ref().ok()?.inner_track_m)
    }

    fn runs(&self) -> usize {
        self.done.len() - self.reused
    }
}

/// The quantities of each standard in `standards`, from `cloud` with the caller's settings
/// (front direction, exclusion boxes, tyre radius, noise, scan path; the zone and band are the
/// standard's). The calculator runs once per distinct (zone, band) set-up; `known`, the caller's
/// own result of `cloud` with `base`, serves the set-up it was computed with instead of a run.
pub fn compute_profiles(
    cloud: &[V3],
    base: &AnglesConfig,
    known: Option<&AnglesResult>,
    standards: &[Standard],
) -> Vec<ProfileResult> {
    compute_profiles_counted(cloud, base, known, standards).0
}

/// [`compute_profiles`] and the number of calculator runs it took.
pub fn compute_profiles_counted(
    cloud: &[V3],
    base: &AnglesConfig,
    known: Option<&AnglesResult>,
    standards: &[Standard],
) -> (Vec<ProfileResult>, usize) {
    let mut runs = Runs {
        cloud,
        base,
        done: Vec::new(),
        reused: 0,
    };
    if let Some(r) = known {
        let setup = Setup {
            zone: base.zone,
            band: base.band,
        };
        runs.done.push((setup, Ok(r.clone())));
        runs.reused = 1;
    }
    let out = standards
        .iter()
        .map(|&standard| {
            let quantities = standard
                .quantities()
                .iter()
                .map(|&kind| ProfileQuantity {
                    kind,
                    name: standard.term(kind),
                    measure: measure(&mut runs, standard, kind),
                })
                .collect();
            ProfileResult {
                standard,
                quantities,
                notes: standard.notes(),
            }
        })
        .collect();
    let n = runs.runs();
    (out, n)
}

fn angle_measure(f: Option<&AngleFinding>, r: &AnglesResult, q: Quantity) -> Measure {
    match f {
        Some(f) => Measure::Value {
            value: f.angle_rad.to_degrees(),
            u: f.uncertainty.expanded.to_degrees(),
            witness_in_vehicle: f.witness_in_vehicle,
        },
        None => Measure::NotMeasured(
            r.not_measured_reason(q)
                .unwrap_or("no part of the vehicle in the zone")
                .to_string(),
        ),
    }
}

/// The clearance budget of a lowest envelope sample: the calculator's own for its ground
/// clearance ([`crate::uncertainty::of_clearance`]: the noise normal to the underside and the
/// floor's).
fn clearance_uncertainty(r: &AnglesResult) -> Uncertainty {
    crate::uncertainty::of_clearance(crate::uncertainty::Inputs {
        noise_m: r.noise_sigma_m,
        bin_m: r.bin_m,
        ground_m: r.ground.noise_sigma_m,
        trajectory_per_m: 0.0,
    })
}

fn lowest<'s>(samples: impl Iterator<Item = &'s EnvelopeSample>) -> Option<&'s EnvelopeSample> {
    samples.min_by(|a, b| a.z_m.total_cmp(&b.z_m))
}

fn sample_measure(s: &EnvelopeSample, r: &AnglesResult) -> Measure {
    Measure::Value {
        value: s.z_m,
        u: clearance_uncertainty(r).expanded,
        witness_in_vehicle: V3::new(s.x_m, s.y_m, s.z_m),
    }
}

/// Why a whole-vehicle quantity is not measured: any part of the underside not covered.
fn uncovered(r: &AnglesResult) -> Option<String> {
    let reasons: Vec<String> = r
        .not_measured
        .iter()
        .filter(|n| n.kind == crate::Absence::NotCovered)
        .map(|n| format!("{}: {}", n.quantity.name(), n.reason))
        .collect();
    (!reasons.is_empty()).then(|| {
        format!(
            "part of the underside was not covered, its lowest point may be there ({})",
            reasons.join("; ")
        )
    })
}

/// Height of the apex of the arc through `(-a, 0)` and `(a, 0)` (the tyre footprints' centres,
/// front view) that passes through `(y, z)`: the EU clearance under an axle for that point.
pub fn arc_apex_height(half_track_m: f64, y_m: f64, z_m: f64) -> Option<f64> {
    if !(z_m > 0.0 && y_m.abs() < half_track_m) {
        return None;
    }
    let a = half_track_m;
    let c = (y_m * y_m + z_m * z_m - a * a) / (2.0 * z_m);
    Some(c + a.hypot(c))
}

/// Samples under an axle: within one free tyre radius of it along x.
fn under_axle<'a>(
    r: &'a AnglesResult,
    axle: &'a Axle,
) -> impl Iterator<Item = &'a EnvelopeSample> + 'a {
    let reach = axle.free_radius_m;
    r.envelope
        .iter()
        .filter(move |s| (s.x_m - axle.x_m).abs() <= reach)
}

fn no_underside(which: &str) -> Measure {
    Measure::NotMeasured(format!(
        "no underside seen under the {which} axle between the inner tyre faces"
    ))
}

fn measure(runs: &mut Runs<'_>, standard: Standard, kind: QuantityKind) -> Measure {
    use QuantityKind as Q;
    let angles = Setup {
        zone: standard.zone(),
        band: standard.angle_band(),
    };
    // The clearances' set-ups do not depend on the zone (it only bounds the angles): one zone
    // for all standards, so they share the run.
    let inner = Setup {
        zone: Zone::Tyre,
        band: Band::INNER,
    };
    let result = match kind {
        Q::Approach
        | Q::Breakover
        | Q::Departure
        | Q::RunningClearance
        | Q::ClearanceBetweenAxles
        | Q::ClearanceExcludingWheels => runs.get(angles),
        Q::FrontAxleClearance
        | Q::RearAxleClearance
        | Q::ClearanceUnderFrontAxle
        | Q::ClearanceUnderRearAxle => runs.get(inner),
        Q::CentralClearance => {
            // The band needs the inner track: from a run that has it (any set-up fits the same
            // tyres), running the angles' set-up first if none has.
            if runs.inner_track().is_none()
                && let Err(e) = runs.get(angles)
            {
                return Measure::NotMeasured(e);
            }
            let Some(inner_track) = runs.inner_track() else {
                return Measure::NotMeasured(
                    "the inner track is unknown (tyres on both sides are needed for the \
                     central 80 %)"
                        .into(),
                );
            };
            runs.get(Setup {
                zone: Zone::Axle,
                band: Band::HalfWidth(0.4 * inner_track),
            })
        }
    };
    match result {
        Ok(r) => derive(r, kind),
        Err(e) => Measure::NotMeasured(e),
    }
}

/// The quantity `kind` from the run of its set-up.
fn derive(r: &AnglesResult, kind: QuantityKind) -> Measure {
    use QuantityKind as Q;
    match kind {
        Q::Approach => angle_measure(r.approach.as_ref(), r, Quantity::Approach),
        Q::Departure => angle_measure(r.departure.as_ref(), r, Quantity::Departure),
        Q::Breakover => angle_measure(r.breakover.as_ref(), r, Quantity::Breakover),
        Q::ClearanceBetweenAxles => match &r.ground_clearance {
            Some(c) => Measure::Value {
                value: c.height_m,
                u: c.uncertainty.expanded,
                witness_in_vehicle: c.witness_in_vehicle,
            },
            None => Measure::NotMeasured(
                r.not_measured_reason(Quantity::GroundClearance)
                    .unwrap_or("no underside between the axles")
                    .to_string(),
            ),
        },
        Q::RunningClearance | Q::CentralClearance => {
            if let Some(why) = uncovered(r) {
                return Measure::NotMeasured(why);
            }
            lowest(r.envelope.iter()).map_or_else(
                || Measure::NotMeasured("no underside in the band".into()),
                |s| sample_measure(s, r),
            )
        }
        Q::ClearanceExcludingWheels => {
            if let Some(why) = uncovered(r) {
                return Measure::NotMeasured(why);
            }
            let inner_half = r.inner_track_m.map_or(f64::INFINITY, |t| t / 2.0);
            let in_wheel = |s: &EnvelopeSample| {
                s.y_m.abs() >= inner_half
                    && [&r.front_axle, &r.rear_axle].iter().any(|a| {
                        (s.x_m - a.x_m).hypot(s.z_m - a.loaded_radius_m) <= a.free_radius_m
                    })
            };
            lowest(r.envelope.iter().filter(|s| !in_wheel(s))).map_or_else(
                || Measure::NotMeasured("no underside outside the wheels".into()),
                |s| sample_measure(s, r),
            )
        }
        Q::FrontAxleClearance | Q::RearAxleClearance => {
            let (axle, which) = if kind == Q::FrontAxleClearance {
                (&r.front_axle, "front")
            } else {
                (&r.rear_axle, "rear")
            };
            lowest(under_axle(r, axle))
                .map_or_else(|| no_underside(which), |s| sample_measure(s, r))
        }
        Q::ClearanceUnderFrontAxle | Q::ClearanceUnderRearAxle => {
            let (axle, which) = if kind == Q::ClearanceUnderFrontAxle {
                (&r.front_axle, "front")
            } else {
                (&r.rear_axle, "rear")
            };
            let Some(track) = r.track_m else {
                return Measure::NotMeasured(
                    "the track is unknown (tyres on both sides are needed for the arc)".into(),
                );
            };
            let a = track / 2.0;
            let best = under_axle(r, axle)
                .filter_map(|s| Some((arc_apex_height(a, s.y_m, s.z_m)?, s)))
                .min_by(|x, y| x.0.total_cmp(&y.0));
            match best {
                Some((h, s)) => {
                    // U: the sample's height U through the arc's sensitivity to it.
                    let u_z = clearance_uncertainty(r).expanded;
                    let dz = 1e-4;
                    let slope = match (
                        arc_apex_height(a, s.y_m, s.z_m + dz),
                        arc_apex_height(a, s.y_m, s.z_m - dz),
                    ) {
                        (Some(p), Some(m)) => (p - m) / (2.0 * dz),
                        _ => 1.0,
                    };
                    Measure::Value {
                        value: h,
                        u: slope.abs() * u_z,
                        witness_in_vehicle: V3::new(s.x_m, s.y_m, s.z_m),
                    }
                }
                None => no_underside(which),
            }
        }
    }
}

/// A decision on one value against a lower limit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Decision {
    /// `value - U >= limit`.
    Pass,
    /// `value + U < limit`.
    Fail,
    /// The interval `value +- U` straddles the limit.
    Inconclusive,
    /// The quantity was not measured.
    NoDecision,
}

impl Decision {
    /// `pass`, `fail`, `inconclusive`, `no decision`.
    pub fn label(self) -> &'static str {
        match self {
            Decision::Pass => "pass",
            Decision::Fail => "fail",
            Decision::Inconclusive => "inconclusive",
            Decision::NoDecision => "no decision",
        }
    }
}

/// Guarded acceptance against a lower limit ([`DECISION_RULE`]).
pub fn decide(value: f64, u: f64, limit: f64) -> Decision {
    if value - u >= limit {
        Decision::Pass
    } else if value + u < limit {
        Decision::Fail
    } else {
        Decision::Inconclusive
    }
}

/// A set of pass/fail criteria.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Thresholds {
    /// 49 CFR 523.5(b)(2): capable of off-highway operation.
    Cfr523_5,
    /// EU off-road vehicle (2018/858 Annex I Part A, formerly 87/403/EEC).
    EuOffRoad,
}

/// One criterion: every listed quantity at least `limit`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Criterion {
    /// Label, e.g. `approach >= 28 deg`.
    pub label: &'static str,
    /// The quantities that must each meet the limit.
    pub kinds: &'static [QuantityKind],
    /// Lower limit, in the quantities' unit.
    pub limit: f64,
}

/// The decision on one criterion.
#[derive(Debug, Clone, PartialEq)]
pub struct CriterionDecision {
    /// The criterion.
    pub criterion: Criterion,
    /// Its decision (all its quantities combined: any fail fails, all pass pass).
    pub decision: Decision,
    /// Each quantity's value and U (or reason) and decision.
    pub parts: Vec<(QuantityKind, Measure, Decision)>,
}

/// The overall verdict by the count rule.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// At least the required count passes.
    Met,
    /// Too many fail for the count to be reached.
    NotMet,
    /// Neither: undecided criteria could tip it.
    Inconclusive,
}

impl Verdict {
    /// `met`, `not met`, `inconclusive`.
    pub fn label(self) -> &'static str {
        match self {
            Verdict::Met => "met",
            Verdict::NotMet => "not met",
            Verdict::Inconclusive => "inconclusive",
        }
    }
}

/// A profile classified against thresholds.
#[derive(Debug, Clone, PartialEq)]
pub struct Classification {
    /// Which thresholds.
    pub thresholds: Thresholds,
    /// Each criterion's decision.
    pub criteria: Vec<CriterionDecision>,
    /// Criteria passed.
    pub passed: usize,
    /// Criteria failed.
    pub failed: usize,
    /// The verdict.
    pub verdict: Verdict,
}

impl Thresholds {
    /// Both, in order.
    pub const ALL: [Thresholds; 2] = [Thresholds::Cfr523_5, Thresholds::EuOffRoad];

    /// Identifier (`cfr523.5`, `eu-offroad`).
    pub fn id(self) -> &'static str {
        match self {
            Thresholds::Cfr523_5 => "cfr523.5",
            Thresholds::EuOffRoad => "eu-offroad",
        }
    }

    /// Parse an id.
    pub fn parse(s: &str) -> Option<Thresholds> {
        Thresholds::ALL.into_iter().find(|t| t.id() == s.trim())
    }

    /// Title.
    pub fn title(self) -> &'static str {
        match self {
            Thresholds::Cfr523_5 => {
                "49 CFR 523.5(b)(2): automobile capable of off-highway operation"
            }
            Thresholds::EuOffRoad => "EU off-road vehicle (M1, N1): geometric criteria",
        }
    }

    /// Where the limits and the count rule come from, and what the verdict leaves out.
    pub fn source(self) -> &'static str {
        match self {
            Thresholds::Cfr523_5 => {
                "49 CFR 523.5(b)(2): at least four of the five characteristics (the \
                 front and rear axle clearances are one characteristic, each >= 18 cm), at curb \
                 weight on a level surface. Limits from the CFR text as quoted in the project's \
                 domain notes; the 'four of' count is the eCFR wording of 523.5(b)(2) as recalled \
                 (the retrieved copies of 523.5 and NHTSA interpretation 11-000612 cite \
                 523.5(b)(2) for the running clearance but were cut before the count). Not \
                 checked: 523.5(b)(1), four-wheel drive or GVWR over 6,000 lb."
            }
            Thresholds::EuOffRoad => {
                "Directive 87/403/EEC limits, carried into 2007/46/EC Annex II and \
                 Regulation (EU) 2018/858 Annex I Part A: at least five of the six requirements \
                 (summary at kanzlei-voigt.de, as quoted in the project's domain notes). Not \
                 checked: the drive (front and rear axles driven simultaneously, a differential \
                 lock) and the 25 % (M1) / 30 % gradient; other categories have other rules."
            }
        }
    }

    /// The standard whose profile it classifies.
    pub fn standard(self) -> Standard {
        match self {
            Thresholds::Cfr523_5 => Standard::Cfr523Sae,
            Thresholds::EuOffRoad => Standard::Eu2018_858,
        }
    }

    /// Criteria that must pass for the verdict to be met.
    pub fn required(self) -> usize {
        match self {
            Thresholds::Cfr523_5 => 4,
            Thresholds::EuOffRoad => 5,
        }
    }

    /// The criteria.
    pub fn criteria(self) -> &'static [Criterion] {
        use QuantityKind as Q;
        match self {
            Thresholds::Cfr523_5 => &[
                Criterion {
                    label: "approach angle >= 28 deg",
                    kinds: &[Q::Approach],
                    limit: 28.0,
                },
                Criterion {
                    label: "breakover angle >= 14 deg",
                    kinds: &[Q::Breakover],
                    limit: 14.0,
                },
                Criterion {
                    label: "departure angle >= 20 deg",
                    kinds: &[Q::Departure],
                    limit: 20.0,
                },
                Criterion {
                    label: "running clearance >= 20 cm",
                    kinds: &[Q::RunningClearance],
                    limit: 0.20,
                },
                Criterion {
                    label: "front and rear axle clearances >= 18 cm each",
                    kinds: &[Q::FrontAxleClearance, Q::RearAxleClearance],
                    limit: 0.18,
                },
            ],
            Thresholds::EuOffRoad => &[
                Criterion {
                    label: "approach angle >= 25 deg",
                    kinds: &[Q::Approach],
                    limit: 25.0,
                },
                Criterion {
                    label: "departure angle >= 20 deg",
                    kinds: &[Q::Departure],
                    limit: 20.0,
                },
                Criterion {
                    label: "ramp angle >= 20 deg",
                    kinds: &[Q::Breakover],
                    limit: 20.0,
                },
                Criterion {
                    label: "ground clearance under the front axle >= 180 mm",
                    kinds: &[Q::ClearanceUnderFrontAxle],
                    limit: 0.18,
                },
                Criterion {
                    label: "ground clearance under the rear axle >= 180 mm",
                    kinds: &[Q::ClearanceUnderRearAxle],
                    limit: 0.18,
                },
                Criterion {
                    label: "ground clearance between the axles >= 200 mm",
                    kinds: &[Q::ClearanceBetweenAxles],
                    limit: 0.20,
                },
            ],
        }
    }

    /// Classify `profile` (its standard must be [`Thresholds::standard`]; a quantity it lacks
    /// gives no decision).
    pub fn classify(self, profile: &ProfileResult) -> Classification {
        let criteria: Vec<CriterionDecision> = self
            .criteria()
            .iter()
            .map(|c| {
                let parts: Vec<(QuantityKind, Measure, Decision)> = c
                    .kinds
                    .iter()
                    .map(|&k| {
                        let m = if profile.standard == self.standard() {
                            profile.get(k).cloned()
                        } else {
                            None
                        }
                        .unwrap_or_else(|| {
                            Measure::NotMeasured(format!(
                                "the {} profile does not report it",
                                profile.standard.short()
                            ))
                        });
                        let d = m
                            .value_u()
                            .map_or(Decision::NoDecision, |(v, u)| decide(v, u, c.limit));
                        (k, m, d)
                    })
                    .collect();
                let ds = parts.iter().map(|p| p.2);
                let decision = if ds.clone().any(|d| d == Decision::Fail) {
                    Decision::Fail
                } else if ds.clone().all(|d| d == Decision::Pass) {
                    Decision::Pass
                } else if ds.clone().any(|d| d == Decision::NoDecision) {
                    Decision::NoDecision
                } else {
                    Decision::Inconclusive
                };
                CriterionDecision {
                    criterion: *c,
                    decision,
                    parts,
                }
            })
            .collect();
        let count = |d: Decision| criteria.iter().filter(|c| c.decision == d).count();
        let (passed, failed) = (count(Decision::Pass), count(Decision::Fail));
        let verdict = verdict(passed, failed, criteria.len(), self.required());
        Classification {
            thresholds: self,
            criteria,
            passed,
            failed,
            verdict,
        }
    }
}

/// The count rule: met when at least `required` of `total` pass; not met when the failures leave
/// too few to reach it; otherwise inconclusive.
pub fn verdict(passed: usize, failed: usize, total: usize, required: usize) -> Verdict {
    if passed >= required {
        Verdict::Met
    } else if total - failed < required {
        Verdict::NotMet
    } else {
        Verdict::Inconclusive
    }
}

/// Classify every requested threshold set whose standard's profile is in `profiles`.
pub fn classify_all(profiles: &[ProfileResult], thresholds: &[Thresholds]) -> Vec<Classification> {
    thresholds
        .iter()
        .filter_map(|t| {
            profiles
                .iter()
                .find(|p| p.standard == t.standard())
                .map(|p| t.classify(p))
        })
        .collect()
}

/// `value ± U`, degrees to 2 decimals, metres to 3.
fn with_u(unit: Unit, value: f64, u: f64) -> String {
    match unit {
        Unit::Degree => format!("{value:.2} ± {u:.2}"),
        Unit::Metre => format!("{value:.3} ± {u:.3}"),
    }
}

/// A quantity as `value ± U` (degrees to 2 decimals, metres to 3), or `not measured [n]` with
/// the reason's footnote number.
fn cell(kind: QuantityKind, m: &Measure, footnotes: &mut Vec<String>) -> String {
    match m {
        Measure::Value { value, u, .. } => with_u(kind.unit(), *value, *u),
        Measure::NotMeasured(why) => {
            let n = footnotes.iter().position(|f| f == why).unwrap_or_else(|| {
                footnotes.push(why.clone());
                footnotes.len() - 1
            });
            format!("not measured [{}]", n + 1)
        }
    }
}

/// The side-by-side table: a header (quantity, then one column per standard), one row per
/// quantity any standard reports (`-`: the standard does not define it), and the footnotes
/// giving each not-measured reason. Shared by `passangle angles`'s table and the lab report.
pub fn side_by_side(profiles: &[ProfileResult]) -> (Vec<String>, Vec<Vec<String>>, Vec<String>) {
    let mut header = vec!["quantity (deg / m), value ± U (k = 2)".to_owned()];
    header.extend(profiles.iter().map(|p| p.standard.short().to_owned()));
    let mut footnotes = Vec::new();
    let rows = QuantityKind::ALL
        .into_iter()
        .filter(|k| profiles.iter().any(|p| p.get(*k).is_some()))
        .map(|k| {
            let mut row = vec![k.label().to_owned()];
            row.extend(profiles.iter().map(|p| {
                p.get(k)
                    .map_or_else(|| "-".to_owned(), |m| cell(k, m, &mut footnotes))
            }));
            row
        })
        .collect();
    (header, rows, footnotes)
}

/// One line per decision set: the verdict, then each criterion's decision.
pub fn decision_lines(c: &Classification) -> Vec<String> {
    let mut lines = vec![format!(
        "{}: {} ({} of {} criteria pass, {} fail; needs {})",
        c.thresholds.title(),
        c.verdict.label().to_uppercase(),
        c.passed,
        c.criteria.len(),
        c.failed,
        c.thresholds.required()
    )];
    for d in &c.criteria {
        let values: Vec<String> = d
            .parts
            .iter()
            .map(|(k, m, dec)| {
                let v = match m {
                    Measure::Value { value, u, .. } => {
                        format!("{} {}", with_u(k.unit(), *value, *u), k.unit().symbol())
                    }
                    Measure::NotMeasured(why) => format!("not measured ({why})"),
                };
                if d.parts.len() > 1 {
                    format!("{}: {v} {}", k.label(), dec.label())
                } else {
                    v
                }
            })
            .collect();
        lines.push(format!(
            "  {:<14} {}: {}",
            d.decision.label(),
            d.criterion.label,
            values.join("; ")
        ));
    }
    lines
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tangent_slope;

    /// A box part, vehicle frame: (x0, x1), (y0, y1), (z0, z1).
    type Part = [(f64, f64); 3];

    const WHEELBASE: f64 = 2.8;
    const TRACK: f64 = 1.8;
    const LOADED_R: f64 = 0.32;
    const FREE_R: f64 = 0.335;
    const RIM_R: f64 = 0.22;
    const TYRE_W: f64 = 0.22;
    /// Inner tyre face: 0.79 m; the central 80 % reaches 0.632 m.
    const INNER_Y: f64 = TRACK / 2.0 - TYRE_W / 2.0;
    const S: f64 = 0.01;

    /// A low part just ahead of the front axle, outboard of the central 80 % (a step or a
    /// splash guard): ahead of the axle, behind the tyre's front (1.4 + 0.335 m).
    const FRONT_PART: Part = [(1.66, 1.71), (0.65, 0.74), (0.09, 0.30)];
    /// A low part mid-wheelbase, outboard of the central 80 % but inside the inner faces.
    const SIDE_PART: Part = [(-0.3, 0.3), (0.66, 0.74), (0.15, 0.30)];
    /// A rear differential under the rear axle, central.
    const DIFF: Part = [(-1.55, -1.25), (-0.15, 0.12), (0.20, 0.30)];

    fn steps(a: f64, b: f64, s: f64) -> impl Iterator<Item = f64> {
        let n = ((b - a).abs() / s).ceil().max(1.0) as usize;
        (0..=n).map(move |i| a + (b - a) * i as f64 / n as f64)
    }

    fn box_faces(p: &Part, out: &mut Vec<V3>) {
        let [(x0, x1), (y0, y1), (z0, z1)] = *p;
        for x in steps(x0, x1, S) {
            for y in steps(y0, y1, S) {
                out.push(V3::new(x, y, z0));
            }
            for z in steps(z0, z1, S) {
                out.push(V3::new(x, y0, z));
                out.push(V3::new(x, y1, z));
            }
        }
        for y in steps(y0, y1, S) {
            for z in steps(z0, z1, S) {
                out.push(V3::new(x0, y, z));
                out.push(V3::new(x1, y, z));
            }
        }
    }

    fn tyre(xc: f64, sign: f64, out: &mut Vec<V3>) {
        let tau = std::f64::consts::TAU;
        let (y_in, y_out) = (sign * INNER_Y, sign * (INNER_Y + TYRE_W));
        for rho in steps(RIM_R, FREE_R, S) {
            let n = (tau * rho / S).ceil() as usize;
            for k in 0..n {
                let t = k as f64 / n as f64 * tau;
                let z = LOADED_R + rho * t.sin();
                if z >= 0.0 {
                    out.push(V3::new(xc + rho * t.cos(), y_in, z));
                }
            }
        }
        let n = (tau * FREE_R / S).ceil() as usize;
        for k in 0..n {
            let t = k as f64 / n as f64 * tau;
            let (x, z) = (
                xc + FREE_R * t.cos(),
                (LOADED_R + FREE_R * t.sin()).max(0.0),
            );
            for y in steps(y_in, y_out, S) {
                out.push(V3::new(x, y, z));
            }
        }
    }

    /// A box-bodied vehicle (floor 0.30 m, front end at 2.3 m from 0.35 m up, rear end at
    /// -2.2 m from 0.40 m up) with the parts, four tyres and the ground, noiseless, vehicle frame.
    fn vehicle(parts: &[Part]) -> Vec<V3> {
        let profile: [(f64, f64); 6] = [
            (2.3, 0.60),
            (2.3, 0.35),
            (2.0, 0.30),
            (-1.9, 0.30),
            (-2.2, 0.40),
            (-2.2, 0.60),
        ];
        let mut out = Vec::new();
        let hw = INNER_Y - 0.03;
        for w in profile.windows(2) {
            let ((x0, z0), (x1, z1)) = (w[0], w[1]);
            let n = ((x1 - x0).hypot(z1 - z0) / S).ceil().max(1.0) as usize;
            for i in 0..=n {
                let t = i as f64 / n as f64;
                let (x, z) = (x0 + (x1 - x0) * t, z0 + (z1 - z0) * t);
                for y in steps(-hw, hw, S) {
                    out.push(V3::new(x, y, z));
                }
            }
        }
        for p in parts {
            box_faces(p, &mut out);
        }
        for xc in [WHEELBASE / 2.0, -WHEELBASE / 2.0] {
            tyre(xc, 1.0, &mut out);
            tyre(xc, -1.0, &mut out);
        }
        let half_patch = (FREE_R.powi(2) - LOADED_R.powi(2)).sqrt();
        for x in steps(-3.3, 3.3, 0.02) {
            for y in steps(-1.4, 1.4, 0.02) {
                let under_tyre = (x.abs() - WHEELBASE / 2.0).abs() < half_patch
                    && y.abs() >= INNER_Y - 0.001
                    && y.abs() <= INNER_Y + TYRE_W + 0.001;
                if !under_tyre {
                    out.push(V3::new(x, y, 0.0));
                }
            }
        }
        out
    }

    fn value(p: &ProfileResult, k: QuantityKind) -> (f64, f64, V3) {
        match p.get(k) {
            Some(Measure::Value {
                value,
                u,
                witness_in_vehicle,
            }) => (*value, *u, *witness_in_vehicle),
            other => panic!("{:?} {k:?}: {other:?}", p.standard),
        }
    }

    fn deg(d: f64, z: f64) -> f64 {
        tangent_slope(d, z, LOADED_R).unwrap().to_degrees()
    }

    #[test]
    fn every_standard_from_one_scan_follows_the_geometry() {
        use QuantityKind as Q;
        let cloud = vehicle(&[FRONT_PART, SIDE_PART, DIFF]);
        let (profiles, runs) =
            compute_profiles_counted(&cloud, &AnglesConfig::default(), None, &Standard::ALL);
        // Tyre and axle zone at the whole width, the inner band, the central 80 %.
        assert_eq!(runs, 4, "one calculator run per distinct set-up");
        // The caller's own result serves its set-up (the default: tyre zone, whole width).
        let known = compute_angles(&cloud, &AnglesConfig::default()).unwrap();
        let (reused, runs) = compute_profiles_counted(
            &cloud,
            &AnglesConfig::default(),
            Some(&known),
            &Standard::ALL,
        );
        assert_eq!(runs, 3, "the known result is not computed again");
        assert_eq!(reused, profiles);
        let by = |s: Standard| profiles.iter().find(|p| p.standard == s).unwrap();
        let (cfr, eu, iso) = (
            by(Standard::Cfr523Sae),
            by(Standard::Eu2018_858),
            by(Standard::Iso612),
        );

        // Zones: the front part lies ahead of the axle but behind the tyre's front, outside the
        // tyre's side-view disc. The EU (axle zone) approach touches its front lower corner
        // (0.31 m ahead of the axle, 0.09 m up); the CFR (tyre zone) approach ignores it and
        // touches the bumper's lower corner (0.9 m ahead, 0.35 m up).
        let (eu_a, eu_u, eu_w) = value(eu, Q::Approach);
        let (cfr_a, _, cfr_w) = value(cfr, Q::Approach);
        assert!((eu_a - deg(0.31, 0.09)).abs() < 0.3, "EU approach {eu_a}");
        assert!((cfr_a - deg(0.9, 0.35)).abs() < 0.3, "CFR approach {cfr_a}");
        assert!(cfr_a - eu_a > 2.5, "the zones differ: {cfr_a} vs {eu_a}");
        assert!((1.65..1.72).contains(&eu_w[0]), "EU witness {eu_w:?}");
        assert!(cfr_w[0] > 2.2, "CFR witness {cfr_w:?}");
        assert!(eu_u > 0.0 && eu_u < 1.0, "U {eu_u}");
        // Behind the rear axle nothing lies between the axle and the tyre's rear outside the
        // disc: both zones agree on the departure (the rear corner, 0.8 m behind, 0.40 m up).
        let (cfr_d, _, _) = value(cfr, Q::Departure);
        let (eu_d, _, _) = value(eu, Q::Departure);
        assert!((cfr_d - deg(0.8, 0.40)).abs() < 0.3, "departure {cfr_d}");
        assert!((cfr_d - eu_d).abs() < 0.05);
        // The ramp angle does not depend on the zone.
        assert!((value(cfr, Q::Breakover).0 - value(eu, Q::Breakover).0).abs() < 0.01);

        // Clearances. Central 80 % (|y| <= 0.632 m): the side and front parts (outboard of it)
        // are ignored, the differential (0.20 m) is the lowest.
        let (c, cu, w) = value(iso, Q::CentralClearance);
        assert!(
            (c - 0.20).abs() < 0.01 && w[1].abs() < 0.2,
            "central {c} at {w:?}"
        );
        assert!(cu > 0.0 && cu < 0.01);
        for s in [Standard::GbT12673, Standard::IndiaArai] {
            assert!((value(by(s), Q::CentralClearance).0 - c).abs() < 1e-9);
        }
        // EU between the axles, whole width: the side part (0.15 m).
        let (b, _, w) = value(eu, Q::ClearanceBetweenAxles);
        assert!(
            (b - 0.15).abs() < 0.01 && w[0].abs() <= 0.31,
            "between {b} at {w:?}"
        );
        // CFR running clearance, whole vehicle: the front part (0.09 m).
        let (rc, _, w) = value(cfr, Q::RunningClearance);
        assert!(
            (rc - 0.09).abs() < 0.01 && w[0] > 1.6,
            "running {rc} at {w:?}"
        );
        // Axle clearances, between the inner faces within one tyre radius of the axle: the front
        // part lies 0.26-0.31 m ahead of the front axle (0.09 m), the differential under the rear.
        let (fa, _, _) = value(cfr, Q::FrontAxleClearance);
        let (ra, _, w) = value(cfr, Q::RearAxleClearance);
        assert!((fa - 0.09).abs() < 0.01, "front axle {fa}");
        assert!(
            (ra - 0.20).abs() < 0.01 && (-1.56..-1.24).contains(&w[0]),
            "rear {ra} {w:?}"
        );
        // EU under an axle: the arc through the footprints' centres (y = +-0.9 m) touching the
        // lowest point. The differential is central: the arc's apex is its height. The front
        // part is 0.695 m out (its bottom's mean y): the apex is well above its 0.09 m.
        let (eu_r, _, _) = value(eu, Q::ClearanceUnderRearAxle);
        assert!((eu_r - 0.20).abs() < 0.01, "EU rear {eu_r}");
        let (eu_f, _, w) = value(eu, Q::ClearanceUnderFrontAxle);
        let expect = arc_apex_height(TRACK / 2.0, 0.695, 0.09).unwrap();
        assert!(expect > 0.2, "{expect}");
        assert!(
            (eu_f - expect).abs() < 0.015,
            "EU front {eu_f} vs {expect} at {w:?}"
        );

        // The verdicts follow from these values and are stated for both threshold sets.
        let decisions = classify_all(&profiles, &Thresholds::ALL);
        assert_eq!(decisions.len(), 2);
        // CFR: approach 22.7 < 28 fails, breakover ~12 < 14 fails: at most 3 of 5.
        assert_eq!(decisions[0].verdict, Verdict::NotMet, "{:?}", decisions[0]);
    }

    #[test]
    fn the_axle_zone_counts_a_part_the_tyre_zone_does_not_and_nothing_else_moves() {
        // Without the front part both zones see the same bumper corner.
        let cloud = vehicle(&[DIFF]);
        let profiles = compute_profiles(
            &cloud,
            &AnglesConfig::default(),
            None,
            &[Standard::Cfr523Sae, Standard::Eu2018_858],
        );
        let a: Vec<f64> = profiles
            .iter()
            .map(|p| value(p, QuantityKind::Approach).0)
            .collect();
        assert!((a[0] - a[1]).abs() < 0.01, "{a:?}");
        assert!((a[0] - deg(0.9, 0.35)).abs() < 0.3, "{a:?}");
    }

    fn measured(value: f64, u: f64) -> Measure {
        Measure::Value {
            value,
            u,
            witness_in_vehicle: V3::zeros(),
        }
    }

    fn profile(standard: Standard, values: &[(QuantityKind, Measure)]) -> ProfileResult {
        ProfileResult {
            standard,
            quantities: values
                .iter()
                .map(|(kind, m)| ProfileQuantity {
                    kind: *kind,
                    name: standard.term(*kind),
                    measure: m.clone(),
                })
                .collect(),
            notes: Vec::new(),
        }
    }

    #[test]
    fn guarded_acceptance_at_its_boundaries() {
        // value - U exactly at the limit passes; value + U exactly at it is not a fail.
        assert_eq!(decide(30.5, 0.5, 30.0), Decision::Pass);
        assert_eq!(decide(30.4375, 0.5, 30.0), Decision::Inconclusive);
        assert_eq!(decide(29.5, 0.5, 30.0), Decision::Inconclusive);
        assert_eq!(decide(29.4375, 0.5, 30.0), Decision::Fail);
        assert_eq!(decide(0.25, 0.0625, 0.1875), Decision::Pass);
        assert_eq!(decide(0.1875, 0.0, 0.1875), Decision::Pass);
        assert_eq!(decide(0.125, 0.0625, 0.1875), Decision::Inconclusive);
        assert_eq!(decide(0.1, 0.0625, 0.1875), Decision::Fail);
        // A value above the limit whose U straddles it is not a pass.
        assert_eq!(decide(28.3, 0.6, 28.0), Decision::Inconclusive);
    }

    #[test]
    fn the_count_rules_and_not_measured_quantities() {
        use QuantityKind as Q;
        let nm = || Measure::NotMeasured("the front overhang was not seen from below".into());
        let cfr = |approach: Measure, rear_axle: Measure| {
            profile(
                Standard::Cfr523Sae,
                &[
                    (Q::Approach, approach),
                    (Q::Breakover, measured(13.0, 0.25)),
                    (Q::Departure, measured(25.0, 0.5)),
                    (Q::RunningClearance, measured(0.3125, 0.0625)),
                    (Q::FrontAxleClearance, measured(0.25, 0.0625)),
                    (Q::RearAxleClearance, rear_axle),
                ],
            )
        };
        let t = Thresholds::Cfr523_5;
        // Breakover fails (13.25 < 14); the other four pass: 4 of 5, met.
        let c = t.classify(&cfr(measured(30.0, 1.0), measured(0.25, 0.0625)));
        assert_eq!(
            (c.passed, c.failed, c.verdict),
            (4, 1, Verdict::Met),
            "{c:?}"
        );
        // The approach straddles 28: 3 pass, 1 fail, 1 inconclusive: could still be 4.
        let c = t.classify(&cfr(measured(28.5, 1.0), measured(0.25, 0.0625)));
        assert_eq!(c.criteria[0].decision, Decision::Inconclusive);
        assert_eq!(c.verdict, Verdict::Inconclusive);
        // Not measured: no decision, never a pass; the verdict stays open.
        let c = t.classify(&cfr(nm(), measured(0.25, 0.0625)));
        assert_eq!(c.criteria[0].decision, Decision::NoDecision);
        assert!(matches!(c.criteria[0].parts[0].1, Measure::NotMeasured(_)));
        assert_eq!(c.verdict, Verdict::Inconclusive);
        // The axle clearances are one criterion, each >= 18 cm: one failing axle fails it.
        let c = t.classify(&cfr(measured(30.0, 1.0), measured(0.125, 0.03125)));
        assert_eq!(c.criteria[4].decision, Decision::Fail);
        assert_eq!((c.passed, c.failed, c.verdict), (3, 2, Verdict::NotMet));
        // One axle passing, the other not measured: no decision on the pair.
        let c = t.classify(&cfr(measured(30.0, 1.0), nm()));
        assert_eq!(c.criteria[4].decision, Decision::NoDecision);
        assert_eq!(c.verdict, Verdict::Inconclusive);

        // EU: five of six.
        let eu = |ramp: f64| {
            profile(
                Standard::Eu2018_858,
                &[
                    (Q::Approach, measured(26.0, 0.5)),
                    (Q::Breakover, measured(ramp, 0.5)),
                    (Q::Departure, measured(19.0, 0.5)),
                    (Q::ClearanceBetweenAxles, measured(0.25, 0.01)),
                    (Q::ClearanceUnderFrontAxle, measured(0.2, 0.01)),
                    (Q::ClearanceUnderRearAxle, measured(0.2, 0.01)),
                ],
            )
        };
        let c = Thresholds::EuOffRoad.classify(&eu(22.0));
        assert_eq!((c.passed, c.failed, c.verdict), (5, 1, Verdict::Met));
        let c = Thresholds::EuOffRoad.classify(&eu(18.0));
        assert_eq!(c.verdict, Verdict::NotMet);
        // A profile of another standard gives no decisions.
        let c = Thresholds::EuOffRoad.classify(&cfr(measured(30.0, 1.0), nm()));
        assert!(
            c.criteria
                .iter()
                .all(|c| c.decision == Decision::NoDecision)
        );
        assert_eq!(c.verdict, Verdict::Inconclusive);
        assert_eq!(verdict(0, 2, 6, 5), Verdict::NotMet);
        assert_eq!(verdict(4, 1, 6, 5), Verdict::Inconclusive);
    }

    #[test]
    fn the_arc_apex_is_the_height_of_a_central_point_and_higher_off_centre() {
        assert!((arc_apex_height(0.8, 0.0, 0.2).unwrap() - 0.2).abs() < 1e-12);
        // Off centre the apex is higher, and the point lies on the circle through the
        // footprints (+-0.8, 0) with that apex: centre height c = (h^2 - a^2) / 2h.
        let h = arc_apex_height(0.8, 0.5, 0.2).unwrap();
        assert!(h > 0.2 + 0.05, "{h}");
        let c = (h * h - 0.64) / (2.0 * h);
        let on_circle = 0.5f64.powi(2) + (0.2 - c).powi(2) - (0.64 + c * c);
        assert!(on_circle.abs() < 1e-12, "{on_circle}");
        assert!(arc_apex_height(0.8, 0.9, 0.2).is_none());
        assert!(arc_apex_height(0.8, 0.0, 0.0).is_none());
    }

    #[test]
    fn standards_parse_from_the_command_line() {
        assert_eq!(Standard::parse_list("all").unwrap(), Standard::ALL.to_vec());
        assert_eq!(
            Standard::parse_list("eu,cfr").unwrap(),
            vec![Standard::Cfr523Sae, Standard::Eu2018_858]
        );
        assert!(Standard::parse_list("sae").unwrap_err().contains("`sae`"));
        assert_eq!(Thresholds::parse("eu-offroad"), Some(Thresholds::EuOffRoad));
        assert_eq!(Thresholds::parse("x"), None);
    }
}
