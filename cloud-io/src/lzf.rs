//! LZF decompression (liblzf's format, as PCL's `binary_compressed` uses it). Bounds-checked:
//! malformed input gives an error, never a panic or an output larger than `expected_len`.
//!
//! Format: a control byte `c`. `c < 32`: a literal run of `c + 1` bytes follows. Otherwise a back
//! reference: length `(c >> 5) + 2` (if `c >> 5 == 7`, the next byte adds to the length), offset
//! `((c & 0x1f) << 8) + next byte + 1` back from the end of the output.

/// The most bytes one input byte can decode to: a 3-byte back reference copies 264 bytes.
pub(super) const MAX_RATIO: usize = 88;

pub(super) fn decompress(input: &[u8], expected_len: usize) -> Result<Vec<u8>, String> {
    let mut out = Vec::with_capacity(expected_len.min(input.len().saturating_mul(8) + 64));
    let mut ip = 0;
    let take = |ip: &mut usize| -> Result<u8, String> {
        let b = *input.get(*ip).ok_or("LZF block ends inside a code")?;
        *ip += 1;
        Ok(b)
    };
    while ip < input.len() {
        let ctrl = take(&mut ip)? as usize;
        if ctrl < 32 {
            let len = ctrl + 1;
            let lit = input
                .get(ip..ip + len)
                .ok_or("LZF literal run past the end of the block")?;
            if out.len() + len > expected_len {
                return Err(format!(
                    "LZF output exceeds the declared {expected_len} bytes"
                ));
            }
            out.extend_from_slice(lit);
            ip += len;
        } else {
            let mut len = ctrl >> 5;
            if len == 7 {
                len += take(&mut ip)? as usize;
            }
            len += 2;
            let back = ((ctrl & 0x1f) << 8) + take(&mut ip)? as usize + 1;
            if back > out.len() {
                return Err(format!(
                    "LZF back reference {back} before the start of the output"
                ));
            }
            if out.len() + len > expected_len {
                return Err(format!(
                    "LZF output exceeds the declared {expected_len} bytes"
                ));
            }
            let from = out.len() - back;
            for k in 0..len {
                let b = out[from + k];
                out.push(b);
            }
        }
    }
    if out.len() != expected_len {
        return Err(format!(
            "LZF output is {} bytes, {expected_len} declared",
            out.len()
        ));
    }
    Ok(out)
}

/// A simple, valid LZF encoder (literal runs plus greedy back references), used by the tests to
/// produce `binary_compressed` PCD files.
#[cfg(test)]
pub(super) fn compress(input: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    let mut lit: Vec<u8> = Vec::new();
    let flush = |lit: &mut Vec<u8>, out: &mut Vec<u8>| {
        for chunk in lit.chunks(32) {
            out.push((chunk.len() - 1) as u8);
            out.extend_from_slice(chunk);
        }
        lit.clear();
    };
    let mut i = 0;
    while i < input.len() {
        // Search a match of >= 3 bytes within 8 KiB back.
        let mut best = (0, 0);
        let start = i.saturating_sub(8192);
        for j in start..i {
            let mut l = 0;
            while i + l < input.len() && l < 264 && input[j + l] == input[i + l] {
                l += 1;
            }
            if l > best.1 {
                best = (i - j, l);
            }
        }
        if best.1 >= 3 {
            flush(&mut lit, &mut out);
            let (back, len) = (best.0 - 1, best.1 - 2);
            if len < 7 {
                out.push(((len << 5) | (back >> 8)) as u8);
            } else {
                out.push(((7 << 5) | (back >> 8)) as u8);
                out.push((len - 7) as u8);
            }
            out.push((back & 0xff) as u8);
            i += best.1;
        } else {
            lit.push(input[i]);
            i += 1;
        }
    }
    flush(&mut lit, &mut out);
    out
}
