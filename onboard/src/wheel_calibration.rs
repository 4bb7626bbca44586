//! The wheels' distance scale from a calibration drive: parked, a straight drive toward or away
//! from a wall, parked again (docs/operator/run.md, "Calibrating the wheels' distance"). Pure:
//! the run's lidar frames and wheel reports in, a scale out.
//!
//! Mecanum wheels report a distance off by a nearly constant factor on one floor. Below the
//! slip meter's threshold (`fusion.wheel-scale-min-slip`) the pipeline keeps it, and the cloud
//! keeps it between parts seen at different times: the simulated city car's rear axle and mud
//! flaps 1.3 cm further apart than they are, its departure 3 degrees off (decision record 043).
//! The walls seen from the two parked positions give the travel to a millimetre
//! ([`vlp16::travel`]); the scale is that travel over the wheels' distance between the same two
//! moments, for `[processing] wheel-distance-scale`.
//!
//! 1. **Parked spans**: the wheels are moving where their speed exceeds [`PARKED_MPS`]; the
//!    frames that end before the first such report and those that start after the last one
//!    are the two parked captures, each at least [`MIN_PARKED_FRAMES`] frames.
//! 2. **Wheels' distance**: their path length from their last report before the drive to their
//!    first after it, at least [`MIN_DRIVE_M`]; the direction between the two, turned into the
//!    lidar's frame by the mount, is the expected direction of travel.
//! 3. **Travel**: [`vlp16::travel::travel_between`] of the two captures' walls.
//!
//! Approximate: with walls ahead or behind only, the sideways part of the drive is neglected (a
//! straight drive keeps it to millimetres); the standard error takes the returns as
//! independent.

use pipeline::config::MountConfig;
use pipeline::fusion::WHEEL_SCALE_RANGE;
use pipeline::geom::{Pose, V3};
use pipeline::{LidarFrame, WheelOdometry};
use vlp16::calibration::CalibrationError;
use vlp16::travel::{Travel, TravelError, travel_between, walls_of};

/// Wheel speed below which the robot is parked, m/s.
pub const PARKED_MPS: f64 = 0.005;

/// Whether wheels reporting these speeds are moving (faster than [`PARKED_MPS`]).
#[must_use]
pub fn moving(vx_mps: f64, vy_mps: f64) -> bool {
    vx_mps.hypot(vy_mps) > PARKED_MPS
}
/// Fewest frames of each parked capture (half a second at 600 rpm).
pub const MIN_PARKED_FRAMES: usize = 5;
/// Shortest calibration drive, metres: over a shorter one a millimetre of the walls is more
/// than 0.1 % of the distance.
pub const MIN_DRIVE_M: f64 = 1.0;

/// The calibration's result.
#[derive(Debug, Clone, PartialEq)]
pub struct WheelCalibration {
    /// True distance over the wheels' distance: `[processing] wheel-distance-scale`.
    pub scale: f64,
    /// Its standard error.
    pub standard_error: f64,
    /// The wheels' distance between the parked captures, metres.
    pub wheel_distance_m: f64,
    /// The walls' travel.
    pub travel: Travel,
    /// The parked captures, (first frame start, last frame start) seconds, before and after.
    pub parked_s: [(f64, f64); 2],
}

/// Why a recording gives no scale.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum WheelCalibrationError {
    /// The wheels did not report a drive.
    #[error(
        "the wheels report {distance_m:.2} m between the parked captures; a calibration drive needs at least {MIN_DRIVE_M} m"
    )]
    NoDrive {
        /// The wheels' distance, metres.
        distance_m: f64,
    },
    /// Too few lidar frames while parked.
    #[error(
        "only {frames} lidar frames while parked {which} the drive; park the robot for at least a second {which} it"
    )]
    NotParked {
        /// `before` or `after`.
        which: &'static str,
        /// Frames found.
        frames: usize,
    },
    /// A capture's walls.
    #[error("{0}")]
    Walls(TravelError),
    /// The scale is beyond any wheel's plausible error.
    #[error(
        "the walls give {travel_m:.3} m against the wheels' {wheel_m:.3} m: a scale outside {}..{}, not a scale error (a wrong wall matched, or the wheels slipped badly)",
        WHEEL_SCALE_RANGE.0,
        WHEEL_SCALE_RANGE.1
    )]
    Implausible {
        /// The walls' travel, metres.
        travel_m: f64,
        /// The wheels' distance, metres.
        wheel_m: f64,
    },
}

/// The wheels' distance scale from a calibration drive's frames and wheel reports (sorted by
/// stamp, one clock), with the lidar mounted as `mounts` says (module docs).
pub fn calibrate_wheels(
    lidar: &[LidarFrame],
    wheel: &[WheelOdometry],
    mounts: &MountConfig,
) -> Result<WheelCalibration, WheelCalibrationError> {
    let is_moving = |w: &WheelOdometry| moving(w.vx_mps, w.vy_mps);
    let (Some(first), Some(last)) = (
        wheel.iter().position(is_moving),
        wheel.iter().rposition(is_moving),
    ) else {
        return Err(WheelCalibrationError::NoDrive { distance_m: 0.0 });
    };
    // The last report before the drive and the first after it.
    let (i_before, i_after) = (first.saturating_sub(1), (last + 1).min(wheel.len() - 1));
    let (before, after) = (&wheel[i_before], &wheel[i_after]);
    let (t_go, t_stop) = (wheel[first].stamp_s, wheel[last].stamp_s);
    let frame_end = |f: &LidarFrame| {
        f.stamp_s
            + f.points
                .iter()
                .map(|p| f64::from(p.time_offset_s))
                .fold(0.0, f64::max)
    };
    let start: Vec<&LidarFrame> = lidar.iter().filter(|f| frame_end(f) < t_go).collect();
    let end: Vec<&LidarFrame> = lidar.iter().filter(|f| f.stamp_s > t_stop).collect();
    for (which, frames) in [("before", &start), ("after", &end)] {
        if frames.len() < MIN_PARKED_FRAMES {
            return Err(WheelCalibrationError::NotParked {
                which,
                frames: frames.len(),
            });
        }
    }
    let (dx, dy) = (after.x_m - before.x_m, after.y_m - before.y_m);
    // The wheels' path length: their heading drifts, so their chord is shorter than what they
    // report having driven (the true path is straight).
    let wheel_distance_m: f64 = wheel[i_before..=i_after]
        .windows(2)
        .map(|w| (w[1].x_m - w[0].x_m).hypot(w[1].y_m - w[0].y_m))
        .sum();
    if wheel_distance_m < MIN_DRIVE_M {
        return Err(WheelCalibrationError::NoDrive {
            distance_m: wheel_distance_m,
        });
    }
    // The direction of travel in the robot frame at the start, then in the lidar's frame.
    let (s, c) = before.yaw_rad.sin_cos();
    let in_robot = V3::new(c * dx + s * dy, -s * dx + c * dy, 0.0) / dx.hypot(dy);
    let robot_from_lidar = Pose::from_xyz_rpy(mounts.lidar_xyz_m, mounts.lidar_rpy_rad);
    let direction = robot_from_lidar.inverse().apply_vector(in_robot);
    let points = |frames: &[&LidarFrame]| -> Vec<V3> {
        frames
            .iter()
            .flat_map(|f| f.points.iter())
            .map(|p| V3::from(p.xyz_in_lidar_m.map(f64::from)))
            .collect()
    };
    let walls = |frames: &[&LidarFrame], wrap: fn(CalibrationError) -> TravelError| {
        walls_of(&points(frames)).map_err(|e| WheelCalibrationError::Walls(wrap(e)))
    };
    let (start_walls, end_walls) = (
        walls(&start, TravelError::Start)?,
        walls(&end, TravelError::End)?,
    );
    let travel = travel_between(&start_walls, &end_walls, direction.into(), wheel_distance_m)
        .map_err(WheelCalibrationError::Walls)?;
    let scale = travel.distance_m / wheel_distance_m;
    if !(WHEEL_SCALE_RANGE.0..=WHEEL_SCALE_RANGE.1).contains(&scale) {
        return Err(WheelCalibrationError::Implausible {
            travel_m: travel.distance_m,
            wheel_m: wheel_distance_m,
        });
    }
    let span = |frames: &[&LidarFrame]| {
        (
            frames.first().map_or(0.0, |f| f.stamp_s),
            frames.last().map_or(0.0, |f| f.stamp_s),
        )
    };
    Ok(WheelCalibration {
        scale,
        standard_error: travel.standard_error_m / wheel_distance_m,
        wheel_distance_m,
        parked_s: [span(&start), span(&end)],
        travel,
    })
}
