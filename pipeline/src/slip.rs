//! Wheel slip: the wheels' distance scale, measured by the laser over a long baseline.
//!
//! Mecanum wheels slip, and slipping wheels report more distance than the robot travels, by a
//! nearly constant factor on one floor (the simulated `suv-offset` pass: 3 %). Under a car the
//! laser determines x in only some frames (about 40 % on that pass), fusion fills the others from
//! the wheels, and the trajectory takes the wheels' scale: 10-20 cm too long over 7 m, and every
//! part seen from two places is smeared by the difference.
//!
//! **Why not from the scan-to-scan increments.** Over one frame (2.5 cm at 0.25 m/s) the laser's
//! x has a few millimetres of noise, about 10 % of the increment, and whatever small bias the
//! registration has is a large share of it: over the frames where it was determined, the
//! scan-to-scan x read 0.974-1.039 of the true distance on the five simulated passes, so a
//! factor estimated from it found "slip" on slip-free passes (decision record 005).
//!
//! **Long baseline.** Here a scan is registered against a keyframe scan `baseline_m` behind it by
//! the wheels (0.25 m: ten 10 Hz frames at 0.25 m/s), starting from the estimated relative pose,
//! with the same two-step registration and degeneracy test as the scan-to-scan odometry. The
//! registration's error is per registration, not per metre, so over ten times the distance it is
//! about a tenth of the share: laser / true distance over the determined measurements 0.995-1.000
//! on the five simulated passes (seed 1, suv-offset seeds 1-3), one measurement's spread about
//! 1 %. Each measurement gives, per translation component the registration determined and the
//! wheels moved along by at least half the baseline, a pair (laser distance, wheel distance) for
//! [`super::fusion::Fusion::add_scale_measurement`], which estimates the factor and applies it only
//! where it is significant.
//!
//! The same registration, where it determines the yaw, also compares the wheels' turn with the
//! laser's over the baseline: evidence of a wheel yaw-rate bias
//! ([`super::fusion::Fusion::add_yaw_measurement`]).
//!
//! A keyframe is kept every quarter baseline, so the measurements overlap in time but no two share
//! a scan pair (a quarter of the wait for the first ones), and at most every second frame. Cost:
//! one extra registration per keyframe (every 2-3 frames at 10 Hz and 0.25-0.3 m/s) and up to
//! five kept scan targets. The frame rule is a CPU budget for slow lidar rates: at 5 Hz and
//! 0.35 m/s a frame moves 7 cm, more than a quarter baseline, and the meter registered every
//! frame (the simulated pickup pass, no slip: 9.4-9.8 ms of CPU per frame, 8.0-8.6 with the rule,
//! the same output; the 10 and 20 Hz passes keep every keyframe they had).

use std::collections::VecDeque;
use std::f64::consts::{PI, TAU};
use std::sync::Arc;

use super::config::LaserOdometryConfig;
use super::geom::Pose;
use super::laser_odometry::FeatureTarget;
use super::registration::{Scan, register_two_step};

/// Keyframes kept per baseline: one every `baseline / KEYFRAMES_PER_BASELINE`.
const KEYFRAMES_PER_BASELINE: f64 = 4.0;

/// Fewest frames from one keyframe to the next (so at most one extra registration per this many
/// frames).
const MIN_FRAMES_BETWEEN_KEYFRAMES: u64 = 2;

/// A scan kept as the far end of later measurements.
#[derive(Debug, Clone)]
struct Keyframe {
    /// The scan's frame index.
    frame: u64,
    /// The scan's start, seconds.
    stamp_s: f64,
    /// Wheel odometry's pose at the scan's start.
    wheel: Pose,
    /// The estimated pose at the scan's start.
    world_from_robot: Pose,
    /// The scan's features (robot frame), indexed as a registration target; shared with the
    /// pipeline's scan-to-scan target, not copied.
    target: Arc<FeatureTarget>,
}

/// A scan as the slip meter takes it: its frame index, its start, and the robot's pose then by
/// the wheels and by the pipeline's estimate.
#[derive(Debug, Clone, Copy)]
pub struct ScanAt {
    /// The scan's frame index.
    pub frame: u64,
    /// The scan's start, seconds.
    pub stamp_s: f64,
    /// Wheel odometry's pose at the scan's start.
    pub wheel: Pose,
    /// The estimated pose at the scan's start.
    pub world_from_robot: Pose,
}

/// What one long-baseline registration measured ([`SlipMeter::measure`]).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Measurement {
    /// The baseline's interval: the keyframe's and the scan's start, seconds.
    pub interval_s: (f64, f64),
    /// `(laser, wheel)` distances, metres, per determined translation component.
    pub distances: Vec<(f64, f64)>,
    /// When the registration determined the yaw: the wheels' turn minus the laser's over the
    /// baseline, radians (evidence of a wheel yaw-rate bias,
    /// [`super::fusion::Fusion::add_yaw_measurement`]).
    pub yaw: Option<f64>,
}

impl Measurement {
    /// True when nothing was measured.
    pub fn is_empty(&self) -> bool {
        self.distances.is_empty() && self.yaw.is_none()
    }
}

/// Measures the distance between keyframes and later scans by the laser and by the wheels.
#[derive(Debug, Clone)]
pub struct SlipMeter {
    baseline_m: f64,
    keyframes: VecDeque<Keyframe>,
}

impl SlipMeter {
    /// A meter measuring over `baseline_m` of wheel travel (0: never measures).
    pub fn new(baseline_m: f64) -> Self {
        Self {
            baseline_m,
            keyframes: VecDeque::new(),
        }
    }

    /// Register `scan` (taken `at`) against the newest keyframe at least a baseline behind it by the wheels, and drop
    /// that keyframe and the older ones. Returns the `(laser, wheel)` distance pairs of the
    /// translation components (x, y of the keyframe's robot frame) that the registration
    /// determined and the wheels moved along by at least half the baseline, and the yaw evidence
    /// when it determined the yaw; empty when no keyframe is far enough behind.
    pub fn measure(
        &mut self,
        at: &ScanAt,
        scan: Scan<'_>,
        config: &LaserOdometryConfig,
    ) -> Measurement {
        let (stamp_s, wheel, world_from_robot) = (at.stamp_s, &at.wheel, &at.world_from_robot);
        let far_enough = |k: &Keyframe| travelled(&k.wheel, wheel) >= self.baseline_m;
        let Some(newest_far) = self.keyframes.iter().rposition(far_enough) else {
            return Measurement::default();
        };
        let Some(keyframe) = self.keyframes.drain(..=newest_far).next_back() else {
            return Measurement::default();
        };
        let prior = keyframe
            .world_from_robot
            .inverse()
            .compose(world_from_robot);
        let laser = register_two_step(&keyframe.target, scan, prior, config);
        let wheel_relative = keyframe.wheel.inverse().compose(wheel);
        let wheel_m = wheel_relative.translation;
        let yaw = (!laser.degenerate[2]).then(|| {
            let turn = |p: &Pose| p.rpy()[2];
            let excess = turn(&wheel_relative) - turn(&laser.pose);
            // Into (-pi, pi]: both turns are small, their difference must stay so.
            PI - (PI - excess).rem_euclid(TAU)
        });
        Measurement {
            interval_s: (keyframe.stamp_s, stamp_s),
            distances: (0..2)
                .filter(|&k| !laser.degenerate[3 + k] && wheel_m[k].abs() >= 0.5 * self.baseline_m)
                .map(|k| (laser.pose.translation[k], wheel_m[k]))
                .collect(),
            yaw,
        }
    }

    /// True when a keyframe lies at least a baseline behind wheel pose `wheel` (so
    /// [`Self::measure`] would register against it).
    pub fn is_due(&self, wheel: &Pose) -> bool {
        self.keyframes
            .front()
            .is_some_and(|k| travelled(&k.wheel, wheel) >= self.baseline_m)
    }

    /// True when scan number `frame` with wheel pose `wheel` should become a keyframe: none is
    /// kept yet, or the newest is a quarter baseline and `MIN_FRAMES_BETWEEN_KEYFRAMES` frames
    /// behind. Never when the meter is off.
    pub fn wants_keyframe(&self, frame: u64, wheel: &Pose) -> bool {
        self.baseline_m > 0.0
            && self.keyframes.back().is_none_or(|k| {
                frame >= k.frame + MIN_FRAMES_BETWEEN_KEYFRAMES
                    && travelled(&k.wheel, wheel) >= self.baseline_m / KEYFRAMES_PER_BASELINE
            })
    }

    /// Keep the scan taken `at` as a keyframe (see [`Self::wants_keyframe`]), with its features
    /// indexed as a registration `target`.
    pub fn add_keyframe(&mut self, at: ScanAt, target: Arc<FeatureTarget>) {
        self.keyframes.push_back(Keyframe {
            frame: at.frame,
            stamp_s: at.stamp_s,
            wheel: at.wheel,
            world_from_robot: at.world_from_robot,
            target,
        });
    }
}

/// Distance between two wheel odometry poses, metres.
fn travelled(a: &Pose, b: &Pose) -> f64 {
    let t = a.inverse().compose(b).translation;
    t[0].hypot(t[1])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::{moved, scan_of, scene, target_of};

    /// A scan taken at `pose` by both the wheels and the estimate.
    fn scan_at(frame: u64, stamp_s: f64, pose: Pose) -> ScanAt {
        ScanAt {
            frame,
            stamp_s,
            wheel: pose,
            world_from_robot: pose,
        }
    }

    fn at(x_m: f64) -> Pose {
        Pose::from_xyz_rpy([x_m, 0.0, 0.0], [0.0; 3])
    }

    /// The synthetic tyres are a small share of the residuals: accept weaker directions than the
    /// default, as the registration tests do.
    fn config() -> LaserOdometryConfig {
        LaserOdometryConfig {
            degeneracy_eigen_min: 0.01,
            degeneracy_rotation_eigen_min_m2: 0.01,
            ..LaserOdometryConfig::default()
        }
    }

    #[test]
    fn a_scan_a_baseline_on_measures_the_distance_slipping_wheels_overstate() {
        let (planes, corners) = scene(true);
        let mut meter = SlipMeter::new(0.25);
        assert!(meter.wants_keyframe(0, &at(0.0)));
        meter.add_keyframe(
            scan_at(0, 0.0, at(0.0)),
            Arc::new(target_of(&planes, &corners)),
        );
        // The next keyframe is due a quarter baseline and two frames on.
        assert!(!meter.wants_keyframe(5, &at(0.05)));
        assert!(meter.wants_keyframe(5, &at(0.07)));
        assert!(!meter.wants_keyframe(1, &at(0.07)), "one frame on");
        assert!(meter.wants_keyframe(2, &at(0.07)));
        // Short of the baseline nothing is measured.
        let truth = at(0.2);
        let (sp, sc) = (moved(&planes, &truth), moved(&corners, &truth));
        let scan = scan_of(&sp, &sc);
        assert!(!meter.is_due(&at(0.2)));
        assert!(
            meter
                .measure(&scan_at(1, 1.0, at(0.2)), scan, &config())
                .is_empty()
        );
        // The robot moved 0.26 m; the wheels (5 % slip), and the estimate built on them, 0.273 m.
        let truth = at(0.26);
        let (sp, sc) = (moved(&planes, &truth), moved(&corners, &truth));
        let scan = scan_of(&sp, &sc);
        let wheel = at(0.26 * 1.05);
        assert!(meter.is_due(&wheel));
        let measured = meter.measure(&scan_at(1, 1.0, wheel), scan, &config());
        let pairs = &measured.distances;
        // x only: the wheels did not move along y.
        assert_eq!(pairs.len(), 1, "{pairs:?}");
        // The tyres determine the yaw: neither turned, over the 1 s since the keyframe.
        let turn_rad = measured.yaw.expect("yaw determined");
        let (from_s, to_s) = measured.interval_s;
        assert!(
            turn_rad.abs() < 1e-3 && (to_s - from_s - 1.0).abs() < 1e-12,
            "{measured:?}"
        );
        let (laser_m, wheel_m) = pairs[0];
        assert!((laser_m - 0.26).abs() < 2e-3, "{laser_m}");
        assert!((wheel_m - 0.273).abs() < 1e-12, "{wheel_m}");
        // The keyframe is used up.
        assert!(
            meter
                .measure(&scan_at(1, 1.0, wheel), scan, &config())
                .is_empty()
        );
    }

    #[test]
    fn a_direction_the_scan_does_not_determine_gives_no_measurement() {
        // Ground and underbody only: x is degenerate, so the registration's x is the prior's
        // (the wheels' own distance) and must not count as a measurement.
        let (planes, corners) = scene(false);
        let mut meter = SlipMeter::new(0.25);
        meter.add_keyframe(
            scan_at(0, 0.0, at(0.0)),
            Arc::new(target_of(&planes, &corners)),
        );
        let truth = at(0.26);
        let (sp, sc) = (moved(&planes, &truth), moved(&corners, &truth));
        let scan = scan_of(&sp, &sc);
        let wheel = at(0.273);
        assert!(
            meter
                .measure(&scan_at(1, 1.0, wheel), scan, &config())
                .is_empty()
        );
        // Off: no keyframes at all.
        assert!(!SlipMeter::new(0.0).wants_keyframe(0, &at(1.0)));
    }
}
