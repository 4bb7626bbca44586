use std::fmt::Write as _;

use proptest::prelude::*;

use super::*;

const ALL_FORMATS: [CloudFormat; 5] = [
    CloudFormat::Ply,
    CloudFormat::Pcd,
    CloudFormat::Text,
    CloudFormat::E57,
    CloudFormat::Las,
];

fn sample() -> Cloud {
    Cloud {
        points_m: vec![[1.0, -2.5, 0.125], [0.1, 0.2, 0.3], [-1e-3, 4.0, 1234.5]],
    }
}

fn ply_binary(big_endian: bool, points: &[[f64; 3]]) -> Vec<u8> {
    // float x, double y, extra uchar, float z, then a face element with a list property.
    let fmt = if big_endian {
        "binary_big_endian"
    } else {
        "binary_little_endian"
    };
    let mut out = format!(
        "ply\nformat {fmt} 1.0\ncomment test\nelement vertex {}\nproperty float x\nproperty double y\n\
         property uchar intensity\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n",
        points.len()
    )
    .into_bytes();
    let put = |out: &mut Vec<u8>, mut b: Vec<u8>| {
        if big_endian {
            b.reverse();
        }
        out.extend(b);
    };
    for p in points {
        put(&mut out, (p[0] as f32).to_le_bytes().to_vec());
        put(&mut out, p[1].to_le_bytes().to_vec());
        out.push(7);
        put(&mut out, (p[2] as f32).to_le_bytes().to_vec());
    }
    out.push(3);
    for i in 0..3i32 {
        put(&mut out, i.to_le_bytes().to_vec());
    }
    out
}

#[test]
fn ply_round_trips_ascii_and_binary() {
    for encoding in [PlyEncoding::Ascii, PlyEncoding::BinaryLittleEndian] {
        let mut bytes = Vec::new();
        write_ply(&mut bytes, &sample(), encoding).unwrap();
        let (cloud, stats) = parse_cloud(&bytes, CloudFormat::Ply).unwrap();
        assert_eq!(cloud, sample(), "{encoding:?}");
        assert_eq!(stats.points_in_file, 3);
        assert_eq!(stats.dropped_non_finite, 0);
    }
}

#[test]
fn ply_binary_both_endians_with_extra_properties_and_faces() {
    let pts = [[1.5, -2.25, 0.5], [3.0, 4.0, -5.0]];
    for be in [false, true] {
        let (cloud, stats) = parse_cloud(&ply_binary(be, &pts), CloudFormat::Ply).unwrap();
        assert_eq!(cloud.points_m, pts.to_vec(), "big endian {be}");
        assert_eq!(
            stats.encoding,
            if be {
                "binary_big_endian"
            } else {
                "binary_little_endian"
            }
        );
    }
}

#[test]
fn ply_ascii_with_elements_before_vertices_and_crlf() {
    let text = "ply\r\nformat ascii 1.0\r\nelement camera 1\r\nproperty float fx\r\nelement vertex 2\r\n\
                property float z\r\nproperty float y\r\nproperty float x\r\nproperty list uchar int idx\r\n\
                end_header\r\n9\r\n3 2 1 2 5 6\r\n6 5 4 0\r\n";
    let (cloud, _) = parse_cloud(text.as_bytes(), CloudFormat::Ply).unwrap();
    assert_eq!(cloud.points_m, vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
}

#[test]
fn nan_points_are_dropped_and_counted() {
    let text = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
                end_header\n1 2 3\nnan 0 0\n0 inf 1\n";
    let (cloud, stats) = parse_cloud(text.as_bytes(), CloudFormat::Ply).unwrap();
    assert_eq!(cloud.points_m, vec![[1.0, 2.0, 3.0]]);
    assert_eq!(stats.points_in_file, 3);
    assert_eq!(stats.dropped_non_finite, 2);
}

#[test]
fn all_nan_cloud_is_empty_error() {
    let text = "1 nan 3\nnan 1 2\n";
    let err = parse_cloud(text.as_bytes(), CloudFormat::Text).unwrap_err();
    assert_eq!(
        err,
        ParseError::Empty {
            points_in_file: 2,
            dropped_non_finite: 2
        }
    );
    let err = parse_cloud(b"# only a comment\n", CloudFormat::Text).unwrap_err();
    assert!(matches!(
        err,
        ParseError::Empty {
            points_in_file: 0,
            ..
        }
    ));
}

#[test]
fn truncated_binary_ply_names_the_counts() {
    let mut bytes = ply_binary(false, &[[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
    let header_len = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11;
    bytes.truncate(header_len + 17 + 5);
    let err = parse_cloud(&bytes, CloudFormat::Ply).unwrap_err();
    assert_eq!(
        err,
        ParseError::Truncated {
            what: "vertices",
            declared: 2,
            complete: 1
        }
    );
    assert!(err.to_string().contains("declares 2 vertices"), "{err}");
}

#[test]
fn malformed_ply_headers_name_the_line() {
    let cases: [(&str, usize, &str); 4] = [
        (
            "ply\nformat ascii 1.0\nelement vertex two\nend_header\n",
            3,
            "bad count",
        ),
        (
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n1 2\n",
            3,
            "no scalar property `z`",
        ),
        ("ply\nformat zip 1.0\nend_header\n", 2, "unknown format"),
        (
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty quad x\nend_header\n",
            4,
            "unknown property type",
        ),
    ];
    for (text, line, needle) in cases {
        match parse_cloud(text.as_bytes(), CloudFormat::Ply).unwrap_err() {
            ParseError::Header { line: l, message } => {
                assert_eq!(l, line, "{text}");
                assert!(message.contains(needle), "{message}");
            }
            other => panic!("{other:?}"),
        }
    }
    let err = parse_cloud(b"ply\nformat ascii 1.0\n", CloudFormat::Ply).unwrap_err();
    assert!(err.to_string().contains("header ends"), "{err}");
}

#[test]
fn ply_ascii_bad_number_names_line() {
    let text = "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n\
                end_header\n1 2 3\n1 two 3\n";
    let err = parse_cloud(text.as_bytes(), CloudFormat::Ply).unwrap_err();
    assert!(matches!(err, ParseError::Data { line: 9, .. }), "{err:?}");
    assert!(err.to_string().contains("`two`"));
}

fn pcd_header(data: &str, n: usize) -> String {
    format!(
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z rgb\nSIZE 4 8 4 4\nTYPE F F F U\n\
         COUNT 1 1 1 1\nWIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {data}\n"
    )
}

#[test]
fn pcd_ascii_binary_and_compressed() {
    let pts: [[f64; 3]; 3] = [[0.5, -1.25, 2.0], [3.0, 0.0, -0.75], [1.0, 1.0, 1.0]];
    let mut ascii = pcd_header("ascii", 3);
    for p in pts {
        writeln!(ascii, "{} {} {} 0", p[0], p[1], p[2]).unwrap();
    }
    let mut binary = pcd_header("binary", 3).into_bytes();
    for p in pts {
        binary.extend((p[0] as f32).to_le_bytes());
        binary.extend(p[1].to_le_bytes());
        binary.extend((p[2] as f32).to_le_bytes());
        binary.extend(7u32.to_le_bytes());
    }
    let mut soa = Vec::new();
    for p in pts {
        soa.extend((p[0] as f32).to_le_bytes());
    }
    for p in pts {
        soa.extend(p[1].to_le_bytes());
    }
    for p in pts {
        soa.extend((p[2] as f32).to_le_bytes());
    }
    soa.extend([0u8; 12]);
    let block = lzf::compress(&soa);
    assert_eq!(lzf::decompress(&block, soa.len()).unwrap(), soa);
    let mut compressed = pcd_header("binary_compressed", 3).into_bytes();
    compressed.extend((block.len() as u32).to_le_bytes());
    compressed.extend((soa.len() as u32).to_le_bytes());
    compressed.extend(&block);
    for (bytes, enc) in [
        (ascii.into_bytes(), "ascii"),
        (binary, "binary"),
        (compressed, "binary_compressed"),
    ] {
        let (cloud, stats) = parse_cloud(&bytes, CloudFormat::Pcd).unwrap();
        assert_eq!(cloud.points_m, pts.to_vec(), "{enc}");
        assert_eq!(stats.encoding, enc);
    }
}

#[test]
fn pcd_errors_are_specific() {
    let mut truncated = pcd_header("binary", 3).into_bytes();
    truncated.extend([0u8; 25]);
    assert_eq!(
        parse_cloud(&truncated, CloudFormat::Pcd).unwrap_err(),
        ParseError::Truncated {
            what: "points",
            declared: 3,
            complete: 1
        }
    );
    let bad = "VERSION 0.7\nFIELDS x y z\nSIZE 4 4\nTYPE F F F\nPOINTS 1\nDATA ascii\n1 2 3\n";
    let err = parse_cloud(bad.as_bytes(), CloudFormat::Pcd).unwrap_err();
    assert_eq!(
        err,
        ParseError::Header {
            line: 3,
            message: "SIZE has 2 entries, FIELDS has 3".into()
        }
    );
    let no_z = "FIELDS x y\nPOINTS 1\nDATA ascii\n1 2\n";
    assert!(
        parse_cloud(no_z.as_bytes(), CloudFormat::Pcd)
            .unwrap_err()
            .to_string()
            .contains("no `z`")
    );
}

#[test]
fn text_formats() {
    let csv = "X,Y,Z,intensity\n1,2,3,9\n# comment\n\n4;5;6;1\n";
    let (cloud, _) = parse_cloud(csv.as_bytes(), CloudFormat::Text).unwrap();
    assert_eq!(cloud.points_m, vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
    let reordered = "i z y x\n0 3 2 1\n";
    let (cloud, _) = parse_cloud(reordered.as_bytes(), CloudFormat::Text).unwrap();
    assert_eq!(cloud.points_m, vec![[1.0, 2.0, 3.0]]);
    let mut xyz = Vec::new();
    write_xyz(&mut xyz, &sample()).unwrap();
    assert_eq!(parse_cloud(&xyz, CloudFormat::Text).unwrap().0, sample());
    let err = parse_cloud(b"1 2 3\n4 5\n", CloudFormat::Text).unwrap_err();
    assert!(matches!(err, ParseError::Data { line: 2, .. }), "{err:?}");
}

#[test]
fn detects_formats() {
    assert_eq!(
        detect_format(Some(Path::new("a.PLY")), b""),
        Some(CloudFormat::Ply)
    );
    assert_eq!(detect_format(None, b"ply\nformat"), Some(CloudFormat::Ply));
    assert_eq!(
        detect_format(None, b"# .PCD v0.7\n"),
        Some(CloudFormat::Pcd)
    );
    assert_eq!(
        detect_format(None, b"1.0 2.0 3.0\n"),
        Some(CloudFormat::Text)
    );
    assert_eq!(detect_format(None, &[0xff, 0x00, 0x12]), None);
}

#[test]
fn read_cloud_errors_name_the_file() {
    let err = read_cloud(Path::new("/nonexistent/dir/cloud.ply")).unwrap_err();
    assert!(
        err.to_string().starts_with("/nonexistent/dir/cloud.ply:"),
        "{err}"
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn parsers_never_panic_on_random_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
        for format in ALL_FORMATS {
            let _ = parse_cloud(&bytes, format);
        }
    }

    #[test]
    fn parsers_never_panic_on_mutated_files(
        which in 0usize..7,
        edits in proptest::collection::vec((any::<u16>(), any::<u8>()), 1..8),
        cut in any::<u16>(),
    ) {
        let mut bytes = match which {
            0 => ply_binary(false, &[[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]),
            1 => ply_binary(true, &[[1.0, 2.0, 3.0]]),
            2 => { let mut v = pcd_header("binary_compressed", 1).into_bytes();
                   let soa = [0u8; 20]; let block = lzf::compress(&soa);
                   v.extend((block.len() as u32).to_le_bytes()); v.extend(20u32.to_le_bytes()); v.extend(block); v }
            3 => pcd_header("ascii", 2).into_bytes(),
            4 => { let mut v = Vec::new(); write_e57(io::Cursor::new(&mut v), &sample(), "m").unwrap(); v }
            5 => write_las(io::Cursor::new(Vec::new()), &sample(), 1e-3, false).unwrap().into_inner(),
            _ => write_las(io::Cursor::new(Vec::new()), &sample(), 1e-3, true).unwrap().into_inner(),
        };
        for (at, b) in edits {
            if !bytes.is_empty() {
                let i = at as usize % bytes.len();
                bytes[i] = b;
            }
        }
        bytes.truncate(cut as usize % (bytes.len() + 1));
        for format in ALL_FORMATS {
            let _ = parse_cloud(&bytes, format);
        }
    }
}
