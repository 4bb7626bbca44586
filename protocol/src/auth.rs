//! Radio session: pairing keys, key ids, the sealed-frame layout and the replay window.
//!
//! Every radio frame after the handshake is *sealed*: the whole inner frame (six-byte header and
//! postcard payload, no CRC) is encrypted and authenticated with ChaCha20-Poly1305 under a
//! per-direction transport key of a Noise `NNpsk0` session (Noise protocol framework, revision 34;
//! the pairing key is the PSK). The outer frame is an ordinary frame:
//!
//! ```text
//!  outer header: version | msg id = ids::SEALED | seq = session id (u16) | flags 0
//!  outer payload: nonce u64 LE | ChaCha20-Poly1305(inner header | inner payload) incl. 16-byte tag
//! ```
//!
//! The nonce is explicit (WireGuard / DTLS style), so a receiver decrypts any frame that arrives,
//! in any order, after any loss; the [`ReplayWindow`] accepts each nonce at most once and refuses
//! nonces older than its window. Sessions are created by the handshake (see
//! `link::session`); every handshake derives fresh keys, so no counter has to survive a
//! restart.
//!
//! This module stays `no_std`: it has the wire layout, the key type and the replay window. The
//! Noise handshake and the AEAD live in the onboard crate (the `snow` crate needs `alloc`).

use sha2::{Digest, Sha256};

use crate::frame::{HEADER_LEN, MAX_PAYLOAD_LEN};

/// Bytes of a pairing key.
pub const KEY_LEN: usize = 32;
/// Bytes of the explicit nonce in front of a sealed payload.
pub const NONCE_LEN: usize = 8;
/// Bytes of the AEAD tag (Poly1305).
pub const AEAD_TAG_LEN: usize = 16;
/// Bytes a sealed frame's payload adds to the inner frame (nonce and tag).
pub const SEAL_OVERHEAD: usize = NONCE_LEN + AEAD_TAG_LEN;
/// Largest inner payload that still fits a sealed frame: the outer payload holds the nonce, the
/// inner header, the inner payload and the tag.
pub const MAX_INNER_PAYLOAD_LEN: usize = MAX_PAYLOAD_LEN - SEAL_OVERHEAD - HEADER_LEN;
/// Bytes of a Noise `NNpsk0` handshake message without payload (an ephemeral key and a tag).
pub const HANDSHAKE_MSG_LEN: usize = 48;

/// A pre-shared pairing key.
#[derive(Clone, PartialEq, Eq)]
pub struct Key(pub [u8; KEY_LEN]);

impl core::fmt::Debug for Key {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "Key(id {:08x})", key_id(self))
    }
}

/// The public id of a pairing key: the first four bytes (big-endian) of
/// SHA-256("passangle key id" || key). It names the key in handshakes, in `passangle pair`'s
/// output and in the robot's key list; it reveals nothing usable about the key.
pub fn key_id(key: &Key) -> u32 {
    let digest = Sha256::new()
        .chain_update(b"passangle key id")
        .chain_update(key.0)
        .finalize();
    u32::from_be_bytes([digest[0], digest[1], digest[2], digest[3]])
}

/// Width of the [`ReplayWindow`], nonces.
pub const REPLAY_WINDOW: u64 = 1024;

/// Outcome of [`ReplayWindow::check`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Replay {
    /// Not seen: accept (after the AEAD verified, call [`ReplayWindow::mark`]).
    Fresh,
    /// Seen before: drop.
    Seen,
    /// Older than the window: drop.
    TooOld,
}

/// Sliding anti-replay window over 64-bit nonces (RFC 6479 style bitmap): the highest nonce
/// accepted and which of the [`REPLAY_WINDOW`] nonces below it were accepted. Reordering within
/// the window and any loss are fine; each nonce is accepted at most once.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ReplayWindow {
    /// Highest accepted nonce + 1 (0: none accepted yet).
    top: u64,
    /// Bit `n % REPLAY_WINDOW` is set when nonce `n` (within the window) was accepted.
    bits: [u64; (REPLAY_WINDOW / 64) as usize],
}

impl Default for ReplayWindow {
    fn default() -> Self {
        Self::new()
    }
}

impl ReplayWindow {
    /// A window that has accepted nothing.
    pub const fn new() -> Self {
        Self {
            top: 0,
            bits: [0; (REPLAY_WINDOW / 64) as usize],
        }
    }

    fn slot(nonce: u64) -> (usize, u64) {
        let i = nonce % REPLAY_WINDOW;
        ((i / 64) as usize, 1u64 << (i % 64))
    }

    /// Whether `nonce` would be accepted (checked before decrypting; nothing changes).
    pub fn check(&self, nonce: u64) -> Replay {
        if nonce == u64::MAX {
            // Noise reserves 2^64 - 1; it also keeps `top` from overflowing.
            return Replay::TooOld;
        }
        if nonce >= self.top {
            return Replay::Fresh;
        }
        if self.top - nonce > REPLAY_WINDOW {
            return Replay::TooOld;
        }
        let (word, bit) = Self::slot(nonce);
        if self.bits[word] & bit == 0 {
            Replay::Fresh
        } else {
            Replay::Seen
        }
    }

    /// Records `nonce` as accepted (call only after the AEAD verified the frame). Returns false
    /// (and changes nothing) when [`Self::check`] would not say [`Replay::Fresh`].
    pub fn mark(&mut self, nonce: u64) -> bool {
        if self.check(nonce) != Replay::Fresh {
            return false;
        }
        if nonce >= self.top {
            // Clear the slots the window slides past (all of them after a long jump).
            let advance = nonce - self.top + 1;
            if advance >= REPLAY_WINDOW {
                self.bits = [0; (REPLAY_WINDOW / 64) as usize];
            } else {
                for n in self.top..=nonce {
                    let (word, bit) = Self::slot(n);
                    self.bits[word] &= !bit;
                }
            }
            self.top = nonce + 1;
        }
        let (word, bit) = Self::slot(nonce);
        self.bits[word] |= bit;
        true
    }

    /// Highest accepted nonce (`None`: none yet).
    pub fn highest(&self) -> Option<u64> {
        self.top.checked_sub(1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn window_accepts_each_nonce_once_and_tolerates_reordering() {
        let mut w = ReplayWindow::new();
        assert_eq!(w.highest(), None);
        for n in [5, 1, 3, 2, 9, 4] {
            assert_eq!(w.check(n), Replay::Fresh, "nonce {n}");
            assert!(w.mark(n));
        }
        for n in [5, 1, 3, 2, 9, 4] {
            assert_eq!(w.check(n), Replay::Seen, "nonce {n} again");
            assert!(!w.mark(n));
        }
        assert_eq!(w.check(0), Replay::Fresh, "lost and late, still inside");
        assert_eq!(w.highest(), Some(9));
        assert!(w.mark(9 + REPLAY_WINDOW + 1));
        assert_eq!(w.check(9), Replay::TooOld);
        assert_eq!(w.check(5), Replay::TooOld);
        assert_eq!(w.check(9 + REPLAY_WINDOW), Replay::Fresh);
        assert!(!w.mark(u64::MAX), "the reserved nonce");
        assert!(w.mark(u64::MAX - 1));
        assert_eq!(w.check(u64::MAX - 1), Replay::Seen);
    }

    #[test]
    fn window_slide_clears_reused_slots() {
        let mut w = ReplayWindow::new();
        assert!(w.mark(3));
        // 3 + REPLAY_WINDOW shares 3's slot: sliding there must clear it, not report it seen.
        assert!(w.mark(3 + REPLAY_WINDOW));
        assert_eq!(w.check(3), Replay::TooOld);
        assert_eq!(w.check(4), Replay::Fresh);
        assert!(w.mark(4));
        assert_eq!(w.check(4), Replay::Seen);
    }

    #[test]
    fn key_ids_differ_per_key_and_hide_it() {
        let a = key_id(&Key([1; KEY_LEN]));
        let b = key_id(&Key([2; KEY_LEN]));
        assert_ne!(a, b);
        assert_eq!(a, key_id(&Key([1; KEY_LEN])));
        assert!(!format!("{:?}", Key([1; KEY_LEN])).contains("0101"));
    }

    #[test]
    fn sealed_budget_holds_the_largest_inner_payload() {
        assert_eq!(MAX_INNER_PAYLOAD_LEN, 210);
    }
}
