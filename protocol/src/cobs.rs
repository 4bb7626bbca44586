//! Consistent Overhead Byte Stuffing (Cheshire and Baker, 1999), allocation-free.
//!
//! Encoding removes every 0x00 from a block of bytes at a cost of one byte per started 254 bytes
//! (plus one), so 0x00 can delimit frames on a byte stream. Both functions work on caller buffers and
//! never panic.

/// Worst-case encoded length of `len` raw bytes (without the 0x00 delimiter).
pub const fn max_encoded_len(len: usize) -> usize {
    len + len / 254 + 1
}

/// Encodes `input` into `output`, returning the encoded length, or `None` if `output` is too small.
/// The result contains no 0x00 byte; the caller appends the delimiter.
pub fn encode(input: &[u8], output: &mut [u8]) -> Option<usize> {
    let mut code_index = 0;
    let mut out_index = 1;
    let mut code: u8 = 1;
    *output.get_mut(code_index)? = 0;
    for &byte in input {
        if byte == 0 {
            *output.get_mut(code_index)? = code;
            code_index = out_index;
            *output.get_mut(code_index)? = 0;
            out_index += 1;
            code = 1;
        } else {
            *output.get_mut(out_index)? = byte;
            out_index += 1;
            code += 1;
            if code == 0xFF {
                *output.get_mut(code_index)? = code;
                code_index = out_index;
                *output.get_mut(code_index)? = 0;
                out_index += 1;
                code = 1;
            }
        }
    }
    *output.get_mut(code_index)? = code;
    Some(out_index)
}

/// Why a COBS block did not decode.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CobsError {
    /// A 0x00 byte inside the block (the delimiter must not be part of it).
    ZeroInBlock,
    /// A code byte points past the end of the block.
    Truncated,
    /// The output buffer is too small.
    OutputTooSmall,
}

/// Decodes one COBS block (without its 0x00 delimiter) into `output`, returning the decoded length.
pub fn decode(input: &[u8], output: &mut [u8]) -> Result<usize, CobsError> {
    let mut in_index = 0;
    let mut out_index = 0;
    while in_index < input.len() {
        let code = input[in_index];
        if code == 0 {
            return Err(CobsError::ZeroInBlock);
        }
        in_index += 1;
        let run = usize::from(code) - 1;
        let end = in_index + run;
        let chunk = input.get(in_index..end).ok_or(CobsError::Truncated)?;
        if chunk.contains(&0) {
            return Err(CobsError::ZeroInBlock);
        }
        output
            .get_mut(out_index..out_index + run)
            .ok_or(CobsError::OutputTooSmall)?
            .copy_from_slice(chunk);
        out_index += run;
        in_index = end;
        if code != 0xFF && in_index < input.len() {
            *output.get_mut(out_index).ok_or(CobsError::OutputTooSmall)? = 0;
            out_index += 1;
        }
    }
    Ok(out_index)
}

/// Decodes one COBS block in place (the decoded bytes are never longer than the encoded ones),
/// returning the decoded length.
pub fn decode_in_place(buf: &mut [u8]) -> Result<usize, CobsError> {
    let mut in_index = 0;
    let mut out_index = 0;
    while in_index < buf.len() {
        let code = buf[in_index];
        if code == 0 {
            return Err(CobsError::ZeroInBlock);
        }
        in_index += 1;
        let run = usize::from(code) - 1;
        let end = in_index + run;
        if end > buf.len() {
            return Err(CobsError::Truncated);
        }
        if buf[in_index..end].contains(&0) {
            return Err(CobsError::ZeroInBlock);
        }
        buf.copy_within(in_index..end, out_index);
        out_index += run;
        in_index = end;
        if code != 0xFF && in_index < buf.len() {
            buf[out_index] = 0;
            out_index += 1;
        }
    }
    Ok(out_index)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn enc(input: &[u8]) -> Vec<u8> {
        let mut out = vec![0; max_encoded_len(input.len())];
        let n = encode(input, &mut out).unwrap();
        out.truncate(n);
        out
    }

    #[test]
    fn wikipedia_vectors() {
        assert_eq!(enc(&[]), [0x01]);
        assert_eq!(enc(&[0x00]), [0x01, 0x01]);
        assert_eq!(enc(&[0x00, 0x00]), [0x01, 0x01, 0x01]);
        assert_eq!(enc(&[0x00, 0x11, 0x00]), [0x01, 0x02, 0x11, 0x01]);
        assert_eq!(
            enc(&[0x11, 0x22, 0x00, 0x33]),
            [0x03, 0x11, 0x22, 0x02, 0x33]
        );
        assert_eq!(
            enc(&[0x11, 0x00, 0x00, 0x00]),
            [0x02, 0x11, 0x01, 0x01, 0x01]
        );
        let run: Vec<u8> = (1..=254).collect();
        let mut expected = vec![0xFF];
        expected.extend(&run);
        expected.push(0x01);
        assert_eq!(enc(&run), expected);
    }

    #[test]
    fn rejects_bad_blocks() {
        let mut out = [0u8; 16];
        assert_eq!(decode(&[0x03, 0x11], &mut out), Err(CobsError::Truncated));
        assert_eq!(decode(&[0x02, 0x00], &mut out), Err(CobsError::ZeroInBlock));
        assert_eq!(decode(&[0x00], &mut out), Err(CobsError::ZeroInBlock));
        assert_eq!(
            decode(&[0x05, 1, 2, 3, 4], &mut [0u8; 2]),
            Err(CobsError::OutputTooSmall)
        );
    }

    proptest! {
        #[test]
        fn round_trip(data in proptest::collection::vec(any::<u8>(), 0..700)) {
            let encoded = enc(&data);
            prop_assert!(!encoded.contains(&0));
            prop_assert!(encoded.len() <= max_encoded_len(data.len()));
            let mut out = vec![0; data.len() + 1];
            let n = decode(&encoded, &mut out).unwrap();
            prop_assert_eq!(&out[..n], &data[..]);
            let mut in_place = encoded.clone();
            let n = decode_in_place(&mut in_place).unwrap();
            prop_assert_eq!(&in_place[..n], &data[..]);
        }

        #[test]
        fn decode_never_panics(data in proptest::collection::vec(any::<u8>(), 0..600)) {
            let mut out = vec![0; 300];
            let _ = decode(&data, &mut out);
            let mut buf = data.clone();
            let _ = decode_in_place(&mut buf);
        }
    }
}
