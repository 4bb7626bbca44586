//! The result record: `result.json` of a run, as the robot records it, the radio delivers it (in
//! its wire form, [`MeasurementResult`]) and the handheld saves it.
//!
//! It lives with the link so that the handheld's client ([`crate::client`]) saves the very record
//! the robot's recorder writes without linking the recorder or the service.

use std::collections::BTreeMap;

use protocol::bounded::Text;
use protocol::radio::{Absence, MeasurementResult, ResultWarnings};
use serde::{Deserialize, Serialize};

/// A number of `result.json` that JSON has no spelling for (NaN: an angle the calculator could
/// not determine) is written as `null` by serde_json; read back, `null` is NaN again. Before, such
/// a `result.json` made the whole run unreadable (`Recording::open_run`: "invalid type: null,
/// expected f32"), so `passangle replay` and the handheld's fetch refused it.
fn null_as_nan<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f32, D::Error> {
    Ok(Option::<f32>::deserialize(d)?.unwrap_or(f32::NAN))
}

/// `result.json`: the measurement in radians and, for people, degrees; angles that could not be
/// determined are NaN (`null` in the file).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ResultRecord {
    /// The run.
    pub run_id: u32,
    /// Vehicle identifier.
    pub vehicle_id: String,
    /// Approach angle, rad.
    #[serde(deserialize_with = "null_as_nan")]
    pub approach_rad: f32,
    /// Departure angle, rad.
    #[serde(deserialize_with = "null_as_nan")]
    pub departure_rad: f32,
    /// Ramp breakover angle, rad.
    #[serde(deserialize_with = "null_as_nan")]
    pub breakover_rad: f32,
    /// Approach angle, degrees (for people; the radians are authoritative).
    #[serde(deserialize_with = "null_as_nan")]
    pub approach_deg: f32,
    /// Departure angle, degrees.
    #[serde(deserialize_with = "null_as_nan")]
    pub departure_deg: f32,
    /// Ramp breakover angle, degrees.
    #[serde(deserialize_with = "null_as_nan")]
    pub breakover_deg: f32,
    /// Smallest ground clearance between the axles, m.
    #[serde(deserialize_with = "null_as_nan")]
    pub ground_clearance_m: f32,
    /// Expanded uncertainty (k = 2) of the approach angle, rad (`null`: not measured).
    #[serde(default = "nan", deserialize_with = "null_as_nan")]
    pub approach_u_rad: f32,
    /// Expanded uncertainty (k = 2) of the departure angle, rad.
    #[serde(default = "nan", deserialize_with = "null_as_nan")]
    pub departure_u_rad: f32,
    /// Expanded uncertainty (k = 2) of the ramp breakover angle, rad.
    #[serde(default = "nan", deserialize_with = "null_as_nan")]
    pub breakover_u_rad: f32,
    /// Expanded uncertainty (k = 2) of the approach angle, degrees (for people).
    #[serde(default = "nan", deserialize_with = "null_as_nan")]
    pub approach_u_deg: f32,
    /// Expanded uncertainty (k = 2) of the departure angle, degrees.
    #[serde(default = "nan", deserialize_with = "null_as_nan")]
    pub departure_u_deg: f32,
    /// Expanded uncertainty (k = 2) of the ramp breakover angle, degrees.
    #[serde(default = "nan", deserialize_with = "null_as_nan")]
    pub breakover_u_deg: f32,
    /// Expanded uncertainty (k = 2) of the ground clearance, m.
    #[serde(default = "nan", deserialize_with = "null_as_nan")]
    pub ground_clearance_u_m: f32,
    /// Each quantity that was not measured (`approach`, `departure`, `breakover`,
    /// `ground_clearance`): why. Its value above is `null`.
    #[serde(default)]
    pub not_measured: BTreeMap<String, NotMeasuredRecord>,
    /// Wheelbase, m.
    #[serde(deserialize_with = "null_as_nan")]
    pub wheelbase_m: f32,
    /// Track, m.
    #[serde(deserialize_with = "null_as_nan")]
    pub track_m: f32,
    /// Points supporting the approach-limiting feature.
    pub approach_support: u16,
    /// Points supporting the departure-limiting feature.
    pub departure_support: u16,
    /// Points supporting the breakover-limiting feature.
    pub breakover_support: u16,
    /// RMS residual of the tyre fits, m.
    #[serde(deserialize_with = "null_as_nan")]
    pub tyre_fit_rms_m: f32,
    /// Warning names.
    pub warnings: Vec<String>,
    /// Points in the cloud.
    pub cloud_points: u32,
    /// Every standard's quantities from the same cloud, side by side (`angles::profiles`;
    /// docs/method/standards.md). Empty in files written before the profiles existed.
    #[serde(default)]
    pub profiles: Vec<ProfileRecord>,
}

/// One standard's quantities in `result.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProfileRecord {
    /// Identifier: `cfr`, `eu`, `iso612`, `gbt`, `arai`, `adr`.
    pub standard: String,
    /// Title.
    pub title: String,
    /// Where the definitions are.
    pub citation: String,
    /// What the profile measures, cannot measure and assumes.
    pub notes: Vec<String>,
    /// The quantities, in the standard's order.
    pub quantities: Vec<ProfileQuantityRecord>,
}

/// One quantity of a standard's profile: a value with its expanded uncertainty, or `null` and
/// why it was not measured.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProfileQuantityRecord {
    /// Identifier, e.g. `approach`, `running_clearance`, `clearance_under_front_axle`.
    pub id: String,
    /// The standard's own name of it.
    pub name: String,
    /// `deg` or `m`.
    pub unit: String,
    /// The value (`null`: not measured).
    pub value: Option<f64>,
    /// Expanded uncertainty, k = 2 (`null`: not measured).
    pub u: Option<f64>,
    /// Why it was not measured (`null`: measured).
    pub not_measured: Option<String>,
}

/// Why a quantity of `result.json` was not measured.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NotMeasuredRecord {
    /// `nothing_in_zone` or `not_covered` ([`Absence`]).
    pub kind: String,
    /// In words: what is missing.
    pub reason: String,
}

fn nan() -> f32 {
    f32::NAN
}

/// The quantities of a result in the wire's [`MeasurementResult::absent`] order.
pub const QUANTITIES: [&str; 4] = ["approach", "departure", "breakover", "ground_clearance"];

fn absence_name(a: Absence) -> &'static str {
    match a {
        Absence::Measured => "measured",
        Absence::NothingInZone => "nothing_in_zone",
        Absence::NotCovered => "not_covered",
    }
}

impl ResultRecord {
    /// From the wire form (the reasons in the wire's words; the service replaces them with the
    /// calculator's own when it has them).
    pub fn from_wire(r: &MeasurementResult) -> Self {
        let not_measured = QUANTITIES
            .iter()
            .zip(r.absent)
            .filter_map(|(q, a)| {
                a.reason().map(|reason| {
                    (
                        (*q).to_owned(),
                        NotMeasuredRecord {
                            kind: absence_name(a).to_owned(),
                            reason: reason.to_owned(),
                        },
                    )
                })
            })
            .collect();
        Self {
            run_id: r.run_id,
            vehicle_id: r.vehicle_id.as_str().to_owned(),
            approach_rad: r.approach_rad,
            departure_rad: r.departure_rad,
            breakover_rad: r.breakover_rad,
            approach_deg: r.approach_rad.to_degrees(),
            departure_deg: r.departure_rad.to_degrees(),
            breakover_deg: r.breakover_rad.to_degrees(),
            ground_clearance_m: r.ground_clearance_m,
            approach_u_rad: r.approach_u_rad,
            departure_u_rad: r.departure_u_rad,
            breakover_u_rad: r.breakover_u_rad,
            approach_u_deg: r.approach_u_rad.to_degrees(),
            departure_u_deg: r.departure_u_rad.to_degrees(),
            breakover_u_deg: r.breakover_u_rad.to_degrees(),
            ground_clearance_u_m: r.ground_clearance_u_m,
            not_measured,
            wheelbase_m: r.wheelbase_m,
            track_m: r.track_m,
            approach_support: r.approach_support,
            departure_support: r.departure_support,
            breakover_support: r.breakover_support,
            tyre_fit_rms_m: r.tyre_fit_rms_m,
            warnings: r.warnings.names().map(str::to_owned).collect(),
            cloud_points: r.cloud_points,
            profiles: Vec::new(),
        }
    }

    /// To the wire form (`preview_chunks` 0: set when offered).
    pub fn to_wire(&self) -> MeasurementResult {
        let mut warnings = ResultWarnings::EMPTY;
        for (flag, name) in ResultWarnings::NAMES {
            if self.warnings.iter().any(|w| w == name) {
                warnings.insert(*flag);
            }
        }
        MeasurementResult {
            run_id: self.run_id,
            vehicle_id: Text::truncated(&self.vehicle_id),
            approach_rad: self.approach_rad,
            departure_rad: self.departure_rad,
            breakover_rad: self.breakover_rad,
            ground_clearance_m: self.ground_clearance_m,
            approach_u_rad: self.approach_u_rad,
            departure_u_rad: self.departure_u_rad,
            breakover_u_rad: self.breakover_u_rad,
            ground_clearance_u_m: self.ground_clearance_u_m,
            absent: QUANTITIES.map(|q| {
                self.not_measured
                    .get(q)
                    .map_or(Absence::Measured, |n| match n.kind.as_str() {
                        "nothing_in_zone" => Absence::NothingInZone,
                        _ => Absence::NotCovered,
                    })
            }),
            wheelbase_m: self.wheelbase_m,
            track_m: self.track_m,
            approach_support: self.approach_support,
            departure_support: self.departure_support,
            breakover_support: self.breakover_support,
            tyre_fit_rms_m: self.tyre_fit_rms_m,
            warnings,
            cloud_points: self.cloud_points,
            preview_chunks: 0,
            records: protocol::bounded::List::default(),
        }
    }
}

/// The run directory name of `run_id`.
pub fn run_dir_name(run_id: u32) -> String {
    format!("run-{run_id:06}")
}
