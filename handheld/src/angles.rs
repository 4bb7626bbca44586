//! `passangle angles CLOUD`: the passing angles of any underside point cloud (PLY, PCD, XYZ/CSV,
//! E57 from terrestrial scanners, LAS/LAZ).
//!
//! Reads the cloud through `cloud_io`, runs the pure calculator `angles`, and prints
//! a table (default) or one JSON object (`--json`); `--report FILE.svg` writes the side view.
//! Degrees appear only here, at the user boundary.

use std::io::Write;
use std::path::PathBuf;

use angles::profiles::{
    Classification, DECISION_RULE, Decision, Measure, ProfileResult, QuantityKind, Standard,
    Thresholds, Unit, classify_all, compute_profiles, decision_lines, side_by_side,
};
use angles::{
    AngleFinding, AnglesConfig, AnglesResult, Band, ExclusionBox, Quantity, Uncertainty, V3, Zone,
    compute_angles, side_view_svg,
};
use anyhow::{Context, anyhow, bail};
use cloud_io::{ParseLimits, ReadStats, read_cloud_with};
use serde_json::{Value, json};

/// Arguments of `passangle angles`.
#[derive(Debug, clap::Args)]
pub struct AnglesArgs {
    /// Point cloud file: .ply, .pcd, .xyz, .csv, .txt, .e57, .las or .laz (metres, z roughly up;
    /// E57 scans are merged by their poses, LAS in feet is converted).
    pub cloud: PathBuf,
    /// Direction of the vehicle's front in the cloud: `+x` (default) or `-x`.
    #[arg(long, default_value = "+x", allow_hyphen_values = true)]
    pub front: String,
    /// Approach/departure zone: `tyre` (ahead of the front tyre, CFR/SAE) or `axle` (ahead of the axle, EU).
    #[arg(long, default_value = "tyre")]
    pub zone: String,
    /// Ignore the points in a box `x0,x1,y0,y1,z0,z1` (metres, cloud frame), e.g. a tow hook; repeatable.
    #[arg(long, allow_hyphen_values = true)]
    pub exclude: Vec<String>,
    /// Static loaded tyre radius (metres) to use instead of the fitted wheel-centre height.
    #[arg(long)]
    pub tyre_radius: Option<f64>,
    /// Lateral band of the side-view envelope: `outer` (between the outer tyre faces, 10 cm
    /// outside each: the vehicle's whole width, as the standards' side views), `inner` (between
    /// the inner tyre faces), `full`, or a half width in metres about the centreline.
    #[arg(long, default_value = "outer")]
    pub band: String,
    /// Range noise sigma in metres (default: estimated from the cloud).
    #[arg(long)]
    pub noise: Option<f64>,
    /// The scanner's stated range accuracy in metres (0.03 for the VLP-16); returns this close
    /// to a tyre count as the tyre's (default: 3 noise sigma).
    #[arg(long, value_name = "M")]
    pub range_accuracy: Option<f64>,
    /// A robot run's `scan.toml` (beside its `cloud.ply`): the lidar's path and the trajectory's
    /// error the robot's service gave the calculator. With it the calculator checks the scan's
    /// coverage and the lidar's view, and takes the returns' rays, as the robot did (a VLP-16;
    /// `--range-accuracy` defaults to its 0.03 m).
    #[arg(long, value_name = "SCAN_TOML")]
    pub scan: Option<PathBuf>,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Refuse clouds declaring more points than this (bounds the reader's memory: 24 bytes a
    /// point, plus the file).
    #[arg(long, default_value_t = ParseLimits::DEFAULT_MAX_POINTS, value_name = "N")]
    pub max_points: usize,
    /// Write the side-view report (SVG) to this file.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Standards to report side by side: `all` (default), `none`, or a comma-separated list of
    /// `cfr` (49 CFR 523.2 / SAE J1100), `eu` (EU 2018/858), `iso612`, `gbt` (GB/T 12673),
    /// `arai` (India), `adr` (Australia). Each runs the calculator with its own zone and band
    /// (docs/method/standards.md).
    #[arg(long, default_value = "all")]
    pub standard: String,
    /// Print pass/fail decisions against 49 CFR 523.5 (with the `cfr` profile) and the EU off-road
    /// criteria (with `eu`), by guarded acceptance with the expanded uncertainty.
    #[arg(long)]
    pub decide: bool,
}

/// The standards of `--standard` (`none`: no profiles).
///
/// # Errors
/// An unknown id.
pub fn parse_standards(s: &str) -> anyhow::Result<Vec<Standard>> {
    if s.trim() == "none" {
        return Ok(Vec::new());
    }
    Standard::parse_list(s).map_err(|e| anyhow::anyhow!("--standard: {e}"))
}

/// The standards' profiles and, with `decide`, every threshold set whose standard is among them.
pub struct Profiles {
    /// One per standard.
    pub profiles: Vec<ProfileResult>,
    /// The decisions (empty unless asked for).
    pub decisions: Vec<Classification>,
}

impl Profiles {
    /// Compute the profiles of `standards` (reusing `known`, the result of `points` with
    /// `config`) and, if asked, decide on `thresholds`.
    pub fn compute(
        points: &[V3],
        config: &AnglesConfig,
        known: &AnglesResult,
        standards: &[Standard],
        thresholds: &[Thresholds],
    ) -> Self {
        let profiles = compute_profiles(points, config, Some(known), standards);
        let decisions = classify_all(&profiles, thresholds);
        Self {
            profiles,
            decisions,
        }
    }

    /// No profiles.
    pub fn none() -> Self {
        Self {
            profiles: Vec::new(),
            decisions: Vec::new(),
        }
    }
}

/// Run the command, writing the table or JSON to `out`. The table or JSON is written even when an
/// angle is undetermined; the command then fails naming the missing angles, so scripts see a
/// non-zero exit whenever the three angles were not all measured.
pub fn run(args: &AnglesArgs, out: &mut impl Write) -> anyhow::Result<()> {
    let config = config_from(args)?;
    let limits = ParseLimits {
        max_points: args.max_points,
        ..ParseLimits::default()
    };
    let (cloud, stats) = read_cloud_with(&args.cloud, &limits)?;
    let points: Vec<V3> = cloud.points_m.iter().map(|&p| p.into()).collect();
    let result = compute_angles(&points, &config)
        .with_context(|| format!("{}: computing the angles", args.cloud.display()))?;
    if let Some(path) = &args.report {
        std::fs::write(path, side_view_svg(&result))
            .with_context(|| format!("writing the report {}", path.display()))?;
    }
    let standards = parse_standards(&args.standard)?;
    let thresholds: &[Thresholds] = if args.decide { &Thresholds::ALL } else { &[] };
    let profiles = Profiles::compute(&points, &config, &result, &standards, thresholds);
    if args.json {
        let v = to_json(args, &stats, &result, &profiles);
        writeln!(out, "{}", serde_json::to_string_pretty(&v)?)?;
    } else {
        write_table(out, args, &stats, &result)?;
        write_profiles(out, &profiles)?;
    }
    missing_angles(&result).map_or(Ok(()), |missing| {
        bail!("{}: not measured: {missing}", args.cloud.display())
    })
}

/// The angles a result lacks, each with its reason (`None`: all three were measured).
pub fn missing_angles(r: &AnglesResult) -> Option<String> {
    let missing: Vec<String> = [
        (Quantity::Approach, r.approach.is_some()),
        (Quantity::Breakover, r.breakover.is_some()),
        (Quantity::Departure, r.departure.is_some()),
    ]
    .into_iter()
    .filter(|(_, found)| !found)
    .map(|(q, _)| {
        format!(
            "{} ({})",
            q.name(),
            r.not_measured_reason(q).unwrap_or("no reason given")
        )
    })
    .collect();
    (!missing.is_empty()).then(|| missing.join("; "))
}

fn config_from(args: &AnglesArgs) -> anyhow::Result<AnglesConfig> {
    let front_is_positive_x = match args.front.as_str() {
        "+x" | "x" => true,
        "-x" => false,
        other => bail!("--front: expected `+x` or `-x`, got `{other}`"),
    };
    let zone = match args.zone.as_str() {
        "tyre" | "tire" => Zone::Tyre,
        "axle" => Zone::Axle,
        other => bail!("--zone: expected `tyre` or `axle`, got `{other}`"),
    };
    let exclude = args
        .exclude
        .iter()
        .enumerate()
        .map(|(i, s)| parse_box(s).with_context(|| format!("--exclude #{}", i + 1)))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let config = AnglesConfig {
        front_is_positive_x,
        zone,
        band: parse_band(&args.band)?,
        exclude,
        tyre_radius_m: args.tyre_radius,
        noise_m: args.noise,
        range_accuracy_m: args.range_accuracy,
        ..AnglesConfig::default()
    };
    let Some(path) = &args.scan else {
        return Ok(config);
    };
    let scan =
        onboard::scan_file::ScanRecord::read_file(path).map_err(|e| anyhow!("--scan: {e}"))?;
    Ok(AnglesConfig {
        scan_path_in_cloud: scan.path_m.iter().map(|&p| p.into()).collect(),
        trajectory_x_sigma_per_m: scan.trajectory_x_sigma_per_m,
        scanner_view: Some(angles::ScannerView::VLP16),
        range_accuracy_m: args.range_accuracy.or(Some(vlp16::RANGE_ACCURACY_M)),
        ..config
    })
}

fn parse_band(s: &str) -> anyhow::Result<Band> {
    Ok(match s {
        "inner" => Band::INNER,
        "outer" => Band::OUTER,
        "full" => Band::Full,
        w => {
            let half: f64 = w.parse().with_context(|| {
                format!("--band: expected `inner`, `outer`, `full` or metres, got `{w}`")
            })?;
            if !(half.is_finite() && half > 0.0) {
                bail!("--band: half width must be > 0 m, got {half}");
            }
            Band::HalfWidth(half)
        }
    })
}

fn parse_box(s: &str) -> anyhow::Result<ExclusionBox> {
    let v: Vec<f64> = s
        .split(',')
        .map(|t| {
            t.trim()
                .parse::<f64>()
                .with_context(|| format!("`{t}` in `{s}` is not a number"))
        })
        .collect::<anyhow::Result<_>>()?;
    if let Some(bad) = v.iter().find(|x| !x.is_finite()) {
        bail!("`{s}`: {bad} is not a finite coordinate");
    }
    let [x0, x1, y0, y1, z0, z1] = v[..] else {
        bail!(
            "`{s}`: expected six numbers x0,x1,y0,y1,z0,z1, got {}",
            v.len()
        );
    };
    for (name, lo, hi) in [("x", x0, x1), ("y", y0, y1), ("z", z0, z1)] {
        if lo > hi {
            bail!("`{s}`: {name}0 ({lo}) must not exceed {name}1 ({hi})");
        }
    }
    Ok(ExclusionBox {
        min_in_cloud: V3::new(x0, y0, z0),
        max_in_cloud: V3::new(x1, y1, z1),
    })
}

fn deg(f: Option<&AngleFinding>) -> Value {
    f.map_or(Value::Null, |f| json!(round(f.angle_rad.to_degrees(), 4)))
}

/// The expanded uncertainty U (k = 2) of an angle, degrees (`null` when not measured).
fn u_deg(f: Option<&AngleFinding>) -> Value {
    f.map_or(Value::Null, |f| {
        json!(round(f.uncertainty.expanded.to_degrees(), 4))
    })
}

/// An uncertainty budget: U and the standard uncertainties of each source, in `unit` (degrees
/// for angles, metres for the clearance).
fn budget(u: &Uncertainty, to_unit: impl Fn(f64) -> f64) -> Value {
    json!({
        "expanded_k2": round(to_unit(u.expanded), 5),
        "witness_height": round(to_unit(u.witness_height), 5),
        "witness_position": round(to_unit(u.witness_position), 5),
        "tyre_radius": round(to_unit(u.tyre_radius), 5),
        "axle_position": round(to_unit(u.axle_position), 5),
        "ground": round(to_unit(u.ground), 5),
        "trajectory": round(to_unit(u.trajectory), 5),
        "end_reach": round(to_unit(u.end_reach), 5),
    })
}

/// `{quantity: reason}` for every quantity the calculator did not measure.
pub fn not_measured_json(r: &AnglesResult) -> Value {
    let mut m = serde_json::Map::new();
    for n in &r.not_measured {
        m.insert(n.quantity.name().to_owned(), json!(n.reason));
    }
    Value::Object(m)
}

fn round(v: f64, digits: i32) -> f64 {
    let k = 10f64.powi(digits);
    (v * k).round() / k
}

fn v3(p: V3) -> Value {
    json!([round(p[0], 4), round(p[1], 4), round(p[2], 4)])
}

fn witness(f: Option<&AngleFinding>) -> Value {
    f.map_or(Value::Null, |f| {
        let mut w = json!({
            "angle_deg": round(f.angle_rad.to_degrees(), 4),
            "in_vehicle_m": v3(f.witness_in_vehicle),
            "in_cloud_m": v3(f.witness_in_cloud),
            "support_points": f.support,
            "uncertainty_deg": budget(&f.uncertainty, f64::to_degrees),
        });
        if let Some((front, rear)) = f.parts_rad {
            w["front_tangent_deg"] = json!(round(front.to_degrees(), 4));
            w["rear_tangent_deg"] = json!(round(rear.to_degrees(), 4));
        }
        w
    })
}

fn to_json(args: &AnglesArgs, stats: &ReadStats, r: &AnglesResult, profiles: &Profiles) -> Value {
    let p = r.points;
    let mut v = json!({
        "file": args.cloud.display().to_string(),
        "format": format!("{} {}", stats.format, stats.encoding),
    });
    v.as_object_mut()
        .expect("an object")
        .extend(result_json(r, profiles));
    v["points"] = json!({
        "read": stats.points_in_file,
        "dropped": stats.dropped_non_finite + stats.dropped_invalid + p.non_finite,
        "flagged_invalid": stats.dropped_invalid,
        "excluded": p.excluded,
        "used": p.input - p.non_finite - p.excluded,
        "ground": p.ground,
        "tyre": p.tyre,
        "body": p.body,
        "body_in_band": p.body_in_band,
        "outliers_below_envelope": p.outliers_below_envelope,
    });
    v["reader_notes"] = json!(stats.notes);
    v
}

/// The calculator's result as JSON fields: each angle in degrees with its expanded uncertainty
/// (`*_u_deg`, k = 2), `null` and a reason under `not_measured` when it was not measured; the
/// witnesses with their uncertainty budgets, the tyres, the vehicle frame and the warnings.
/// Shared by `passangle angles --json` and `passangle replay --json`, with the standards'
/// profiles under `profiles` ([`profiles_json`]).
pub fn result_json(r: &AnglesResult, p: &Profiles) -> serde_json::Map<String, Value> {
    let tyres: Vec<Value> = r
        .tyres
        .iter()
        .map(|t| {
            json!({
                "position": t.position.label(),
                "centre_in_vehicle_m": v3(t.centre_in_vehicle),
                "centre_in_cloud_m": v3(t.centre_in_cloud),
                "loaded_radius_m": round(t.loaded_radius_m, 4),
                "free_radius_m": round(t.free_radius_m, 4),
                "loaded_radius_u_m": round(t.u_loaded_radius_m, 5),
                "centre_x_u_m": round(t.u_centre_x_m, 5),
                "width_m": round(t.width_m, 4),
                "fit_residual_m": round(t.residual_rms_m, 5),
                "fit_points": t.fit_points,
            })
        })
        .collect();
    let v = json!({
        "zone": match r.zone { Zone::Tyre => "tyre", Zone::Axle => "axle" },
        "approach_deg": deg(r.approach.as_ref()),
        "approach_u_deg": u_deg(r.approach.as_ref()),
        "departure_deg": deg(r.departure.as_ref()),
        "departure_u_deg": u_deg(r.departure.as_ref()),
        "breakover_deg": deg(r.breakover.as_ref()),
        "breakover_u_deg": u_deg(r.breakover.as_ref()),
        "ground_clearance_m": r.ground_clearance.as_ref().map(|c| round(c.height_m, 4)),
        "ground_clearance_u_m": r.ground_clearance.as_ref().map(|c| round(c.uncertainty.expanded, 5)),
        "not_measured": not_measured_json(r),
        "wheelbase_m": round(r.wheelbase_m, 4),
        "track_m": r.track_m.map(|t| round(t, 4)),
        "inner_track_m": r.inner_track_m.map(|t| round(t, 4)),
        "tyres": tyres,
        "witness": {
            "approach": witness(r.approach.as_ref()),
            "departure": witness(r.departure.as_ref()),
            "breakover": witness(r.breakover.as_ref()),
            "ground_clearance": r.ground_clearance.as_ref().map(|c| json!({
                "in_vehicle_m": v3(c.witness_in_vehicle),
                "in_cloud_m": v3(c.witness_in_cloud),
                "uncertainty_m": budget(&c.uncertainty, |v| v),
            })),
        },
        "frame": {
            "origin_in_cloud_m": v3(r.frame.origin_in_cloud),
            "x_axis_in_cloud": v3(r.frame.x_axis_in_cloud),
            "y_axis_in_cloud": v3(r.frame.y_axis_in_cloud),
            "z_axis_in_cloud": v3(r.frame.z_axis_in_cloud),
            "yaw_deg": round(r.yaw_rad.to_degrees(), 3),
            "ground_tilt_deg": round(r.ground.tilt_rad.to_degrees(), 3),
        },
        "noise_sigma_m": round(r.noise_sigma_m, 5),
        "envelope_bin_m": r.bin_m,
        "band_y_m": [finite_or_null(r.band_y_m.0), finite_or_null(r.band_y_m.1)],
        "warnings": r.warnings,
        "profiles": profiles_json(p),
    });
    match v {
        Value::Object(m) => m,
        _ => unreachable!("json! of an object literal is an object"),
    }
}

fn finite_or_null(v: f64) -> Value {
    if v.is_finite() {
        json!(round(v, 4))
    } else {
        Value::Null
    }
}

/// The table's first lines: the file, its format, the point counts and the reader's notes.
fn write_source(
    out: &mut impl Write,
    args: &AnglesArgs,
    stats: &ReadStats,
    non_finite: usize,
    excluded: usize,
) -> std::io::Result<()> {
    writeln!(
        out,
        "{} ({} {}): {} points read, {non_finite} dropped (NaN/inf), {excluded} excluded",
        args.cloud.display(),
        stats.format,
        stats.encoding,
        stats.points_in_file,
    )?;
    if stats.dropped_invalid > 0 {
        writeln!(
            out,
            "{} points flagged invalid by the file (no return) dropped",
            stats.dropped_invalid
        )?;
    }
    for note in &stats.notes {
        writeln!(out, "note: {note}")?;
    }
    Ok(())
}

/// The table's rows of the angles and the clearance, each with U or why it was not measured.
fn write_angle_rows(out: &mut impl Write, r: &AnglesResult) -> std::io::Result<()> {
    writeln!(
        out,
        "  angle        degrees   U (k=2)   witness x, y, z (m, vehicle frame)   support"
    )?;
    for (q, f) in [
        (Quantity::Approach, &r.approach),
        (Quantity::Departure, &r.departure),
        (Quantity::Breakover, &r.breakover),
    ] {
        let name = q.name();
        match f {
            Some(f) => {
                let w = f.witness_in_vehicle;
                writeln!(
                    out,
                    "  {name:<10} {:>8.2}   {:>7.2}   {:>7.3} {:>7.3} {:>7.3}               {:>6}",
                    f.angle_rad.to_degrees(),
                    f.uncertainty.expanded.to_degrees(),
                    w[0],
                    w[1],
                    w[2],
                    f.support
                )?;
            }
            None => writeln!(
                out,
                "  {name:<10} not measured: {}",
                r.not_measured_reason(q).unwrap_or("no reason given")
            )?,
        }
    }
    match &r.ground_clearance {
        Some(c) => {
            let w = c.witness_in_vehicle;
            writeln!(
                out,
                "  clearance  {:>7.3} m  {:>5.3} m   {:>7.3} {:>7.3} {:>7.3}",
                c.height_m, c.uncertainty.expanded, w[0], w[1], w[2]
            )?;
        }
        None => writeln!(
            out,
            "  clearance  not measured: {}",
            r.not_measured_reason(Quantity::GroundClearance)
                .unwrap_or("no reason given")
        )?,
    }
    Ok(())
}

fn write_table(
    out: &mut impl Write,
    args: &AnglesArgs,
    stats: &ReadStats,
    r: &AnglesResult,
) -> std::io::Result<()> {
    let p = r.points;
    write_source(
        out,
        args,
        stats,
        p.non_finite + stats.dropped_non_finite,
        p.excluded,
    )?;
    writeln!(
        out,
        "zone: {}",
        match r.zone {
            Zone::Tyre => "ahead of / behind the tyres (CFR/SAE)",
            Zone::Axle => "ahead of / behind the axles (EU)",
        }
    )?;
    writeln!(out)?;
    write_angle_rows(out, r)?;
    writeln!(out)?;
    write!(out, "wheelbase {:.3} m", r.wheelbase_m)?;
    if let Some(t) = r.track_m {
        write!(out, ", track {t:.3} m")?;
    }
    writeln!(
        out,
        ", yaw {:.2} deg, ground tilt {:.2} deg, noise {:.1} mm",
        r.yaw_rad.to_degrees(),
        r.ground.tilt_rad.to_degrees(),
        r.noise_sigma_m * 1e3
    )?;
    writeln!(
        out,
        "  tyre  centre x, y (m)     loaded r   free r   width   fit rms"
    )?;
    for t in &r.tyres {
        let c = t.centre_in_vehicle;
        writeln!(
            out,
            "  {:<4} {:>7.3} {:>7.3}    {:>7.3}  {:>7.3}  {:>6.3}  {:>5.1} mm",
            t.position.label(),
            c[0],
            c[1],
            t.loaded_radius_m,
            t.free_radius_m,
            t.width_m,
            t.residual_rms_m * 1e3
        )?;
    }
    writeln!(
        out,
        "points: ground {}, tyre {}, body {} ({} in band, {} below the envelope: noise tail or outliers)",
        p.ground, p.tyre, p.body, p.body_in_band, p.outliers_below_envelope
    )?;
    for w in &r.warnings {
        writeln!(out, "warning: {w}")?;
    }
    Ok(())
}

fn unit_round(unit: Unit, v: f64) -> f64 {
    match unit {
        Unit::Degree => round(v, 3),
        Unit::Metre => round(v, 4),
    }
}

fn measure_json(kind: QuantityKind, m: &Measure) -> Value {
    let unit = kind.unit();
    match m {
        Measure::Value {
            value,
            u,
            witness_in_vehicle,
        } => json!({
            "value": unit_round(unit, *value),
            "u": unit_round(unit, *u),
            "unit": unit.symbol(),
            "witness_in_vehicle_m": v3(*witness_in_vehicle),
            "not_measured": Value::Null,
        }),
        Measure::NotMeasured(why) => json!({
            "value": Value::Null,
            "u": Value::Null,
            "unit": unit.symbol(),
            "not_measured": why,
        }),
    }
}

fn classification_json(c: &Classification) -> Value {
    let criteria: Vec<Value> = c
        .criteria
        .iter()
        .map(|d| {
            let unit = d.criterion.kinds[0].unit();
            json!({
                "criterion": d.criterion.label,
                "limit": d.criterion.limit,
                "unit": unit.symbol(),
                "decision": d.decision.label(),
                "quantities": d.parts.iter().map(|(k, m, dec)| {
                    let mut v = measure_json(*k, m);
                    v["id"] = json!(k.id());
                    v["decision"] = json!(dec.label());
                    v
                }).collect::<Vec<_>>(),
            })
        })
        .collect();
    json!({
        "thresholds": c.thresholds.id(),
        "title": c.thresholds.title(),
        "source": c.thresholds.source(),
        "rule": DECISION_RULE,
        "count_rule": format!("at least {} of {}", c.thresholds.required(), c.criteria.len()),
        "passed": c.passed,
        "failed": c.failed,
        "verdict": c.verdict.label(),
        "criteria": criteria,
    })
}

/// The profiles as JSON: per standard its id, title, citation, notes, the quantities (value, U
/// at k = 2, unit, the limiting point, or `null` and why not measured) and, when decisions were
/// asked for, the decisions on the thresholds that classify it.
pub fn profiles_json(p: &Profiles) -> Value {
    let v: Vec<Value> = p
        .profiles
        .iter()
        .map(|pr| {
            let quantities: Vec<Value> = pr
                .quantities
                .iter()
                .map(|q| {
                    let mut v = measure_json(q.kind, &q.measure);
                    v["id"] = json!(q.kind.id());
                    v["name"] = json!(q.name);
                    v
                })
                .collect();
            let decisions: Vec<Value> = p
                .decisions
                .iter()
                .filter(|c| c.thresholds.standard() == pr.standard)
                .map(classification_json)
                .collect();
            let mut v = json!({
                "standard": pr.standard.id(),
                "title": pr.standard.title(),
                "citation": pr.standard.citation(),
                "zone": match pr.standard.zone() { Zone::Tyre => "tyre", Zone::Axle => "axle" },
                "notes": pr.notes,
                "quantities": quantities,
            });
            if !decisions.is_empty() {
                v["decisions"] = json!(decisions);
            }
            v
        })
        .collect();
    json!(v)
}

/// The table's standards section: the side-by-side table, the reasons, and the decisions.
fn write_profiles(out: &mut impl Write, p: &Profiles) -> std::io::Result<()> {
    if p.profiles.is_empty() {
        return Ok(());
    }
    let (header, rows, footnotes) = side_by_side(&p.profiles);
    let width = |i: usize| {
        rows.iter()
            .map(|r| r[i].chars().count())
            .chain([header[i].chars().count()])
            .max()
            .unwrap_or(0)
    };
    let widths: Vec<usize> = (0..header.len()).map(width).collect();
    let line = |cells: &[String]| {
        cells
            .iter()
            .zip(&widths)
            .map(|(c, w)| format!("{c:<w$}"))
            .collect::<Vec<_>>()
            .join("  ")
            .trim_end()
            .to_owned()
    };
    writeln!(out)?;
    writeln!(
        out,
        "standards, side by side (each its own zone and band; docs/method/standards.md):"
    )?;
    writeln!(out, "  {}", line(&header))?;
    for r in &rows {
        writeln!(out, "  {}", line(r))?;
    }
    for (i, f) in footnotes.iter().enumerate() {
        writeln!(out, "  [{}] {f}", i + 1)?;
    }
    if p.decisions.is_empty() {
        writeln!(
            out,
            "each profile's notes (what it measures, cannot and assumes): --json, or \
             docs/method/standards.md"
        )?;
        return Ok(());
    }
    writeln!(out)?;
    writeln!(out, "decisions: {DECISION_RULE}")?;
    for c in &p.decisions {
        for l in decision_lines(c) {
            writeln!(out, "{l}")?;
        }
        writeln!(out, "  source: {}", c.thresholds.source())?;
        if let Some(pr) = p
            .profiles
            .iter()
            .find(|pr| pr.standard == c.thresholds.standard())
        {
            for n in &pr.notes {
                writeln!(out, "  note: {n}")?;
            }
        }
    }
    if p.decisions.iter().any(|c| {
        c.criteria
            .iter()
            .any(|d| d.decision == Decision::NoDecision)
    }) {
        writeln!(out, "a criterion with no decision counts neither way")?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_boxes_bands_and_rejects_bad_ones() {
        let b = parse_box("-3.3,-2.6, -0.1,0.1,0.3,0.56").unwrap();
        let close = |a: V3, b: [f64; 3]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-12);
        assert!(close(b.min_in_cloud, [-3.3, -0.1, 0.3]), "{b:?}");
        assert!(close(b.max_in_cloud, [-2.6, 0.1, 0.56]), "{b:?}");
        let e = parse_box("1,2,3").unwrap_err().to_string();
        assert!(e.contains("six numbers"), "{e}");
        let e = parse_box("2,1,0,1,0,1").unwrap_err().to_string();
        assert!(e.contains("x0 (2) must not exceed x1 (1)"), "{e}");
        let e = format!("{:#}", parse_box("a,1,0,1,0,1").unwrap_err());
        assert!(e.contains("`a`"), "{e}");
        assert_eq!(parse_band("full").unwrap(), Band::Full);
        assert_eq!(parse_band("outer").unwrap(), Band::OUTER);
        assert_eq!(parse_band("0.5").unwrap(), Band::HalfWidth(0.5));
        assert!(parse_band("-1").is_err() && parse_band("wide").is_err());
    }
}
