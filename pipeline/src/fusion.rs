//! Step 6b, odometry fusion under the constant-velocity constraint (paper section 3.4, Algorithm 1,
//! eqs. 6-7), with wheel odometry as a third source.
//!
//! Every source is expressed as a **rate** over the lidar interval: the increment
//! `log(robot_prev_from_robot_cur)` as `[rx, ry, rz, tx, ty, tz]` divided by the interval's length,
//! so thresholds do not depend on the frame rate. Each source also says which of the six components
//! it actually determines (`available`): wheel odometry knows nothing of z, roll and pitch; a laser
//! scan between two parallel planes knows nothing of x, y and yaw (see [`super::laser_odometry`]).
//!
//! 1. **Reference** (eq. 6): the mean of the last `reference_frames` (ten) fused rates. The paper
//!    averages `(d_l + d_v) / 2`; averaging the fused result instead keeps a degenerate source out of
//!    the reference.
//! 2. **Deviations** (eq. 7): `delta = d - reference` per source.
//! 3. **Selection** (Algorithm 1), separately for rotation (rx, ry, rz) and translation (tx, ty, tz):
//!    if every laser deviation is below its tolerance, the laser wins; otherwise the source with the
//!    smallest summed absolute deviation wins (`min{Sum(...)}`; the paper chooses between laser and
//!    visual, the wheel is a third candidate here).
//!    With `gate-laser-by-wheel`, the laser must also lie within tolerance of the wheel odometry
//!    wherever the wheels determine a component (an addition to the paper: on simulator data a
//!    slowly biased laser otherwise wins every frame).
//! 4. **Gaps**: a component the winner does not determine is taken from the available source
//!    closest to the reference, else from the reference itself (constant velocity), else zero.
//!    A rotation rate is never taken from the reference (the prediction, [`Fusion::predict`],
//!    follows the same rule): the reference is the mean of the last fused rates, so holding it
//!    keeps whatever rotation rate the laser last reported, noise included, and integrates it for
//!    as long as the laser stays degenerate (laser only under a car: tens of degrees of yaw over a
//!    pass). The robot drives straight by design (docs/architecture.md, section 1), so without a
//!    source the best guess of a rotation rate is zero. Translation keeps the reference (the
//!    robot does keep driving at its speed).
//!
//! The same wheel gate is offered to the scan-to-map refinement ([`Fusion::refinement_gate`]), for
//! its rotation only.
//!
//! Until the reference holds `reference_frames` rates, the laser is used wherever it is determined
//! and, with `gate-laser-by-wheel`, agrees with the wheels (else the wheels). Ungated, the
//! warm-up took the laser's yaw rate of up to 2.4 degrees per second in the first 0.5 s on the
//! simulated `suv-offset` pass (seed 3: 1 degree of yaw before the reference existed).
//!
//! **Wheel scale (slip)**: wheels that slip report more distance than the robot travels, by a
//! nearly constant factor on one floor. The wheels' translation is multiplied by the factor
//! [`Fusion::wheel_scale`] in selection and gap filling (not in the prediction, see
//! [`Fusion::predict`]), so where the laser is degenerate (between two planes) the calibrated
//! wheels fill in. The evidence comes from long baselines (`wheel-scale-baseline-m` > 0):
//! `(laser, wheel)` distance pairs over 0.25 m of travel from [`super::slip::SlipMeter`], via
//! [`Fusion::add_scale_measurement`]. The factor is the least-squares
//! `s = sum(laser * wheel) / sum(wheel^2)` over the last [`MAX_SCALE_MEASUREMENTS`] pairs, and it
//! is applied only when it is **significant**: at least [`MIN_SCALE_MEASUREMENTS`] pairs counted
//! as independent (overlapping baselines share their errors), and `|s - 1|` above both
//! `wheel-scale-min-slip` and three standard errors of `s` (from the pairs' scatter about the fit,
//! over the independent count). Otherwise it is 1: a slip-free run keeps its exact wheels instead
//! of taking the measurement's noise as a correction. Over one frame instead of a long baseline,
//! the laser's x is too noisy and biased for a few per cent (see [`super::slip`]): a per-frame
//! estimate finds slip on slip-free simulated passes.
//!
//! **Wheel yaw-rate bias** (`wheel-yaw-bias`): the same long-baseline registrations, where they
//! determine the yaw, give the wheels' turn minus the laser's over the baseline's duration
//! ([`Fusion::add_yaw_measurement`]); the least-squares bias is taken off the wheels' yaw rate in
//! selection and gap filling when it exceeds three standard errors
//! ([`Fusion::wheel_yaw_bias_radps`]).
//!
//! The factor is clamped to [`WHEEL_SCALE_RANGE`]; pairs that disagree by more than that range are
//! outliers and are skipped.

use std::collections::VecDeque;

use super::config::FusionConfig;
use super::geom::Twist6;

/// One source's estimate over a lidar interval.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SourceRate {
    /// Rate `[rx, ry, rz, tx, ty, tz]` per second.
    pub rate: Twist6,
    /// Which components this source determines.
    pub available: [bool; 6],
}

/// Where a fused component came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Source {
    /// Laser odometry.
    Laser,
    /// Visual (depth) odometry.
    Visual,
    /// Wheel odometry.
    Wheel,
    /// The constant-velocity reference.
    Reference,
    /// Nothing known: zero.
    Zero,
}

/// The fused rate and where each component came from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fused {
    /// Rate per second.
    pub rate: Twist6,
    /// Source of each component.
    pub chosen: [Source; 6],
}

/// The wheel scale factor is clamped to this range (a robot slipping more than 20 % is stuck).
pub const WHEEL_SCALE_RANGE: (f64, f64) = (0.8, 1.2);

/// Fewer long-baseline distance measurements than this, counted as independent
/// (`Slope::independent`: four back-to-back baselines, or 1 m covered by overlapping ones at
/// the default 0.25 m): the wheel scale stays 1. (Three: the simulated off-roader's seed 10
/// with the assumed wheel errors still took a false slip; 10 seeds per vehicle, sd < 0.15 on 11
/// of 15 angles on exact wheels against 12 with four.)
pub const MIN_SCALE_MEASUREMENTS: usize = 4;

/// Fewer long-baseline yaw measurements than this: no yaw-rate bias is taken.
pub const MIN_YAW_MEASUREMENTS: usize = 4;

/// The long-baseline factor is estimated over at most this many of the latest measurements
/// (about 10 m of travel at the default 0.25 m baseline, keyframes a quarter baseline apart).
pub const MAX_SCALE_MEASUREMENTS: usize = 160;

/// One long-baseline measurement ([`super::slip::SlipMeter`]): `y = slope * x` evidence (laser
/// and wheel distance, or excess turn and duration) over the interval `from_s..to_s`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Baseline {
    y: f64,
    x: f64,
    from_s: f64,
    to_s: f64,
}

/// The fusion state: the history of fused rates and the wheel-scale evidence.
#[derive(Debug, Clone)]
pub struct Fusion {
    config: FusionConfig,
    history: VecDeque<Twist6>,
    /// `(laser, wheel)` distances of the latest long-baseline measurements, with their
    /// intervals.
    scale_measurements: VecDeque<Baseline>,
    /// `(wheel turn - laser turn, duration)` of the latest long-baseline measurements that
    /// determined the yaw (radians, seconds), with their intervals.
    yaw_measurements: VecDeque<Baseline>,
    /// A wheel scale known from an earlier pass over the same frames (the pipeline's slip
    /// replay), applied while this fusion's own measurements are not yet significant.
    preset_scale: Option<f64>,
}

impl Fusion {
    /// A fresh fusion with an empty history.
    pub fn new(config: FusionConfig) -> Self {
        Self {
            config,
            history: VecDeque::new(),
            scale_measurements: VecDeque::new(),
            yaw_measurements: VecDeque::new(),
            preset_scale: None,
        }
    }

    /// Apply `scale` as the wheel scale until this fusion's own long-baseline estimate is
    /// significant (then that one): the pipeline's slip replay starts its second pass with the
    /// scale the first pass measured.
    pub fn preset_wheel_scale(&mut self, scale: f64) {
        self.preset_scale = Some(scale.clamp(WHEEL_SCALE_RANGE.0, WHEEL_SCALE_RANGE.1));
    }

    /// The wheels' yaw-rate bias, rad/s (what they report minus what the laser measured, per
    /// second), when `wheel-yaw-bias` is on, at least [`MIN_YAW_MEASUREMENTS`] long-baseline
    /// measurements determined the yaw and the least-squares bias exceeds three standard
    /// errors; else 0.
    ///
    /// Unlike the scale's, this standard error counts overlapping measurements as independent:
    /// their error is mostly the registrations' own yaw noise, one per registration, and the
    /// wheels' yaw wander decorrelates within a baseline (0.3 s in the assumed model against
    /// 0.8-1 s). Counted like the scale's, the estimate would almost never become significant on
    /// the simulated passes with the assumed wheel errors (decision record 001).
    pub fn wheel_yaw_bias_radps(&self) -> f64 {
        if !self.config.wheel_yaw_bias || self.yaw_measurements.len() < MIN_YAW_MEASUREMENTS {
            return 0.0;
        }
        let b = least_squares_slope(&self.yaw_measurements);
        if b.value.abs() > 3.0 * b.standard_error {
            b.value
        } else {
            0.0
        }
    }

    /// Long-baseline measurements kept for the wheel yaw-rate bias.
    pub fn yaw_measurements(&self) -> usize {
        self.yaw_measurements.len()
    }

    /// Add one long-baseline yaw measurement ([`super::slip::SlipMeter`]): the wheels' turn minus
    /// the laser's over the baseline, radians, and the baseline's interval `(from, to)`, seconds.
    pub fn add_yaw_measurement(&mut self, excess_rad: f64, (from_s, to_s): (f64, f64)) {
        let dt_s = to_s - from_s;
        if !(dt_s > 0.0 && excess_rad.is_finite()) {
            return;
        }
        push_latest(
            &mut self.yaw_measurements,
            Baseline {
                y: excess_rad,
                x: dt_s,
                from_s,
                to_s,
            },
        );
    }

    /// The current wheel scale factor: laser distance over wheel distance. 1 until there is
    /// enough evidence, while the long-baseline estimate is not significant, and when the
    /// estimator is off (see the module docs); a preset scale ([`Fusion::preset_wheel_scale`])
    /// instead of 1.
    pub fn wheel_scale(&self) -> f64 {
        let fit = least_squares_slope(&self.scale_measurements);
        let s = fit.value;
        let significant = fit.independent >= MIN_SCALE_MEASUREMENTS as f64
            && (s - 1.0).abs()
                > self
                    .config
                    .wheel_scale_min_slip
                    .max(3.0 * fit.overlap_standard_error());
        if significant {
            s.clamp(WHEEL_SCALE_RANGE.0, WHEEL_SCALE_RANGE.1)
        } else {
            self.preset_scale.unwrap_or(1.0)
        }
    }

    /// The long-baseline wheel scale estimate whether or not it is applied: the least-squares
    /// factor and its standard error with overlapping measurements counted once (infinite with
    /// fewer than two measurements).
    pub fn wheel_scale_estimate(&self) -> (f64, f64) {
        let fit = least_squares_slope(&self.scale_measurements);
        (fit.value, fit.overlap_standard_error())
    }

    /// Long-baseline measurements kept for the wheel scale.
    pub fn scale_measurements(&self) -> usize {
        self.scale_measurements.len()
    }

    /// Add one long-baseline measurement ([`super::slip::SlipMeter`]): the distance along one
    /// translation component by the laser and by the (raw) wheels over the interval
    /// `(from, to)`, seconds. Ignored when the long-baseline estimator is off, the wheels barely
    /// moved, or the ratio is outside [`WHEEL_SCALE_RANGE`].
    pub fn add_scale_measurement(
        &mut self,
        laser_m: f64,
        wheel_m: f64,
        (from_s, to_s): (f64, f64),
    ) {
        let ratio = laser_m / wheel_m;
        let usable = self.config.wheel_scale_baseline_m > 0.0
            && wheel_m.abs() > 1e-3
            && ratio > WHEEL_SCALE_RANGE.0
            && ratio < WHEEL_SCALE_RANGE.1
            && to_s > from_s;
        if !usable {
            return;
        }
        push_latest(
            &mut self.scale_measurements,
            Baseline {
                y: laser_m,
                x: wheel_m,
                from_s,
                to_s,
            },
        );
    }

    /// `wheel` with its translation multiplied by the wheel scale and its yaw rate less the
    /// measured yaw-rate bias.
    fn scaled(&self, wheel: &SourceRate) -> SourceRate {
        let s = self.wheel_scale();
        let mut out = *wheel;
        for k in 3..6 {
            out.rate[k] *= s;
        }
        out.rate[2] -= self.wheel_yaw_bias_radps();
        out
    }

    /// The constant-velocity reference (eq. 6), once the history is full.
    pub fn reference(&self) -> Option<Twist6> {
        let n = self.config.reference_frames.max(1);
        if self.history.len() < n {
            return None;
        }
        let mut mean = [0.0; 6];
        for r in &self.history {
            for k in 0..6 {
                mean[k] += r[k] / n as f64;
            }
        }
        Some(mean)
    }

    /// The reference with its rotation rates zero: the value for a component no source
    /// determines (see the module docs).
    fn gap_reference(&self) -> Option<Twist6> {
        self.reference()
            .map(|r| std::array::from_fn(|k| if k < 3 { 0.0 } else { r[k] }))
    }

    /// Per group (rotation, translation): whether `rate` lies within the tolerances of the wheel
    /// odometry wherever the wheels determine a component (true without wheels or with the gate
    /// off). The scan-to-map refinement uses it as Algorithm 1's laser is gated.
    pub fn agrees_with_wheel(&self, rate: &Twist6, wheel: Option<&SourceRate>) -> [bool; 2] {
        let wheel = wheel.filter(|_| self.config.use_wheel && self.config.gate_laser_by_wheel);
        let c = &self.config;
        [
            ([0, 1, 2], c.rotation_tolerance_radps),
            ([3, 4, 5], c.translation_tolerance_mps),
        ]
        .map(|(group, tol)| wheel.is_none_or(|w| within_wheel(rate, w, &group, &tol)))
    }

    /// Which groups (rotation, translation) of the scan-to-map refinement's increment `rate` to
    /// keep: with `gate-refinement-rotation-by-wheel`, the rotation is rejected (the fused
    /// prediction's stays) when it disagrees with the wheels ([`Self::agrees_with_wheel`]); the
    /// translation is always kept. The map's x and y corrections are what the refinement is for;
    /// its weakly determined yaw jumps (up to 1-2 degrees a frame on the simulated `suv-offset`
    /// pass) are not.
    pub fn refinement_gate(&self, rate: &Twist6, wheel: Option<&SourceRate>) -> [bool; 2] {
        if !self.config.gate_refinement_rotation_by_wheel {
            return [true; 2];
        }
        [self.agrees_with_wheel(rate, wheel)[0], true]
    }

    /// The best prediction before the laser runs: per component visual, then wheel, then the
    /// reference (rotation zero, see the module docs), then the last fused rate, else zero.
    ///
    /// The wheels enter unscaled: the prediction is the laser's starting point, and a laser that
    /// converges only part of the way would otherwise confirm the current wheel scale and drive
    /// it further each frame (a feedback loop that took a 3 % slip for 6 % on the simulated SUV).
    pub fn predict(&self, visual: Option<&SourceRate>, wheel: Option<&SourceRate>) -> Twist6 {
        let fallback = self
            .gap_reference()
            .or_else(|| self.history.back().copied())
            .unwrap_or([0.0; 6]);
        std::array::from_fn(|k| {
            [visual, wheel]
                .into_iter()
                .flatten()
                .find(|s| s.available[k])
                .map_or(fallback[k], |s| s.rate[k])
        })
    }

    /// Fuse one interval's sources (Algorithm 1) and push the result into the history.
    pub fn fuse(
        &mut self,
        laser: Option<&SourceRate>,
        visual: Option<&SourceRate>,
        wheel: Option<&SourceRate>,
    ) -> Fused {
        let visual = visual.filter(|_| self.config.use_visual);
        let raw_wheel = wheel.filter(|_| self.config.use_wheel);
        let scaled_wheel = raw_wheel.map(|w| self.scaled(w));
        let wheel = scaled_wheel.as_ref();
        let reference = self.reference();
        let gap_reference = self.gap_reference();
        let candidates = [
            (Source::Laser, laser),
            (Source::Visual, visual),
            (Source::Wheel, wheel),
        ];
        let mut fused = Fused {
            rate: [0.0; 6],
            chosen: [Source::Zero; 6],
        };
        for (group, tolerance) in [
            ([0, 1, 2], self.config.rotation_tolerance_radps),
            ([3, 4, 5], self.config.translation_tolerance_mps),
        ] {
            let winner = match reference {
                // Warm-up: the laser where it agrees with the wheels (the gate holds from the
                // first frame), else the wheels.
                None => laser.map(|l| {
                    let gated_out = self.config.gate_laser_by_wheel
                        && wheel.is_some_and(|w| !within_wheel(&l.rate, w, &group, &tolerance));
                    if gated_out {
                        Source::Wheel
                    } else {
                        Source::Laser
                    }
                }),
                Some(r) => select(
                    &candidates,
                    &group,
                    &tolerance,
                    &r,
                    self.config.gate_laser_by_wheel,
                ),
            };
            for &k in &group {
                let from_winner = candidates
                    .iter()
                    .find(|(s, c)| Some(*s) == winner && c.is_some_and(|c| c.available[k]));
                let (source, value) = if let Some((s, c)) = from_winner {
                    (*s, c.map_or(0.0, |c| c.rate[k]))
                } else {
                    fill_gap(
                        &candidates,
                        k,
                        reference.as_ref(),
                        gap_reference.as_ref(),
                        self.history.back(),
                    )
                };
                fused.rate[k] = value;
                fused.chosen[k] = source;
            }
        }
        let n = self.config.reference_frames.max(1);
        self.history.push_back(fused.rate);
        while self.history.len() > n {
            self.history.pop_front();
        }
        fused
    }
}

/// A least-squares slope through the origin and its uncertainty.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Slope {
    value: f64,
    /// Standard error from the measurements' scatter about the fit, counting them as
    /// independent (infinite with fewer than two).
    standard_error: f64,
    /// Their count.
    count: usize,
    /// The effective number of independent measurements when their errors are shared along
    /// the stretch of travel they cover: the union of their intervals in units of their mean
    /// duration, between 1 and their count (0 with none).
    independent: f64,
}

impl Slope {
    /// The standard error with the measurements counted as [`Self::independent`].
    ///
    /// The distance measurements overlap in time (a keyframe every quarter baseline, so up to
    /// four cover the same stretch of travel), and the wheels' scale wander (correlated over
    /// about a second, a baseline's duration) and the registration's bias (it depends on what
    /// the scans see, so it is shared along a stretch) are common to them. Counted as
    /// independent, 4-7 overlapping measurements over the first metre of the simulated
    /// off-roader with the assumed wheel errors read a "significant" 3 % slip that was not there
    /// (seeds 2 and 10: ATE 69 and 47 mm, 29 and 13 with this count). Conservative where the
    /// errors are per registration.
    fn overlap_standard_error(&self) -> f64 {
        if self.independent <= 0.0 {
            return f64::INFINITY;
        }
        self.standard_error * (self.count as f64 / self.independent).sqrt()
    }
}

/// The least-squares slope `s` of `y = s * x` over the measurements (the wheel scale: laser
/// distance over wheel distance; the yaw-rate bias: excess turn over duration).
fn least_squares_slope(measurements: &VecDeque<Baseline>) -> Slope {
    let (value, xx) = slope_through_origin(measurements.iter().map(|m| (m.y, m.x)));
    let count = measurements.len();
    if count < 2 {
        return Slope {
            value,
            standard_error: f64::INFINITY,
            count,
            independent: count as f64,
        };
    }
    let scatter: f64 = measurements
        .iter()
        .map(|m| (m.y - value * m.x).powi(2))
        .sum();
    let sigma = (scatter / (count - 1) as f64).sqrt();
    let mean_duration_s =
        measurements.iter().map(|m| m.to_s - m.from_s).sum::<f64>() / count as f64;
    Slope {
        value,
        standard_error: sigma / xx.sqrt(),
        count,
        independent: (covered_s(measurements) / mean_duration_s).clamp(1.0, count as f64),
    }
}

/// The least-squares slope `s` of `y = s * x` over `(y, x)` pairs, and `sum(x^2)`.
fn slope_through_origin(pairs: impl Iterator<Item = (f64, f64)>) -> (f64, f64) {
    let (yx, xx) = pairs.fold((0.0, 0.0), |(yx, xx), (y, x)| (yx + y * x, xx + x * x));
    (yx / xx, xx)
}

/// Append `m`, keeping the latest [`MAX_SCALE_MEASUREMENTS`].
fn push_latest(measurements: &mut VecDeque<Baseline>, m: Baseline) {
    measurements.push_back(m);
    while measurements.len() > MAX_SCALE_MEASUREMENTS {
        measurements.pop_front();
    }
}

/// Length of the union of the measurements' intervals, seconds.
fn covered_s(measurements: &VecDeque<Baseline>) -> f64 {
    let mut intervals: Vec<(f64, f64)> = measurements.iter().map(|m| (m.from_s, m.to_s)).collect();
    intervals.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut covered = 0.0;
    let mut reach = f64::NEG_INFINITY;
    for (from, to) in intervals {
        covered += (to - from.max(reach)).max(0.0);
        reach = reach.max(to);
    }
    covered
}

/// Algorithm 1 for one group: the laser if it is within tolerance everywhere (and determines the
/// whole group), else the available source with the smallest summed deviation.
fn select(
    candidates: &[(Source, Option<&SourceRate>)],
    group: &[usize; 3],
    tolerance: &[f64; 3],
    reference: &Twist6,
    gate_by_wheel: bool,
) -> Option<Source> {
    // The wheel gate: where wheel odometry determines a component, the laser must also agree with
    // it (a biased laser otherwise passes the reference test slowly, frame after frame).
    let wheel = candidates
        .iter()
        .find(|(s, _)| *s == Source::Wheel)
        .and_then(|(_, c)| *c)
        .filter(|_| gate_by_wheel);
    let mut laser_gated_out = false;
    if let Some((_, Some(laser))) = candidates.first() {
        laser_gated_out = wheel.is_some_and(|w| !within_wheel(&laser.rate, w, group, tolerance));
        if !laser_gated_out
            && group.iter().all(|&k| laser.available[k])
            && group
                .iter()
                .zip(tolerance)
                .all(|(&k, &tol)| (laser.rate[k] - reference[k]).abs() < tol)
        {
            return Some(Source::Laser);
        }
    }
    candidates
        .iter()
        .filter(|(s, _)| !(laser_gated_out && *s == Source::Laser))
        .filter_map(|(s, c)| c.map(|c| (*s, c)))
        .filter(|(_, c)| group.iter().any(|&k| c.available[k]))
        .map(|(s, c)| {
            // Unavailable components count as a full tolerance-sized miss.
            let sum: f64 = group
                .iter()
                .zip(tolerance)
                .map(|(&k, &tol)| {
                    if c.available[k] {
                        (c.rate[k] - reference[k]).abs()
                    } else {
                        tol
                    }
                })
                .sum();
            (s, sum)
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(s, _)| s)
}

/// True when `rate` lies within `tolerance` of the wheels in every component of `group` that the
/// wheels determine.
fn within_wheel(
    rate: &Twist6,
    wheel: &SourceRate,
    group: &[usize; 3],
    tolerance: &[f64; 3],
) -> bool {
    group
        .iter()
        .zip(tolerance)
        .all(|(&k, &tol)| !wheel.available[k] || (rate[k] - wheel.rate[k]).abs() < tol)
}

/// Component `k` from the available source closest to the reference, else from `gap_reference`
/// (the reference, rotation decayed), else zero.
fn fill_gap(
    candidates: &[(Source, Option<&SourceRate>)],
    k: usize,
    reference: Option<&Twist6>,
    gap_reference: Option<&Twist6>,
    last: Option<&Twist6>,
) -> (Source, f64) {
    let target = reference.or(last).map_or(0.0, |r| r[k]);
    let best = candidates
        .iter()
        .filter_map(|(s, c)| c.filter(|c| c.available[k]).map(|c| (*s, c.rate[k])))
        .min_by(|a, b| (a.1 - target).abs().total_cmp(&(b.1 - target).abs()));
    match (best, gap_reference) {
        (Some(b), _) => b,
        (None, Some(r)) => (Source::Reference, r[k]),
        (None, None) => (Source::Zero, 0.0),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rate(v: Twist6) -> SourceRate {
        SourceRate {
            rate: v,
            available: [true; 6],
        }
    }

    /// The interval of the `i`-th of back-to-back 0.8 s measurements.
    fn apart(i: usize) -> (f64, f64) {
        (0.8 * i as f64, 0.8 * (i + 1) as f64)
    }

    fn warm(f: &mut Fusion, v: Twist6) {
        for _ in 0..10 {
            f.fuse(Some(&rate(v)), None, None);
        }
    }

    #[test]
    fn laser_within_tolerance_wins() {
        let mut f = Fusion::new(FusionConfig::default());
        let cruise = [0.0, 0.0, 0.0, 0.3, 0.0, 0.0];
        warm(&mut f, cruise);
        let laser = rate([0.0, 0.0, 0.005, 0.31, 0.0, 0.0]);
        let wheel = rate([0.0, 0.0, 0.0, 0.3, 0.0, 0.0]);
        let out = f.fuse(Some(&laser), None, Some(&wheel));
        assert_eq!(out.chosen, [Source::Laser; 6]);
        assert!((out.rate[3] - 0.31).abs() < 1e-12);
    }

    #[test]
    fn a_laser_jump_is_replaced_by_the_closest_source() {
        let mut f = Fusion::new(FusionConfig {
            use_visual: true,
            ..FusionConfig::default()
        });
        let cruise = [0.0, 0.0, 0.0, 0.3, 0.0, 0.0];
        warm(&mut f, cruise);
        let laser = rate([0.0, 0.0, 0.0, 0.9, 0.0, 0.0]);
        let visual = rate([0.0, 0.0, 0.0, 0.29, 0.01, 0.0]);
        let wheel = rate([0.0, 0.0, 0.0, 0.33, 0.0, 0.0]);
        let out = f.fuse(Some(&laser), Some(&visual), Some(&wheel));
        assert_eq!(out.chosen[3..], [Source::Visual; 3]);
        assert_eq!(out.chosen[..3], [Source::Laser; 3]);
        assert!((out.rate[3] - 0.29).abs() < 1e-12);
    }

    #[test]
    fn degenerate_laser_components_are_filled_by_wheel_then_reference() {
        let mut f = Fusion::new(FusionConfig::default());
        warm(&mut f, [0.0, 0.0, 0.0, 0.3, 0.0, 0.0]);
        let mut laser = rate([0.0, 0.0, 0.0, 0.0, 0.0, 0.001]);
        laser.available = [true, true, false, false, false, true];
        let wheel = SourceRate {
            rate: [0.0, 0.0, 0.0, 0.32, 0.0, 0.0],
            available: [false, false, true, true, true, false],
        };
        let out = f.fuse(Some(&laser), None, Some(&wheel));
        assert_eq!(out.chosen[3], Source::Wheel);
        assert!((out.rate[3] - 0.32).abs() < 1e-12);
        assert_eq!(out.chosen[5], Source::Laser);
        // Without the wheel, x comes from the constant-velocity reference.
        let out = f.fuse(Some(&laser), None, None);
        assert_eq!(out.chosen[3], Source::Reference);
        assert!(out.rate[3] > 0.29);
    }

    #[test]
    fn the_wheel_gate_rejects_a_laser_that_disagrees_with_the_wheels() {
        let mut f = Fusion::new(FusionConfig::default());
        warm(&mut f, [0.0, 0.0, 0.0, 0.3, 0.0, 0.0]);
        let laser = rate([0.0, 0.0, 0.0, 0.315, 0.0, 0.0]);
        let wheel = SourceRate {
            rate: [0.0, 0.0, 0.0, 0.29, 0.0, 0.0],
            available: [false, false, true, true, true, false],
        };
        let out = f.fuse(Some(&laser), None, Some(&wheel));
        assert_eq!(out.chosen[3], Source::Wheel);
        let mut ungated = Fusion::new(FusionConfig {
            gate_laser_by_wheel: false,
            ..FusionConfig::default()
        });
        warm(&mut ungated, [0.0, 0.0, 0.0, 0.3, 0.0, 0.0]);
        let out = ungated.fuse(Some(&laser), None, Some(&wheel));
        assert_eq!(out.chosen[3], Source::Laser);
    }

    #[test]
    fn a_significant_long_baseline_slip_scales_the_wheels_and_noise_does_not() {
        use rand::{Rng, SeedableRng};
        use rand_chacha::ChaCha8Rng;
        // `n` measurements over 0.25 m reading `ratio` of the wheels' distance, 1 % noise.
        let measured = |ratio: f64, n: usize| {
            let mut f = Fusion::new(FusionConfig::default());
            let mut rng = ChaCha8Rng::seed_from_u64(3);
            for i in 0..n {
                let noise = 0.01 * 3.0_f64.sqrt() * (2.0 * rng.random::<f64>() - 1.0);
                f.add_scale_measurement(0.25 * ratio * (1.0 + noise), 0.25, apart(i));
            }
            f
        };
        // 3 % slip is found to within its noise and applied where the wheels fill in.
        let f = measured(0.97, 20);
        assert!(
            (f.wheel_scale() - 0.97).abs() < 0.005,
            "{}",
            f.wheel_scale()
        );
        let mut f = f;
        warm(&mut f, [0.0, 0.0, 0.0, 0.3, 0.0, 0.0]);
        let wheel = SourceRate {
            rate: [0.0, 0.0, 0.0, 0.3, 0.0, 0.0],
            available: [false, false, true, true, true, false],
        };
        let mut blind = rate([0.0; 6]);
        blind.available[3] = false;
        let out = f.fuse(Some(&blind), None, Some(&wheel));
        assert_eq!(out.chosen[3], Source::Wheel);
        assert!(
            (out.rate[3] - 0.3 * f.wheel_scale()).abs() < 1e-12,
            "{:?}",
            out.rate
        );
        // Too few measurements: 1.
        assert!((measured(0.97, MIN_SCALE_MEASUREMENTS - 1).wheel_scale() - 1.0).abs() < 1e-15);
        // A slip-free run whose measurements read 0.5 % or even 2 % short (the registration's
        // bias approaching a car on the simulated off-roader) keeps its exact wheels.
        assert!((measured(0.995, 40).wheel_scale() - 1.0).abs() < 1e-15);
        assert!((measured(0.98, 40).wheel_scale() - 1.0).abs() < 1e-15);
        // 1.5 % off but within three standard errors (few, noisy measurements): 1.
        let mut noisy = Fusion::new(FusionConfig::default());
        for (i, l) in [0.27, 0.23, 0.26, 0.225].into_iter().enumerate() {
            noisy.add_scale_measurement(l, 0.25, apart(i));
        }
        assert!((noisy.wheel_scale() - 1.0).abs() < 1e-15);
        // Off: nothing is collected.
        let mut off = Fusion::new(FusionConfig {
            wheel_scale_baseline_m: 0.0,
            ..FusionConfig::default()
        });
        for i in 0..20 {
            off.add_scale_measurement(0.97 * 0.25, 0.25, apart(i));
        }
        assert_eq!(off.scale_measurements(), 0);
        assert!((off.wheel_scale() - 1.0).abs() < 1e-15);
    }

    #[test]
    fn a_preset_scale_holds_until_the_own_estimate_is_significant() {
        let mut f = Fusion::new(FusionConfig::default());
        f.preset_wheel_scale(0.97);
        assert!((f.wheel_scale() - 0.97).abs() < 1e-15);
        // Too few measurements of its own, and then a significant estimate, which wins.
        f.add_scale_measurement(0.25 * 0.95, 0.25, apart(0));
        assert!((f.wheel_scale() - 0.97).abs() < 1e-15);
        for i in 1..20 {
            f.add_scale_measurement(0.25 * 0.95, 0.25, apart(i));
        }
        assert!((f.wheel_scale() - 0.95).abs() < 1e-9, "{}", f.wheel_scale());
        // A preset outside the plausible range is clamped like a measured scale.
        let mut wild = Fusion::new(FusionConfig::default());
        wild.preset_wheel_scale(0.1);
        assert!((wild.wheel_scale() - WHEEL_SCALE_RANGE.0).abs() < 1e-15);
    }

    #[test]
    fn overlapping_baselines_count_as_the_travel_they_cover() {
        // The simulated off-roader's first metre with the assumed wheel errors (seed 2): the
        // long-baseline ratios of 0.85 s measurements a quarter baseline (0.25 s) apart.
        let ratios = [0.9665, 0.9639, 0.9908, 0.9771, 0.9605, 0.9478];
        let overlapping = |n: usize, spacing_s: f64| {
            let mut f = Fusion::new(FusionConfig::default());
            for (i, r) in ratios.iter().cycle().take(n).enumerate() {
                let from_s = spacing_s * i as f64;
                f.add_scale_measurement(0.25 * r, 0.25, (from_s, from_s + 0.85));
            }
            f
        };
        // Six overlapping measurements cover 2.1 s, 2.5 baselines: not enough to tell a 3 %
        // slip from the shared error (counted as six independent ones they were, and the
        // wheels took a 0.968 scale they did not have).
        let f = overlapping(6, 0.25);
        assert!((f.wheel_scale() - 1.0).abs() < 1e-15, "{}", f.wheel_scale());
        let fit = least_squares_slope(&f.scale_measurements);
        assert!((fit.independent - 2.1 / 0.85).abs() < 1e-9, "{fit:?}");
        assert!(fit.overlap_standard_error() > 1.5 * fit.standard_error);
        // The same readings back to back (no overlap) are six independent measurements.
        let f = overlapping(6, 0.85);
        assert!(
            (f.wheel_scale() - 0.9678).abs() < 1e-3,
            "{}",
            f.wheel_scale()
        );
        // Overlapping, but spread over enough travel: applied.
        let f = overlapping(24, 0.25);
        assert!(
            (f.wheel_scale() - 0.9678).abs() < 1e-3,
            "{}",
            f.wheel_scale()
        );
        // Separate stretches add up: the union of the intervals, not the span.
        let mut f = Fusion::new(FusionConfig::default());
        for from_s in [0.0, 0.25, 10.0, 10.25] {
            f.add_scale_measurement(0.24, 0.25, (from_s, from_s + 1.0));
        }
        let fit = least_squares_slope(&f.scale_measurements);
        assert!((fit.independent - 2.5).abs() < 1e-12, "{fit:?}");
    }

    #[test]
    fn a_significant_wheel_yaw_bias_is_taken_off_the_wheels_and_noise_is_not() {
        use rand::{Rng, SeedableRng};
        use rand_chacha::ChaCha8Rng;
        // `n` measurements over 0.8 s, the wheels turning `bias` rad/s more than the laser,
        // with 0.02 degree of registration noise each (a rate noise of 0.025 deg/s, so the
        // estimate's standard error over 20 is about 6 % of a 0.1 deg/s bias).
        let measured = |bias: f64, n: usize, on: bool| {
            let mut f = Fusion::new(FusionConfig {
                wheel_yaw_bias: on,
                ..FusionConfig::default()
            });
            let mut rng = ChaCha8Rng::seed_from_u64(5);
            for i in 0..n {
                let noise =
                    0.02_f64.to_radians() * 3.0_f64.sqrt() * (2.0 * rng.random::<f64>() - 1.0);
                f.add_yaw_measurement(bias * 0.8 + noise, apart(i));
            }
            f
        };
        let bias = 0.1_f64.to_radians();
        let mut f = measured(bias, 20, true);
        assert!(
            (f.wheel_yaw_bias_radps() - bias).abs() < 0.2 * bias,
            "{}",
            f.wheel_yaw_bias_radps()
        );
        // Taken off where the wheels fill in the yaw.
        warm(&mut f, [0.0, 0.0, 0.0, 0.3, 0.0, 0.0]);
        let wheel = SourceRate {
            rate: [0.0, 0.0, bias, 0.3, 0.0, 0.0],
            available: [false, false, true, true, true, false],
        };
        let mut blind = rate([0.0; 6]);
        blind.available[2] = false;
        let out = f.fuse(Some(&blind), None, Some(&wheel));
        assert_eq!(out.chosen[2], Source::Wheel);
        assert!(out.rate[2].abs() < 0.2 * bias, "{:?}", out.rate);
        // No bias: nothing taken off; too few measurements or the switch off: nothing either.
        assert!(measured(0.0, 40, true).wheel_yaw_bias_radps().abs() < 1e-15);
        assert!(
            measured(bias, MIN_YAW_MEASUREMENTS - 1, true)
                .wheel_yaw_bias_radps()
                .abs()
                < 1e-15
        );
        assert!(measured(bias, 20, false).wheel_yaw_bias_radps().abs() < 1e-15);
    }

    #[test]
    fn the_wheel_gate_holds_before_the_reference_exists() {
        // First frame: the laser reports 2.3 degrees per second of yaw the wheels do not see.
        let wheel = SourceRate {
            rate: [0.0, 0.0, 0.0, 0.3, 0.0, 0.0],
            available: [false, false, true, true, true, false],
        };
        let laser = rate([0.0, 0.0, 0.04, 0.3, 0.0, 0.0]);
        let mut f = Fusion::new(FusionConfig::default());
        let out = f.fuse(Some(&laser), None, Some(&wheel));
        assert_eq!(out.chosen[2], Source::Wheel);
        assert!(out.rate[2].abs() < 1e-15, "{:?}", out.rate);
        // Its translation agrees with the wheels: the laser's.
        assert_eq!(out.chosen[3..], [Source::Laser; 3]);
        let mut ungated = Fusion::new(FusionConfig {
            gate_laser_by_wheel: false,
            ..FusionConfig::default()
        });
        let out = ungated.fuse(Some(&laser), None, Some(&wheel));
        assert_eq!(out.chosen[2], Source::Laser);
    }

    #[test]
    fn a_rotation_no_source_determines_decays_to_zero_and_translation_holds() {
        // Laser only: the laser saw a yaw rate of 0.05 rad/s for ten frames, then loses yaw (and
        // x) between two planes. Holding the reference integrated that rate for the rest of the
        // pass; the default takes zero for the rotation and keeps the speed.
        let turning = [0.0, 0.0, 0.05, 0.3, 0.0, 0.0];
        let mut blind = rate([0.0; 6]);
        blind.available = [true, true, false, false, true, true];
        let mut f = Fusion::new(FusionConfig {
            use_wheel: false,
            ..FusionConfig::default()
        });
        warm(&mut f, turning);
        let out = f.fuse(Some(&blind), None, None);
        assert_eq!(out.chosen[2], Source::Reference);
        assert_eq!(out.chosen[3], Source::Reference);
        assert!((out.rate[3] - 0.3).abs() < 1e-12, "{:?}", out.rate);
        let prediction = f.predict(None, None)[2];
        assert!(
            out.rate[2].abs() < 1e-12 && prediction.abs() < 1e-12,
            "{} {prediction}",
            out.rate[2]
        );
    }

    #[test]
    fn the_refinement_gate_compares_each_group_with_the_wheels() {
        let f = Fusion::new(FusionConfig::default());
        let wheel = SourceRate {
            rate: [0.0, 0.0, 0.0, 0.3, 0.0, 0.0],
            available: [false, false, true, true, true, false],
        };
        // Roll and z are not the wheels' business; yaw 0.02 rad/s off is.
        let refined = [0.5, 0.0, 0.02, 0.305, 0.0, 0.1];
        assert_eq!(f.agrees_with_wheel(&refined, Some(&wheel)), [false, true]);
        let refined = [0.5, 0.0, 0.005, 0.35, 0.0, 0.1];
        assert_eq!(f.agrees_with_wheel(&refined, Some(&wheel)), [true, false]);
        assert_eq!(f.agrees_with_wheel(&refined, None), [true, true]);
        let ungated = Fusion::new(FusionConfig {
            gate_laser_by_wheel: false,
            ..FusionConfig::default()
        });
        assert_eq!(
            ungated.agrees_with_wheel(&refined, Some(&wheel)),
            [true, true]
        );
    }

    #[test]
    fn the_refinement_keeps_the_maps_translation_but_not_a_yaw_the_wheels_deny() {
        let wheel = SourceRate {
            rate: [0.0, 0.0, 0.0, 0.3, 0.0, 0.0],
            available: [false, false, true, true, true, false],
        };
        // A refined increment 0.02 rad/s of yaw and 0.05 m/s of x off the wheels.
        let refined = [0.0, 0.0, 0.02, 0.35, 0.0, 0.0];
        let f = Fusion::new(FusionConfig::default());
        assert_eq!(f.refinement_gate(&refined, Some(&wheel)), [false, true]);
        assert_eq!(f.refinement_gate(&refined, None), [true, true]);
        let agreeing = [0.0, 0.0, 0.005, 0.35, 0.0, 0.0];
        assert_eq!(f.refinement_gate(&agreeing, Some(&wheel)), [true, true]);
        let off = Fusion::new(FusionConfig {
            gate_refinement_rotation_by_wheel: false,
            ..FusionConfig::default()
        });
        assert_eq!(off.refinement_gate(&refined, Some(&wheel)), [true, true]);
    }

    #[test]
    fn prediction_prefers_visual_then_wheel_then_reference() {
        let mut f = Fusion::new(FusionConfig::default());
        assert!(f.predict(None, None).iter().all(|&v| v == 0.0));
        warm(&mut f, [0.0, 0.0, 0.0, 0.3, 0.0, 0.0]);
        let wheel = SourceRate {
            rate: [0.0, 0.0, 0.1, 0.2, 0.0, 0.0],
            available: [false, false, true, true, true, false],
        };
        let p = f.predict(None, Some(&wheel));
        assert!((p[3] - 0.2).abs() < 1e-12 && (p[2] - 0.1).abs() < 1e-12);
        assert!(p[5].abs() < 1e-12);
    }
}
