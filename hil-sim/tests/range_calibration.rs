//! The range calibration (`vlp16::calibration`, `passangle lidar --calibrate`) on the simulated
//! VLP-16: a 2 s recording with the robot parked in test hall A
//! (`scenarios/field/lidar-calibration-hall-a.toml`), and one with the sensor on a 1.5 m tripod
//! there (`lidar-calibration-tripod-hall-a.toml`); the lasers carry per-laser range biases of
//! 1 cm RMS. The offsets it estimates must take most of each calibrated laser's bias away.
//! (The command line's use of it: `handheld/tests/lidar_calibration.rs`.)

#![allow(clippy::unwrap_used)]

mod common;

use common::crate_dir;
use hil_sim::scenario::Scenario;
use hil_sim::vlp16::Vlp16Sim;
use vlp16::DecoderConfig;
use vlp16::calibration::estimate_range_offsets;

fn scenario(name: &str) -> Scenario {
    Scenario::load(&crate_dir().join("scenarios/field").join(name)).unwrap()
}

/// The calibration of a recording: the estimate, the simulated biases, the calibrated lasers
/// and the RMS of their biases before and after.
fn calibrate(s: &Scenario) -> (vlp16::calibration::RangeCalibration, Vec<usize>, f64, f64) {
    let config = DecoderConfig::default();
    let points: Vec<vlp16::Point> = s
        .decoded_vlp16_frames(&s.scene(), &config)
        .into_iter()
        .flat_map(|f| f.points)
        .collect();
    let cal = estimate_range_offsets(&points, &config).unwrap();
    let truth = true_biases(s);
    let calibrated: Vec<usize> = (0..16)
        .filter(|&l| cal.standard_error_m[l].is_some())
        .collect();
    let n = calibrated.len() as f64;
    let rms = |f: &dyn Fn(usize) -> f64| {
        (calibrated.iter().map(|&l| f(l).powi(2)).sum::<f64>() / n).sqrt()
    };
    let before = rms(&|l| truth[l]);
    let after = rms(&|l| cal.offsets_m[l] - truth[l]);
    (cal, calibrated, before, after)
}

fn true_biases(s: &Scenario) -> [f64; 16] {
    let scene = s.scene();
    let motion = s.motion();
    Vlp16Sim::new(&scene, &motion, s.lidar_config(), s.lidar_seed()).range_bias_m()
}

#[test]
fn on_the_robot_the_offsets_take_the_upward_lasers_biases_away() {
    let (cal, calibrated, before, after) = calibrate(&scenario("lidar-calibration-hall-a.toml"));
    // Every upward laser sees the walls; the downward ones see the floor from 0.12 m up.
    for l in (1..16).step_by(2) {
        assert!(calibrated.contains(&l), "laser {l} not calibrated: {cal:?}");
    }
    // The estimator leaves a few millimetres (returns where the walls meet surfaces it did
    // not find, range noise); the biases are a centimetre RMS.
    assert!(after < 0.004, "RMS left {after} m of {before} m");
    assert!(after < before / 2.0, "RMS left {after} m of {before} m");
}

#[test]
fn on_a_tripod_every_laser_is_calibrated() {
    let (cal, calibrated, before, after) =
        calibrate(&scenario("lidar-calibration-tripod-hall-a.toml"));
    assert_eq!(calibrated.len(), 16, "{cal:?}");
    assert!(after < 0.0025, "RMS left {after} m of {before} m");
    assert!(after < before / 4.0, "RMS left {after} m of {before} m");
}
