//! `passangle lidar CAPTURE --calibrate` on simulated captures: a 2 s recording with the robot
//! parked in test hall A (`hil-sim/scenarios/field/lidar-calibration-hall-a.toml`, per-laser
//! range biases of 1 cm RMS) gives offsets near the simulated biases and the line for the
//! onboard config; the same recording in the empty world (no wall), or with the robot driving,
//! fails and says why.

#![allow(clippy::unwrap_used, missing_docs)]

mod common;

use std::path::{Path, PathBuf};

use common::{passangle, temp_root};
use hil_sim::scenario::Scenario;
use hil_sim::vlp16::Vlp16Sim;
use serde_json::Value;

fn scenario(empty_world: bool, speed_mps: f64) -> Scenario {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../hil-sim/scenarios/field/lidar-calibration-hall-a.toml");
    let s = Scenario::load(&path).unwrap();
    let mut file = s.file.clone();
    if empty_world {
        file.world = None;
        file.hall = None;
    }
    file.robot.speed_mps = speed_mps;
    Scenario::from_parts(&path, file, s.vehicle.clone()).unwrap()
}

/// The scenario's packets as a pcap, as `passangle-sim lidar --pcap` writes them.
fn write_pcap(s: &Scenario, dir: &Path) -> PathBuf {
    let path = dir.join("capture.pcap");
    let scene = s.scene();
    let motion = s.motion();
    let sim = Vlp16Sim::new(&scene, &motion, s.lidar_config(), s.lidar_seed());
    let file = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
    let mut w = vlp16::pcap::PcapWriter::new(file).unwrap();
    for d in sim.datagrams(s.duration_s) {
        d.write_pcap(&mut w).unwrap();
    }
    drop(w);
    path
}

#[test]
fn a_parked_capture_in_a_hall_calibrates_the_lasers_that_see_walls() {
    let s = scenario(false, 0.001);
    let dir = temp_root("lidar-calibration");
    let pcap = write_pcap(&s, &dir);
    let truth = {
        let scene = s.scene();
        let motion = s.motion();
        Vlp16Sim::new(&scene, &motion, s.lidar_config(), s.lidar_seed()).range_bias_m()
    };
    let (code, text) = passangle(
        &["lidar", pcap.to_str().unwrap(), "--calibrate", "--json"],
        None,
    );
    assert_eq!(code, 0, "{text}");
    let doc: Value = serde_json::from_str(&text).unwrap();
    let lasers = doc["lasers"].as_array().unwrap();
    assert_eq!(lasers.len(), 16);
    for (l, entry) in lasers.iter().enumerate() {
        let offset = entry["offset_m"].as_f64().unwrap();
        if entry["standard_error_m"].is_null() {
            assert!(offset == 0.0, "laser {l}: uncalibrated but offset {offset}");
            continue;
        }
        // Within a few millimetres of a bias of up to 3 cm (see hil-sim's range_calibration).
        assert!(
            (offset - truth[l]).abs() < 0.01,
            "laser {l}: {offset} vs {}",
            truth[l]
        );
    }
    let line = doc["config_line"].as_str().unwrap();
    assert!(line.starts_with("lidar-range-offsets-m = ["), "{line}");
    // The text form names the lasers it could not calibrate and how to reach them.
    let (code, text) = passangle(&["lidar", pcap.to_str().unwrap(), "--calibrate"], None);
    assert_eq!(code, 0, "{text}");
    assert!(text.contains("not calibrated"), "{text}");
    assert!(
        text.contains("[processing]\nlidar-range-offsets-m = ["),
        "{text}"
    );
}

/// `passangle lidar --calibrate` on the parked capture, in the empty world or with the robot
/// driving at `speed_mps`: it must fail; its output.
fn refused(empty_world: bool, speed_mps: f64, name: &str) -> String {
    let s = scenario(empty_world, speed_mps);
    let pcap = write_pcap(&s, &temp_root(name));
    let (code, text) = passangle(&["lidar", pcap.to_str().unwrap(), "--calibrate"], None);
    assert_ne!(code, 0, "{text}");
    text
}

#[test]
fn a_capture_without_walls_fails_and_says_why() {
    let text = refused(true, 0.001, "lidar-calibration-empty");
    assert!(
        text.contains("walls"),
        "the error names what the capture lacks: {text}"
    );
}

#[test]
fn a_capture_while_driving_is_refused() {
    // The robot drives off at 0.3 m/s: the walls smear by decimetres over the capture.
    let text = refused(false, 0.3, "lidar-calibration-moving");
    assert!(
        text.contains("range calibration") && text.contains("stand still"),
        "{text}"
    );
}
