//! Any text as a recording's `odometry.csv`: the reader never panics, every report it accepts is
//! finite, and it keeps at most one report per line.
#![no_main]

use libfuzzer_sys::fuzz_target;
use onboard::recorder::parse_odometry_csv;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok((reports, cut)) = parse_odometry_csv(text) {
        assert!(reports.len() + cut <= text.lines().count());
        for (_, o) in reports {
            let values = [o.x_m, o.y_m, o.yaw_rad, o.vx_mps, o.vy_mps, o.wz_radps];
            assert!(values.iter().chain(&o.wheel_speed_radps).all(|v| v.is_finite()));
        }
    }
});
