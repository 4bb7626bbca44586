//! Any bytes as VLP-16 data and position packets: parsing never panics, what parses re-emits
//! byte for byte (data) or to an equal repr (position), and the frame assembler survives a stream
//! of the input cut into packet-sized pieces (valid ones included, via a patched copy).
#![no_main]

use libfuzzer_sys::fuzz_target;
use vlp16::{
    DataPacketRepr, DecoderConfig, FrameAssembler, PositionPacket, PositionPacketRepr, Vlp16Packet,
};

fuzz_target!(|data: &[u8]| {
    if let Ok(packet) = Vlp16Packet::new_checked(data)
        && let Ok(repr) = DataPacketRepr::parse(&packet)
    {
        assert_eq!(&repr.to_bytes()[..], data);
    }
    if let Ok(packet) = PositionPacket::new_checked(data)
        && let Ok(repr) = PositionPacketRepr::parse(&packet)
    {
        let again = PositionPacketRepr::parse(&PositionPacket::new_unchecked(&repr.to_bytes()[..]));
        assert_eq!(again, Ok(repr));
        let _ = repr.nmea_sentence();
    }
    let Some((&cut, rest)) = data.split_first() else {
        return;
    };
    let config = DecoderConfig {
        cut_azimuth_rad: f32::from(cut) / 256.0 * core::f32::consts::TAU,
        ..DecoderConfig::default()
    };
    let Ok(mut assembler) = FrameAssembler::new(config) else {
        return;
    };
    for chunk in rest.chunks(1206) {
        // A copy with valid flags and factory bytes, so the decoder itself gets exercised.
        let mut patched = [0u8; 1206];
        patched[..chunk.len()].copy_from_slice(chunk);
        for block in 0..12 {
            patched[block * 100] = 0xff;
            patched[block * 100 + 1] = 0xee;
        }
        patched[1204] = 0x37 + chunk.first().copied().unwrap_or(0) % 3;
        patched[1205] = 0x22;
        let _ = assembler.push_data(chunk, 0);
        let _ = assembler.push_data(&patched, 1);
        let _ = assembler.push_position(chunk);
        while let Some(frame) = assembler.pop_frame() {
            assert!(
                frame
                    .points
                    .iter()
                    .all(|p| p.x_m.is_finite() && p.ring < 16)
            );
        }
    }
    assembler.finish();
});
