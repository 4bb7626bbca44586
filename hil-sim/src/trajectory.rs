//! Robot poses over time: the input of every sensor model.
//!
//! Sensors never compute motion themselves; they ask a [`Trajectory`] for `world_from_robot` at the
//! instant of each firing or exposure. Two implementations:
//! - [`StraightRun`]: the scenario's analytic motion (constant-speed straight line with an optional
//!   acceleration ramp, lateral offset, yaw misalignment, wheel slip and seeded pitch/roll vibration).
//!   It is a pure function of time, so any instant can be evaluated in any order.
//! - [`SampledTrajectory`]: time-stamped poses (e.g. from the simulated ESCs and firmware later),
//!   linearly interpolated.
//!
//! # Robot frame
//! x forward, y left, z up; origin on the ground below the robot's centre. A pose's
//! `position_m` is that origin in the world (vehicle) frame.
//!
//! # Ground-truth file (CSV)
//! [`write_truth_csv`] writes one line per sample after a `#` comment header:
//! `time_s,x_m,y_m,z_m,roll_rad,pitch_rad,yaw_rad,wheel_distance_m`. Time is simulation time in
//! seconds since the scenario start (the sensors' clocks are offset from it by fixed amounts given in
//! their own files); the pose is `world_from_robot` in the vehicle frame; `wheel_distance_m` is the
//! distance the wheel encoders would report (it exceeds the true distance by the slip).
//! [`parse_trajectory_csv`] reads such files (and the robot simulation's pose history) back into a
//! [`SampledTrajectory`], so a recorded or externally simulated motion can drive the sensors.

use std::f64::consts::TAU;
use std::io::Write;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::geometry::{Pose, Vec3};

/// A robot pose as a function of simulation time.
pub trait Trajectory {
    /// `world_from_robot` at `t_s` seconds since the scenario start.
    fn pose_at(&self, t_s: f64) -> Pose;

    /// Distance the wheel encoders report at `t_s` (equal to the true path length without slip).
    fn wheel_distance_at(&self, t_s: f64) -> f64;
}

/// Small pitch and roll oscillation: a sum of sinusoids with seeded frequencies and phases whose RMS
/// equals the requested sigma. Smooth, bounded and evaluable at any time (unlike white noise).
#[derive(Clone, Debug, PartialEq)]
pub struct Vibration {
    /// `(pitch amplitude rad, roll amplitude rad, frequency Hz, pitch phase rad, roll phase rad)`.
    components: Vec<[f64; 5]>,
}

impl Vibration {
    /// Number of sinusoids summed per axis.
    pub const COMPONENTS: usize = 4;

    /// A vibration with RMS `pitch_sigma_rad` / `roll_sigma_rad`, frequencies drawn uniformly in
    /// 3..15 Hz from `seed`.
    pub fn new(pitch_sigma_rad: f64, roll_sigma_rad: f64, seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let k = Self::COMPONENTS as f64;
        // Each sinusoid of amplitude A has RMS A / sqrt(2); K of them: A = sigma * sqrt(2 / K).
        let scale = (2.0 / k).sqrt();
        let components = (0..Self::COMPONENTS)
            .map(|_| {
                [
                    pitch_sigma_rad * scale,
                    roll_sigma_rad * scale,
                    rng.random_range(3.0..15.0),
                    rng.random_range(0.0..TAU),
                    rng.random_range(0.0..TAU),
                ]
            })
            .collect();
        Self { components }
    }

    /// No vibration.
    pub fn none() -> Self {
        Self {
            components: Vec::new(),
        }
    }

    /// `(pitch_rad, roll_rad)` at `t_s`.
    pub fn at(&self, t_s: f64) -> (f64, f64) {
        self.components.iter().fold((0.0, 0.0), |(p, r), c| {
            let w = TAU * c[2] * t_s;
            (p + c[0] * (w + c[3]).sin(), r + c[1] * (w + c[4]).sin())
        })
    }
}

/// The scenario's analytic motion: a straight run along `heading_rad` from `start_m`.
#[derive(Clone, Debug, PartialEq)]
pub struct StraightRun {
    /// Start position of the robot origin, world frame (z is normally 0).
    pub start_m: Vec3,
    /// Direction of travel, radians from the world x axis.
    pub heading_rad: f64,
    /// Robot body yaw relative to the direction of travel (a mecanum robot can crab), radians.
    pub yaw_misalignment_rad: f64,
    /// Cruise speed commanded to the wheels, m/s.
    pub speed_mps: f64,
    /// Acceleration from rest to cruise, m/s^2; 0 or less means cruising from t = 0.
    pub accel_mps2: f64,
    /// Longitudinal slip ratio: true distance = (1 - slip) * wheel distance.
    pub slip: f64,
    /// Pitch/roll vibration.
    pub vibration: Vibration,
    /// Seconds the robot stands still before it starts.
    pub still_s: f64,
    /// Wheel distance after which the robot has braked to a stop at `accel_mps2` (`None`: it
    /// cruises on).
    pub stop_after_m: Option<f64>,
}

impl StraightRun {
    /// Distance commanded to the wheels after `t_s`: standing still for `still_s`, then a
    /// trapezoid profile, with the stop when `stop_after_m` is set.
    fn commanded_distance(&self, t_s: f64) -> f64 {
        let t = (t_s - self.still_s).max(0.0);
        match self.stop_after_m {
            None => self.cruising_distance(t),
            Some(d) => self.stopping_distance(t, d),
        }
    }

    /// The profile without the stop, `t` seconds after the start.
    fn cruising_distance(&self, t: f64) -> f64 {
        if self.accel_mps2 <= 0.0 {
            return self.speed_mps * t;
        }
        let t_ramp = self.speed_mps / self.accel_mps2;
        if t < t_ramp {
            0.5 * self.accel_mps2 * t * t
        } else {
            0.5 * self.speed_mps * t_ramp + self.speed_mps * (t - t_ramp)
        }
    }

    /// The profile braking to a stop at `d` metres, `t` seconds after the start: a trapezoid,
    /// or a triangle when `d` is too short to reach the cruise speed.
    fn stopping_distance(&self, t: f64, d: f64) -> f64 {
        let a = self.accel_mps2;
        if a <= 0.0 {
            return (self.speed_mps * t).min(d);
        }
        let (peak, t_ramp, t_cruise) = self.stop_profile(d);
        let d_ramp = 0.5 * peak * t_ramp;
        if t < t_ramp {
            0.5 * a * t * t
        } else if t < t_ramp + t_cruise {
            d_ramp + peak * (t - t_ramp)
        } else {
            let u = (t - t_ramp - t_cruise).min(t_ramp);
            d - d_ramp + peak * u - 0.5 * a * u * u
        }
    }

    /// A stop at `d` metres (`accel_mps2` > 0): the peak speed (the cruise speed, or less when
    /// `d` is too short to reach it), the time of each ramp and the time at the peak.
    fn stop_profile(&self, d: f64) -> (f64, f64, f64) {
        let peak = self.speed_mps.min((self.accel_mps2 * d).sqrt());
        let t_ramp = peak / self.accel_mps2;
        (peak, t_ramp, (d - peak * t_ramp) / peak)
    }

    /// Time from the scenario's start until the wheels have covered `distance_m` (the pause
    /// before the start included) and, for a run that stops, until the stop plus the pause
    /// after it.
    pub fn time_for_wheel_distance(&self, distance_m: f64) -> f64 {
        if self.speed_mps <= 0.0 {
            return self.still_s;
        }
        if let Some(d) = self.stop_after_m
            && self.accel_mps2 > 0.0
        {
            let (_, t_ramp, t_cruise) = self.stop_profile(d);
            return 2.0 * self.still_s + 2.0 * t_ramp + t_cruise;
        }
        self.still_s + self.moving_time(distance_m)
    }

    fn moving_time(&self, distance_m: f64) -> f64 {
        if self.accel_mps2 <= 0.0 {
            return distance_m / self.speed_mps;
        }
        let t_ramp = self.speed_mps / self.accel_mps2;
        let d_ramp = 0.5 * self.speed_mps * t_ramp;
        if distance_m < d_ramp {
            (2.0 * distance_m / self.accel_mps2).sqrt()
        } else {
            t_ramp + (distance_m - d_ramp) / self.speed_mps
        }
    }
}

impl Trajectory for StraightRun {
    fn pose_at(&self, t_s: f64) -> Pose {
        let s = (1.0 - self.slip) * self.commanded_distance(t_s);
        let (sin_h, cos_h) = self.heading_rad.sin_cos();
        let (pitch_rad, roll_rad) = self.vibration.at(t_s);
        Pose {
            position_m: self.start_m + Vec3::new(s * cos_h, s * sin_h, 0.0),
            roll_rad,
            pitch_rad,
            yaw_rad: self.heading_rad + self.yaw_misalignment_rad,
        }
    }

    fn wheel_distance_at(&self, t_s: f64) -> f64 {
        self.commanded_distance(t_s)
    }
}

/// Time-stamped poses, linearly interpolated (yaw along the shorter arc); clamped at both ends.
#[derive(Clone, Debug, PartialEq)]
pub struct SampledTrajectory {
    samples: Vec<(f64, Pose, f64)>,
}

/// Why samples could not form a trajectory.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TrajectoryError {
    /// No samples.
    #[error("a sampled trajectory needs at least one sample")]
    Empty,
    /// Times must be finite and strictly increasing.
    #[error("sample {index}: time {time_s} s is not finite or not after the previous sample")]
    NotIncreasing {
        /// Index of the offending sample.
        index: usize,
        /// Its time.
        time_s: f64,
    },
}

impl SampledTrajectory {
    /// Build from `(time_s, pose, wheel_distance_m)` samples with strictly increasing times.
    pub fn new(samples: Vec<(f64, Pose, f64)>) -> Result<Self, TrajectoryError> {
        if samples.is_empty() {
            return Err(TrajectoryError::Empty);
        }
        for (i, s) in samples.iter().enumerate() {
            if !s.0.is_finite() || (i > 0 && s.0 <= samples[i - 1].0) {
                return Err(TrajectoryError::NotIncreasing {
                    index: i,
                    time_s: s.0,
                });
            }
        }
        Ok(Self { samples })
    }

    /// Sample another trajectory every `step_s` over `[0, duration_s]`.
    pub fn sample(source: &impl Trajectory, duration_s: f64, step_s: f64) -> Self {
        let n = (duration_s / step_s).ceil().max(0.0) as usize;
        let samples = (0..=n)
            .map(|k| {
                let t = (k as f64 * step_s).min(duration_s.max(0.0));
                (t, source.pose_at(t), source.wheel_distance_at(t))
            })
            .collect::<Vec<_>>();
        let mut samples = samples;
        samples.dedup_by(|a, b| a.0 <= b.0);
        Self { samples }
    }

    /// The samples.
    pub fn samples(&self) -> &[(f64, Pose, f64)] {
        &self.samples
    }

    fn bracket(&self, t_s: f64) -> (usize, usize, f64) {
        let n = self.samples.len();
        let i = self.samples.partition_point(|s| s.0 <= t_s);
        if i == 0 {
            return (0, 0, 0.0);
        }
        if i >= n {
            return (n - 1, n - 1, 0.0);
        }
        let (t0, t1) = (self.samples[i - 1].0, self.samples[i].0);
        (i - 1, i, (t_s - t0) / (t1 - t0))
    }
}

fn lerp_angle(a: f64, b: f64, f: f64) -> f64 {
    let d = (b - a + std::f64::consts::PI).rem_euclid(TAU) - std::f64::consts::PI;
    a + f * d
}

impl Trajectory for SampledTrajectory {
    fn pose_at(&self, t_s: f64) -> Pose {
        let (i, j, f) = self.bracket(t_s);
        let (a, b) = (&self.samples[i].1, &self.samples[j].1);
        Pose {
            position_m: a.position_m + (b.position_m - a.position_m) * f,
            roll_rad: lerp_angle(a.roll_rad, b.roll_rad, f),
            pitch_rad: lerp_angle(a.pitch_rad, b.pitch_rad, f),
            yaw_rad: lerp_angle(a.yaw_rad, b.yaw_rad, f),
        }
    }

    fn wheel_distance_at(&self, t_s: f64) -> f64 {
        let (i, j, f) = self.bracket(t_s);
        self.samples[i].2 + f * (self.samples[j].2 - self.samples[i].2)
    }
}

/// Write the ground-truth CSV (format in the module docs), one line every `step_s` over
/// `[0, duration_s]`.
pub fn write_truth_csv(
    out: &mut impl Write,
    trajectory: &impl Trajectory,
    duration_s: f64,
    step_s: f64,
) -> std::io::Result<()> {
    writeln!(
        out,
        "# passangle-sim ground truth: world_from_robot in the vehicle frame (x front, y left, z up, m, rad)"
    )?;
    writeln!(
        out,
        "# time_s is simulation time since the scenario start; wheel_distance_m is what the encoders report"
    )?;
    writeln!(
        out,
        "time_s,x_m,y_m,z_m,roll_rad,pitch_rad,yaw_rad,wheel_distance_m"
    )?;
    let n = (duration_s / step_s).round().max(0.0) as u64;
    for k in 0..=n {
        let t = k as f64 * step_s;
        let p = trajectory.pose_at(t);
        let q = p.position_m;
        writeln!(
            out,
            "{t:.6},{:.6},{:.6},{:.6},{:.7},{:.7},{:.7},{:.6}",
            q.x,
            q.y,
            q.z,
            p.roll_rad,
            p.pitch_rad,
            p.yaw_rad,
            trajectory.wheel_distance_at(t)
        )?;
    }
    Ok(())
}

/// Why a trajectory CSV was rejected (line numbers count from 1, comments included).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TrajectoryCsvError {
    /// No header line with the required columns.
    #[error("no header line: need columns time_s (or stamp_us), x_m, y_m and yaw_rad")]
    NoHeader,
    /// A required column is missing from the header.
    #[error("line {line}: header lacks column `{column}`")]
    MissingColumn {
        /// Header line.
        line: usize,
        /// The column.
        column: &'static str,
    },
    /// A data line has too few fields or a field is not a finite number.
    #[error("line {line}: field `{column}` is missing or not a finite number")]
    BadField {
        /// The line.
        line: usize,
        /// The column.
        column: String,
    },
    /// The samples do not form a trajectory.
    #[error("{0}")]
    Samples(#[from] TrajectoryError),
}

/// Parse a trajectory CSV: lines starting with `#` are comments, the first other line is the
/// header, then one sample per line. Columns are found by name, in any order: `time_s` or
/// `stamp_us` (microseconds), `x_m`, `y_m`, `yaw_rad`, and optionally `z_m`, `roll_rad`,
/// `pitch_rad`, `wheel_distance_m` (0 when absent); other columns are ignored. Reads both this
/// crate's ground-truth files and the robot simulation's pose history
/// (`stamp_us,x_m,y_m,yaw_rad,...`). Never panics.
pub fn parse_trajectory_csv(text: &str) -> Result<SampledTrajectory, TrajectoryCsvError> {
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty() && !l.starts_with('#'));
    let (header_index, header) = lines.next().ok_or(TrajectoryCsvError::NoHeader)?;
    let names: Vec<&str> = header.split(',').map(str::trim).collect();
    let find = |name: &str| names.iter().position(|n| *n == name);
    let required = |name: &'static str| {
        find(name).ok_or(TrajectoryCsvError::MissingColumn {
            line: header_index + 1,
            column: name,
        })
    };
    let (time_col, time_scale) = match (find("time_s"), find("stamp_us")) {
        (Some(c), _) => (c, 1.0),
        (None, Some(c)) => (c, 1e-6),
        (None, None) => {
            return Err(TrajectoryCsvError::MissingColumn {
                line: header_index + 1,
                column: "time_s",
            });
        }
    };
    let (x, y, yaw) = (required("x_m")?, required("y_m")?, required("yaw_rad")?);
    let optional = [
        find("z_m"),
        find("roll_rad"),
        find("pitch_rad"),
        find("wheel_distance_m"),
    ];
    let mut samples = Vec::new();
    for (index, line) in lines {
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        let get = |col: usize| -> Result<f64, TrajectoryCsvError> {
            fields
                .get(col)
                .and_then(|f| f.parse::<f64>().ok())
                .filter(|v| v.is_finite())
                .ok_or_else(|| TrajectoryCsvError::BadField {
                    line: index + 1,
                    column: names[col].to_owned(),
                })
        };
        let opt = |col: Option<usize>| col.map_or(Ok(0.0), get);
        let pose = Pose {
            position_m: Vec3::new(get(x)?, get(y)?, opt(optional[0])?),
            roll_rad: opt(optional[1])?,
            pitch_rad: opt(optional[2])?,
            yaw_rad: get(yaw)?,
        };
        samples.push((get(time_col)? * time_scale, pose, opt(optional[3])?));
    }
    Ok(SampledTrajectory::new(samples)?)
}

impl SampledTrajectory {
    /// The same motion started from `start` instead of the origin: every pose `p` becomes
    /// `start * p` (for files whose poses are relative to where the robot began).
    #[must_use]
    pub fn relative_to(&self, start: &Pose) -> Self {
        let world_from_start = start.to_isometry();
        let samples = self
            .samples
            .iter()
            .map(|(t, p, w)| {
                let m = world_from_start.compose(&p.to_isometry());
                let r = &m.rotation;
                let pose = Pose {
                    position_m: m.translation,
                    roll_rad: r[(2, 1)].atan2(r[(2, 2)]),
                    pitch_rad: (-r[(2, 0)]).clamp(-1.0, 1.0).asin(),
                    yaw_rad: r[(1, 0)].atan2(r[(0, 0)]),
                };
                (*t, pose, *w)
            })
            .collect();
        Self { samples }
    }

    /// Time of the last sample, seconds.
    pub fn end_time_s(&self) -> f64 {
        self.samples.last().map_or(0.0, |s| s.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run() -> StraightRun {
        StraightRun {
            start_m: Vec3::new(2.0, 0.1, 0.0),
            heading_rad: std::f64::consts::PI,
            yaw_misalignment_rad: 0.02,
            speed_mps: 0.3,
            accel_mps2: 0.5,
            slip: 0.05,
            vibration: Vibration::new(0.002, 0.001, 9),
            still_s: 0.0,
            stop_after_m: None,
        }
    }

    #[test]
    fn a_run_that_stops_stands_still_before_and_after() {
        let r = StraightRun {
            still_s: 1.0,
            stop_after_m: Some(3.0),
            slip: 0.0,
            ..run()
        };
        assert_eq!(r.pose_at(0.9).position_m, r.pose_at(0.0).position_m);
        let end = r.time_for_wheel_distance(3.0);
        // 1 s still, 0.6 s ramp up, 9.4 s cruise, 0.6 s braking, 1 s still.
        assert!((end - 12.6).abs() < 1e-9, "{end}");
        assert!((r.wheel_distance_at(end - 1.0) - 3.0).abs() < 1e-12);
        assert!((r.wheel_distance_at(end + 5.0) - 3.0).abs() < 1e-12);
        let v = (r.wheel_distance_at(5.0) - r.wheel_distance_at(4.0)) / 1.0;
        assert!((v - 0.3).abs() < 1e-12, "{v}");
        // Too short to reach the cruise speed: a triangle, still ending at the distance.
        let short = StraightRun {
            stop_after_m: Some(0.1),
            ..r
        };
        assert!((short.wheel_distance_at(short.time_for_wheel_distance(0.1)) - 0.1).abs() < 1e-12);
    }

    #[test]
    fn straight_run_moves_at_slipped_speed_after_the_ramp() {
        let r = run();
        let (a, b) = (r.pose_at(10.0), r.pose_at(11.0));
        let v = (b.position_m - a.position_m).norm();
        assert!((v - 0.3 * 0.95).abs() < 1e-12, "{v}");
        assert!(
            b.position_m.x < a.position_m.x,
            "heading 180 degrees drives toward -x"
        );
        assert!((r.wheel_distance_at(11.0) - r.wheel_distance_at(10.0) - 0.3).abs() < 1e-12);
        assert!((a.yaw_rad - (std::f64::consts::PI + 0.02)).abs() < 1e-12);
        let t = r.time_for_wheel_distance(3.0);
        assert!((r.wheel_distance_at(t) - 3.0).abs() < 1e-12);
        assert!(
            (r.time_for_wheel_distance(0.01) - 0.2).abs() < 1e-12,
            "inside the ramp"
        );
    }

    #[test]
    fn vibration_has_the_requested_rms_and_is_reproducible() {
        let v = Vibration::new(0.01, 0.02, 3);
        assert_eq!(v, Vibration::new(0.01, 0.02, 3));
        assert_ne!(v, Vibration::new(0.01, 0.02, 4));
        let n = 200_000;
        let (mut sp, mut sr) = (0.0, 0.0);
        for k in 0..n {
            let (p, r) = v.at(f64::from(k) * 1e-3);
            sp += p * p;
            sr += r * r;
        }
        let (rp, rr) = ((sp / f64::from(n)).sqrt(), (sr / f64::from(n)).sqrt());
        assert!(
            (rp - 0.01).abs() < 0.001 && (rr - 0.02).abs() < 0.002,
            "{rp} {rr}"
        );
    }

    #[test]
    fn sampled_trajectory_interpolates_and_rejects_bad_times() {
        let r = run();
        let s = SampledTrajectory::sample(&r, 5.0, 0.01);
        let (a, b) = (s.pose_at(3.333), r.pose_at(3.333));
        assert!((a.position_m - b.position_m).norm() < 1e-4);
        assert!((s.pose_at(-1.0).position_m - r.pose_at(0.0).position_m).norm() < 1e-12);
        assert_eq!(SampledTrajectory::new(vec![]), Err(TrajectoryError::Empty));
        let p = Pose::default();
        assert_eq!(
            SampledTrajectory::new(vec![(0.0, p, 0.0), (0.0, p, 0.0)]),
            Err(TrajectoryError::NotIncreasing {
                index: 1,
                time_s: 0.0
            })
        );
        // Yaw interpolates across the +-pi seam along the short way.
        let p0 = Pose { yaw_rad: 3.1, ..p };
        let p1 = Pose { yaw_rad: -3.1, ..p };
        let t = SampledTrajectory::new(vec![(0.0, p0, 0.0), (1.0, p1, 0.0)]).expect("valid");
        assert!(t.pose_at(0.5).yaw_rad.abs() > 3.1);
    }

    #[test]
    fn truth_csv_parses_back_into_the_same_trajectory() {
        let mut out = Vec::new();
        write_truth_csv(&mut out, &run(), 2.0, 0.01).expect("in memory");
        let parsed = parse_trajectory_csv(&String::from_utf8(out).expect("ascii")).expect("valid");
        for t in [0.0, 0.731, 1.999] {
            let (a, b) = (parsed.pose_at(t), run().pose_at(t));
            assert!((a.position_m - b.position_m).norm() < 1e-5, "t {t}");
            assert!(
                (a.pitch_rad - b.pitch_rad).abs() < 1e-5 && (a.yaw_rad - b.yaw_rad).abs() < 1e-6
            );
        }
        assert!((parsed.end_time_s() - 2.0).abs() < 1e-9);
    }

    #[test]
    fn robot_history_csv_reads_with_microsecond_stamps_and_errors_name_the_line() {
        let text = "stamp_us,x_m,y_m,yaw_rad,vx_mps,vy_mps,wz_radps,wheel_distance_m\n0,0,0,0,0,0,0,0\n1000000,0.3,0,0,0.3,0,0,0.31\n";
        let t = parse_trajectory_csv(text).expect("valid");
        assert!((t.pose_at(0.5).position_m.x - 0.15).abs() < 1e-12);
        assert!((t.wheel_distance_at(1.0) - 0.31).abs() < 1e-12);
        let start = Pose {
            position_m: Vec3::new(2.0, 0.1, 0.0),
            yaw_rad: std::f64::consts::PI,
            ..Pose::default()
        };
        let moved = t.relative_to(&start).pose_at(1.0);
        assert!((moved.position_m - Vec3::new(1.7, 0.1, 0.0)).norm() < 1e-12);
        assert!((moved.yaw_rad.abs() - std::f64::consts::PI).abs() < 1e-12);
        let bad = text.replace("1000000,0.3", "1000000,abc");
        assert_eq!(
            parse_trajectory_csv(&bad),
            Err(TrajectoryCsvError::BadField {
                line: 3,
                column: "x_m".into()
            })
        );
        assert_eq!(
            parse_trajectory_csv("# only a comment\ntime_s,x_m,y_m\n"),
            Err(TrajectoryCsvError::MissingColumn {
                line: 2,
                column: "yaw_rad"
            })
        );
        assert_eq!(parse_trajectory_csv(""), Err(TrajectoryCsvError::NoHeader));
    }

    proptest::proptest! {
        #[test]
        fn arbitrary_csv_never_panics(body in "[0-9a-z_,. eE+\\-\n#]{0,300}") {
            let _ = parse_trajectory_csv(&body);
            let _ = parse_trajectory_csv(&format!("time_s,x_m,y_m,yaw_rad\n{body}"));
            let _ = parse_trajectory_csv(&format!("stamp_us,yaw_rad,x_m,y_m,z_m,roll_rad,pitch_rad\n{body}"));
        }
    }

    #[test]
    fn truth_csv_has_header_and_one_line_per_sample() {
        let mut out = Vec::new();
        write_truth_csv(&mut out, &run(), 1.0, 0.01).expect("in memory");
        let text = String::from_utf8(out).expect("ascii");
        let data: Vec<&str> = text.lines().filter(|l| !l.starts_with('#')).collect();
        assert_eq!(
            data[0],
            "time_s,x_m,y_m,z_m,roll_rad,pitch_rad,yaw_rad,wheel_distance_m"
        );
        assert_eq!(data.len(), 102);
        assert_eq!(data[101].split(',').count(), 8);
    }
}
