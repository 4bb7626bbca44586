//! VLP-16 decoding, frame assembly and sources (DESIGN.md section 6 step 1).
//!
//! - [`packet`]: the 1206-byte data packet as a checked view [`Vlp16Packet`] plus
//!   [`DataPacketRepr`] parse/emit (the simulator builds byte-exact packets with `emit`).
//! - [`position`]: the 512-byte position packet (timestamp, PPS state, NMEA).

pub mod packet;
pub mod position;

pub use packet::{
    BlockRepr, ChannelRepr, DataPacketRepr, PacketError, Product, ReturnMode, Vlp16Packet,
};
pub use position::{PositionError, PositionPacket, PositionPacketRepr, PpsStatus};
