//! Fuzz the point-cloud readers (PLY, PCD incl. LZF `binary_compressed`, XYZ/CSV): never panic,
//! and every point returned is finite.
#![no_main]

use libfuzzer_sys::fuzz_target;
use onboard::cloud::{CloudFormat, parse_cloud};

fuzz_target!(|data: &[u8]| {
    for format in [CloudFormat::Ply, CloudFormat::Pcd, CloudFormat::Text] {
        if let Ok((cloud, stats)) = parse_cloud(data, format) {
            assert!(cloud.points_m.iter().flatten().all(|v| v.is_finite()));
            assert_eq!(cloud.points_m.len() + stats.dropped_non_finite, stats.points_in_file);
        }
    }
});
