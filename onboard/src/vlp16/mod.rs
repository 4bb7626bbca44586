//! VLP-16 decoding, frame assembly and sources (docs/architecture.md section 6 step 1).
//!
//! - [`packet`]: the 1206-byte data packet as a checked view [`Vlp16Packet`] plus
//!   [`DataPacketRepr`] parse/emit (the simulator builds byte-exact packets with `emit`).
//! - [`position`]: the 512-byte position packet (timestamp, PPS state, NMEA).
//! - [`decoder`]: [`FrameAssembler`], the pure packet → point → frame stage.
//! - [`source`]: [`source::PacketSource`] over live UDP ([`source::UdpSource`]) and capture files
//!   ([`source::PcapSource`]).

pub mod decoder;
pub mod packet;
pub mod position;
pub mod source;

pub use decoder::{
    AzimuthInterpolation, ConfigError, DecodeError, DecodeStats, DecoderConfig, Frame,
    FrameAssembler, Point, ReturnKind,
};

pub use packet::{
    BlockRepr, ChannelRepr, DataPacketRepr, PacketError, Product, ReturnMode, Vlp16Packet,
};
pub use position::{PositionError, PositionPacket, PositionPacketRepr, PpsStatus};
