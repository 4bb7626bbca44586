//! CAN bus load: the exact on-wire length of classic CAN 2.0A data frames, bit stuffing included.
//!
//! A standard data frame is SOF (1), identifier (11), RTR (1), IDE (1), r0 (1), DLC (4), data
//! (8 x len), CRC-15 (15), then CRC delimiter, ACK slot, ACK delimiter (3), EOF (7) and the
//! intermission (3). From SOF to the end of the CRC, the transmitter inserts a complement bit after
//! every five equal bits. An 8-byte frame is therefore 111 bits without stuffing and at most 135
//! bits with it. The C620 bus carries 4 feedback frames and 1 command frame per millisecond: about
//! 56-68 % of 1 Mbit/s, so this bus must not be shared with other devices.

/// CRC-15/CAN over a bit sequence (polynomial 0x4599).
fn crc15(bits: &[bool]) -> u16 {
    let mut crc: u16 = 0;
    for &bit in bits {
        let next = bit ^ ((crc >> 14) & 1 == 1);
        crc = (crc << 1) & 0x7FFF;
        if next {
            crc ^= 0x4599;
        }
    }
    crc
}

fn push_bits(out: &mut heapless::Vec<bool, 128>, value: u32, width: u32) {
    for i in (0..width).rev() {
        // Capacity 128 holds the longest classic frame before stuffing (98 + 15 bits).
        let _ = out.push((value >> i) & 1 == 1);
    }
}

/// Bits on the wire for a standard-id data frame with `data` (at most 8 bytes; longer data is
/// cut to 8), including stuffing, the fixed trailer and the 3-bit intermission.
pub fn frame_bits(id: u16, data: &[u8]) -> u32 {
    let data = &data[..data.len().min(8)];
    let mut bits = heapless::Vec::<bool, 128>::new();
    push_bits(&mut bits, 0, 1); // SOF (dominant)
    push_bits(&mut bits, u32::from(id & 0x7FF), 11);
    push_bits(&mut bits, 0, 3); // RTR, IDE, r0: data frame, standard id
    // `data.len()` is at most 8 here.
    push_bits(&mut bits, u32::try_from(data.len()).unwrap_or(8), 4);
    for byte in data {
        push_bits(&mut bits, u32::from(*byte), 8);
    }
    let crc = crc15(&bits);
    push_bits(&mut bits, u32::from(crc), 15);

    let mut stuffed = 0u32;
    let mut run = 0u32;
    let mut last = None;
    for &bit in &bits {
        if Some(bit) == last {
            run += 1;
        } else {
            run = 1;
            last = Some(bit);
        }
        if run == 5 {
            // A complement bit follows; it starts a new run of length 1.
            stuffed += 1;
            run = 1;
            last = Some(!bit);
        }
    }
    let base = u32::try_from(bits.len()).unwrap_or(u32::MAX);
    base + stuffed + 3 + 7 + 3
}

/// Bus load (0..1) of frames sent per second whose mean length is `mean_bits`, at `bitrate`.
pub fn load(frames_per_s: f32, mean_bits: f32, bitrate: f32) -> f32 {
    frames_per_s * mean_bits / bitrate
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn lengths_without_and_with_heavy_stuffing() {
        // Alternating identifier and data bits stuff only where the CRC happens to run.
        let alternating = frame_bits(0x555, &[0x55; 8]);
        assert!((111..=114).contains(&alternating), "{alternating}");
        // All-zero identifier and data: one stuff bit after every five zeros, at least 15 of
        // them in the 82 bits from SOF to the end of the data (the worst case is one per four
        // bits, for runs like 0000 0 1111 1 0000 ...).
        let zeros = frame_bits(0x000, &[0; 8]);
        assert!((111 + 15..=135).contains(&zeros), "{zeros}");
        // An empty frame: 47 bits before stuffing.
        assert!((47..=47 + 8).contains(&frame_bits(0x123, &[])));
    }

    #[test]
    fn crc15_of_a_known_frame() {
        // The CRC register over no bits is zero, and one dominant (0) bit keeps it zero.
        assert_eq!(crc15(&[]), 0);
        assert_eq!(crc15(&[false]), 0);
        assert_eq!(crc15(&[true]), 0x4599);
    }

    #[test]
    fn chassis_bus_load_is_in_the_expected_band() {
        // 4 feedback frames and 1 command frame per ms, each 111-135 bits.
        let lo = load(5000.0, 111.0, 1.0e6);
        let hi = load(5000.0, 135.0, 1.0e6);
        assert!((lo - 0.555).abs() < 1e-6 && (hi - 0.675).abs() < 1e-6);
    }

    proptest! {
        #[test]
        fn eight_byte_frames_are_111_to_135_bits(id in 0u16..0x800, data: [u8; 8]) {
            let bits = frame_bits(id, &data);
            prop_assert!((111..=135).contains(&bits), "{}", bits);
        }
    }
}
