//! The firmware's whole control logic under arbitrary MCU-link bytes and ESC feedback frames,
//! one chunk per 1 ms step: it never panics, and the wheel currents never exceed the configured
//! current limit, whatever configuration the bytes managed to set.
#![no_main]

use control::machine::EscSample;
use control::{BusState, Config, Controller, Inputs};
use libfuzzer_sys::fuzz_target;
use protocol::esc::{EscFeedback, amps_to_raw};

fuzz_target!(|data: &[u8]| {
    let Some((&split, stream)) = data.split_first() else { return };
    let chunk = usize::from(split % 64).max(1);
    let Ok(mut controller) = Controller::new(Config::default()) else { return };
    for (step, piece) in stream.chunks(chunk).enumerate() {
        let now_us = (step as u64 + 1) * 1000;
        // A piece that starts with 0xEE carries one ESC frame: id byte, 8 data bytes.
        let mut esc = heapless::Vec::<EscSample, 1>::new();
        let mut link_rx = piece;
        if let [0xEE, id, rest @ ..] = piece
            && rest.len() >= 8
        {
            if let Ok(feedback) = EscFeedback::decode(&rest[..8]) {
                let _ = esc.push(EscSample { esc_id: *id % 6, feedback, stamp_us: now_us });
            }
            link_rx = &rest[8..];
        }
        let bus = if step % 97 == 96 { BusState::BusOff } else { BusState::Active };
        let out = controller.step(now_us, &Inputs { esc: &esc, link_rx, bus, battery_mv: 24_000 });
        let limit = amps_to_raw(controller.machine().config().pid.output_limit_a).unsigned_abs() + 1;
        assert!(out.currents_raw.iter().all(|c| c.unsigned_abs() <= limit), "{:?}", out.currents_raw);
    }
});
