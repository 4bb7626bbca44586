//! `passangle angles` end to end: a crude box vehicle written as PLY, the binary run on it, the JSON
//! checked for the fields the issue asks for and for the approach angle of its bumper corner.
//! (The calculator's accuracy is tested in `onboard/tests/angles_synthetic.rs` against brute force.)

#![allow(clippy::unwrap_used)]

use std::io::BufWriter;
use std::path::PathBuf;
use std::process::Command;

use cloud_io::{Cloud, PlyEncoding, write_ply};

mod common;

/// A fresh directory for test `name` holding the box vehicle as `box.ply`: (directory, PLY).
fn box_ply(name: &str) -> (PathBuf, PathBuf) {
    let dir = common::temp_root(name);
    let ply = dir.join("box.ply");
    let cloud = Cloud {
        points_m: box_vehicle(),
    };
    write_ply(
        BufWriter::new(std::fs::File::create(&ply).unwrap()),
        &cloud,
        PlyEncoding::BinaryLittleEndian,
    )
    .unwrap();
    (dir, ply)
}

/// Ground, a flat floor at 0.2 m ending in a vertical bumper face at x = +-2 m, four rigid tyres
/// (radius 0.3 m, centres at x = +-1.3 m, |y| = 0.75 m, width 0.2 m). 1 cm spacing.
fn box_vehicle() -> Vec<[f64; 3]> {
    let s = 0.01;
    let mut pts = Vec::new();
    let range = |a: f64, b: f64| {
        let n = ((b - a) / s).round() as i32;
        (0..=n).map(move |i| a + f64::from(i) * s)
    };
    for x in range(-2.0, 2.0) {
        for y in range(-0.6, 0.6) {
            pts.push([x, y, 0.2]);
        }
    }
    for x in [-2.0, 2.0] {
        for y in range(-0.6, 0.6) {
            for z in range(0.2, 0.5) {
                pts.push([x, y, z]);
            }
        }
    }
    for xc in [-1.3, 1.3] {
        for side in [-1.0, 1.0] {
            for k in 0..189 {
                let t = f64::from(k) / 189.0 * std::f64::consts::TAU;
                for y in range(0.65, 0.85) {
                    pts.push([xc + 0.3 * t.cos(), side * y, 0.3 + 0.3 * t.sin()]);
                }
                for rho in range(0.15, 0.3) {
                    pts.push([xc + rho * t.cos(), side * 0.65, 0.3 + rho * t.sin()]);
                }
            }
        }
    }
    for x in range(-3.0, 3.0).step_by(2) {
        for y in range(-1.3, 1.3).step_by(2) {
            pts.push([x, y, 0.0]);
        }
    }
    pts
}

#[test]
fn angles_json_has_the_fields_and_the_right_approach() {
    let (dir, ply) = box_ply("angles-cli");
    let svg = dir.join("side.svg");
    let out = Command::new(env!("CARGO_BIN_EXE_passangle"))
        .args(["angles", "--json", "--report"])
        .arg(&svg)
        .arg(&ply)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for key in [
        "approach_deg",
        "departure_deg",
        "breakover_deg",
        "ground_clearance_m",
        "wheelbase_m",
        "track_m",
        "tyres",
        "witness",
        "points",
        "warnings",
    ] {
        assert!(v.get(key).is_some(), "missing {key} in {v}");
    }
    for key in ["used", "ground", "tyre", "body", "dropped"] {
        assert!(v["points"].get(key).is_some(), "missing points.{key}");
    }
    assert_eq!(v["tyres"].as_array().unwrap().len(), 4);
    // Closed form for the bumper corner (d = 0.7 m, z = 0.2 m, r = 0.3 m): 16.974 degrees.
    let expect = (0.3f64 / 0.7f64.hypot(0.1)).asin() - 0.1f64.atan2(0.7);
    for key in ["approach_deg", "departure_deg"] {
        let got = v[key].as_f64().unwrap();
        assert!(
            (got - expect.to_degrees()).abs() < 0.05,
            "{key} {got} vs {}",
            expect.to_degrees()
        );
    }
    assert!((v["wheelbase_m"].as_f64().unwrap() - 2.6).abs() < 0.005);
    assert!((v["ground_clearance_m"].as_f64().unwrap() - 0.2).abs() < 0.005);
    let w = &v["witness"]["approach"]["in_vehicle_m"];
    assert!((w[0].as_f64().unwrap() - 2.0).abs() < 0.01, "{w}");
    let svg_text = std::fs::read_to_string(&svg).unwrap();
    assert!(svg_text.starts_with("<svg") && svg_text.contains("approach"));
    // Every standard's profile (default `--standard all`), each with its citation and notes.
    let profiles = v["profiles"].as_array().unwrap();
    let ids: Vec<&str> = profiles
        .iter()
        .map(|p| p["standard"].as_str().unwrap())
        .collect();
    assert_eq!(ids, ["cfr", "eu", "iso612", "gbt", "arai", "adr"]);
    for p in profiles {
        assert!(p["citation"].as_str().unwrap().len() > 10);
        assert!(!p["notes"].as_array().unwrap().is_empty());
        assert!(p.get("decisions").is_none(), "no decisions unless asked");
        let approach = &p["quantities"][0];
        assert_eq!(approach["id"], "approach");
        assert_eq!(approach["unit"], "deg");
        let got = approach["value"].as_f64().unwrap();
        assert!((got - expect.to_degrees()).abs() < 0.05, "{p}");
        assert!(approach["u"].as_f64().unwrap() > 0.0);
    }
    // The central 80 % of the inner track sees the floor.
    let central = &profiles[2]["quantities"][3];
    assert_eq!(central["id"], "central_clearance");
    assert!(
        (central["value"].as_f64().unwrap() - 0.2).abs() < 0.005,
        "{central}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn decisions_follow_the_guarded_rule_and_the_count() {
    let (dir, ply) = box_ply("angles-decide");
    let run = |json: bool| {
        let mut c = Command::new(env!("CARGO_BIN_EXE_passangle"));
        c.args(["angles", "--standard", "cfr,eu", "--decide"])
            .arg(&ply);
        if json {
            c.arg("--json");
        }
        let out = c.output().unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        out.stdout
    };
    let v: serde_json::Value = serde_json::from_slice(&run(true)).unwrap();
    let profiles = v["profiles"].as_array().unwrap();
    assert_eq!(profiles.len(), 2);
    // CFR 523.5: approach and departure (17 deg) fail, breakover (17.8 deg) and the axle
    // clearances (0.2 m against 0.18) pass, the running clearance sits on its 0.20 m limit: within
    // U of it, inconclusive. Two passes and one open criterion cannot reach four: not met.
    let cfr = &profiles[0]["decisions"][0];
    assert_eq!(cfr["thresholds"], "cfr523.5");
    let decisions: Vec<&str> = cfr["criteria"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["decision"].as_str().unwrap())
        .collect();
    assert_eq!(decisions, ["fail", "pass", "fail", "inconclusive", "pass"]);
    assert_eq!(cfr["verdict"], "not met");
    assert!(cfr["rule"].as_str().unwrap().contains("value - U >= limit"));
    let eu = &profiles[1]["decisions"][0];
    assert_eq!(eu["thresholds"], "eu-offroad");
    assert_eq!(eu["verdict"], "not met");
    let table = String::from_utf8(run(false)).unwrap();
    assert!(table.contains("standards, side by side"), "{table}");
    assert!(
        table.contains("CFR/SAE") && table.contains("EU 2018/858"),
        "{table}"
    );
    assert!(
        table.contains("NOT MET") && table.contains("inconclusive"),
        "{table}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn bad_input_is_a_clear_error() {
    let dir = std::env::temp_dir().join(format!("passangle-angles-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let ply = dir.join("bad.ply");
    std::fs::write(
        &ply,
        "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nend_header\n1\n2\n",
    )
    .unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_passangle"))
        .arg("angles")
        .arg(&ply)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("bad.ply") && err.contains("no scalar property `y`"),
        "{err}"
    );
    let out = Command::new(env!("CARGO_BIN_EXE_passangle"))
        .args(["angles", "--exclude", "1,2,3"])
        .arg(&ply)
        .output()
        .unwrap();
    assert!(String::from_utf8_lossy(&out.stderr).contains("six numbers"));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn an_undetermined_angle_prints_the_table_and_fails() {
    let (dir, ply) = box_ply("angles-partial");
    // Excluding the body ahead of the front tyres (bumper face and floor) leaves the approach
    // zone empty; departure and breakover are still measured.
    let out = Command::new(env!("CARGO_BIN_EXE_passangle"))
        .args(["angles", "--exclude", "1.6,2.1,-0.7,0.7,0.1,0.6"])
        .args(["--exclude", "0.9,1.7,-0.62,0.62,0.1,0.6"])
        .arg(&ply)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stdout}");
    assert!(
        stdout.contains("approach   not measured: no body points ahead of the front tyres")
            && stdout.contains("departure     16.97"),
        "{stdout}"
    );
    assert!(
        stderr.contains("box.ply: not measured: approach (no body points ahead of the front tyres"),
        "{stderr}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// `--scan`: a run's `scan.toml` gives the calculator the robot's path. A path under the whole
/// box gives its angles; one that stops short of the rear axle is refused with the coverage
/// reason; a broken file is refused, naming it. Both refusals exit non-zero.
#[test]
fn a_scan_file_gives_the_path_and_a_broken_one_is_named() {
    let (dir, ply) = box_ply("angles-cli-scan");
    let scan = dir.join("scan.toml");
    let run = |scan_text: &str| {
        std::fs::write(&scan, scan_text).unwrap();
        Command::new(env!("CARGO_BIN_EXE_passangle"))
            .args(["angles", "--json", "--standard", "none", "--scan"])
            .arg(&scan)
            .arg(&ply)
            .output()
            .unwrap()
    };
    let path_to = |x_end: f64| onboard::scan_file::ScanRecord {
        trajectory_x_sigma_per_m: 0.005,
        path_m: (0..=60)
            .map(|i| [2.8 + (x_end - 2.8) * f64::from(i) / 60.0, 0.0, 0.12])
            .collect(),
    };
    let out = run(&path_to(-2.8).to_toml());
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(v["approach_deg"].as_f64().is_some() && v["departure_deg"].as_f64().is_some());
    let out = run(&path_to(-0.2).to_toml());
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("was not covered"), "{err}");
    let out = run("trajectory_x_sigma_per_m = 0.005\npath_m = [[1.0, 0.0]]\n");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--scan") && err.contains("scan.toml"), "{err}");
}
