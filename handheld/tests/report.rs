//! `passangle report` on a signed run with a real cloud (a synthetic sedan scanned as the robot
//! scans it, front toward the cloud's -x as the service writes it): every section filled, the
//! not-measured departure shown with its reason, the hashes and signature statuses listed, tags
//! balanced; then a screenshot in headless Chromium (required unless PASSANGLE_SKIP_BROWSER=1).
#![allow(clippy::unwrap_used, missing_docs)]

mod common;

#[path = "common/browser.rs"]
mod browser;

#[path = "../../onboard/tests/synth/mod.rs"]
mod synth;

use common::{passangle, temp_root};
use std::path::{Path, PathBuf};

use angles::{AnglesConfig, V3, compute_angles};
use cloud_io::{Cloud, PlyEncoding, write_ply};
use onboard::signing::{DeviceKey, SEED_LEN};
use protocol::bounded::Text;
use protocol::radio::{Absence, MeasurementResult, ResultWarnings};

/// A sedan scanned at 1 cm with 3 mm noise, turned so its front faces the cloud's -x (the robot
/// entered under the front bumper: `processing.enter-at-front = true`, as in the example config).
fn cloud() -> Cloud {
    let v = synth::sedan();
    let scan = synth::Scan {
        noise_m: 0.003,
        outliers: 10,
        ..synth::Scan::noiseless(0.01)
    };
    let pose = synth::Pose {
        yaw_rad: 183f64.to_radians(),
        tilt_rad: 0.5f64.to_radians(),
        tilt_axis_rad: 0.3,
        shift_m: [4.0, 0.2, 0.3],
    };
    Cloud {
        points_m: synth::sample(&v, scan)
            .into_iter()
            .map(|p| pose.apply(p))
            .collect(),
    }
}

/// A signed run whose result is the calculator's on the cloud, except the departure, recorded as
/// not covered by the scan.
fn signed_run(root: &Path, key: DeviceKey) -> PathBuf {
    let cloud = cloud();
    let config = AnglesConfig {
        front_is_positive_x: false,
        ..AnglesConfig::default()
    };
    let points: Vec<V3> = cloud.points_m.iter().map(|&p| p.into()).collect();
    let a = compute_angles(&points, &config).unwrap();
    let (ap, br, gc) = (
        a.approach.as_ref().unwrap(),
        a.breakover.as_ref().unwrap(),
        a.ground_clearance.as_ref().unwrap(),
    );
    let mut absent = [Absence::Measured; 4];
    absent[1] = Absence::NotCovered;
    let wire = MeasurementResult {
        run_id: 1,
        vehicle_id: Text::truncated("AB-123"),
        approach_rad: ap.angle_rad as f32,
        departure_rad: f32::NAN,
        breakover_rad: br.angle_rad as f32,
        ground_clearance_m: gc.height_m as f32,
        approach_u_rad: ap.uncertainty.expanded as f32,
        departure_u_rad: f32::NAN,
        breakover_u_rad: br.uncertainty.expanded as f32,
        ground_clearance_u_m: gc.uncertainty.expanded as f32,
        absent,
        wheelbase_m: a.wheelbase_m as f32,
        track_m: a.track_m.unwrap() as f32,
        approach_support: 100,
        departure_support: 0,
        breakover_support: 50,
        tyre_fit_rms_m: 0.002,
        warnings: ResultWarnings::EMPTY,
        cloud_points: cloud.points_m.len() as u32,
        preview_chunks: 0,
        records: protocol::bounded::List::default(),
    };
    let mut ply = Vec::new();
    write_ply(&mut ply, &cloud, PlyEncoding::BinaryLittleEndian).unwrap();
    common::signed_run(root, key, &wire, &ply, angles::side_view_svg(&a).as_bytes())
}

/// Every element closed in order (HTML void elements and `/>` aside).
fn assert_balanced(html: &str) {
    const VOID: [&str; 6] = ["meta", "br", "hr", "img", "link", "input"];
    let mut stack: Vec<String> = Vec::new();
    let mut rest = html;
    while let Some(at) = rest.find('<') {
        let end = rest[at..].find('>').expect("an unclosed <") + at;
        let tag = &rest[at + 1..end];
        rest = &rest[end + 1..];
        if tag.starts_with('!') {
            continue;
        }
        let self_closing = tag.ends_with('/');
        let name: String = tag
            .trim_start_matches('/')
            .chars()
            .take_while(char::is_ascii_alphanumeric)
            .collect();
        assert!(!name.is_empty(), "an empty tag <{tag}>");
        if tag.starts_with('/') {
            let open = stack.pop().unwrap_or_default();
            assert_eq!(open, name, "</{name}> closes <{open}>");
        } else if !self_closing && !VOID.contains(&name.as_str()) {
            stack.push(name);
        }
    }
    assert!(stack.is_empty(), "left open: {stack:?}");
}

#[test]
fn report_fills_every_section_and_renders_in_chromium() {
    let root = temp_root("report");
    let key = DeviceKey::from_seed(&[0x11; SEED_LEN]);
    let public = key.public();
    let dir = signed_run(&root, key);
    let lab = root.join("lab.toml");
    std::fs::copy(
        concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../docs/operator/lab.example.toml"
        ),
        &lab,
    )
    .unwrap();
    let html_path = root.join("report.html");
    let (code, text) = passangle(
        &[
            "report",
            dir.to_str().unwrap(),
            "--lab",
            lab.to_str().unwrap(),
            "--out",
            html_path.to_str().unwrap(),
            "--public-key",
            &public.to_hex(),
        ],
        None,
    );
    assert_eq!(code, 0, "{text}");
    let html = std::fs::read_to_string(&html_path).unwrap();
    assert_balanced(&html);
    assert!(
        !html.contains("{}") && !html.contains("NaN"),
        "a placeholder left"
    );
    for needle in [
        "Report id",
        "Date of measurement</th><td>2026-09-21 14:13:20 UTC",
        // The lab file's fields.
        "Test Lab GmbH",
        "WVWZZZ1KZAW000001",
        "unladen",
        "2.3 bar",
        "Customer",
        // Method, profile and standard.
        "49 CFR 523.2",
        "No pass/fail limits were given",
        // Results with U; the departure's reason instead of a number.
        "U (k = 2)",
        "Approach angle</th><td class=\"num\">",
        "not measured: the scan did not cover",
        // The recomputation against result.json: the departure differs.
        "departure: recorded not measured, recomputed",
        // Side view, each witness with its close-up, tyres, floor.
        "passangle side view",
        "Approach witness:",
        "Departure witness:",
        "Ramp breakover witness:",
        "Ground clearance witness:",
        "FL</th>",
        "RR</th>",
        "Floor flatness",
        // Provenance.
        &format!("device key <span class=\"hash\">{}", public.id()),
        env!("CARGO_PKG_VERSION"),
        "SHA-256 of config.toml: <span class=\"hash\">",
        "every signed file verifies",
        &format!("verified: {}", public.id()),
        "lidar.pcap",
        "odometry.csv",
    ] {
        assert!(html.contains(needle), "no {needle:?} in the report");
    }
    assert!(!html.contains("not given"), "every lab field was given");
    // The standards side by side (recomputed from cloud.ply: this result.json has no profiles).
    for needle in [
        "<h2>Standards</h2>",
        "CFR/SAE",
        "ISO 612",
        "recomputed from cloud.ply",
    ] {
        assert!(html.contains(needle), "no {needle:?} in the report");
    }
    assert!(
        !html.contains("<h3>Decisions</h3>"),
        "no decisions unless asked"
    );
    decisions_when_asked(&dir, &lab, &root);
    let id = text
        .split("(report ")
        .nth(1)
        .unwrap()
        .trim()
        .trim_end_matches(')');
    assert_eq!(id.len(), 16, "{text}");
    assert!(html.contains(id));
    // SHA-256 of every file, as hex in the table.
    let cloud_hash = {
        use sha2::Digest;
        signing::to_hex(&sha2::Sha256::digest(
            std::fs::read(dir.join("cloud.ply")).unwrap(),
        ))
    };
    assert!(html.contains(&cloud_hash));

    without_key_or_lab(&dir, &lab, id);
    browser::screenshot(&html_path, &root);
    tampered(&dir, &public.to_hex());
    named_by_meta(&dir, &public.id());
    std::fs::remove_dir_all(&root).unwrap();
}

/// meta.json names the robot: the report names it without result.json's signature too.
fn named_by_meta(dir: &Path, key_id: &str) {
    let meta: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("meta.json")).unwrap()).unwrap();
    assert_eq!(meta["robot_id"], key_id, "{meta}");
    std::fs::remove_file(dir.join("result.json.sig")).unwrap();
    let (code, text) = passangle(&["report", dir.to_str().unwrap()], None);
    assert_eq!(code, 0, "{text}");
    let html = std::fs::read_to_string(dir.join("report-handheld.html")).unwrap();
    assert!(
        html.contains(&format!("device key <span class=\"hash\">{key_id}")),
        "the robot is not named from meta.json"
    );
}

/// A lab file asking for decisions: the rule and both verdicts are stated.
fn decisions_when_asked(dir: &Path, lab: &Path, root: &Path) {
    let asking = root.join("lab-decide.toml");
    let text = std::fs::read_to_string(lab).unwrap();
    std::fs::write(
        &asking,
        format!("decide = [\"cfr523.5\", \"eu-offroad\"]\n{text}"),
    )
    .unwrap();
    let out = root.join("report-decide.html");
    let (code, text) = passangle(
        &[
            "report",
            dir.to_str().unwrap(),
            "--lab",
            asking.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ],
        None,
    );
    assert_eq!(code, 0, "{text}");
    let html = std::fs::read_to_string(&out).unwrap();
    assert_balanced(&html);
    for needle in [
        "<h3>Decisions</h3>",
        "Decision rule: guarded acceptance",
        "value - U &gt;= limit",
        "49 CFR 523.5(b)(2)",
        "EU off-road vehicle",
    ] {
        assert!(html.contains(needle), "no {needle:?} in the report");
    }
    assert!(!html.contains("No pass/fail limits were given"));
}

/// No key, no lab file, the default output: said so, not failed; the same id. An unknown key in
/// the lab file is an error naming it.
fn without_key_or_lab(dir: &Path, lab: &Path, id: &str) {
    let (code, text) = passangle(&["report", dir.to_str().unwrap()], None);
    assert_eq!(code, 0, "{text}");
    let bare = std::fs::read_to_string(dir.join("report-handheld.html")).unwrap();
    assert_balanced(&bare);
    assert!(bare.contains("signatures not checked"));
    assert!(bare.contains("not given"));
    assert!(
        !bare.contains(">report-handheld.html<"),
        "the report does not list itself"
    );
    assert!(bare.contains(id), "same run, same id");

    // The run's own lab.toml (the one `measure --lab` sent) stands in for --lab.
    std::fs::write(dir.join("lab.toml"), "[lab]\nname = \"Hall B lab\"\n").unwrap();
    let (code, text) = passangle(&["report", dir.to_str().unwrap()], None);
    assert_eq!(code, 0, "{text}");
    let own = std::fs::read_to_string(dir.join("report-handheld.html")).unwrap();
    assert!(own.contains("Hall B lab") && own.contains("lab.toml of the run"));
    std::fs::remove_file(dir.join("lab.toml")).unwrap();

    // An unknown key in the lab file is an error naming it.
    std::fs::write(lab, "[vehicle]\ncolour = \"red\"\n").unwrap();
    let (code, text) = passangle(
        &[
            "report",
            dir.to_str().unwrap(),
            "--lab",
            lab.to_str().unwrap(),
        ],
        None,
    );
    assert_ne!(code, 0);
    assert!(text.contains("colour"), "{text}");
}

/// A changed digit of result.json: the report still renders and names the file as changed.
fn tampered(dir: &Path, key: &str) {
    let result = dir.join("result.json");
    let text = std::fs::read_to_string(&result).unwrap();
    let forged = text.replacen("\"run_id\": 1", "\"run_id\": 2", 1);
    assert_ne!(forged, text);
    std::fs::write(&result, forged).unwrap();
    let (code, text) = passangle(
        &["report", dir.to_str().unwrap(), "--public-key", key],
        None,
    );
    assert_eq!(code, 0, "{text}");
    let html = std::fs::read_to_string(dir.join("report-handheld.html")).unwrap();
    assert!(
        html.contains("1 file(s) FAILED"),
        "the summary names the failure"
    );
    assert!(
        html.contains("CHANGED after"),
        "result.json is named as changed"
    );
}
