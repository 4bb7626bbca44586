//! Any text as a candump log: `hil_sim::can_bus::parse_candump_log` never panics, and every frame
//! it accepts survives a write -> parse round trip.
#![no_main]

use hil_sim::can_bus::parse_candump_log;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(records) = parse_candump_log(text) {
        for (t, iface, frame) in records {
            if iface.contains(char::is_whitespace) || iface.is_empty() {
                continue;
            }
            let line = format!(
                "({}.{:06}) {iface} {}",
                t / 1_000_000,
                t % 1_000_000,
                frame.to_candump()
            );
            let again = parse_candump_log(&line).expect("a written record parses");
            assert_eq!(again.len(), 1);
            assert_eq!(again[0].2, frame);
        }
    }
});
