//! E57 and LAS/LAZ: round trips through the crates' writers, scans with poses, spherical
//! coordinates, invalid flags, units, and refusals of malformed headers.

use std::io::Cursor;

use ::e57::{E57Writer, Quaternion, Record, RecordDataType, RecordName, RecordValue, Transform};

use super::*;

fn grid(n: usize) -> Vec<[f64; 3]> {
    (0..n)
        .map(|i| {
            let f = i as f64;
            [0.25 * f - 3.0, (f * 0.37).sin() * 0.8, 0.1 + 0.01 * f]
        })
        .collect()
}

fn close(a: [f64; 3], b: [f64; 3], tol: f64) -> bool {
    a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol)
}

#[test]
fn e57_round_trip_is_exact() {
    let cloud = Cloud {
        points_m: grid(500),
    };
    let mut bytes = Vec::new();
    write_e57(Cursor::new(&mut bytes), &cloud, "round-trip").unwrap();
    assert_eq!(detect_format(None, &bytes), Some(CloudFormat::E57));
    let (back, stats) = parse_cloud(&bytes, CloudFormat::E57).unwrap();
    assert_eq!(back, cloud);
    assert_eq!((stats.points_in_file, stats.dropped_invalid), (500, 0));
    assert_eq!(stats.encoding, "cartesian");
}

/// Two scans: a Cartesian one with invalid-state flags under a rotation of 90 degrees about z
/// and a translation, and a spherical one without a pose.
fn two_scans() -> Vec<u8> {
    let mut bytes = Vec::new();
    let mut w = E57Writer::new(Cursor::new(&mut bytes), "two-scans").unwrap();
    let proto = vec![
        Record::CARTESIAN_X_F64,
        Record::CARTESIAN_Y_F64,
        Record::CARTESIAN_Z_F64,
        Record::CARTESIAN_INVALID_STATE,
    ];
    let mut scan = w.add_pointcloud("scan-a", proto).unwrap();
    let half = std::f64::consts::FRAC_PI_4;
    scan.set_transform(Some(Transform {
        rotation: Quaternion {
            w: half.cos(),
            x: 0.0,
            y: 0.0,
            z: half.sin(),
        },
        translation: ::e57::Translation {
            x: 10.0,
            y: 0.0,
            z: 1.0,
        },
    }));
    for (p, state) in [
        ([1.0, 0.0, 0.0], 0),
        ([0.0, 2.0, 0.5], 0),
        ([9.0, 9.0, 9.0], 2),
    ] {
        let mut v: Vec<RecordValue> = p.iter().map(|&c| RecordValue::Double(c)).collect();
        v.push(RecordValue::Integer(state));
        scan.add_point(v).unwrap();
    }
    scan.finalize().unwrap();
    let proto = vec![
        Record {
            name: RecordName::SphericalRange,
            data_type: RecordDataType::F64,
        },
        Record {
            name: RecordName::SphericalAzimuth,
            data_type: RecordDataType::F64,
        },
        Record {
            name: RecordName::SphericalElevation,
            data_type: RecordDataType::F64,
        },
        Record {
            name: RecordName::SphericalInvalidState,
            data_type: RecordDataType::Integer { min: 0, max: 2 },
        },
    ];
    let mut scan = w.add_pointcloud("scan-b", proto).unwrap();
    // range 2 at azimuth 90 deg, elevation 30 deg; then a direction without range (state 1).
    for (r, az, el, state) in [
        (2.0, 90f64.to_radians(), 30f64.to_radians(), 0),
        (0.0, 0.0, 0.0, 1),
    ] {
        scan.add_point(vec![
            RecordValue::Double(r),
            RecordValue::Double(az),
            RecordValue::Double(el),
            RecordValue::Integer(state),
        ])
        .unwrap();
    }
    scan.finalize().unwrap();
    w.finalize().unwrap();
    drop(w);
    bytes
}

#[test]
fn e57_scans_are_posed_converted_and_invalid_points_dropped() {
    let bytes = two_scans();
    let (cloud, stats) = parse_cloud(&bytes, CloudFormat::E57).unwrap();
    let expected = [
        // Rotated 90 degrees about z: (x, y) -> (-y, x), then translated by (10, 0, 1).
        [10.0, 1.0, 1.0],
        [8.0, 0.0, 1.5],
        // Spherical: x = r cos(el) cos(az), y = r cos(el) sin(az), z = r sin(el).
        [0.0, 3f64.sqrt(), 1.0],
    ];
    assert_eq!(cloud.points_m.len(), 3, "{:?}", cloud.points_m);
    for (got, want) in cloud.points_m.iter().zip(expected) {
        assert!(close(*got, want, 1e-12), "{got:?} != {want:?}");
    }
    assert_eq!(stats.points_in_file, 5);
    assert_eq!(stats.dropped_invalid, 2);
    assert_eq!(stats.encoding, "spherical");
    assert!(
        stats.notes.iter().any(|n| n.contains("2 scans merged")),
        "{:?}",
        stats.notes
    );
}

#[test]
fn e57_refuses_bad_headers_poses_and_limits() {
    let bytes = two_scans();
    // The XML length field (bytes 32..40) beyond the file.
    let mut long_xml = bytes.clone();
    long_xml[32..40].copy_from_slice(&(1u64 << 40).to_le_bytes());
    let e = parse_cloud(&long_xml, CloudFormat::E57)
        .unwrap_err()
        .to_string();
    assert!(e.contains("XML section of 1099511627776 bytes"), "{e}");
    // Not E57 at all.
    let e = parse_cloud(b"ASTM-E5", CloudFormat::E57)
        .unwrap_err()
        .to_string();
    assert!(e.contains("not an E57 file"), "{e}");
    // A flipped byte in the first page: the page CRC catches it.
    let mut flipped = bytes.clone();
    flipped[60] ^= 0x40;
    assert!(parse_cloud(&flipped, CloudFormat::E57).is_err());
    // Five points declared, limit four.
    let limits = ParseLimits {
        max_points: 4,
        ..ParseLimits::default()
    };
    let e = parse_cloud_with(&bytes, CloudFormat::E57, &limits).unwrap_err();
    assert_eq!(
        e,
        ParseError::OverLimit {
            what: "points",
            declared: 5,
            limit: 4
        }
    );
}

#[test]
fn e57_refuses_constant_fields_and_non_rotations() {
    let one_bit = RecordDataType::ScaledInteger {
        min: 0,
        max: 1,
        scale: 0.001,
        offset: 0.0,
    };
    // The crate's writer cannot write zero-bit fields: write 0..=1 and declare 0..=0 in the XML.
    let mut bytes = Vec::new();
    {
        let mut w = E57Writer::new(Cursor::new(&mut bytes), "constant").unwrap();
        let proto = [
            RecordName::CartesianX,
            RecordName::CartesianY,
            RecordName::CartesianZ,
        ]
        .map(|name| Record {
            name,
            data_type: one_bit.clone(),
        })
        .to_vec();
        let mut scan = w.add_pointcloud("c", proto).unwrap();
        for _ in 0..3 {
            scan.add_point(vec![RecordValue::ScaledInteger(0); 3])
                .unwrap();
        }
        scan.finalize().unwrap();
        w.finalize_customized_xml(|xml| Ok(xml.replace("maximum=\"1\"", "maximum=\"0\"")))
            .unwrap();
    }
    let e = parse_cloud(&bytes, CloudFormat::E57)
        .unwrap_err()
        .to_string();
    assert!(e.contains("every field is a constant"), "{e}");

    let mut bytes = Vec::new();
    {
        let mut w = E57Writer::new(Cursor::new(&mut bytes), "scaled-pose").unwrap();
        let proto = vec![
            Record::CARTESIAN_X_F64,
            Record::CARTESIAN_Y_F64,
            Record::CARTESIAN_Z_F64,
        ];
        let mut scan = w.add_pointcloud("s", proto).unwrap();
        scan.set_transform(Some(Transform {
            rotation: Quaternion {
                w: 2.0,
                x: 0.0,
                y: 0.0,
                z: 0.0,
            },
            translation: ::e57::Translation::default(),
        }));
        scan.add_point(vec![RecordValue::Double(1.0); 3]).unwrap();
        scan.finalize().unwrap();
        w.finalize().unwrap();
    }
    let e = parse_cloud(&bytes, CloudFormat::E57)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("scan 1:") && e.contains("not a finite unit quaternion"),
        "{e}"
    );
}

fn las_bytes(points: &[[f64; 3]], resolution_m: f64, compressed: bool) -> Vec<u8> {
    let cloud = Cloud {
        points_m: points.to_vec(),
    };
    write_las(Cursor::new(Vec::new()), &cloud, resolution_m, compressed)
        .unwrap()
        .into_inner()
}

#[test]
fn las_and_laz_round_trip_within_the_scale() {
    let points = grid(3000);
    for compressed in [false, true] {
        let bytes = las_bytes(&points, 1e-4, compressed);
        assert_eq!(detect_format(None, &bytes), Some(CloudFormat::Las));
        let (back, stats) = parse_cloud(&bytes, CloudFormat::Las).unwrap();
        assert_eq!(back.points_m.len(), points.len());
        for (a, b) in back.points_m.iter().zip(&points) {
            assert!(close(*a, *b, 0.5e-4 + 1e-12), "{a:?} vs {b:?}");
        }
        assert_eq!(
            stats.encoding,
            if compressed { "LAZ" } else { "uncompressed" }
        );
        assert!(
            stats.notes.iter().any(|n| n.contains("taken as metres")),
            "{:?}",
            stats.notes
        );
    }
}

/// A LAS file whose header says US survey feet through GeoTIFF keys.
fn las_in_feet(points: &[[f64; 3]], model_type: u16) -> Vec<u8> {
    let mut builder = ::las::Builder::from((1, 2));
    builder.transforms = ::las::Vector {
        x: ::las::Transform {
            scale: 0.001,
            offset: 0.0,
        },
        y: ::las::Transform {
            scale: 0.001,
            offset: 0.0,
        },
        z: ::las::Transform {
            scale: 0.001,
            offset: 0.0,
        },
    };
    // GeoKeyDirectory: version 1.1.0, 2 keys: GTModelType = model_type, ProjLinearUnits = 9003.
    let keys: Vec<u8> = [1u16, 1, 0, 2, 1024, 0, 1, model_type, 3076, 0, 1, 9003]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    builder.vlrs.push(::las::Vlr {
        user_id: "LASF_Projection".to_owned(),
        record_id: 34735,
        description: String::new(),
        data: keys,
    });
    let mut w =
        ::las::Writer::new(Cursor::new(Vec::new()), builder.into_header().unwrap()).unwrap();
    for p in points {
        w.write_point(::las::Point {
            x: p[0],
            y: p[1],
            z: p[2],
            ..::las::Point::default()
        })
        .unwrap();
    }
    w.into_inner().unwrap().into_inner()
}

#[test]
fn las_in_us_survey_feet_is_converted_and_geographic_refused() {
    let feet = [[3937.0, 0.0, 39.37], [0.0, -1200.0, 0.0]];
    let (cloud, stats) = parse_cloud(&las_in_feet(&feet, 1), CloudFormat::Las).unwrap();
    let ft = 1200.0 / 3937.0;
    for (got, p) in cloud.points_m.iter().zip(feet) {
        let want = [p[0] * ft, p[1] * ft, p[2] * ft];
        assert!(close(*got, want, 1e-9), "{got:?} != {want:?}");
    }
    assert!(
        stats
            .notes
            .iter()
            .any(|n| n.contains("US survey foot") && n.contains("converted to metres")),
        "{:?}",
        stats.notes
    );
    let e = parse_cloud(&las_in_feet(&feet, 2), CloudFormat::Las)
        .unwrap_err()
        .to_string();
    assert!(e.contains("geographic"), "{e}");
}

#[test]
fn las_refuses_truncation_huge_counts_and_bad_scales() {
    let bytes = las_bytes(&grid(100), 1e-3, false);
    let cut = &bytes[..bytes.len() - 30];
    let e = parse_cloud(cut, CloudFormat::Las).unwrap_err();
    assert!(
        matches!(
            e,
            ParseError::Truncated {
                declared: 100,
                complete: 98,
                ..
            }
        ),
        "{e}"
    );
    // The 1.4 count field (byte 247) raised beyond the limit, the legacy one (byte 107) zero.
    let mut huge = bytes.clone();
    huge[107..111].copy_from_slice(&[0; 4]);
    huge[247..255].copy_from_slice(&(1u64 << 40).to_le_bytes());
    let e = parse_cloud(&huge, CloudFormat::Las).unwrap_err();
    assert!(
        matches!(e, ParseError::OverLimit { what: "points", .. }),
        "{e}"
    );
    // An extended VLR whose 64-bit length runs far past the file.
    let mut evlr = bytes.clone();
    let start = bytes.len() as u64;
    evlr[235..243].copy_from_slice(&start.to_le_bytes());
    evlr[243..247].copy_from_slice(&1u32.to_le_bytes());
    evlr.extend_from_slice(&[0u8; 20]);
    evlr.extend_from_slice(&(1u64 << 50).to_le_bytes());
    evlr.extend_from_slice(&[0u8; 32]);
    let e = parse_cloud(&evlr, CloudFormat::Las)
        .unwrap_err()
        .to_string();
    assert!(e.contains("extended VLR") && e.contains("beyond"), "{e}");
    // x scale 0.
    let mut zero = bytes;
    zero[131..139].copy_from_slice(&0f64.to_le_bytes());
    let e = parse_cloud(&zero, CloudFormat::Las)
        .unwrap_err()
        .to_string();
    assert!(e.contains("x scale 0"), "{e}");
}
