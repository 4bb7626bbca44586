//! `passangle export RUN_DIR --mcap`: a short simulated run (VLP-16 packets from the sedan
//! scenario, wheel odometry, depth frames, a result and a fused cloud) recorded by the onboard
//! recorder, exported, and read back with the `mcap` crate (always) and with the PyPI `mcap`
//! reader (when `python3` with `mcap` is installed; otherwise the test says so loudly).
#![allow(clippy::unwrap_used, missing_docs)]

mod common;

use common::temp_root;
use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::process::Command;

use cloud_io::{Cloud, PlyEncoding, write_ply};
use hil_sim::scenario::Scenario;
use hil_sim::trajectory::Trajectory;
use hil_sim::vlp16::{Datagram, Vlp16Sim};
use hil_sim::world::Scene;
use onboard::recorder::{Intrinsics, RecordedOutcome, ResultRecord, RunRecorder};
use protocol::bounded::Text;
use protocol::mcu::Odometry;
use protocol::radio::{StartMeasurement, Zone};
use serde_json::Value;

const BASE_US: u64 = 1_790_000_000_000_000;
const DEPTH_FRAMES: u64 = 4;

/// The result the recorded run ends with.
fn result_record() -> ResultRecord {
    ResultRecord {
        run_id: 1,
        vehicle_id: "export test".into(),
        approach_rad: 0.3,
        departure_rad: 0.3,
        breakover_rad: 0.2,
        approach_deg: 17.19,
        departure_deg: 17.19,
        breakover_deg: 11.46,
        ground_clearance_m: 0.15,
        approach_u_rad: 0.007,
        departure_u_rad: 0.007,
        breakover_u_rad: 0.009,
        approach_u_deg: 0.4,
        departure_u_deg: 0.4,
        breakover_u_deg: 0.5,
        ground_clearance_u_m: 0.004,
        not_measured: BTreeMap::new(),
        wheelbase_m: 2.7,
        track_m: 1.5,
        approach_support: 10,
        departure_support: 10,
        breakover_support: 10,
        tyre_fit_rms_m: 0.002,
        warnings: Vec::new(),
        cloud_points: 1000,
        profiles: Vec::new(),
    }
}

/// Records 1.2 s of the sedan scenario; returns the run directory.
fn record_run(root: &Path) -> PathBuf {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../hil-sim/scenarios/sedan-pass.toml");
    let scenario = Scenario::load(&path).unwrap();
    let scene = Scene::from_vehicle(&scenario.vehicle);
    let sim = Vlp16Sim::new(
        &scene,
        &scenario.run,
        scenario.lidar_config(),
        scenario.lidar_seed(),
    );
    let params = StartMeasurement {
        vehicle_id: Text::truncated("export test"),
        speed_mps: 0.2,
        distance_m: 1.0,
        zone: Zone::Tyre,
        lab: protocol::radio::LabRef::NONE,
    };
    let config = include_str!("../../onboard/onboard.example.toml");
    let mut rec = RunRecorder::begin(root, 1, &params, BASE_US, config).unwrap();
    let src = "192.168.1.201:2368".parse().unwrap();
    let data = "192.168.1.100:2368".parse().unwrap();
    let position = "192.168.1.100:8308".parse().unwrap();
    let to_us = |s: f64| BASE_US + (s * 1e6) as u64;
    let duration_s = 1.2;
    for d in sim.datagrams(duration_s) {
        match d {
            Datagram::Data { send_s, payload } => {
                rec.lidar_packet(to_us(send_s) * 1000, src, data, &payload[..]);
            }
            Datagram::Position { send_s, payload } => {
                rec.lidar_packet(to_us(send_s) * 1000, src, position, &payload[..]);
            }
        }
    }
    for i in 0..=120u32 {
        let t = f64::from(i) * 0.01;
        rec.odometry(
            to_us(t),
            &Odometry {
                stamp_us: (t * 1e6) as u64,
                x_m: scenario.run.wheel_distance_at(t) as f32,
                y_m: 0.0,
                yaw_rad: 0.0,
                vx_mps: 0.2,
                vy_mps: 0.0,
                wz_radps: 0.0,
                wheel_speed_radps: [1.0; 4],
            },
        );
    }
    let k = Intrinsics {
        fx: 105.0,
        fy: 105.0,
        cx: 53.0,
        cy: 30.0,
        depth_scale_m: 0.001,
    };
    for i in 0..DEPTH_FRAMES {
        let depth: Vec<u16> = (0..106u16 * 60).map(|p| 400 + p % 97 + i as u16).collect();
        rec.depth_frame(to_us(0.25 * i as f64), 106, 60, &depth, &k);
    }
    let cloud = Cloud {
        points_m: (0..1000)
            .map(|i| [f64::from(i) * 0.004, 0.1, 0.3])
            .collect(),
    };
    let mut ply = Vec::new();
    write_ply(
        BufWriter::new(&mut ply),
        &cloud,
        PlyEncoding::BinaryLittleEndian,
    )
    .unwrap();
    rec.save_file("cloud.ply", &ply);
    rec.save_result(&result_record());
    let dir = rec.dir().to_owned();
    assert!(rec.finish(RecordedOutcome::Completed).is_empty());
    dir
}

const TOPICS: [(&str, &str); 7] = [
    ("/lidar/points", "foxglove.PointCloud"),
    ("/cloud", "foxglove.PointCloud"),
    ("/tf", "foxglove.FrameTransform"),
    ("/camera/depth", "foxglove.RawImage"),
    ("/camera/depth_info", "passangle.DepthInfo"),
    ("/odometry", "passangle.WheelOdometry"),
    ("/result", "passangle.Result"),
];

fn decode_base64(s: &str) -> Vec<u8> {
    let val = |c: u8| match c {
        b'A'..=b'Z' => c - b'A',
        b'a'..=b'z' => c - b'a' + 26,
        b'0'..=b'9' => c - b'0' + 52,
        b'+' => 62,
        b'/' => 63,
        _ => panic!("not base64: {c}"),
    };
    let mut out = Vec::new();
    for q in s.as_bytes().chunks(4) {
        let n = q
            .iter()
            .take_while(|&&c| c != b'=')
            .fold(0u32, |acc, &c| (acc << 6) | u32::from(val(c)));
        let k = q.iter().filter(|&&c| c != b'=').count();
        let n = n << (6 * (4 - k));
        out.extend_from_slice(&n.to_be_bytes()[1..k]);
    }
    out
}

#[test]
fn export_writes_every_channel_and_reads_back() {
    let root = temp_root("export");
    let dir = record_run(&root);
    let out = root.join("run.mcap");
    let status = Command::new(env!("CARGO_BIN_EXE_passangle"))
        .args(["export", "--rebuild"])
        .arg(&dir)
        .arg("--mcap")
        .arg(&out)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&status.stdout);
    assert!(
        status.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&status.stderr)
    );
    println!("{stdout}");

    // Read back with the mcap crate.
    let bytes = std::fs::read(&out).unwrap();
    let mut counts: BTreeMap<String, u64> = BTreeMap::new();
    let mut schemas: BTreeMap<String, String> = BTreeMap::new();
    let mut children = BTreeMap::<String, u64>::new();
    let mut lidar_points = 0usize;
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let topic = m.channel.topic.clone();
        assert_eq!(m.channel.message_encoding, "json");
        let schema = m.channel.schema.as_ref().unwrap();
        assert_eq!(schema.encoding, "jsonschema");
        let _: Value = serde_json::from_slice(&schema.data).unwrap();
        schemas.insert(topic.clone(), schema.name.clone());
        *counts.entry(topic.clone()).or_default() += 1;
        let v: Value = serde_json::from_slice(&m.data).unwrap();
        match topic.as_str() {
            "/lidar/points" | "/cloud" => {
                let data = decode_base64(v["data"].as_str().unwrap());
                let stride = v["point_stride"].as_u64().unwrap() as usize;
                assert_eq!(data.len() % stride, 0);
                if topic == "/lidar/points" {
                    assert_eq!(stride, 16);
                    lidar_points += data.len() / stride;
                } else {
                    assert_eq!(data.len() / stride, 1000, "the cloud.ply points");
                    let x = f32::from_le_bytes(data[12..16].try_into().unwrap());
                    assert!((x - 0.004).abs() < 1e-7, "second point x {x}");
                }
            }
            "/camera/depth" => {
                assert_eq!(v["encoding"], "16UC1");
                let data = decode_base64(v["data"].as_str().unwrap());
                assert_eq!(data.len(), 2 * 106 * 60);
                let first = u16::from_le_bytes([data[0], data[1]]);
                assert!((400..=403).contains(&first), "{first}");
            }
            "/tf" => {
                *children
                    .entry(v["child_frame_id"].as_str().unwrap().to_owned())
                    .or_default() += 1;
                let q = &v["rotation"];
                let n: f64 = ["x", "y", "z", "w"]
                    .iter()
                    .map(|k| q[k].as_f64().unwrap().powi(2))
                    .sum();
                assert!((n - 1.0).abs() < 1e-9, "{v}");
            }
            _ => {}
        }
        assert!(m.log_time >= BASE_US * 1000, "{topic} at {}", m.log_time);
    }
    for (topic, schema) in TOPICS {
        assert!(
            counts.get(topic).copied().unwrap_or(0) > 0,
            "{topic}: {counts:?}"
        );
        assert_eq!(schemas[topic], schema);
    }
    assert!(counts["/lidar/points"] >= 8, "{counts:?}");
    assert!(lidar_points > 10_000, "{lidar_points} lidar points");
    assert_eq!(counts["/camera/depth"], DEPTH_FRAMES);
    assert_eq!(counts["/odometry"], 121);
    assert_eq!(children["base_link"], 121);
    for static_child in ["run", "lidar", "camera"] {
        assert_eq!(children[static_child], 1, "{children:?}");
    }
    // --rebuild: the pipeline's fused trajectory, one pose per processed lidar frame.
    let fused = children["base_link_fused"];
    assert!(
        (8..=counts["/lidar/points"]).contains(&fused),
        "{children:?}"
    );
    assert!(
        !stdout.contains("the sensor mounts on /tf are the defaults"),
        "{stdout}"
    );
    println!("mcap crate read back: {counts:?}");

    check_with_pypi_mcap(&out, &counts, &schemas);
    let _ = std::fs::remove_dir_all(&root);
}

/// Reads the file with the PyPI `mcap` reader (`tests/mcap_read.py`): the same messages per
/// topic, schemas and encodings, with `$PASSANGLE_PYTHON` (`scripts/test.sh` points it at a venv
/// with `mcap`) or `python3`. Says so loudly when that Python lacks `mcap`.
fn check_with_pypi_mcap(
    out: &Path,
    counts: &BTreeMap<String, u64>,
    schemas: &BTreeMap<String, String>,
) {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/mcap_read.py");
    let python = std::env::var("PASSANGLE_PYTHON").unwrap_or_else(|_| "python3".to_owned());
    let probe = Command::new(&python).args(["-c", "import mcap"]).output();
    if probe.is_ok_and(|o| o.status.success()) {
        let py = Command::new(&python)
            .arg(&script)
            .arg(out)
            .output()
            .unwrap();
        assert!(
            py.status.success(),
            "{}",
            String::from_utf8_lossy(&py.stderr)
        );
        let v: Value = serde_json::from_slice(&py.stdout).unwrap();
        println!("PyPI mcap read back: {v}");
        for (topic, n) in counts {
            assert_eq!(v["counts"][topic].as_u64(), Some(*n), "{topic}: {v}");
            assert_eq!(v["schemas"][topic], schemas[topic].as_str());
            assert_eq!(
                v["encodings"][topic],
                serde_json::json!(["json", "jsonschema"])
            );
        }
        assert_eq!(v["counts"].as_object().unwrap().len(), counts.len(), "{v}");
        assert_eq!(
            v["statistics_messages"].as_u64(),
            Some(counts.values().sum::<u64>())
        );
    } else {
        eprintln!(
            "NOTE: NOT CHECKED with the PyPI `mcap` reader: python3 with the `mcap` package is \
             not installed here (`pip install mcap`); only the mcap crate's read-back ran"
        );
    }
}
