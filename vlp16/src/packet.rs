//! The VLP-16 data packet (UDP port 2368, 1206-byte payload) as a checked, zero-copy view plus a
//! `Repr` with `parse` and `emit`, in the style of smoltcp's `wire` module.
//!
//! Layout (VLP-16 User Manual 63-9243 Rev D, section 9; all multi-byte fields little-endian):
//!
//! ```text
//! offset  size  field
//!      0   100  data block 0: flag 0xFFEE (bytes FF EE), azimuth u16 (0.01 deg, 0..35999),
//!                             32 channel records of distance u16 (2 mm) + reflectivity u8
//!    100   100  data block 1
//!    ...
//!   1100   100  data block 11
//!   1200     4  timestamp u32, microseconds past the top of the hour (first firing of block 0)
//!   1204     1  return mode (0x37 strongest, 0x38 last, 0x39 dual)
//!   1205     1  product id (0x22 VLP-16; 0x21 from firmware older than 3.0.29.0)
//! ```
//!
//! Every byte of the payload is a field, so `emit(parse(bytes)) == bytes` for any valid packet and
//! the simulator can build byte-exact packets from a [`DataPacketRepr`].
//!
//! No-panic contract: [`Vlp16Packet::new_checked`] verifies the length once; after that every getter
//! reads inside the buffer. Getters that take a block or channel index panic only on an index out of
//! range (`block >= 12`, `channel >= 32`), which is a programming error, never a property of the
//! bytes. [`DataPacketRepr::parse`] never panics on any input.

use thiserror::Error;

/// Length of a VLP-16 data packet payload in bytes.
pub const DATA_PACKET_LEN: usize = 1206;
/// Data blocks per packet.
pub const BLOCKS_PER_PACKET: usize = 12;
/// Channel records per data block (two firing sequences of 16 lasers).
pub const CHANNELS_PER_BLOCK: usize = 32;
/// Lasers in one firing sequence.
pub const LASERS: usize = 16;
/// The block flag 0xFFEE as it appears on the wire (bytes FF EE), read as a little-endian u16.
pub const BLOCK_FLAG: u16 = 0xEEFF;
/// Azimuths are in hundredths of a degree, `0..=AZIMUTH_RAW_MAX`. Real sensors occasionally send
/// exactly 36000 (the VeloView sample capture has one), which is accepted and means 0.
pub const AZIMUTH_RAW_MAX: u16 = 36_000;
/// Distance unit: 2 mm.
pub const DISTANCE_RESOLUTION_M: f32 = 0.002;
/// UDP destination port of data packets.
pub const DATA_PORT: u16 = 2368;

/// Byte ranges of the fields.
pub mod field {
    use core::ops::Range;

    /// Size of one data block.
    pub const BLOCK_LEN: usize = 100;
    /// Flag, relative to the block start.
    pub const BLOCK_FLAG: Range<usize> = 0..2;
    /// Azimuth, relative to the block start.
    pub const BLOCK_AZIMUTH: Range<usize> = 2..4;
    /// First channel record, relative to the block start.
    pub const BLOCK_CHANNELS: usize = 4;
    /// Size of one channel record (distance u16 + reflectivity u8).
    pub const CHANNEL_LEN: usize = 3;
    /// Timestamp, microseconds past the hour.
    pub const TIMESTAMP: Range<usize> = 1200..1204;
    /// Return mode byte.
    pub const RETURN_MODE: usize = 1204;
    /// Product id byte.
    pub const PRODUCT: usize = 1205;
}

/// Why a data packet was rejected. Each variant names the field that was wrong.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum PacketError {
    /// The payload is not 1206 bytes long.
    #[error("data packet is {len} bytes, expected {DATA_PACKET_LEN}")]
    WrongLength {
        /// The length received.
        len: usize,
    },
    /// A block does not start with the flag bytes FF EE.
    #[error("block {block}: flag is {flag:#06x}, expected 0xeeff (bytes ff ee)")]
    BadBlockFlag {
        /// Block index 0..12.
        block: u8,
        /// The flag read (little-endian).
        flag: u16,
    },
    /// A block azimuth is above 36000 (360.00 degrees).
    #[error("block {block}: azimuth {azimuth_raw} (0.01 deg) is above 36000")]
    AzimuthOutOfRange {
        /// Block index 0..12.
        block: u8,
        /// The azimuth read.
        azimuth_raw: u16,
    },
    /// The return-mode byte is not 0x37, 0x38 or 0x39.
    #[error("return mode byte {0:#04x} is not 0x37 (strongest), 0x38 (last) or 0x39 (dual)")]
    UnknownReturnMode(u8),
    /// The product byte is not a VLP-16 (0x22, or 0x21 from old firmware).
    #[error("product byte {0:#04x} is not a VLP-16 (0x22, or 0x21 from firmware before 3.0.29.0)")]
    UnsupportedProduct(u8),
}

/// Return mode (factory byte at offset 1204).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ReturnMode {
    /// 0x37: the strongest return of each firing.
    Strongest,
    /// 0x38: the last return of each firing.
    Last,
    /// 0x39: both; blocks come in pairs with the same azimuth, even = last, odd = strongest
    /// (or second strongest when the last is also the strongest).
    Dual,
}

impl ReturnMode {
    /// The wire byte.
    pub const fn to_byte(self) -> u8 {
        match self {
            Self::Strongest => 0x37,
            Self::Last => 0x38,
            Self::Dual => 0x39,
        }
    }

    /// Parses the wire byte.
    pub const fn from_byte(byte: u8) -> Result<Self, PacketError> {
        match byte {
            0x37 => Ok(Self::Strongest),
            0x38 => Ok(Self::Last),
            0x39 => Ok(Self::Dual),
            other => Err(PacketError::UnknownReturnMode(other)),
        }
    }

    /// A short lowercase name for reports.
    pub const fn name(self) -> &'static str {
        match self {
            Self::Strongest => "strongest",
            Self::Last => "last",
            Self::Dual => "dual",
        }
    }
}

/// Product id (factory byte at offset 1205).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Product {
    /// 0x22: VLP-16 / Puck LITE (firmware 3.0.29.0 and later).
    Vlp16,
    /// 0x21: written by VLP-16 firmware older than 3.0.29.0 (the byte is the HDL-32E's id; the
    /// packet layout is the VLP-16's). Accepted; callers warn once.
    Vlp16OldFirmware,
}

impl Product {
    /// The wire byte.
    pub const fn to_byte(self) -> u8 {
        match self {
            Self::Vlp16 => 0x22,
            Self::Vlp16OldFirmware => 0x21,
        }
    }

    /// Parses the wire byte.
    pub const fn from_byte(byte: u8) -> Result<Self, PacketError> {
        match byte {
            0x22 => Ok(Self::Vlp16),
            0x21 => Ok(Self::Vlp16OldFirmware),
            other => Err(PacketError::UnsupportedProduct(other)),
        }
    }

    /// A short name for reports.
    pub const fn name(self) -> &'static str {
        match self {
            Self::Vlp16 => "VLP-16 (0x22)",
            Self::Vlp16OldFirmware => "VLP-16, firmware < 3.0.29.0 (0x21)",
        }
    }
}

/// A read-only or read-write view of a VLP-16 data packet payload.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Vlp16Packet<T: AsRef<[u8]>> {
    buffer: T,
}

const fn block_start(block: usize) -> usize {
    block * field::BLOCK_LEN
}

const fn channel_start(block: usize, channel: usize) -> usize {
    block * field::BLOCK_LEN + field::BLOCK_CHANNELS + channel * field::CHANNEL_LEN
}

fn read_u16(bytes: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([bytes[at], bytes[at + 1]])
}

fn check_indices(block: usize, channel: usize) {
    assert!(
        block < BLOCKS_PER_PACKET && channel < CHANNELS_PER_BLOCK,
        "block {block} / channel {channel} out of range"
    );
}

impl<T: AsRef<[u8]>> Vlp16Packet<T> {
    /// Wraps a buffer without checking its length. Getters may then panic on a short buffer: use
    /// [`Self::new_checked`] for untrusted bytes.
    pub const fn new_unchecked(buffer: T) -> Self {
        Self { buffer }
    }

    /// Wraps a buffer after checking that it is exactly one data packet long.
    pub fn new_checked(buffer: T) -> Result<Self, PacketError> {
        let packet = Self::new_unchecked(buffer);
        packet.check_len()?;
        Ok(packet)
    }

    /// Checks the length (exactly [`DATA_PACKET_LEN`]).
    pub fn check_len(&self) -> Result<(), PacketError> {
        let len = self.buffer.as_ref().len();
        if len == DATA_PACKET_LEN {
            Ok(())
        } else {
            Err(PacketError::WrongLength { len })
        }
    }

    /// Checks every field that can be wrong: block flags, azimuth range, return mode and product.
    /// After this succeeds, [`DataPacketRepr::parse`] and the decoder accept the packet.
    pub fn check_fields(&self) -> Result<(ReturnMode, Product), PacketError> {
        self.check_len()?;
        for block in 0..BLOCKS_PER_PACKET {
            let flag = self.block_flag(block);
            if flag != BLOCK_FLAG {
                return Err(PacketError::BadBlockFlag {
                    block: block as u8,
                    flag,
                });
            }
            let azimuth_raw = self.azimuth_raw(block);
            if azimuth_raw > AZIMUTH_RAW_MAX {
                return Err(PacketError::AzimuthOutOfRange {
                    block: block as u8,
                    azimuth_raw,
                });
            }
        }
        let mode = ReturnMode::from_byte(self.return_mode_byte())?;
        let product = Product::from_byte(self.product_byte())?;
        Ok((mode, product))
    }

    /// Returns the underlying buffer.
    pub fn into_inner(self) -> T {
        self.buffer
    }

    /// The raw bytes.
    pub fn as_bytes(&self) -> &[u8] {
        self.buffer.as_ref()
    }

    /// Flag of `block` as read little-endian (valid: [`BLOCK_FLAG`]).
    pub fn block_flag(&self, block: usize) -> u16 {
        check_indices(block, 0);
        read_u16(
            self.buffer.as_ref(),
            block_start(block) + field::BLOCK_FLAG.start,
        )
    }

    /// Azimuth of `block` in hundredths of a degree (valid: 0..=36000, 36000 meaning 0).
    pub fn azimuth_raw(&self, block: usize) -> u16 {
        check_indices(block, 0);
        read_u16(
            self.buffer.as_ref(),
            block_start(block) + field::BLOCK_AZIMUTH.start,
        )
    }

    /// Distance of `channel` (0..32: laser `channel % 16` of sequence `channel / 16`) in `block`,
    /// in units of 2 mm; 0 means no return.
    pub fn distance_raw(&self, block: usize, channel: usize) -> u16 {
        check_indices(block, channel);
        read_u16(self.buffer.as_ref(), channel_start(block, channel))
    }

    /// Calibrated reflectivity of `channel` in `block`.
    pub fn reflectivity(&self, block: usize, channel: usize) -> u8 {
        check_indices(block, channel);
        self.buffer.as_ref()[channel_start(block, channel) + 2]
    }

    /// The 100 bytes of `block`.
    pub fn block_bytes(&self, block: usize) -> &[u8] {
        check_indices(block, 0);
        &self.buffer.as_ref()[block_start(block)..block_start(block) + field::BLOCK_LEN]
    }

    /// Timestamp of the first firing of block 0, microseconds past the top of the hour (sensor
    /// clock).
    pub fn timestamp_us(&self) -> u32 {
        let b = &self.buffer.as_ref()[field::TIMESTAMP];
        u32::from_le_bytes([b[0], b[1], b[2], b[3]])
    }

    /// The return-mode byte.
    pub fn return_mode_byte(&self) -> u8 {
        self.buffer.as_ref()[field::RETURN_MODE]
    }

    /// The product-id byte.
    pub fn product_byte(&self) -> u8 {
        self.buffer.as_ref()[field::PRODUCT]
    }
}

impl<T: AsRef<[u8]> + AsMut<[u8]>> Vlp16Packet<T> {
    fn write_u16(&mut self, at: usize, value: u16) {
        self.buffer.as_mut()[at..at + 2].copy_from_slice(&value.to_le_bytes());
    }

    /// Sets the flag of `block` (valid: [`BLOCK_FLAG`]; other values build malformed packets).
    pub fn set_block_flag(&mut self, block: usize, flag: u16) {
        check_indices(block, 0);
        self.write_u16(block_start(block) + field::BLOCK_FLAG.start, flag);
    }

    /// Sets the azimuth of `block` in hundredths of a degree.
    pub fn set_azimuth_raw(&mut self, block: usize, azimuth_raw: u16) {
        check_indices(block, 0);
        self.write_u16(block_start(block) + field::BLOCK_AZIMUTH.start, azimuth_raw);
    }

    /// Sets the distance (2 mm units) of `channel` in `block`.
    pub fn set_distance_raw(&mut self, block: usize, channel: usize, distance_raw: u16) {
        check_indices(block, channel);
        self.write_u16(channel_start(block, channel), distance_raw);
    }

    /// Sets the reflectivity of `channel` in `block`.
    pub fn set_reflectivity(&mut self, block: usize, channel: usize, reflectivity: u8) {
        check_indices(block, channel);
        self.buffer.as_mut()[channel_start(block, channel) + 2] = reflectivity;
    }

    /// Sets the timestamp (microseconds past the hour).
    pub fn set_timestamp_us(&mut self, timestamp_us: u32) {
        self.buffer.as_mut()[field::TIMESTAMP].copy_from_slice(&timestamp_us.to_le_bytes());
    }

    /// Sets the return-mode byte.
    pub fn set_return_mode_byte(&mut self, byte: u8) {
        self.buffer.as_mut()[field::RETURN_MODE] = byte;
    }

    /// Sets the product-id byte.
    pub fn set_product_byte(&mut self, byte: u8) {
        self.buffer.as_mut()[field::PRODUCT] = byte;
    }
}

/// One channel record: a distance in 2 mm units (0 = no return) and a reflectivity.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ChannelRepr {
    /// Distance in units of 2 mm; 0 means no return.
    pub distance_raw: u16,
    /// Calibrated reflectivity 0..255.
    pub reflectivity: u8,
}

/// One data block: azimuth and 32 channel records (two firing sequences of 16 lasers).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BlockRepr {
    /// Azimuth of the block's first firing, hundredths of a degree, 0..=36000 (36000 = 0).
    pub azimuth_raw: u16,
    /// Records 0..16 are sequence 0 (lasers 0..16), 16..32 sequence 1.
    pub channels: [ChannelRepr; CHANNELS_PER_BLOCK],
}

impl Default for BlockRepr {
    fn default() -> Self {
        Self {
            azimuth_raw: 0,
            channels: [ChannelRepr::default(); CHANNELS_PER_BLOCK],
        }
    }
}

/// The high-level content of a valid data packet.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DataPacketRepr {
    /// The 12 data blocks.
    pub blocks: [BlockRepr; BLOCKS_PER_PACKET],
    /// Microseconds past the top of the hour, sensor clock.
    pub timestamp_us: u32,
    /// Return mode.
    pub return_mode: ReturnMode,
    /// Product id.
    pub product: Product,
}

impl DataPacketRepr {
    /// Parses and validates a packet. Never panics.
    pub fn parse<T: AsRef<[u8]>>(packet: &Vlp16Packet<T>) -> Result<Self, PacketError> {
        let (return_mode, product) = packet.check_fields()?;
        let mut blocks = [BlockRepr::default(); BLOCKS_PER_PACKET];
        for (b, block) in blocks.iter_mut().enumerate() {
            block.azimuth_raw = packet.azimuth_raw(b);
            for (c, channel) in block.channels.iter_mut().enumerate() {
                *channel = ChannelRepr {
                    distance_raw: packet.distance_raw(b, c),
                    reflectivity: packet.reflectivity(b, c),
                };
            }
        }
        Ok(Self {
            blocks,
            timestamp_us: packet.timestamp_us(),
            return_mode,
            product,
        })
    }

    /// Length of the emitted payload.
    pub const fn buffer_len(&self) -> usize {
        DATA_PACKET_LEN
    }

    /// Writes every byte of the packet. `packet` must be exactly [`DATA_PACKET_LEN`] bytes long
    /// (build it with [`Vlp16Packet::new_checked`]). Azimuths above 36000 are written as
    /// given, which is how a test builds a malformed packet.
    pub fn emit<T: AsRef<[u8]> + AsMut<[u8]>>(&self, packet: &mut Vlp16Packet<T>) {
        for (b, block) in self.blocks.iter().enumerate() {
            packet.set_block_flag(b, BLOCK_FLAG);
            packet.set_azimuth_raw(b, block.azimuth_raw);
            for (c, channel) in block.channels.iter().enumerate() {
                packet.set_distance_raw(b, c, channel.distance_raw);
                packet.set_reflectivity(b, c, channel.reflectivity);
            }
        }
        packet.set_timestamp_us(self.timestamp_us);
        packet.set_return_mode_byte(self.return_mode.to_byte());
        packet.set_product_byte(self.product.to_byte());
    }

    /// Emits into a new 1206-byte array.
    pub fn to_bytes(&self) -> [u8; DATA_PACKET_LEN] {
        let mut bytes = [0u8; DATA_PACKET_LEN];
        self.emit(&mut Vlp16Packet::new_unchecked(&mut bytes[..]));
        bytes
    }
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;

    fn sample_repr() -> DataPacketRepr {
        let mut blocks = [BlockRepr::default(); BLOCKS_PER_PACKET];
        for (b, block) in blocks.iter_mut().enumerate() {
            block.azimuth_raw = 35_900 + 20 * b as u16;
            if block.azimuth_raw >= AZIMUTH_RAW_MAX {
                block.azimuth_raw -= AZIMUTH_RAW_MAX;
            }
            for (c, channel) in block.channels.iter_mut().enumerate() {
                channel.distance_raw = (b * 100 + c) as u16;
                channel.reflectivity = (b + c) as u8;
            }
        }
        DataPacketRepr {
            blocks,
            timestamp_us: 0x0102_0304,
            return_mode: ReturnMode::Dual,
            product: Product::Vlp16,
        }
    }

    #[test]
    fn emit_into_a5_buffer_sets_every_byte() {
        let repr = sample_repr();
        let mut bytes = [0xa5u8; DATA_PACKET_LEN];
        repr.emit(&mut Vlp16Packet::new_checked(&mut bytes[..]).unwrap());
        assert_eq!(bytes, repr.to_bytes());
        // Golden bytes at the field boundaries.
        assert_eq!(&bytes[0..4], &[0xff, 0xee, 0x3c, 0x8c]); // flag, azimuth 35900 = 0x8c3c
        assert_eq!(&bytes[4..7], &[0, 0, 0]); // block 0 channel 0: distance 0, reflectivity 0
        assert_eq!(&bytes[7..10], &[1, 0, 1]);
        assert_eq!(&bytes[100..104], &[0xff, 0xee, 0x50, 0x8c]); // azimuth 35920
        assert_eq!(&bytes[1200..1206], &[0x04, 0x03, 0x02, 0x01, 0x39, 0x22]);
    }

    #[test]
    fn parse_reads_what_emit_wrote() {
        let repr = sample_repr();
        let bytes = repr.to_bytes();
        let packet = Vlp16Packet::new_checked(&bytes[..]).unwrap();
        assert_eq!(packet.azimuth_raw(5), 0); // 35900 + 100 wraps to 0
        assert_eq!(packet.distance_raw(3, 31), 331);
        assert_eq!(packet.reflectivity(3, 31), 34);
        assert_eq!(DataPacketRepr::parse(&packet).unwrap(), repr);
    }

    #[test]
    fn rejects_each_malformed_field_by_name() {
        let good = sample_repr().to_bytes();
        assert_eq!(
            Vlp16Packet::new_checked(&good[..1205]).unwrap_err(),
            PacketError::WrongLength { len: 1205 }
        );
        let mut bad = good;
        bad[700] = 0xfe; // flag of block 7
        let err = DataPacketRepr::parse(&Vlp16Packet::new_unchecked(&bad[..])).unwrap_err();
        assert_eq!(
            err,
            PacketError::BadBlockFlag {
                block: 7,
                flag: 0xeefe
            }
        );
        assert!(err.to_string().contains("block 7"));
        let mut bad = good;
        bad[202..204].copy_from_slice(&36_000u16.to_le_bytes());
        assert!(DataPacketRepr::parse(&Vlp16Packet::new_unchecked(&bad[..])).is_ok());
        bad[202..204].copy_from_slice(&36_001u16.to_le_bytes());
        let err = DataPacketRepr::parse(&Vlp16Packet::new_unchecked(&bad[..])).unwrap_err();
        assert_eq!(
            err,
            PacketError::AzimuthOutOfRange {
                block: 2,
                azimuth_raw: 36_001
            }
        );
        let mut bad = good;
        bad[1204] = 0x40;
        let err = DataPacketRepr::parse(&Vlp16Packet::new_unchecked(&bad[..])).unwrap_err();
        assert_eq!(err, PacketError::UnknownReturnMode(0x40));
        let mut bad = good;
        bad[1205] = 0x28;
        let err = DataPacketRepr::parse(&Vlp16Packet::new_unchecked(&bad[..])).unwrap_err();
        assert_eq!(err, PacketError::UnsupportedProduct(0x28));
    }

    #[test]
    fn old_firmware_product_byte_is_accepted() {
        let mut repr = sample_repr();
        repr.product = Product::Vlp16OldFirmware;
        let bytes = repr.to_bytes();
        assert_eq!(bytes[1205], 0x21);
        let parsed = DataPacketRepr::parse(&Vlp16Packet::new_unchecked(&bytes[..])).unwrap();
        assert_eq!(parsed.product, Product::Vlp16OldFirmware);
    }

    fn arb_repr() -> impl Strategy<Value = DataPacketRepr> {
        let block = (
            0..=AZIMUTH_RAW_MAX,
            prop::collection::vec(any::<(u16, u8)>(), 32),
        )
            .prop_map(|(azimuth_raw, channels)| {
                let mut block = BlockRepr {
                    azimuth_raw,
                    ..BlockRepr::default()
                };
                for (slot, (distance_raw, reflectivity)) in block.channels.iter_mut().zip(channels)
                {
                    *slot = ChannelRepr {
                        distance_raw,
                        reflectivity,
                    };
                }
                block
            });
        (
            prop::collection::vec(block, BLOCKS_PER_PACKET),
            any::<u32>(),
            prop_oneof![
                Just(ReturnMode::Strongest),
                Just(ReturnMode::Last),
                Just(ReturnMode::Dual)
            ],
            prop_oneof![Just(Product::Vlp16), Just(Product::Vlp16OldFirmware)],
        )
            .prop_map(
                |(blocks, timestamp_us, return_mode, product)| DataPacketRepr {
                    blocks: blocks.try_into().unwrap(),
                    timestamp_us,
                    return_mode,
                    product,
                },
            )
    }

    proptest! {
        #[test]
        fn repr_round_trips_through_bytes(repr in arb_repr()) {
            let bytes = repr.to_bytes();
            let parsed = DataPacketRepr::parse(&Vlp16Packet::new_checked(&bytes[..]).unwrap()).unwrap();
            prop_assert_eq!(&parsed, &repr);
            prop_assert_eq!(parsed.to_bytes(), bytes);
        }

        #[test]
        fn parse_never_panics(bytes in prop::collection::vec(any::<u8>(), 0..1300)) {
            if let Ok(packet) = Vlp16Packet::new_checked(&bytes[..])
                && let Ok(repr) = DataPacketRepr::parse(&packet)
            {
                // Every byte is a field: a valid packet re-emits byte for byte.
                prop_assert_eq!(&repr.to_bytes()[..], &bytes[..]);
            }
        }

        #[test]
        fn mutated_valid_packets_parse_or_fail_cleanly(
            repr in arb_repr(), at in 0..DATA_PACKET_LEN, byte in any::<u8>()
        ) {
            let mut bytes = repr.to_bytes();
            bytes[at] = byte;
            if let Ok(parsed) = DataPacketRepr::parse(&Vlp16Packet::new_unchecked(&bytes[..])) {
                prop_assert_eq!(parsed.to_bytes(), bytes);
            }
        }
    }
}
