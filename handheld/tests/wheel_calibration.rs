//! `passangle wheels RUN_DIR` on a simulated calibration drive recorded as the robot records a
//! run (`onboard::recorder`): parked, 2 m toward the rear wall of test hall A, parked again
//! (`hil-sim/scenarios/field/wheel-calibration-hall-a.toml`, a calibrated lidar) gives the
//! wheels' simulated scale and the line for the onboard config; a drive that never parks fails
//! and says why.

#![allow(clippy::unwrap_used, missing_docs)]

mod common;

use std::net::SocketAddrV4;
use std::path::{Path, PathBuf};

use common::{passangle, temp_root};
use hil_sim::scenario::Scenario;
use hil_sim::vlp16::{SENSOR_IP, Vlp16Sim};
use onboard::recorder::{RecordedOutcome, RunRecorder};
use protocol::bounded::Text;
use protocol::mcu::Odometry;
use protocol::radio::{StartMeasurement, Zone};
use serde_json::Value;

const BASE_US: u64 = 1_790_000_000_000_000;

fn drive(parked: bool) -> Scenario {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../hil-sim/scenarios/field/wheel-calibration-hall-a.toml");
    let s = Scenario::load(&path).unwrap();
    let mut file = s.file.clone();
    file.lidar.range_bias_sigma_m = 0.0;
    file.robot.distance_m = 2.0;
    if parked {
        file.robot.still_s = 1.0;
    } else {
        file.robot.still_s = 0.0;
        file.robot.stop = false;
        file.duration_s = Some(5.0);
    }
    Scenario::from_parts(&path, file, s.vehicle.clone()).unwrap()
}

/// The drive recorded as a run: the VLP-16's packets and 100 Hz wheel reports, each stamped
/// with its send time.
fn record(s: &Scenario, root: &Path) -> PathBuf {
    let params = StartMeasurement {
        vehicle_id: Text::truncated("wheel calibration"),
        speed_mps: 0.3,
        distance_m: 2.0,
        zone: Zone::Tyre,
        lab: protocol::radio::LabRef::NONE,
    };
    let config = include_str!("../../onboard/onboard.example.toml");
    let mut rec = RunRecorder::begin(root, 1, &params, BASE_US, config).unwrap();
    let scene = s.scene();
    let motion = s.motion();
    let sim = Vlp16Sim::new(&scene, &motion, s.lidar_config(), s.lidar_seed());
    let host = SocketAddrV4::new(std::net::Ipv4Addr::new(192, 168, 1, 100), 2368);
    let mut wheel = s.wheel_odometry(0.0).into_iter().peekable();
    for d in sim.datagrams(s.duration_s) {
        while let Some(w) = wheel.next_if(|w| w.stamp_s <= d.send_s()) {
            let o = Odometry {
                stamp_us: (w.stamp_s * 1e6) as u64,
                x_m: w.x_m as f32,
                y_m: w.y_m as f32,
                yaw_rad: w.yaw_rad as f32,
                vx_mps: w.vx_mps as f32,
                vy_mps: w.vy_mps as f32,
                wz_radps: w.wz_radps as f32,
                wheel_speed_radps: [0.0; 4],
            };
            rec.odometry(BASE_US + o.stamp_us, &o);
        }
        let (payload, port) = d.payload_and_port();
        let wall_ns = (BASE_US + (d.send_s() * 1e6) as u64) * 1_000;
        rec.lidar_packet(wall_ns, SocketAddrV4::new(SENSOR_IP, port), host, payload);
    }
    let dir = rec.dir().to_path_buf();
    assert!(rec.finish(RecordedOutcome::Completed).is_empty());
    dir
}

#[test]
fn a_recorded_drive_between_walls_gives_the_wheels_scale() {
    let s = drive(true);
    let root = temp_root("wheels");
    let dir = record(&s, &root);
    let (error, _) =
        hil_sim::wheel_odometry::constant_errors(&s.file.wheel_odometry, s.wheel_seed());
    let truth = 1.0 / (1.0 + error);

    let (code, text) = passangle(&["wheels", dir.to_str().unwrap()], None);
    assert_eq!(code, 0, "{text}");
    assert!(
        text.contains("[processing]\nwheel-distance-scale = "),
        "{text}"
    );
    assert!(text.contains("wall, normal"), "{text}");

    let (code, json) = passangle(&["wheels", dir.to_str().unwrap(), "--json"], None);
    assert_eq!(code, 0, "{json}");
    let v: Value = serde_json::from_str(&json).unwrap();
    let scale = v["scale"].as_f64().unwrap();
    // 2 m between walls 4-9 m away: the travel to a millimetre or two, the scale to 0.1 %.
    assert!(
        (scale - truth).abs() < 1e-3,
        "{scale} against {truth}: {json}"
    );
    assert!(
        error.abs() > 2e-3,
        "the seed draws a scale error to find: {error}"
    );
    assert!((v["configured_scale"].as_f64().unwrap() - 1.0).abs() < 1e-12);
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
fn a_drive_that_never_parks_fails_and_says_so() {
    let root = temp_root("wheels-moving");
    let dir = record(&drive(false), &root);
    let (code, text) = passangle(&["wheels", dir.to_str().unwrap()], None);
    assert_ne!(code, 0, "{text}");
    assert!(text.contains("park the robot"), "{text}");
    let _ = std::fs::remove_dir_all(&root);
}
