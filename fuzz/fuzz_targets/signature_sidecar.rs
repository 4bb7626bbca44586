//! Any bytes as a signature sidecar (`FILE.sig`), and any bytes as the file a real sidecar signed:
//! parsing and verifying never panic, a parsed sidecar never verifies a file its signer did not
//! sign, and a changed file is always reported as changed with at least one change.
#![no_main]

use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;
use onboard::signing::{DeviceKey, Kind, Sidecar, Verdict, sign_bytes};

const RECORD: &[u8] =
    b"{\n  \"run_id\": 7,\n  \"approach_deg\": 25.003555,\n  \"warnings\": []\n}\n";

fn signed() -> &'static (Sidecar, DeviceKey) {
    static S: OnceLock<(Sidecar, DeviceKey)> = OnceLock::new();
    S.get_or_init(|| {
        let key = DeviceKey::from_seed(&[0x5a; 32]);
        (sign_bytes(&key, "result.json", Kind::Json, RECORD), key)
    })
}

fuzz_target!(|data: &[u8]| {
    let (sidecar, key) = signed();
    let public = key.public();
    // The input as a sidecar: whatever it claims, it may only verify what the key signed.
    if let Ok(s) = Sidecar::parse(data) {
        if let Ok(Verdict::Verified { key }) = s.verify(RECORD, &[s.public_key]) {
            assert!(key != public || s == *sidecar, "a forged sidecar verified");
        }
        let _ = s.verify(data, &[public]);
    }
    // The input as the signed file.
    match sidecar.verify(data, &[public]) {
        Ok(Verdict::Verified { .. }) => assert_eq!(data, RECORD),
        Ok(Verdict::Changed { changes, .. }) => assert!(!changes.is_empty()),
        Err(e) => panic!("the real signature failed: {e}"),
    }
});
