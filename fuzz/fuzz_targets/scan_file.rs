//! Fuzz a run's `scan.toml` (`onboard::scan_file::ScanRecord`): any bytes are refused with an
//! error or parse, never panic; what parses writes back to the same record.
#![no_main]

use libfuzzer_sys::fuzz_target;
use onboard::scan_file::ScanRecord;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(record) = ScanRecord::parse(text) {
        assert_eq!(ScanRecord::parse(&record.to_toml()), Ok(record));
    }
});
