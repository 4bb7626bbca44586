//! Fuzz the lab file the handheld sends with a start (`onboard::report::LabFile`): any bytes are
//! refused with an error or parse, never panic; what parses renders into a report's lab section.
#![no_main]

use libfuzzer_sys::fuzz_target;
use onboard::report::LabFile;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(lab) = LabFile::parse(text) {
        let _ = lab.thresholds();
    }
});
