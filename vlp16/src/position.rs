//! The VLP-16 position packet (UDP port 8308, 512-byte payload): sensor timestamp, PPS state and
//! the last NMEA `$GPRMC` sentence from an attached GPS. Checked view plus `Repr` parse/emit.
//!
//! Layout (VLP-16 User Manual 63-9243 Rev D, section 9.3; little-endian):
//!
//! ```text
//! offset  size  field
//!      0   198  unused on the VLP-16 (newer firmware may put gyro/temperature/accel here; ignored)
//!    198     4  timestamp u32, microseconds past the hour (sensor clock)
//!    202     1  PPS status: 0 absent, 1 synchronising, 2 locked, 3 error
//!    203     3  unused
//!    206   128  NMEA sentence (ASCII, NUL-padded)
//!    334   178  unused
//! ```
//!
//! `emit` writes zeros into the unused ranges. No-panic contract as in [`super::packet`].

use thiserror::Error;

/// Length of a position packet payload.
pub const POSITION_PACKET_LEN: usize = 512;
/// UDP destination port of position packets.
pub const POSITION_PORT: u16 = 8308;
/// Size of the NMEA field.
pub const NMEA_LEN: usize = 128;

/// Byte ranges of the fields.
pub mod field {
    use core::ops::Range;

    /// Timestamp, microseconds past the hour.
    pub const TIMESTAMP: Range<usize> = 198..202;
    /// PPS status byte.
    pub const PPS_STATUS: usize = 202;
    /// NMEA sentence, NUL-padded.
    pub const NMEA: Range<usize> = 206..334;
}

/// Why a position packet was rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum PositionError {
    /// The payload is not 512 bytes long.
    #[error("position packet is {len} bytes, expected {POSITION_PACKET_LEN}")]
    WrongLength {
        /// The length received.
        len: usize,
    },
    /// The PPS status byte (offset 202) is not 0..=3.
    #[error("position packet: PPS status byte {0} (offset 202) is not 0..=3")]
    UnknownPpsStatus(u8),
}

/// State of the pulse-per-second input.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PpsStatus {
    /// 0: no PPS detected.
    Absent,
    /// 1: synchronising to PPS.
    Synchronizing,
    /// 2: PPS locked.
    Locked,
    /// 3: error.
    Error,
}

impl PpsStatus {
    /// The wire byte.
    pub const fn to_byte(self) -> u8 {
        match self {
            Self::Absent => 0,
            Self::Synchronizing => 1,
            Self::Locked => 2,
            Self::Error => 3,
        }
    }

    /// Parses the wire byte.
    pub const fn from_byte(byte: u8) -> Result<Self, PositionError> {
        match byte {
            0 => Ok(Self::Absent),
            1 => Ok(Self::Synchronizing),
            2 => Ok(Self::Locked),
            3 => Ok(Self::Error),
            other => Err(PositionError::UnknownPpsStatus(other)),
        }
    }

    /// A short lowercase name for reports.
    pub const fn name(self) -> &'static str {
        match self {
            Self::Absent => "absent",
            Self::Synchronizing => "synchronizing",
            Self::Locked => "locked",
            Self::Error => "error",
        }
    }
}

/// A view of a position packet payload.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PositionPacket<T: AsRef<[u8]>> {
    buffer: T,
}

impl<T: AsRef<[u8]>> PositionPacket<T> {
    /// Wraps a buffer without checking its length.
    pub const fn new_unchecked(buffer: T) -> Self {
        Self { buffer }
    }

    /// Wraps a buffer after checking that it is exactly 512 bytes long.
    pub fn new_checked(buffer: T) -> Result<Self, PositionError> {
        let len = buffer.as_ref().len();
        if len == POSITION_PACKET_LEN {
            Ok(Self { buffer })
        } else {
            Err(PositionError::WrongLength { len })
        }
    }

    /// Returns the underlying buffer.
    pub fn into_inner(self) -> T {
        self.buffer
    }

    /// Microseconds past the hour, sensor clock.
    pub fn timestamp_us(&self) -> u32 {
        let b = &self.buffer.as_ref()[field::TIMESTAMP];
        u32::from_le_bytes([b[0], b[1], b[2], b[3]])
    }

    /// The PPS status byte.
    pub fn pps_status_byte(&self) -> u8 {
        self.buffer.as_ref()[field::PPS_STATUS]
    }

    /// The raw 128-byte NMEA field.
    pub fn nmea_field(&self) -> &[u8] {
        &self.buffer.as_ref()[field::NMEA]
    }
}

impl<T: AsRef<[u8]> + AsMut<[u8]>> PositionPacket<T> {
    /// Sets the timestamp.
    pub fn set_timestamp_us(&mut self, timestamp_us: u32) {
        self.buffer.as_mut()[field::TIMESTAMP].copy_from_slice(&timestamp_us.to_le_bytes());
    }

    /// Sets the PPS status byte.
    pub fn set_pps_status_byte(&mut self, byte: u8) {
        self.buffer.as_mut()[field::PPS_STATUS] = byte;
    }

    /// The raw 128-byte NMEA field, writable.
    pub fn nmea_field_mut(&mut self) -> &mut [u8] {
        &mut self.buffer.as_mut()[field::NMEA]
    }
}

/// The content of a position packet.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PositionPacketRepr {
    /// Microseconds past the hour, sensor clock.
    pub timestamp_us: u32,
    /// PPS state.
    pub pps: PpsStatus,
    /// The NMEA field as sent (ASCII, NUL-padded); see [`Self::nmea_sentence`].
    pub nmea: [u8; NMEA_LEN],
}

impl PositionPacketRepr {
    /// Parses a position packet. Never panics.
    pub fn parse<T: AsRef<[u8]>>(packet: &PositionPacket<T>) -> Result<Self, PositionError> {
        let len = packet.buffer.as_ref().len();
        if len != POSITION_PACKET_LEN {
            return Err(PositionError::WrongLength { len });
        }
        let pps = PpsStatus::from_byte(packet.pps_status_byte())?;
        let mut nmea = [0u8; NMEA_LEN];
        nmea.copy_from_slice(packet.nmea_field());
        Ok(Self {
            timestamp_us: packet.timestamp_us(),
            pps,
            nmea,
        })
    }

    /// Builds a repr with an NMEA sentence (truncated to 128 bytes, NUL-padded).
    pub fn new(timestamp_us: u32, pps: PpsStatus, sentence: &str) -> Self {
        let mut nmea = [0u8; NMEA_LEN];
        let n = sentence.len().min(NMEA_LEN);
        nmea[..n].copy_from_slice(&sentence.as_bytes()[..n]);
        Self {
            timestamp_us,
            pps,
            nmea,
        }
    }

    /// The NMEA sentence without NUL padding and trailing CR/LF; empty when no GPS is attached.
    /// `None` when the bytes are not ASCII.
    pub fn nmea_sentence(&self) -> Option<&str> {
        let end = self.nmea.iter().position(|&b| b == 0).unwrap_or(NMEA_LEN);
        let text = core::str::from_utf8(&self.nmea[..end]).ok()?;
        text.is_ascii().then(|| text.trim_end_matches(['\r', '\n']))
    }

    /// Writes the whole 512-byte packet (unused ranges zeroed). `packet` must be 512 bytes long.
    pub fn emit<T: AsRef<[u8]> + AsMut<[u8]>>(&self, packet: &mut PositionPacket<T>) {
        packet.buffer.as_mut().fill(0);
        packet.set_timestamp_us(self.timestamp_us);
        packet.set_pps_status_byte(self.pps.to_byte());
        packet.nmea_field_mut().copy_from_slice(&self.nmea);
    }

    /// Emits into a new 512-byte array.
    pub fn to_bytes(&self) -> [u8; POSITION_PACKET_LEN] {
        let mut bytes = [0u8; POSITION_PACKET_LEN];
        self.emit(&mut PositionPacket::new_unchecked(&mut bytes[..]));
        bytes
    }
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;

    const RMC: &str = "$GPRMC,123519,A,4807.038,N,01131.000,E,022.4,084.4,230394,003.1,W*6A\r\n";

    #[test]
    fn emit_and_parse_golden_fields() {
        let repr = PositionPacketRepr::new(2_467_108_343, PpsStatus::Locked, RMC);
        let mut bytes = [0xa5u8; POSITION_PACKET_LEN];
        repr.emit(&mut PositionPacket::new_checked(&mut bytes[..]).unwrap());
        assert_eq!(&bytes[198..203], &[0xf7, 0x15, 0x0d, 0x93, 0x02]);
        assert_eq!(&bytes[206..212], b"$GPRMC");
        assert!(bytes[..198].iter().all(|&b| b == 0));
        let parsed =
            PositionPacketRepr::parse(&PositionPacket::new_checked(&bytes[..]).unwrap()).unwrap();
        assert_eq!(parsed, repr);
        assert_eq!(parsed.nmea_sentence(), Some(RMC.trim_end()));
    }

    #[test]
    fn rejects_bad_length_and_pps() {
        assert_eq!(
            PositionPacket::new_checked(&[0u8; 511][..]).unwrap_err(),
            PositionError::WrongLength { len: 511 }
        );
        let mut bytes = [0u8; POSITION_PACKET_LEN];
        bytes[202] = 7;
        let err =
            PositionPacketRepr::parse(&PositionPacket::new_unchecked(&bytes[..])).unwrap_err();
        assert_eq!(err, PositionError::UnknownPpsStatus(7));
        assert!(err.to_string().contains("offset 202"));
    }

    proptest! {
        #[test]
        fn round_trip(ts in any::<u32>(), pps in 0u8..4, text in "[ -~]{0,128}") {
            let repr = PositionPacketRepr::new(ts, PpsStatus::from_byte(pps).unwrap(), &text);
            let bytes = repr.to_bytes();
            let parsed = PositionPacketRepr::parse(&PositionPacket::new_unchecked(&bytes[..])).unwrap();
            prop_assert_eq!(parsed, repr);
            prop_assert_eq!(parsed.nmea_sentence(), Some(text.trim_end_matches(['\r', '\n'])));
        }

        #[test]
        fn parse_never_panics(bytes in prop::collection::vec(any::<u8>(), 0..600)) {
            if let Ok(packet) = PositionPacket::new_checked(&bytes[..])
                && let Ok(repr) = PositionPacketRepr::parse(&packet)
            {
                let _ = repr.nmea_sentence();
            }
        }
    }
}
