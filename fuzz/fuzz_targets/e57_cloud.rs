//! Fuzz the E57 reader (scans, poses, spherical points, invalid flags; the `e57` crate below it) alone: never panic, every point returned is finite, the counts add up, and no
//! file gets more points than the limits allow. libFuzzer's malloc limit catches an allocation
//! the header checks let through. Seeds: the `.e57` files in `onboard/tests/hostile/`.
#![no_main]

use cloud_io::{CloudFormat, ParseLimits, parse_cloud_with};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let limits = ParseLimits {
        max_points: 100_000,
        max_decoded_bytes: 4 << 20,
    };
    if let Ok((cloud, stats)) = parse_cloud_with(data, CloudFormat::E57, &limits) {
        assert!(cloud.points_m.iter().flatten().all(|v| v.is_finite()));
        assert_eq!(
            cloud.points_m.len() + stats.dropped_non_finite + stats.dropped_invalid,
            stats.points_in_file
        );
        assert!(stats.points_in_file <= limits.max_points);
    }
});
