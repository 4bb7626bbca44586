//! Fuzz the point-cloud readers (PLY, PCD incl. LZF `binary_compressed`, XYZ/CSV, E57, LAS/LAZ;
//! `e57_cloud` and `las_cloud` fuzz the last two alone): never panic,
//! every point returned is finite, and no header gets more points than the limits allow. Small
//! limits keep each run fast and make libFuzzer's malloc limit catch any unbounded allocation.
//! Seeds: `onboard/tests/hostile/` (pass it as a corpus directory).
#![no_main]

use cloud_io::{CloudFormat, ParseLimits, parse_cloud_with};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let limits = ParseLimits {
        max_points: 100_000,
        max_decoded_bytes: 4 << 20,
    };
    for format in [
        CloudFormat::Ply,
        CloudFormat::Pcd,
        CloudFormat::Text,
        CloudFormat::E57,
        CloudFormat::Las,
    ] {
        if let Ok((cloud, stats)) = parse_cloud_with(data, format, &limits) {
            assert!(cloud.points_m.iter().flatten().all(|v| v.is_finite()));
            assert_eq!(
                cloud.points_m.len() + stats.dropped_non_finite + stats.dropped_invalid,
                stats.points_in_file
            );
            assert!(stats.points_in_file <= limits.max_points);
        }
    }
});
