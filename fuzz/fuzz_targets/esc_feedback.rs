//! Any CAN id and data: the C620 codec never panics and round-trips what it accepts.
#![no_main]

use libfuzzer_sys::fuzz_target;
use protocol::esc::{EscFeedback, decode_command, encode_command};

fuzz_target!(|data: &[u8]| {
    if let Ok(fb) = EscFeedback::decode(data) {
        assert_eq!(EscFeedback::decode(&fb.encode()), Ok(fb));
    }
    if let Ok(currents) = decode_command(data) {
        let clamped = currents.map(|c| c.clamp(-16384, 16384));
        assert_eq!(decode_command(&encode_command(currents)), Ok(clamped));
    }
});
