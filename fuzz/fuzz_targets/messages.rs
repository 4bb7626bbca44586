//! Any frame payload under any message id: every message-set decoder returns a message or a typed
//! error, never panics; a decoded message re-encodes and decodes to itself.
#![no_main]

use libfuzzer_sys::fuzz_target;
use protocol::frame::{Flags, Frame, Header, MAX_FRAME_LEN};
use protocol::mcu::{FromFirmware, ToFirmware};
use protocol::radio::{ToHandheld, ToOnboard};

macro_rules! check {
    ($set:ty, $frame:expr) => {
        if let Ok(msg) = <$set>::decode($frame) {
            let mut out = [0u8; MAX_FRAME_LEN];
            let n = msg.encode_frame(1, Flags::NONE, &mut out).expect("decoded message re-encodes");
            let mut d = protocol::Deframer::<MAX_FRAME_LEN>::new();
            let mut again = None;
            d.feed_all(&out[..n], |r| again = Some(r.map(|f| <$set>::decode(&f))));
            assert_eq!(again, Some(Ok(Ok(msg))));
        }
    };
}

fuzz_target!(|data: &[u8]| {
    if data.len() < 2 {
        return;
    }
    let msg_id = u16::from_le_bytes([data[0], data[1]]);
    let frame = Frame { header: Header::new(msg_id, 0, Flags::NONE), payload: &data[2..] };
    check!(ToFirmware, &frame);
    check!(FromFirmware, &frame);
    check!(ToOnboard, &frame);
    check!(ToHandheld, &frame);
});
