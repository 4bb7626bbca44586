//! `passangle angles` on one demo-like cloud written as PLY, E57 (one scan, and two scans with
//! their own poses), LAS and LAZ (and a LAZ in projected-grid coordinates): the same angles to
//! 0.001 degrees, through the library and through the command line.
#![allow(clippy::unwrap_used, missing_docs)]

mod common;

#[path = "../../onboard/tests/synth/mod.rs"]
mod synth;

use common::temp_root;

use std::fs::File;
use std::io::{BufWriter, Cursor};
use std::path::Path;
use std::process::Command;

use angles::{AnglesConfig, AnglesResult, V3, compute_angles};
use cloud_io::{Cloud, PlyEncoding, read_cloud, write_e57, write_las, write_ply};
use e57::{E57Writer, Quaternion, Record, RecordValue, Transform, Translation};

/// The LAS/LAZ resolution (scale): 1 micrometre. LAS stores integers, so a LAS copy is a
/// perturbed copy, and the calculator's witness selection among near-tied points is not
/// continuous in the coordinates: on this cloud, rounding to 1 mm moved the angles by up to
/// 0.0019 deg and rounding to 10 micrometres moved the departure angle by 0.0071 deg (another
/// witness won), while 1 micrometre moved them by at most 1.1e-5 deg.
const LAS_RESOLUTION_M: f64 = 1e-6;
const TOLERANCE_DEG: f64 = 0.001;

/// A cloud file's points as the calculator's vectors.
fn vectors(points: &[[f64; 3]]) -> Vec<V3> {
    points.iter().map(|&p| p.into()).collect()
}

/// A sedan scanned at 1 cm with 3 mm range noise, tilted, yawed and shifted as a real cloud is.
fn demo_like_cloud() -> Cloud {
    let v = synth::sedan();
    let scan = synth::Scan {
        noise_m: 0.003,
        outliers: 20,
        ..synth::Scan::noiseless(0.01)
    };
    let pose = synth::Pose {
        yaw_rad: 8f64.to_radians(),
        tilt_rad: 2f64.to_radians(),
        tilt_axis_rad: 0.5,
        shift_m: [12.0, -3.5, 1.3],
    };
    Cloud {
        points_m: synth::sample(&v, scan)
            .into_iter()
            .map(|p| pose.apply(p))
            .collect(),
    }
}

/// The cloud as two E57 scans: the points with an even index in a scan frame turned 30 degrees
/// about z and moved, with that scan's pose bringing them back; the others without a pose.
fn write_two_scans(path: &Path, cloud: &Cloud) {
    let (angle, t) = (30f64.to_radians(), [2.0, -1.0, 0.25]);
    let (s, c) = angle.sin_cos();
    let mut w = E57Writer::from_file(path, "two-scans").unwrap();
    let proto = || {
        vec![
            Record::CARTESIAN_X_F64,
            Record::CARTESIAN_Y_F64,
            Record::CARTESIAN_Z_F64,
        ]
    };
    let values = |p: [f64; 3]| p.iter().map(|&v| RecordValue::Double(v)).collect();
    let mut posed = w.add_pointcloud("posed", proto()).unwrap();
    posed.set_transform(Some(Transform {
        rotation: Quaternion {
            w: (angle / 2.0).cos(),
            x: 0.0,
            y: 0.0,
            z: (angle / 2.0).sin(),
        },
        translation: Translation {
            x: t[0],
            y: t[1],
            z: t[2],
        },
    }));
    for p in cloud.points_m.iter().step_by(2) {
        // scan_from_file = inverse pose: R^T (p - t).
        let d = [p[0] - t[0], p[1] - t[1], p[2] - t[2]];
        posed
            .add_point(values([c * d[0] + s * d[1], -s * d[0] + c * d[1], d[2]]))
            .unwrap();
    }
    posed.finalize().unwrap();
    let mut plain = w.add_pointcloud("plain", proto()).unwrap();
    for p in cloud.points_m.iter().skip(1).step_by(2) {
        plain.add_point(values(*p)).unwrap();
    }
    plain.finalize().unwrap();
    w.finalize().unwrap();
}

fn angles_deg(r: &AnglesResult) -> [f64; 3] {
    [&r.approach, &r.departure, &r.breakover].map(|f| {
        f.as_ref()
            .map(|f| f.angle_rad.to_degrees())
            .expect("every angle is measured on the demo-like cloud")
    })
}

#[test]
fn ply_e57_las_and_laz_copies_give_the_same_angles() {
    let dir = temp_root("formats");
    let cloud = demo_like_cloud();
    let ply = dir.join("cloud.ply");
    write_ply(
        BufWriter::new(File::create(&ply).unwrap()),
        &cloud,
        PlyEncoding::BinaryLittleEndian,
    )
    .unwrap();
    let e57 = dir.join("cloud.e57");
    let mut bytes = Vec::new();
    write_e57(Cursor::new(&mut bytes), &cloud, "demo-like").unwrap();
    std::fs::write(&e57, bytes).unwrap();
    let e57_two = dir.join("cloud-two-scans.e57");
    write_two_scans(&e57_two, &cloud);
    let las = dir.join("cloud.las");
    let laz = dir.join("cloud.laz");
    for (path, compressed) in [(&las, false), (&laz, true)] {
        let out = write_las(
            Cursor::new(Vec::new()),
            &cloud,
            LAS_RESOLUTION_M,
            compressed,
        )
        .unwrap();
        std::fs::write(path, out.into_inner()).unwrap();
    }
    // The same cloud in projected-grid coordinates (500 km east, 5,000 km north, 100 m up), as a
    // surveyor's LAS holds it: offsets large against the vehicle.
    let utm = dir.join("cloud-utm.laz");
    let shifted = Cloud {
        points_m: cloud
            .points_m
            .iter()
            .map(|p| [p[0] + 500_000.0, p[1] + 5_000_000.0, p[2] + 100.0])
            .collect(),
    };
    let out = write_las(Cursor::new(Vec::new()), &shifted, LAS_RESOLUTION_M, true).unwrap();
    std::fs::write(&utm, out.into_inner()).unwrap();

    // The library: read_cloud + compute_angles, at full precision.
    let config = AnglesConfig::default();
    let reference = {
        let (c, _) = read_cloud(&ply).unwrap();
        angles_deg(&compute_angles(&vectors(&c.points_m), &config).unwrap())
    };
    println!(
        "{} points; PLY angles approach {:.6}, departure {:.6}, breakover {:.6} deg",
        cloud.points_m.len(),
        reference[0],
        reference[1],
        reference[2]
    );
    for path in [&e57, &e57_two, &las, &laz, &utm] {
        let (c, stats) = read_cloud(path).unwrap();
        assert_eq!(c.points_m.len(), cloud.points_m.len(), "{}", path.display());
        let got = angles_deg(&compute_angles(&vectors(&c.points_m), &config).unwrap());
        let diff: Vec<f64> = got.iter().zip(reference).map(|(g, r)| g - r).collect();
        println!(
            "{:>20} ({} {}): difference from PLY approach {:+.2e}, departure {:+.2e}, breakover \
             {:+.2e} deg",
            path.file_name().unwrap().to_string_lossy(),
            stats.format,
            stats.encoding,
            diff[0],
            diff[1],
            diff[2]
        );
        assert!(
            diff.iter().all(|d| d.abs() <= TOLERANCE_DEG),
            "{}: {got:?} vs PLY {reference:?}",
            path.display()
        );
    }

    // The command line: `passangle angles --json` on each file, exit 0, same angles.
    let cli = |path: &Path| -> [f64; 3] {
        let out = Command::new(env!("CARGO_BIN_EXE_passangle"))
            .args(["angles", "--json"])
            .arg(path)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}: {}",
            path.display(),
            String::from_utf8_lossy(&out.stderr)
        );
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        ["approach_deg", "departure_deg", "breakover_deg"]
            .map(|k| v[k].as_f64().unwrap_or_else(|| panic!("{k} in {v}")))
    };
    let from_ply = cli(&ply);
    for path in [&e57, &e57_two, &las, &laz, &utm] {
        let got = cli(path);
        for (g, r) in got.iter().zip(from_ply) {
            assert!(
                (g - r).abs() <= TOLERANCE_DEG,
                "{}: {got:?} vs {from_ply:?}",
                path.display()
            );
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}
