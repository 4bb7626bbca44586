//! Framing: `COBS(header | postcard payload | CRC-32) 0x00`, and the IO-free [`Deframer`].
//!
//! ```text
//!  raw frame (before COBS):
//!  +---------+-----------+-----------+-------+------------------+------------------+
//!  | version | msg id    | sequence  | flags | payload          | CRC-32           |
//!  | u8      | u16 LE    | u16 LE    | u8    | postcard, 0..N   | u32 LE           |
//!  +---------+-----------+-----------+-------+------------------+------------------+
//!  on the wire: COBS(raw frame) followed by one 0x00 delimiter
//! ```
//!
//! The CRC is CRC-32/ISO-HDLC (the Ethernet/zlib CRC) over header and payload. The header is a fixed
//! six-byte layout, not postcard, so that it never changes: its first byte is always the protocol
//! version, so a receiver can tell "wrong version" from "garbage" and answer a [`crate::Hello`].

use crc::{CRC_32_ISO_HDLC, Crc};
use serde::Serialize;

/// Size of the fixed header.
pub const HEADER_LEN: usize = 6;
/// Size of the CRC trailer.
pub const CRC_LEN: usize = 4;
/// Largest encoded frame on either link, delimiter included. Both ends size their receive buffers
/// for it; every message's worst case fits (checked by tests).
pub const MAX_FRAME_LEN: usize = 256;
/// Largest raw frame (header + payload + CRC) that still encodes into [`MAX_FRAME_LEN`].
pub const MAX_RAW_LEN: usize = 250;
/// Largest postcard payload of any message.
pub const MAX_PAYLOAD_LEN: usize = MAX_RAW_LEN - HEADER_LEN - CRC_LEN;

// COBS of MAX_RAW_LEN bytes plus the delimiter must fit MAX_FRAME_LEN.
const _: () = assert!(cobs::max_encoding_length(MAX_RAW_LEN) < MAX_FRAME_LEN);
// A raw frame is shorter than one 254-byte COBS block. Only there do COBS encoders differ (some
// end a block of exactly 254 non-zero bytes with an extra 0x01), so below it the `cobs` crate
// writes the bytes of the reference encoding (see the tests).
const _: () = assert!(MAX_RAW_LEN < 254);

const CRC32: Crc<u32> = Crc::<u32>::new(&CRC_32_ISO_HDLC);

/// Worst-case encoded frame length (delimiter included) for a payload of up to `payload_len` bytes.
pub const fn max_frame_len(payload_len: usize) -> usize {
    cobs::max_encoding_length(HEADER_LEN + payload_len + CRC_LEN) + 1
}

/// Header flag bits.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Flags(pub u8);

impl Flags {
    /// No flags.
    pub const NONE: Self = Self(0);
    /// The sender wants an ack (a frame with [`Flags::IS_ACK`], the same msg id and sequence, empty payload).
    pub const ACK_REQUESTED: Self = Self(0x01);
    /// This frame acknowledges the frame with the same msg id and sequence.
    pub const IS_ACK: Self = Self(0x02);

    /// Whether every bit of `other` is set.
    pub const fn contains(self, other: Self) -> bool {
        self.0 & other.0 == other.0
    }

    /// Both flag sets together.
    #[must_use]
    pub const fn union(self, other: Self) -> Self {
        Self(self.0 | other.0)
    }
}

/// The fixed frame header.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Header {
    /// Protocol version of the sender ([`crate::PROTOCOL_VERSION`]).
    pub version: u8,
    /// Message id (one of the explicit constants in [`crate::ids`]).
    pub msg_id: u16,
    /// Sender's sequence number, wrapping; acks echo it.
    pub seq: u16,
    /// Flag bits.
    pub flags: Flags,
}

impl Header {
    /// A header of this protocol version.
    pub const fn new(msg_id: u16, seq: u16, flags: Flags) -> Self {
        Self {
            version: crate::PROTOCOL_VERSION,
            msg_id,
            seq,
            flags,
        }
    }

    /// The six header bytes.
    pub fn to_bytes(&self) -> [u8; HEADER_LEN] {
        let id = self.msg_id.to_le_bytes();
        let seq = self.seq.to_le_bytes();
        [self.version, id[0], id[1], seq[0], seq[1], self.flags.0]
    }

    /// Parses the six header bytes.
    pub fn from_bytes(bytes: [u8; HEADER_LEN]) -> Self {
        Self {
            version: bytes[0],
            msg_id: u16::from_le_bytes([bytes[1], bytes[2]]),
            seq: u16::from_le_bytes([bytes[3], bytes[4]]),
            flags: Flags(bytes[5]),
        }
    }

    /// The ack of this frame: same id and sequence, [`Flags::IS_ACK`], empty payload.
    #[must_use]
    pub const fn ack(&self) -> Self {
        Self::new(self.msg_id, self.seq, Flags::IS_ACK)
    }
}

/// Why a frame could not be encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum EncodeError {
    /// The payload does not fit [`MAX_PAYLOAD_LEN`] (a message whose bound is too large).
    PayloadTooLarge,
    /// The output buffer is too small for the encoded frame.
    OutputTooSmall,
}

impl core::fmt::Display for EncodeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::PayloadTooLarge => write!(f, "payload exceeds {MAX_PAYLOAD_LEN} bytes"),
            Self::OutputTooSmall => write!(f, "output buffer too small for the encoded frame"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for EncodeError {}

/// Encodes `payload` (already postcard bytes) under `header` into `out`; returns the frame length
/// including the trailing 0x00.
pub fn encode_raw(header: Header, payload: &[u8], out: &mut [u8]) -> Result<usize, EncodeError> {
    let mut raw = [0u8; MAX_RAW_LEN];
    let raw_len = HEADER_LEN + payload.len() + CRC_LEN;
    if raw_len > MAX_RAW_LEN {
        return Err(EncodeError::PayloadTooLarge);
    }
    raw[..HEADER_LEN].copy_from_slice(&header.to_bytes());
    raw[HEADER_LEN..HEADER_LEN + payload.len()].copy_from_slice(payload);
    let crc = CRC32.checksum(&raw[..HEADER_LEN + payload.len()]);
    raw[HEADER_LEN + payload.len()..raw_len].copy_from_slice(&crc.to_le_bytes());
    // `try_encode` can return a length past the end of `out` when the block's last code byte
    // would fall just outside it; the delimiter's bounds check below refuses that case too.
    let n = cobs::try_encode(&raw[..raw_len], out).map_err(|_| EncodeError::OutputTooSmall)?;
    *out.get_mut(n).ok_or(EncodeError::OutputTooSmall)? = 0;
    Ok(n + 1)
}

/// Encodes `msg` as a postcard payload into `out` (at most [`MAX_PAYLOAD_LEN`] bytes are used);
/// returns its length. The radio seals header and payload before framing.
pub fn encode_payload<M: Serialize>(msg: &M, out: &mut [u8]) -> Result<usize, EncodeError> {
    let out_len = out.len().min(MAX_PAYLOAD_LEN);
    postcard::to_slice(msg, &mut out[..out_len])
        .map(|s| s.len())
        .map_err(|_| EncodeError::PayloadTooLarge)
}

/// Serialises `msg` with postcard and encodes it under `header` into `out`; returns the frame
/// length including the trailing 0x00.
pub fn encode<M: Serialize>(header: Header, msg: &M, out: &mut [u8]) -> Result<usize, EncodeError> {
    let mut payload = [0u8; MAX_PAYLOAD_LEN];
    let used = postcard::to_slice(msg, &mut payload).map_err(|_| EncodeError::PayloadTooLarge)?;
    let len = used.len();
    encode_raw(header, &payload[..len], out)
}

/// One received frame: its header and its (not yet decoded) postcard payload.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Frame<'a> {
    /// The frame's header.
    pub header: Header,
    /// The postcard payload bytes.
    pub payload: &'a [u8],
}

/// Why bytes between two delimiters were not a frame. The deframer has already resynchronised
/// when it reports one of these: the next frame after the offending delimiter decodes normally.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum DeframeError {
    /// More than the buffer's capacity arrived before a delimiter; the bytes were dropped up to the
    /// next delimiter.
    Oversize,
    /// The block is not valid COBS.
    Cobs,
    /// The decoded frame is shorter than header + CRC.
    TooShort {
        /// Decoded length seen.
        len: usize,
    },
    /// The CRC does not match: the frame was corrupted.
    BadCrc,
}

impl core::fmt::Display for DeframeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Oversize => write!(f, "frame longer than the receive buffer, dropped"),
            Self::Cobs => write!(f, "invalid COBS encoding"),
            Self::TooShort { len } => {
                write!(f, "frame of {len} bytes is shorter than header and CRC")
            }
            Self::BadCrc => write!(f, "CRC mismatch"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for DeframeError {}

/// The result of one [`Deframer::feed`] call.
#[derive(Debug)]
pub enum Feed<'buf, 'input> {
    /// All input was consumed without completing a frame.
    Consumed,
    /// A whole frame; `remaining` is the input after its delimiter (feed it next).
    Frame {
        /// The frame, borrowed from the deframer until the next feed.
        frame: Frame<'buf>,
        /// Input not yet consumed.
        remaining: &'input [u8],
    },
    /// Bytes up to a delimiter were not a frame; `remaining` is the input after that delimiter.
    Error {
        /// What was wrong.
        error: DeframeError,
        /// Input not yet consumed.
        remaining: &'input [u8],
    },
}

/// IO-free frame accumulator for a byte stream (UART, radio, pty, file). Feed it any chunks; it
/// returns whole frames with a valid CRC, or a typed error, and resynchronises at the next 0x00.
/// `N` is the largest encoded frame accepted, without the delimiter.
#[derive(Debug, Clone)]
pub struct Deframer<const N: usize> {
    buf: [u8; N],
    len: usize,
    overflowed: bool,
}

impl<const N: usize> Default for Deframer<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> Deframer<N> {
    /// An empty deframer.
    pub const fn new() -> Self {
        Self {
            buf: [0; N],
            len: 0,
            overflowed: false,
        }
    }

    /// Drops any partial frame (e.g. after a port is reopened).
    pub fn reset(&mut self) {
        self.len = 0;
        self.overflowed = false;
    }

    /// Bytes of a partial frame currently held.
    pub fn pending(&self) -> usize {
        self.len
    }

    /// Consumes `input` up to and including the next delimiter, if any.
    pub fn feed<'s, 'i>(&'s mut self, input: &'i [u8]) -> Feed<'s, 'i> {
        let Some(pos) = input.iter().position(|&b| b == 0) else {
            self.push(input);
            return Feed::Consumed;
        };
        self.push(&input[..pos]);
        let remaining = &input[pos + 1..];
        let overflowed = core::mem::replace(&mut self.overflowed, false);
        let len = core::mem::replace(&mut self.len, 0);
        if overflowed {
            return Feed::Error {
                error: DeframeError::Oversize,
                remaining,
            };
        }
        if len == 0 {
            // Back-to-back delimiters (line idle, or a sender flushing): not an error, not a frame.
            return self.feed(remaining);
        }
        match decode_block(&mut self.buf[..len]) {
            Ok(frame) => Feed::Frame { frame, remaining },
            Err(error) => Feed::Error { error, remaining },
        }
    }

    /// Feeds all of `input`, calling `on_frame` for each whole frame or error, in order.
    pub fn feed_all(
        &mut self,
        mut input: &[u8],
        mut on_frame: impl FnMut(Result<Frame<'_>, DeframeError>),
    ) {
        while !input.is_empty() {
            input = match self.feed(input) {
                Feed::Consumed => return,
                Feed::Frame { frame, remaining } => {
                    on_frame(Ok(frame));
                    remaining
                }
                Feed::Error { error, remaining } => {
                    on_frame(Err(error));
                    remaining
                }
            };
        }
    }

    fn push(&mut self, bytes: &[u8]) {
        if self.overflowed {
            return;
        }
        if let Some(dst) = self.buf.get_mut(self.len..self.len + bytes.len()) {
            dst.copy_from_slice(bytes);
            self.len += bytes.len();
        } else {
            self.overflowed = true;
            self.len = 0;
        }
    }
}

/// Decodes one COBS block (delimiter stripped, so it is non-empty and has no 0x00) in place and
/// checks length and CRC.
fn decode_block(block: &mut [u8]) -> Result<Frame<'_>, DeframeError> {
    let len = cobs::decode_in_place(block).map_err(|_| DeframeError::Cobs)?;
    let raw = &block[..len];
    if len < HEADER_LEN + CRC_LEN {
        return Err(DeframeError::TooShort { len });
    }
    let (body, crc_bytes) = raw.split_at(len - CRC_LEN);
    let crc = u32::from_le_bytes([crc_bytes[0], crc_bytes[1], crc_bytes[2], crc_bytes[3]]);
    if CRC32.checksum(body) != crc {
        return Err(DeframeError::BadCrc);
    }
    let (header, payload) = body.split_at(HEADER_LEN);
    let header = Header::from_bytes([
        header[0], header[1], header[2], header[3], header[4], header[5],
    ]);
    Ok(Frame { header, payload })
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn frame_bytes(header: Header, payload: &[u8]) -> Vec<u8> {
        let mut out = [0u8; MAX_FRAME_LEN];
        let n = encode_raw(header, payload, &mut out).unwrap();
        out[..n].to_vec()
    }

    #[test]
    fn header_bytes_are_fixed() {
        let h = Header {
            version: 1,
            msg_id: 0x0102,
            seq: 0xBEEF,
            flags: Flags::ACK_REQUESTED,
        };
        assert_eq!(h.to_bytes(), [1, 0x02, 0x01, 0xEF, 0xBE, 0x01]);
        assert_eq!(Header::from_bytes(h.to_bytes()), h);
    }

    #[test]
    fn golden_empty_frame() {
        // Header only: version 1, id 0x0002, seq 7, no flags; CRC-32 over those 6 bytes.
        let h = Header {
            version: 1,
            msg_id: 2,
            seq: 7,
            flags: Flags::NONE,
        };
        let bytes = frame_bytes(h, &[]);
        let crc = CRC32.checksum(&[1, 2, 0, 7, 0, 0]).to_le_bytes();
        let mut raw = vec![1, 2, 0, 7, 0, 0];
        raw.extend(crc);
        let mut expect = vec![0u8; 16];
        let n = cobs::try_encode(&raw, &mut expect).unwrap();
        expect.truncate(n);
        expect.push(0);
        assert_eq!(bytes, expect);
        assert_eq!(*bytes.last().unwrap(), 0);
        assert!(!bytes[..bytes.len() - 1].contains(&0));
    }

    #[test]
    fn deframer_splits_and_resyncs() {
        let h = Header::new(0x0101, 1, Flags::NONE);
        let mut stream = vec![0x55, 0x13, 0x37, 0x00]; // garbage then a delimiter
        stream.extend(frame_bytes(h, b"hello"));
        stream.extend([0x00, 0x00]); // idle delimiters
        stream.extend(frame_bytes(Header::new(0x0101, 2, Flags::NONE), b"x"));
        let mut d = Deframer::<MAX_FRAME_LEN>::new();
        let mut got = Vec::new();
        for chunk in stream.chunks(3) {
            d.feed_all(chunk, |r| {
                got.push(r.map(|f| (f.header.seq, f.payload.to_vec())));
            });
        }
        assert_eq!(got.len(), 3);
        assert!(got[0].is_err());
        assert_eq!(got[1], Ok((1, b"hello".to_vec())));
        assert_eq!(got[2], Ok((2, b"x".to_vec())));
    }

    #[test]
    fn deframer_reports_oversize_then_recovers() {
        let mut d = Deframer::<32>::new();
        let mut errs = Vec::new();
        d.feed_all(&[0x22; 100], |r| errs.push(r.map(|f| f.header)));
        assert!(errs.is_empty());
        d.feed_all(&[0x00], |r| errs.push(r.map(|f| f.header)));
        assert_eq!(errs, vec![Err(DeframeError::Oversize)]);
        let h = Header::new(9, 9, Flags::NONE);
        let bytes = frame_bytes(h, &[1, 2, 3]);
        let mut ok = Vec::new();
        d.feed_all(&bytes, |r| ok.push(r.map(|f| f.header)));
        assert_eq!(ok, vec![Ok(h)]);
    }

    #[test]
    fn deframer_rejects_bad_crc_and_short() {
        let mut bytes = frame_bytes(Header::new(5, 5, Flags::NONE), &[9, 9, 9]);
        bytes[3] ^= 0x40;
        if bytes[3] == 0 {
            bytes[3] = 0x41;
        }
        let mut d = Deframer::<MAX_FRAME_LEN>::new();
        let mut got = Vec::new();
        d.feed_all(&bytes, |r| got.push(r.map(|f| f.header)));
        assert_eq!(got.len(), 1);
        assert!(matches!(
            got[0],
            Err(DeframeError::BadCrc | DeframeError::Cobs)
        ));
        got.clear();
        d.feed_all(&[0x03, 0x01, 0x02, 0x00], |r| got.push(r.map(|f| f.header)));
        assert_eq!(got, vec![Err(DeframeError::TooShort { len: 2 })]);
    }

    fn cobs_of(raw: &[u8]) -> Vec<u8> {
        let mut out = vec![0; cobs::max_encoding_length(raw.len())];
        let n = cobs::try_encode(raw, &mut out).unwrap();
        out.truncate(n);
        out
    }

    /// COBS as Cheshire and Baker's paper writes it, byte for byte: the wire encoding.
    fn reference_cobs(raw: &[u8]) -> Vec<u8> {
        let mut out = vec![0];
        let mut code_at = 0;
        for &byte in raw {
            if byte != 0 {
                out.push(byte);
            }
            if byte == 0 || out.len() - code_at == 0xFF {
                out[code_at] = u8::try_from(out.len() - code_at).unwrap();
                code_at = out.len();
                out.push(0);
            }
        }
        out[code_at] = u8::try_from(out.len() - code_at).unwrap();
        out
    }

    #[test]
    fn cobs_wire_vectors() {
        assert_eq!(cobs_of(&[0x00]), [0x01, 0x01]);
        assert_eq!(cobs_of(&[0x00, 0x00]), [0x01, 0x01, 0x01]);
        assert_eq!(cobs_of(&[0x00, 0x11, 0x00]), [0x01, 0x02, 0x11, 0x01]);
        assert_eq!(
            cobs_of(&[0x11, 0x22, 0x00, 0x33]),
            [0x03, 0x11, 0x22, 0x02, 0x33]
        );
        assert_eq!(
            cobs_of(&[0x11, 0x00, 0x00, 0x00]),
            [0x02, 0x11, 0x01, 0x01, 0x01]
        );
        let run: Vec<u8> = (1..=253).collect();
        let mut expected = vec![0xFE];
        expected.extend(&run);
        assert_eq!(cobs_of(&run), expected);
        assert_eq!(reference_cobs(&run), expected);
    }

    #[test]
    fn truncated_block_is_a_cobs_error() {
        // The code byte 0x0C promises eleven bytes; two follow.
        assert_eq!(
            decode_block(&mut [0x0C, 0x11, 0x22]),
            Err(DeframeError::Cobs)
        );
    }

    proptest! {
        #[test]
        fn cobs_is_the_reference_encoding_up_to_max_raw_len(
            raw in proptest::collection::vec(prop_oneof![Just(0u8), any::<u8>()], 1..=MAX_RAW_LEN)
        ) {
            let encoded = cobs_of(&raw);
            prop_assert_eq!(&encoded, &reference_cobs(&raw));
            let mut block = encoded.clone();
            let n = cobs::decode_in_place(&mut block).unwrap();
            prop_assert_eq!(&block[..n], &raw[..]);
        }

        #[test]
        fn encode_refuses_a_buffer_one_byte_short(
            payload in proptest::collection::vec(prop_oneof![Just(0u8), any::<u8>()], 0..=MAX_PAYLOAD_LEN)
        ) {
            let header = Header::new(1, 1, Flags::NONE);
            let len = frame_bytes(header, &payload).len();
            let mut short = vec![0; len - 1];
            prop_assert_eq!(encode_raw(header, &payload, &mut short), Err(EncodeError::OutputTooSmall));
        }

        #[test]
        fn cobs_decode_never_panics(block in proptest::collection::vec(1u8..=255, 1..600)) {
            let mut buf = block.clone();
            let _ = cobs::decode_in_place(&mut buf);
            let mut buf = block;
            let _ = decode_block(&mut buf);
        }
    }
}
