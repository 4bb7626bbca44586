//! The wheels' distance calibration (`onboard::wheel_calibration`, `passangle wheels`) on the
//! simulated robot: the calibration drive of `scenarios/field/wheel-calibration-hall-a.toml`
//! (parked, 4 m toward the rear wall of test hall A, parked again) with the field template's
//! wheel errors, whose constant scale error the seed draws. The scale it measures must match
//! the simulated one; without walls, or without the parked ends, it must say what is missing.

#![allow(clippy::unwrap_used)]

mod common;

use common::crate_dir;
use hil_sim::scenario::Scenario;
use hil_sim::wheel_odometry::constant_errors;
use onboard::wheel_calibration::{WheelCalibrationError, calibrate_wheels};
use pipeline::config::MountConfig;

fn drive(seed: u64, edit: impl FnOnce(&mut hil_sim::scenario::ScenarioFile)) -> Scenario {
    let path = crate_dir().join("scenarios/field/wheel-calibration-hall-a.toml");
    let loaded = Scenario::load(&path).unwrap();
    let mut file = loaded.file.clone();
    file.seed = seed;
    edit(&mut file);
    Scenario::from_parts(&path, file, loaded.vehicle).unwrap()
}

fn calibrate(
    s: &Scenario,
) -> Result<onboard::wheel_calibration::WheelCalibration, WheelCalibrationError> {
    let lidar = s.decoded_lidar_frames(&s.scene());
    let wheel = s.wheel_odometry(0.0);
    // The scenario mounts the VLP-16 as the pipeline's default does.
    calibrate_wheels(&lidar, &wheel, &MountConfig::default())
}

#[test]
fn the_drive_between_walls_gives_the_wheels_scale() {
    for seed in [1, 2] {
        // A calibrated lidar (no range biases left): the walls place the travel to a
        // millimetre or two over 4 m.
        let s = drive(seed, |f| f.lidar.range_bias_sigma_m = 0.0);
        let cal = calibrate(&s).unwrap();
        let (error, _) = constant_errors(&s.file.wheel_odometry, s.wheel_seed());
        let truth = 1.0 / (1.0 + error);
        assert!(
            error.abs() > 2e-3,
            "seed {seed} draws a scale error to find: {error}"
        );
        assert!(
            (cal.scale - truth).abs() < 5e-4,
            "seed {seed}: scale {} against {truth} ({cal:?})",
            cal.scale
        );
        assert!(cal.travel.walls.len() >= 2, "{cal:?}");
        // With the field's 1 cm per-laser biases uncalibrated, the walls' planes tilt with the
        // lasers that reach them, differently from near and far: a few millimetres more.
        let biased = calibrate(&drive(seed, |_| {})).unwrap();
        assert!(
            (biased.scale - truth).abs() < 2e-3,
            "seed {seed}: scale {} against {truth} ({biased:?})",
            biased.scale
        );
    }
}

#[test]
fn a_drive_without_parked_ends_or_without_walls_says_what_is_missing() {
    // Cruising through: no parked capture before the drive.
    let moving = drive(1, |f| {
        f.robot.still_s = 0.0;
        f.robot.stop = false;
        f.duration_s = Some(6.0);
    });
    let e = calibrate(&moving).unwrap_err();
    assert!(
        matches!(
            e,
            WheelCalibrationError::NotParked {
                which: "before",
                ..
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("park the robot"), "{e}");
    // The same drive in the empty world: nothing within range but the floor and the car.
    let open = drive(1, |f| {
        f.world = None;
        f.robot.distance_m = 1.5;
    });
    let e = calibrate(&open).unwrap_err();
    assert!(e.to_string().contains("wall"), "{e}");
}
