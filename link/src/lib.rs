//! Links: the IO-free cores of the radio link (handheld <-> onboard) and the MCU link
//! (onboard <-> firmware). The shells (serial ports, pseudo-terminals, in-memory pipes) only move
//! bytes and time in and out.
//!
//! - [`reliable`]: acks, retransmits with backoff, duplicate suppression by seq, heartbeats,
//!   liveness and a byte-rate limit; used by every end.
//! - [`session`]: the radio's Noise session (handshake, sealed frames, replay window).
//! - [`keys`]: pairing-key files (per-handheld keys with public ids).
//! - [`radio`]: the onboard's radio end (sessions, refusals, results held until acknowledged,
//!   preview chunks with selective resend, per-session rate limits).
//! - [`handheld`]: the handheld's radio end (handshake, preview reassembly and resend requests,
//!   result acks).
//! - [`mcu`]: the onboard's MCU session (hello, config, drive/stop, 20 ms heartbeat).
//! - [`preview`]: cloud decimation, quantisation and chunking.
//! - [`record_files`]: a run's record files (`result.json` and its signature), byte-exact in
//!   chunks.
//! - [`sim`]: a seeded lossy byte pipe for tests and the simulator.
//! - [`record`]: the result record (`result.json`) the link delivers, the robot records and the
//!   handheld saves.
//! - [`client`]: the handheld's blocking client over a [`Port`].

use std::io::{Read, Write};

pub mod chunks;
pub mod client;
pub mod handheld;
pub mod keys;
pub mod mcu;
pub mod preview;
pub mod radio;
pub mod record;
pub mod record_files;
pub mod reliable;
pub mod session;
pub mod sim;

/// A byte stream to a peer (a serial port, a pseudo-terminal, an in-memory pipe). Reads return
/// `Ok(0)`, `WouldBlock` or `TimedOut` when nothing is there; they must not block for long.
pub trait Port: Read + Write + Send {}
impl<T: Read + Write + Send> Port for T {}

#[cfg(test)]
mod tests;
