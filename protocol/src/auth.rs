//! Authentication of radio commands that move the robot.
//!
//! A command `M` travels as [`Authenticated<M>`]`{ counter, body, tag }`. The tag is
//! HMAC-SHA256 (RFC 2104, FIPS 180-4) keyed with the pre-shared pairing key, over
//!
//! ```text
//!   header bytes (6: version, msg id, seq, flags)  ||  postcard(counter: u64 varint, body: M)
//! ```
//!
//! truncated to its first 16 bytes. Why truncate: the radio runs at 57600 baud and every byte costs
//! airtime and loss probability; a 128-bit tag still leaves a forger a 2^-128 chance per attempt,
//! and RFC 2104 section 5 and NIST SP 800-107 allow truncation to at least half the hash length.
//!
//! Replay: the receiver keeps the last accepted counter (the onboard persists it across restarts)
//! and accepts only a larger one. The same counter with the same tag is a retransmission of the
//! accepted command (its ack was lost): [`Verified::Duplicate`], to be acked again but not acted on.
//! Senders use a counter that never repeats for a key, e.g. microseconds since the Unix epoch,
//! kept above the last one they used.

use hmac::{Hmac, Mac};
use postcard::experimental::max_size::MaxSize;
use serde::{Deserialize, Serialize};
use sha2::Sha256;

use crate::frame::{HEADER_LEN, Header, MAX_PAYLOAD_LEN};

/// Bytes of the truncated tag.
pub const TAG_LEN: usize = 16;
/// Bytes of a pairing key.
pub const KEY_LEN: usize = 32;

/// A pre-shared pairing key.
#[derive(Clone, PartialEq, Eq)]
pub struct Key(pub [u8; KEY_LEN]);

impl core::fmt::Debug for Key {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str("Key(<redacted>)")
    }
}

/// A command with its counter and tag.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Authenticated<M> {
    /// Monotonic counter (never reused for a key).
    pub counter: u64,
    /// The command.
    pub body: M,
    /// First 16 bytes of the HMAC-SHA256 tag.
    pub tag: [u8; TAG_LEN],
}

impl<M: MaxSize> MaxSize for Authenticated<M> {
    const POSTCARD_MAX_SIZE: usize = u64::POSTCARD_MAX_SIZE + M::POSTCARD_MAX_SIZE + TAG_LEN;
}

/// Why an authenticated command was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum AuthError {
    /// The tag does not match: wrong key or tampered frame.
    BadTag,
    /// The counter is not newer than the last accepted one.
    Replay {
        /// The counter received.
        counter: u64,
        /// The last accepted counter.
        last: u64,
    },
    /// The body did not serialise within the payload bound.
    Encoding,
}

impl core::fmt::Display for AuthError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::BadTag => write!(
                f,
                "authentication tag mismatch (wrong pairing key or tampered)"
            ),
            Self::Replay { counter, last } => {
                write!(f, "replayed command: counter {counter} is not above {last}")
            }
            Self::Encoding => write!(f, "command does not serialise within the payload bound"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for AuthError {}

fn mac_input<M: Serialize>(
    counter: u64,
    body: &M,
    buf: &mut [u8; MAX_PAYLOAD_LEN],
) -> Result<usize, AuthError> {
    postcard::to_slice(&(counter, body), buf)
        .map(|s| s.len())
        .map_err(|_| AuthError::Encoding)
}

fn full_tag(key: &Key, header: Header, signed: &[u8]) -> Hmac<Sha256> {
    // HMAC accepts keys of any length, so this cannot fail.
    let mut mac = <Hmac<Sha256> as Mac>::new_from_slice(&key.0).unwrap_or_else(|_| unreachable!());
    let header_bytes: [u8; HEADER_LEN] = header.to_bytes();
    mac.update(&header_bytes);
    mac.update(signed);
    mac
}

/// Signs `body` for sending under `header` (the exact header the frame will carry).
pub fn sign<M: Serialize>(
    key: &Key,
    header: Header,
    counter: u64,
    body: M,
) -> Result<Authenticated<M>, AuthError> {
    let mut buf = [0u8; MAX_PAYLOAD_LEN];
    let len = mac_input(counter, &body, &mut buf)?;
    let out = full_tag(key, header, &buf[..len]).finalize().into_bytes();
    let mut tag = [0u8; TAG_LEN];
    tag.copy_from_slice(&out[..TAG_LEN]);
    Ok(Authenticated { counter, body, tag })
}

/// Checks the tag only (constant time), without replay state.
pub fn check_tag<M: Serialize>(
    key: &Key,
    header: Header,
    msg: &Authenticated<M>,
) -> Result<(), AuthError> {
    let mut buf = [0u8; MAX_PAYLOAD_LEN];
    let len = mac_input(msg.counter, &msg.body, &mut buf)?;
    full_tag(key, header, &buf[..len])
        .verify_truncated_left(&msg.tag)
        .map_err(|_| AuthError::BadTag)
}

/// Outcome of a successful verification.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verified {
    /// A new command: act on it.
    Fresh,
    /// The last accepted command again (a retransmission): ack it, do not act again.
    Duplicate,
}

/// Receiver-side replay state: the last accepted counter and tag.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct ReplayGuard {
    last_counter: u64,
    last_tag: Option<[u8; TAG_LEN]>,
}

impl ReplayGuard {
    /// Starts from a persisted last counter (0 for a fresh pairing).
    pub const fn new(last_counter: u64) -> Self {
        Self {
            last_counter,
            last_tag: None,
        }
    }

    /// The last accepted counter (persist it after every [`Verified::Fresh`]).
    pub const fn last_counter(&self) -> u64 {
        self.last_counter
    }

    /// Verifies tag and freshness; on [`Verified::Fresh`] the counter is advanced.
    pub fn verify<M: Serialize>(
        &mut self,
        key: &Key,
        header: Header,
        msg: &Authenticated<M>,
    ) -> Result<Verified, AuthError> {
        check_tag(key, header, msg)?;
        if msg.counter > self.last_counter {
            self.last_counter = msg.counter;
            self.last_tag = Some(msg.tag);
            return Ok(Verified::Fresh);
        }
        if msg.counter == self.last_counter && self.last_tag == Some(msg.tag) {
            return Ok(Verified::Duplicate);
        }
        Err(AuthError::Replay {
            counter: msg.counter,
            last: self.last_counter,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hmac_sha256(key: &[u8], data: &[u8]) -> [u8; 32] {
        let mut mac = <Hmac<Sha256> as Mac>::new_from_slice(key).unwrap();
        mac.update(data);
        mac.finalize().into_bytes().into()
    }

    fn hex(s: &str) -> Vec<u8> {
        (0..s.len())
            .step_by(2)
            .map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap())
            .collect()
    }

    /// RFC 4231 test cases 1, 2, 3, 4, 6 and 7 (case 5 is a truncation case, checked below).
    #[test]
    fn rfc4231_vectors() {
        let cases: &[(Vec<u8>, Vec<u8>, &str)] = &[
            (vec![0x0b; 20], b"Hi There".to_vec(),
             "b0344c61d8db38535ca8afceaf0bf12b881dc200c9833da726e9376c2e32cff7"),
            (b"Jefe".to_vec(), b"what do ya want for nothing?".to_vec(),
             "5bdcc146bf60754e6a042426089575c75a003f089d2739839dec58b964ec3843"),
            (vec![0xaa; 20], vec![0xdd; 50],
             "773ea91e36800e46854db8ebd09181a72959098b3ef8c122d9635514ced565fe"),
            ((1..=25).collect(), vec![0xcd; 50],
             "82558a389a443c0ea4cc819899f2083a85f0faa3e578f8077a2e3ff46729665b"),
            (vec![0xaa; 131], b"Test Using Larger Than Block-Size Key - Hash Key First".to_vec(),
             "60e431591ee0b67f0d8a26aacbf5b77f8e0bc6213728c5140546040f0ee37f54"),
            (vec![0xaa; 131],
             b"This is a test using a larger than block-size key and a larger than block-size data. The key needs to be hashed before being used by the HMAC algorithm.".to_vec(),
             "9b09ffa71b942fcb27635fbcd5b0e944bfdc63644f0713938a7f51535c3a35e2"),
        ];
        for (key, data, expect) in cases {
            assert_eq!(hmac_sha256(key, data).to_vec(), hex(expect));
        }
        // Case 5: truncation to 128 bits.
        let t = hmac_sha256(&[0x0c; 20], b"Test With Truncation");
        assert_eq!(t[..16].to_vec(), hex("a3b6167473100ee06e0c796c2955552b"));
    }

    fn key() -> Key {
        Key([7; KEY_LEN])
    }

    #[test]
    fn sign_verify_replay_duplicate() {
        let h = Header::new(
            crate::ids::START_MEASUREMENT,
            10,
            crate::frame::Flags::ACK_REQUESTED,
        );
        let mut guard = ReplayGuard::new(100);
        let m = sign(&key(), h, 101, 42u32).unwrap();
        assert_eq!(guard.verify(&key(), h, &m), Ok(Verified::Fresh));
        assert_eq!(guard.last_counter(), 101);
        assert_eq!(guard.verify(&key(), h, &m), Ok(Verified::Duplicate));
        let old = sign(&key(), h, 50, 42u32).unwrap();
        assert_eq!(
            guard.verify(&key(), h, &old),
            Err(AuthError::Replay {
                counter: 50,
                last: 101
            })
        );
        // Same counter, other body: a replay, not a duplicate.
        let other = sign(&key(), h, 101, 43u32).unwrap();
        assert_eq!(
            guard.verify(&key(), h, &other),
            Err(AuthError::Replay {
                counter: 101,
                last: 101
            })
        );
    }

    #[test]
    fn tampering_is_detected() {
        let h = Header::new(
            crate::ids::START_MEASUREMENT,
            10,
            crate::frame::Flags::ACK_REQUESTED,
        );
        let mut guard = ReplayGuard::new(0);
        let m = sign(&key(), h, 1, 42u32).unwrap();
        let wrong_key = Key([8; KEY_LEN]);
        assert_eq!(guard.verify(&wrong_key, h, &m), Err(AuthError::BadTag));
        let mut body = m.clone();
        body.body = 41;
        assert_eq!(guard.verify(&key(), h, &body), Err(AuthError::BadTag));
        let mut counter = m.clone();
        counter.counter = 2;
        assert_eq!(guard.verify(&key(), h, &counter), Err(AuthError::BadTag));
        let other_seq = Header::new(h.msg_id, 11, h.flags);
        assert_eq!(guard.verify(&key(), other_seq, &m), Err(AuthError::BadTag));
        let mut tag = m.clone();
        tag.tag[15] ^= 1;
        assert_eq!(guard.verify(&key(), h, &tag), Err(AuthError::BadTag));
        assert_eq!(guard.last_counter(), 0, "nothing was accepted");
        assert_eq!(guard.verify(&key(), h, &m), Ok(Verified::Fresh));
    }
}
