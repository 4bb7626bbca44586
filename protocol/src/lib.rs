//! # passangle wire protocol: interface control document
//!
//! One `no_std`, allocation-free crate shared by the STM32 firmware, the onboard service, the
//! handheld CLI and the simulator. It defines two serial links and the ESC CAN codec:
//!
//! | link  | ends                         | physical                                  | messages            |
//! |-------|------------------------------|-------------------------------------------|---------------------|
//! | MCU   | onboard PC <-> STM32         | UART 921600 8N1, nearly clean             | [`mcu`]             |
//! | radio | handheld <-> onboard PC      | transparent radio modems, 57600, lossy    | [`radio`], [`auth`] |
//! | CAN   | STM32 <-> 4 x DJI C620 ESC   | CAN 1 Mbit/s                              | [`esc`]             |
//!
//! ## Frames (both serial links)
//!
//! ```text
//!  COBS( version u8 | msg id u16 LE | seq u16 LE | flags u8 | postcard payload | CRC-32 u32 LE ) 0x00
//! ```
//!
//! - COBS (the [`cobs`] crate) removes every 0x00 so that 0x00 delimits frames; a receiver that starts mid-frame
//!   or sees garbage resynchronises at the next 0x00. All ends use the one IO-free
//!   [`frame::Deframer`].
//! - CRC-32/ISO-HDLC over header and payload. A frame with a bad CRC is dropped and counted.
//! - The payload is the message in postcard's wire format (varints for integers wider than a byte,
//!   IEEE-754 little-endian floats, length-prefixed bounded lists and text). Enums that appear in
//!   messages are one-byte wire enums with explicit values, never postcard's declaration-order index.
//! - Flags: [`frame::Flags::ACK_REQUESTED`] asks the receiver to answer with an ack: a frame with the
//!   same msg id and seq, [`frame::Flags::IS_ACK`] set and an empty payload. Commands on the radio are
//!   retransmitted (same seq, same bytes) until acked; receivers ack duplicates again but act once.
//! - Largest frame on either link: [`frame::MAX_FRAME_LEN`] = 256 bytes with delimiter; the largest
//!   payload is [`frame::MAX_PAYLOAD_LEN`]. Every message's worst case is bounded at compile time
//!   ([`postcard::experimental::max_size::MaxSize`]) and checked against it by the tests.
//!
//! ## Message ids
//!
//! Explicit constants in [`ids`]: `0x00xx` both links, `0x01xx` onboard -> firmware, `0x018x`
//! firmware -> onboard, `0x02xx` handheld -> onboard, `0x028x` onboard -> handheld.
//!
//! ## Compatibility rules
//!
//! - [`Hello`] (`0x0001`, payload `version: u8, role: u8`) and the six-byte header layout are frozen
//!   forever: any version can decode them, so mismatched ends say "peer speaks version N".
//! - Any change to the bytes of any message bumps [`PROTOCOL_VERSION`]; the golden-bytes snapshot
//!   (`protocol/tests/snapshots/wire.snap`) fails on any drift. Ends refuse all messages but `Hello`
//!   from another version.
//! - New messages get new ids; ids are never reused.
//!
//! ## Authentication
//!
//! Every radio frame but the two handshake messages is sealed in a Noise `NNpsk0` session keyed
//! with the pre-shared pairing key (ChaCha20-Poly1305 with explicit nonces and a replay window);
//! see [`auth`] and [`radio`].
#![cfg_attr(not(any(test, feature = "std")), no_std)]
#![forbid(unsafe_code)]
#![warn(
    missing_docs,
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::cast_possible_wrap
)]

pub mod auth;
pub mod bounded;
pub mod common;
pub mod esc;
pub mod frame;
pub mod mcu;
pub mod message;
pub mod radio;

pub use common::{Heartbeat, Hello, LogLevel, LogLine, Role};
pub use frame::{Deframer, Flags, Frame, Header};
pub use message::{DecodeError, Message};

/// Version of this protocol. Bump on any change to the bytes of any message.
pub const PROTOCOL_VERSION: u8 = 6;

/// Message ids. Explicit, never derived from declaration order; never reused.
pub mod ids {
    /// [`crate::Hello`]. FROZEN.
    pub const HELLO: u16 = 0x0001;
    /// [`crate::Heartbeat`].
    pub const HEARTBEAT: u16 = 0x0002;
    /// [`crate::LogLine`].
    pub const LOG_LINE: u16 = 0x0003;
    /// A sealed radio frame (both directions; see [`crate::auth`]).
    pub const SEALED: u16 = 0x0004;

    /// [`crate::mcu::Drive`].
    pub const DRIVE: u16 = 0x0101;
    /// [`crate::mcu::Stop`].
    pub const STOP: u16 = 0x0102;
    /// [`crate::mcu::McuConfig`].
    pub const SET_CONFIG: u16 = 0x0103;
    /// [`crate::mcu::ClearFaults`].
    pub const CLEAR_FAULTS: u16 = 0x0104;
    /// [`crate::mcu::Odometry`].
    pub const ODOMETRY: u16 = 0x0181;
    /// [`crate::mcu::Status`].
    pub const STATUS: u16 = 0x0182;
    /// [`crate::mcu::Rejected`].
    pub const REJECTED: u16 = 0x0183;

    /// [`crate::radio::StartMeasurement`].
    pub const START_MEASUREMENT: u16 = 0x0201;
    /// [`crate::radio::Abort`].
    pub const ABORT: u16 = 0x0202;
    /// [`crate::radio::ResultAck`].
    pub const RESULT_ACK: u16 = 0x0203;
    /// [`crate::radio::ResendChunks`].
    pub const RESEND_CHUNKS: u16 = 0x0204;
    /// [`crate::radio::StatusRequest`].
    pub const STATUS_REQUEST: u16 = 0x0205;
    /// [`crate::radio::FetchRun`].
    pub const FETCH_RUN: u16 = 0x0206;
    /// [`crate::radio::HandshakeInit`].
    pub const HANDSHAKE_INIT: u16 = 0x0207;
    /// [`crate::radio::ResendRecordChunks`].
    pub const RESEND_RECORD_CHUNKS: u16 = 0x0208;
    /// [`crate::radio::LabChunk`].
    pub const LAB_CHUNK: u16 = 0x0209;
    /// [`crate::radio::Progress`].
    pub const PROGRESS: u16 = 0x0281;
    /// [`crate::radio::MeasurementResult`].
    pub const RESULT: u16 = 0x0282;
    /// [`crate::radio::CloudChunk`].
    pub const CLOUD_CHUNK: u16 = 0x0283;
    /// [`crate::radio::RobotStatus`].
    pub const ROBOT_STATUS: u16 = 0x0284;
    /// [`crate::radio::Refused`].
    pub const REFUSED: u16 = 0x0285;
    /// [`crate::radio::HandshakeReply`].
    pub const HANDSHAKE_REPLY: u16 = 0x0286;
    /// [`crate::radio::RecordChunk`].
    pub const RECORD_CHUNK: u16 = 0x0287;
}
