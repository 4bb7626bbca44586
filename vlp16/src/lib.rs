//! VLP-16 decoding, frame assembly and sources (docs/architecture.md section 6 step 1), and the
//! pcap reader and writer the sources and the run recorder share.
//!
//! - [`packet`]: the 1206-byte data packet as a checked view [`Vlp16Packet`] plus
//!   [`DataPacketRepr`] parse/emit (the simulator builds byte-exact packets with `emit`).
//! - [`position`]: the 512-byte position packet (timestamp, PPS state, NMEA).
//! - [`decoder`]: [`FrameAssembler`], the pure packet → point → frame stage.
//! - [`source`]: [`source::PacketSource`] over live UDP ([`source::UdpSource`]) and capture files
//!   ([`source::PcapSource`]).
//! - [`pcap`]: the checked pcap/pcapng reader, classic-pcap writer and UDP unwrapping.

pub mod calibration;
pub mod decoder;
pub mod packet;
pub mod pcap;
pub mod position;
pub mod source;
pub mod travel;

pub use decoder::{
    AzimuthInterpolation, ConfigError, DecodeError, DecodeStats, DecoderConfig, Frame,
    FrameAssembler, MAX_RANGE_OFFSET_M, Point, RANGE_ACCURACY_M, ReturnKind,
};

pub use packet::{
    BlockRepr, ChannelRepr, DataPacketRepr, PacketError, Product, ReturnMode, Vlp16Packet,
};
pub use position::{PositionError, PositionPacket, PositionPacketRepr, PpsStatus};
