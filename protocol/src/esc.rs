//! DJI C620 ESC CAN codec (RoboMaster C620 + M3508, also the C610 + M2006 frame layout).
//!
//! Classic CAN, 1 Mbit/s, standard 11-bit identifiers, 8 data bytes, all integers big-endian.
//!
//! | id            | direction   | bytes 0-1        | 2-3          | 4-5            | 6           | 7 |
//! |---------------|-------------|------------------|--------------|----------------|-------------|---|
//! | 0x200         | MCU -> ESC  | current ESC 1    | ESC 2        | ESC 3          | ESC 4 (6-7) |   |
//! | 0x1FF         | MCU -> ESC  | current ESC 5    | ESC 6        | ESC 7          | ESC 8 (6-7) |   |
//! | 0x200 + id    | ESC -> MCU  | rotor angle u16  | speed i16    | torque current | temperature | - |
//!
//! Command currents are i16 in -16384..=16384, mapping linearly to -20..=20 A; [`encode_command`]
//! clamps. Feedback (1 kHz per ESC): rotor angle 0..=8191 for one rotor turn, rotor speed in rpm (the
//! motor side, before the 3591/187 gearbox), torque current in the command's scale, temperature in
//! degrees Celsius.
//!
//! Every function here is a plain function over an 11-bit id and a byte slice, with no panics on any
//! input; the `embedded_can::Frame` helpers wrap them so the firmware's bxCAN frames, `socketcan`'s
//! frames and the simulator's in-process frames all share one codec.

use embedded_can::{Frame, Id, StandardId};

/// Command frame id for ESC ids 1..=4.
pub const CMD_ID_1_4: u16 = 0x200;
/// Command frame id for ESC ids 5..=8.
pub const CMD_ID_5_8: u16 = 0x1FF;
/// Feedback frame ids are `FEEDBACK_BASE + esc_id` for `esc_id` in 1..=8.
pub const FEEDBACK_BASE: u16 = 0x200;
/// Largest command current magnitude in raw units (= [`CURRENT_MAX_A`]).
pub const CURRENT_RAW_MAX: i16 = 16384;
/// Current that [`CURRENT_RAW_MAX`] stands for, amperes.
pub const CURRENT_MAX_A: f32 = 20.0;
/// Encoder counts per rotor turn (angle field is 0..=8191).
pub const ENCODER_COUNTS: u16 = 8192;
/// M3508 planetary gearbox ratio (rotor turns per output turn).
pub const M3508_GEAR_RATIO: f32 = 3591.0 / 187.0;
/// Data length of every C620 frame.
pub const FRAME_LEN: usize = 8;

/// What was wrong with a CAN frame handed to the codec.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum EscError {
    /// The frame does not carry exactly 8 data bytes.
    BadLength {
        /// The data length that was seen.
        len: usize,
    },
    /// The identifier is not a C620 feedback id (0x201..=0x208).
    NotFeedback {
        /// The identifier seen (extended ids are reported as 0xFFFF).
        id: u16,
    },
    /// The identifier is not a C620 command id (0x200 or 0x1FF).
    NotCommand {
        /// The identifier seen (extended ids are reported as 0xFFFF).
        id: u16,
    },
    /// The rotor angle field exceeds 8191.
    AngleOutOfRange {
        /// The raw angle value seen.
        angle_raw: u16,
    },
    /// A remote (RTR) frame where a data frame was expected.
    Remote,
}

impl core::fmt::Display for EscError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::BadLength { len } => write!(f, "C620 frame has {len} data bytes, expected 8"),
            Self::NotFeedback { id } => write!(f, "CAN id {id:#05x} is not a C620 feedback id"),
            Self::NotCommand { id } => write!(f, "CAN id {id:#05x} is not a C620 command id"),
            Self::AngleOutOfRange { angle_raw } => {
                write!(f, "C620 rotor angle {angle_raw} is above 8191")
            }
            Self::Remote => write!(f, "remote frame where a C620 data frame was expected"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for EscError {}

/// Converts amperes to the command's raw units, rounded and clamped to +-16384.
/// NaN maps to zero current.
pub fn amps_to_raw(current_a: f32) -> i16 {
    if current_a.is_nan() {
        return 0;
    }
    let raw = current_a * (f32::from(CURRENT_RAW_MAX) / CURRENT_MAX_A);
    let clamped = raw.clamp(-f32::from(CURRENT_RAW_MAX), f32::from(CURRENT_RAW_MAX));
    // In range by the clamp above, so the cast cannot truncate.
    #[allow(clippy::cast_possible_truncation)]
    let rounded = round_half_away(clamped) as i16;
    rounded
}

/// `f32::round` is std-only; this is the same rounding (half away from zero) for no_std.
fn round_half_away(x: f32) -> f32 {
    #[allow(clippy::cast_possible_truncation, clippy::cast_precision_loss)]
    let truncated = x as i32 as f32;
    let frac = x - truncated;
    if frac >= 0.5 {
        truncated + 1.0
    } else if frac <= -0.5 {
        truncated - 1.0
    } else {
        truncated
    }
}

/// Converts a raw command or feedback current to amperes.
pub fn raw_to_amps(raw: i16) -> f32 {
    f32::from(raw) * (CURRENT_MAX_A / f32::from(CURRENT_RAW_MAX))
}

/// Feedback id of ESC `esc_id` (1..=8), or `None` for ids outside that range.
pub fn feedback_id(esc_id: u8) -> Option<u16> {
    (1..=8)
        .contains(&esc_id)
        .then(|| FEEDBACK_BASE + u16::from(esc_id))
}

/// The ESC id (1..=8) that sends feedback on `can_id`, or `None`.
pub fn esc_id_from_feedback(can_id: u16) -> Option<u8> {
    let id = can_id.checked_sub(FEEDBACK_BASE)?;
    u8::try_from(id).ok().filter(|id| (1..=8).contains(id))
}

/// Command frame id that carries ESC `esc_id` (1..=8) and the slot (0..=3) of its current in it.
pub fn command_slot(esc_id: u8) -> Option<(u16, usize)> {
    match esc_id {
        1..=4 => Some((CMD_ID_1_4, usize::from(esc_id - 1))),
        5..=8 => Some((CMD_ID_5_8, usize::from(esc_id - 5))),
        _ => None,
    }
}

/// Encodes four raw currents (big-endian i16 each), clamping each to +-16384.
pub fn encode_command(currents_raw: [i16; 4]) -> [u8; FRAME_LEN] {
    let mut data = [0u8; FRAME_LEN];
    for (chunk, current) in data.chunks_exact_mut(2).zip(currents_raw) {
        let clamped = current.clamp(-CURRENT_RAW_MAX, CURRENT_RAW_MAX);
        chunk.copy_from_slice(&clamped.to_be_bytes());
    }
    data
}

/// Decodes the four raw currents of a command frame's data (values are not clamped, so an ESC
/// model sees exactly what was sent).
pub fn decode_command(data: &[u8]) -> Result<[i16; 4], EscError> {
    let data: &[u8; FRAME_LEN] = data
        .try_into()
        .map_err(|_| EscError::BadLength { len: data.len() })?;
    Ok([
        i16::from_be_bytes([data[0], data[1]]),
        i16::from_be_bytes([data[2], data[3]]),
        i16::from_be_bytes([data[4], data[5]]),
        i16::from_be_bytes([data[6], data[7]]),
    ])
}

/// One C620 feedback report.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct EscFeedback {
    /// Rotor angle, 0..=8191 for one rotor turn.
    pub angle_raw: u16,
    /// Rotor speed, rpm (motor side, before the gearbox).
    pub speed_rpm: i16,
    /// Torque current in the command's raw scale (16384 = 20 A).
    pub current_raw: i16,
    /// Motor temperature, degrees Celsius.
    pub temperature_c: u8,
}

impl EscFeedback {
    /// Decodes a feedback frame's 8 data bytes (byte 7 is reserved and ignored).
    pub fn decode(data: &[u8]) -> Result<Self, EscError> {
        let data: &[u8; FRAME_LEN] = data
            .try_into()
            .map_err(|_| EscError::BadLength { len: data.len() })?;
        let angle_raw = u16::from_be_bytes([data[0], data[1]]);
        if angle_raw >= ENCODER_COUNTS {
            return Err(EscError::AngleOutOfRange { angle_raw });
        }
        Ok(Self {
            angle_raw,
            speed_rpm: i16::from_be_bytes([data[2], data[3]]),
            current_raw: i16::from_be_bytes([data[4], data[5]]),
            temperature_c: data[6],
        })
    }

    /// Encodes the 8 data bytes of a feedback frame (byte 7 zero).
    pub fn encode(&self) -> [u8; FRAME_LEN] {
        let mut data = [0u8; FRAME_LEN];
        data[0..2].copy_from_slice(&self.angle_raw.to_be_bytes());
        data[2..4].copy_from_slice(&self.speed_rpm.to_be_bytes());
        data[4..6].copy_from_slice(&self.current_raw.to_be_bytes());
        data[6] = self.temperature_c;
        data
    }
}

fn standard_raw(id: Id) -> Option<u16> {
    match id {
        Id::Standard(id) => Some(id.as_raw()),
        Id::Extended(_) => None,
    }
}

/// Builds a command frame (`id` is [`CMD_ID_1_4`] or [`CMD_ID_5_8`]) of any `embedded_can` frame type.
pub fn command_frame<F: Frame>(id: u16, currents_raw: [i16; 4]) -> Result<F, EscError> {
    if id != CMD_ID_1_4 && id != CMD_ID_5_8 {
        return Err(EscError::NotCommand { id });
    }
    let std_id = StandardId::new(id).ok_or(EscError::NotCommand { id })?;
    F::new(std_id, &encode_command(currents_raw)).ok_or(EscError::BadLength { len: FRAME_LEN })
}

/// Builds the feedback frame of ESC `esc_id` (1..=8), as a simulated ESC sends it.
pub fn feedback_frame<F: Frame>(esc_id: u8, feedback: &EscFeedback) -> Result<F, EscError> {
    let id = feedback_id(esc_id).ok_or(EscError::NotFeedback {
        id: FEEDBACK_BASE.saturating_add(u16::from(esc_id)),
    })?;
    let std_id = StandardId::new(id).ok_or(EscError::NotFeedback { id })?;
    F::new(std_id, &feedback.encode()).ok_or(EscError::BadLength { len: FRAME_LEN })
}

/// Parses a feedback frame into the sending ESC's id (1..=8) and its report.
pub fn parse_feedback_frame<F: Frame>(frame: &F) -> Result<(u8, EscFeedback), EscError> {
    if frame.is_remote_frame() {
        return Err(EscError::Remote);
    }
    let id = standard_raw(frame.id()).ok_or(EscError::NotFeedback { id: 0xFFFF })?;
    let esc_id = esc_id_from_feedback(id).ok_or(EscError::NotFeedback { id })?;
    Ok((esc_id, EscFeedback::decode(frame.data())?))
}

/// Parses a command frame into its id ([`CMD_ID_1_4`] or [`CMD_ID_5_8`]) and four raw currents.
pub fn parse_command_frame<F: Frame>(frame: &F) -> Result<(u16, [i16; 4]), EscError> {
    if frame.is_remote_frame() {
        return Err(EscError::Remote);
    }
    let id = standard_raw(frame.id()).ok_or(EscError::NotCommand { id: 0xFFFF })?;
    if id != CMD_ID_1_4 && id != CMD_ID_5_8 {
        return Err(EscError::NotCommand { id });
    }
    Ok((id, decode_command(frame.data())?))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A minimal `embedded_can::Frame` for tests (the firmware, socketcan and the simulator each
    /// have their own).
    #[derive(Debug, Clone, PartialEq)]
    struct TestFrame {
        id: Id,
        remote: bool,
        len: usize,
        data: [u8; 8],
    }

    impl Frame for TestFrame {
        fn new(id: impl Into<Id>, data: &[u8]) -> Option<Self> {
            let mut buf = [0u8; 8];
            buf.get_mut(..data.len())?.copy_from_slice(data);
            Some(Self {
                id: id.into(),
                remote: false,
                len: data.len(),
                data: buf,
            })
        }
        fn new_remote(id: impl Into<Id>, dlc: usize) -> Option<Self> {
            (dlc <= 8).then(|| Self {
                id: id.into(),
                remote: true,
                len: dlc,
                data: [0; 8],
            })
        }
        fn is_extended(&self) -> bool {
            matches!(self.id, Id::Extended(_))
        }
        fn is_remote_frame(&self) -> bool {
            self.remote
        }
        fn id(&self) -> Id {
            self.id
        }
        fn dlc(&self) -> usize {
            self.len
        }
        fn data(&self) -> &[u8] {
            &self.data[..self.len]
        }
    }

    #[test]
    fn command_golden_bytes() {
        assert_eq!(
            encode_command([1000, -1000, 16384, -16384]),
            [0x03, 0xE8, 0xFC, 0x18, 0x40, 0x00, 0xC0, 0x00]
        );
        // Clamped to +-16384.
        assert_eq!(
            encode_command([i16::MAX, i16::MIN, 0, 1]),
            [0x40, 0, 0xC0, 0, 0, 0, 0, 1]
        );
    }

    #[test]
    fn feedback_golden_bytes() {
        // Angle 4096, 1200 rpm, -500 raw current, 35 C: as a C620 sends it.
        let data = [0x10, 0x00, 0x04, 0xB0, 0xFE, 0x0C, 35, 0];
        let fb = EscFeedback::decode(&data).unwrap();
        assert_eq!(
            fb,
            EscFeedback {
                angle_raw: 4096,
                speed_rpm: 1200,
                current_raw: -500,
                temperature_c: 35
            }
        );
        assert_eq!(fb.encode(), data);
    }

    #[test]
    fn amps_conversion_clamps_and_rounds() {
        assert_eq!(amps_to_raw(20.0), 16384);
        assert_eq!(amps_to_raw(25.0), 16384);
        assert_eq!(amps_to_raw(-30.0), -16384);
        assert_eq!(amps_to_raw(f32::NAN), 0);
        assert_eq!(amps_to_raw(1.0), 819); // 819.2
        assert_eq!(amps_to_raw(-1.0), -819);
        assert!((raw_to_amps(8192) - 10.0).abs() < 1e-6);
    }

    #[test]
    fn ids_and_slots() {
        assert_eq!(feedback_id(1), Some(0x201));
        assert_eq!(feedback_id(8), Some(0x208));
        assert_eq!(feedback_id(0), None);
        assert_eq!(feedback_id(9), None);
        assert_eq!(esc_id_from_feedback(0x203), Some(3));
        assert_eq!(esc_id_from_feedback(0x200), None);
        assert_eq!(esc_id_from_feedback(0x209), None);
        assert_eq!(esc_id_from_feedback(0x100), None);
        assert_eq!(command_slot(3), Some((CMD_ID_1_4, 2)));
        assert_eq!(command_slot(6), Some((CMD_ID_5_8, 1)));
        assert_eq!(command_slot(0), None);
    }

    #[test]
    fn frame_helpers_round_trip_and_reject() {
        let f: TestFrame = command_frame(CMD_ID_1_4, [1, 2, 3, 4]).unwrap();
        assert_eq!(parse_command_frame(&f), Ok((CMD_ID_1_4, [1, 2, 3, 4])));
        assert_eq!(
            parse_feedback_frame(&f),
            Err(EscError::NotFeedback { id: 0x200 })
        );
        assert!(command_frame::<TestFrame>(0x201, [0; 4]).is_err());

        let fb = EscFeedback {
            angle_raw: 8191,
            speed_rpm: -9000,
            current_raw: 100,
            temperature_c: 90,
        };
        let f: TestFrame = feedback_frame(4, &fb).unwrap();
        assert_eq!(parse_feedback_frame(&f), Ok((4, fb)));
        assert!(feedback_frame::<TestFrame>(9, &fb).is_err());

        let short = TestFrame::new(StandardId::new(0x201).unwrap(), &[0; 7]).unwrap();
        assert_eq!(
            parse_feedback_frame(&short),
            Err(EscError::BadLength { len: 7 })
        );
        let remote = TestFrame::new_remote(StandardId::new(0x201).unwrap(), 8).unwrap();
        assert_eq!(parse_feedback_frame(&remote), Err(EscError::Remote));
        let bad_angle = TestFrame::new(
            StandardId::new(0x201).unwrap(),
            &[0x20, 0, 0, 0, 0, 0, 0, 0],
        )
        .unwrap();
        assert_eq!(
            parse_feedback_frame(&bad_angle),
            Err(EscError::AngleOutOfRange { angle_raw: 8192 })
        );
    }

    proptest! {
        #[test]
        fn command_round_trip(c in proptest::array::uniform4(-16384i16..=16384)) {
            prop_assert_eq!(decode_command(&encode_command(c)).unwrap(), c);
        }

        #[test]
        fn feedback_round_trip(angle in 0u16..8192, rpm: i16, cur: i16, t: u8) {
            let fb = EscFeedback { angle_raw: angle, speed_rpm: rpm, current_raw: cur, temperature_c: t };
            prop_assert_eq!(EscFeedback::decode(&fb.encode()).unwrap(), fb);
        }

        #[test]
        fn decoders_never_panic(data in proptest::collection::vec(any::<u8>(), 0..16), id: u16) {
            let _ = EscFeedback::decode(&data);
            let _ = decode_command(&data);
            let _ = esc_id_from_feedback(id);
        }

        #[test]
        fn amps_raw_is_monotonic_and_bounded(a in -40.0f32..40.0, b in -40.0f32..40.0) {
            let (lo, hi) = if a <= b { (a, b) } else { (b, a) };
            prop_assert!(amps_to_raw(lo) <= amps_to_raw(hi));
            prop_assert!(amps_to_raw(a).abs() <= CURRENT_RAW_MAX);
        }
    }
}
