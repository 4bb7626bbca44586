//! Packet → points → frames: the pure part of VLP-16 input.
//!
//! [`FrameAssembler`] takes data-packet payloads (with the host time they were received) and
//! position-packet payloads, decodes every return into a [`Point`] in the sensor frame of the
//! VLP-16 manual, and cuts the stream into [`Frame`]s where the azimuth wraps past
//! [`DecoderConfig::cut_azimuth_rad`]. It never reads a clock, a file or a socket.
//!
//! # The maths (VLP-16 User Manual 63-9243 Rev D, sections 9.5-9.7)
//!
//! - Each block holds two firing sequences of the 16 lasers. Laser `l` of sequence `s` fires
//!   `55.296 * s + 2.304 * l` microseconds after the block's first firing; a block (firing cycle)
//!   lasts 110.592 us. In dual-return mode two consecutive blocks carry the same cycle.
//! - Its azimuth is interpolated: `alpha = alpha_block + delta * (55.296 s + 2.304 l) / 110.592`,
//!   `delta` being the gap to the next cycle's azimuth (mod 360 degrees); the last cycle of a packet
//!   reuses the previous gap (as the ROS driver does).
//! - `x = r cos(w) sin(alpha)`, `y = r cos(w) cos(alpha)`, `z = r sin(w)` with `w` the laser's
//!   elevation (-15, 1, -13, 3, ... 15 degrees), plus, by default, the laser's vertical offset
//!   (manual Table 9-1, 11.2 mm ... -11.2 mm) added to `z`. This is the manual's form, and it is
//!   also what velodyne-decoder 3.0 does (checked against its output to 1 mm in the tests; the
//!   ROS driver instead shifts the origin perpendicular to the beam, up to 2.9 mm different).
//! - The ring index sorts lasers by elevation: `ring = l / 2` for even `l`, `8 + l / 2` for odd.
//!
//! # Numerics
//!
//! `sin`/`cos` of the block azimuth are evaluated once per block in `f64`; each firing's small
//! offset `d = delta * fraction` (below 0.2 rad, as larger gaps are rejected) is applied with the
//! angle-addition formula and fifth-order Taylor terms for `sin d`/`cos d` (error below 1e-9 rad
//! for the real gaps of 0.1-0.4 degrees). Points are `f32` (8 um resolution at 130 m).

use std::collections::VecDeque;

use thiserror::Error;

use super::packet::{
    AZIMUTH_RAW_MAX, BLOCKS_PER_PACKET, DISTANCE_RESOLUTION_M, LASERS, PacketError, Product,
    ReturnMode, Vlp16Packet,
};
use super::position::{PositionError, PositionPacket, PositionPacketRepr};

/// Elevation of each laser id in a firing sequence, degrees (manual Table 9-1).
pub const ELEVATION_DEG: [f32; LASERS] = [
    -15.0, 1.0, -13.0, 3.0, -11.0, 5.0, -9.0, 7.0, -7.0, 9.0, -5.0, 11.0, -3.0, 13.0, -1.0, 15.0,
];
/// Vertical offset of each laser id, millimetres (manual Table 9-1).
pub const VERTICAL_OFFSET_MM: [f32; LASERS] = [
    11.2, -0.7, 9.7, -2.2, 8.1, -3.7, 6.6, -5.1, 5.1, -6.6, 3.7, -8.1, 2.2, -9.7, 0.7, -11.2,
];
/// Range accuracy, metres: the data sheet's "+-3 cm (typical)". Returns of a surface scatter
/// about it by up to this much along the ray.
pub const RANGE_ACCURACY_M: f64 = 0.03;
/// Time between two laser firings, microseconds.
pub const FIRING_US: f64 = 2.304;
/// Time of one firing sequence (16 firings and the recharge), microseconds.
pub const SEQUENCE_US: f64 = 55.296;
/// Time of one firing cycle (one block in single-return mode), microseconds.
pub const CYCLE_US: f64 = 110.592;
/// Microseconds in an hour: the sensor timestamp wraps here.
pub const HOUR_US: i64 = 3_600_000_000;
/// Largest accepted azimuth step between consecutive firing cycles in a packet (10 degrees; real
/// sensors step 0.1-0.4 degrees). Larger steps are malformed packets.
pub const MAX_CYCLE_STEP_RAW: u16 = 1_000;

/// The ring (0 = lowest beam, 15 = highest) of a laser id 0..16.
pub const fn ring_of_laser(laser_id: usize) -> u8 {
    if laser_id.is_multiple_of(2) {
        (laser_id / 2) as u8
    } else {
        (8 + laser_id / 2) as u8
    }
}

/// How the azimuth of each firing is interpolated between block azimuths.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum AzimuthInterpolation {
    /// The manual's method: each block's gap to the next block, the last block reusing the
    /// previous gap, no rounding. The default.
    #[default]
    PerBlock,
    /// velodyne-decoder 3.0's method, for comparisons with it: one mean gap over the packet and
    /// each firing's azimuth rounded to 0.01 degree (up to 0.005 degree off, 5 mm at 60 m).
    PacketMeanRounded,
}

/// Decoder settings (the `[lidar]` section of the onboard config).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DecoderConfig {
    /// Returns closer than this are dropped. The VLP-16 reports nothing under about 0.5 m anyway;
    /// the default 0.1 m matches velodyne-decoder.
    pub min_range_m: f32,
    /// Returns farther than this are dropped (the distance field ends at 131.07 m).
    pub max_range_m: f32,
    /// Add each laser's vertical offset (manual Table 9-1) to `z`. On by default.
    pub vertical_offset: bool,
    /// Frames are cut where the azimuth passes this angle, radians in `[0, 2 pi)`, measured like
    /// the sensor's azimuth (0 = +y of the manual's frame, clockwise seen from above).
    pub cut_azimuth_rad: f32,
    /// Firing azimuth interpolation.
    pub azimuth_interpolation: AzimuthInterpolation,
    /// Each laser id's range offset, metres, subtracted from its every return: a user
    /// calibration of the per-laser range biases left after the factory's (estimated by
    /// [`crate::calibration`]). Zero by default. The range limits apply to the raw range.
    pub range_offsets_m: [f32; LASERS],
}

impl Default for DecoderConfig {
    fn default() -> Self {
        Self {
            min_range_m: 0.1,
            max_range_m: 131.0,
            vertical_offset: true,
            cut_azimuth_rad: 0.0,
            azimuth_interpolation: AzimuthInterpolation::PerBlock,
            range_offsets_m: [0.0; LASERS],
        }
    }
}

/// A decoder setting out of its domain.
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum ConfigError {
    /// `min_range_m` must be finite, at least 0 and below `max_range_m`.
    #[error("lidar.min_range_m = {min_range_m} must be >= 0 and below max_range_m = {max_range_m}")]
    RangeLimits {
        /// The configured minimum.
        min_range_m: f32,
        /// The configured maximum.
        max_range_m: f32,
    },
    /// `cut_azimuth_rad` must lie in `[0, 2 pi)`.
    #[error("lidar.cut_azimuth_rad = {0} must lie in [0, 2 pi)")]
    CutAzimuth(f32),
    /// A range offset must be finite and at most [`MAX_RANGE_OFFSET_M`] in magnitude.
    #[error(
        "lidar.range_offsets_m[{laser}] = {offset_m} must be finite and within +-{MAX_RANGE_OFFSET_M} m"
    )]
    RangeOffset {
        /// The laser id.
        laser: usize,
        /// The configured offset.
        offset_m: f32,
    },
}

/// Largest accepted range offset, metres: three times the data sheet's +-3 cm accuracy. A
/// larger one is a unit to repair, not to calibrate.
pub const MAX_RANGE_OFFSET_M: f32 = 0.1;

impl DecoderConfig {
    /// Checks every field.
    pub fn check(&self) -> Result<(), ConfigError> {
        let (min, max) = (self.min_range_m, self.max_range_m);
        if !(min.is_finite() && max.is_finite() && min >= 0.0 && min < max) {
            return Err(ConfigError::RangeLimits {
                min_range_m: min,
                max_range_m: max,
            });
        }
        if !(0.0..core::f32::consts::TAU).contains(&self.cut_azimuth_rad) {
            return Err(ConfigError::CutAzimuth(self.cut_azimuth_rad));
        }
        for (laser, &offset_m) in self.range_offsets_m.iter().enumerate() {
            if offset_m.is_nan() || offset_m.abs() > MAX_RANGE_OFFSET_M {
                return Err(ConfigError::RangeOffset { laser, offset_m });
            }
        }
        Ok(())
    }
}

/// Which return of a firing a point is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ReturnKind {
    /// The strongest return (single strongest mode, or dual mode's odd block when stronger than
    /// the last).
    Strongest,
    /// The last return (single last mode, or dual mode's even block).
    Last,
    /// Dual mode's odd block when the last return is also the strongest.
    SecondStrongest,
}

/// One return in the sensor frame of the VLP-16 manual (x right, y forward at azimuth 0, z up).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Point {
    /// x, metres.
    pub x_m: f32,
    /// y, metres.
    pub y_m: f32,
    /// z, metres.
    pub z_m: f32,
    /// Time since the frame's first firing, microseconds (sensor clock).
    pub time_us: f32,
    /// Interpolated azimuth of the firing, radians in `[0, 2 pi)`.
    pub azimuth_rad: f32,
    /// Calibrated reflectivity.
    pub intensity: u8,
    /// Ring 0..16 by elevation (0 = -15 degrees).
    pub ring: u8,
    /// Laser id 0..16 in the firing order.
    pub laser_id: u8,
    /// Which return.
    pub return_kind: ReturnKind,
}

/// One revolution (or the partial first/last one) of points.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// Sequence number of this frame, from 0.
    pub index: u64,
    /// Points in firing order.
    pub points: Vec<Point>,
    /// Sensor time of the frame's first firing, microseconds past the hour (sensor clock).
    pub start_sensor_us: f64,
    /// Host receive time of the packet holding the first firing, nanoseconds on the clock the
    /// packet source stamps with (monotonic for live UDP, capture time for pcap).
    pub start_host_ns: u64,
    /// Data packets that contributed firings.
    pub packets: u32,
    /// Azimuth swept, hundredths of a degree, summed over firing sequences.
    pub sweep_raw: f64,
    /// Sensor time swept, microseconds (matches `sweep_raw`).
    pub duration_us: f64,
    /// True when the frame began at a cut (not the stream's partial first frame).
    pub starts_at_cut: bool,
    /// True when the frame ended at a cut (not flushed by [`FrameAssembler::finish`]).
    pub ends_at_cut: bool,
}

impl Frame {
    fn empty(index: u64) -> Self {
        Self {
            index,
            points: Vec::new(),
            start_sensor_us: 0.0,
            start_host_ns: 0,
            packets: 0,
            sweep_raw: 0.0,
            duration_us: 0.0,
            starts_at_cut: false,
            ends_at_cut: false,
        }
    }

    /// A full revolution: began and ended at the cut angle.
    pub fn is_complete(&self) -> bool {
        self.starts_at_cut && self.ends_at_cut
    }

    /// Rotation rate estimated from the azimuth swept over the sensor time, revolutions per
    /// minute; `None` for a frame spanning no time.
    pub fn rpm(&self) -> Option<f64> {
        (self.duration_us > 0.0)
            .then(|| self.sweep_raw / f64::from(AZIMUTH_RAW_MAX) / (self.duration_us / 60e6))
    }
}

/// Why a data packet was skipped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum DecodeError {
    /// A field is malformed.
    #[error(transparent)]
    Packet(#[from] PacketError),
    /// Consecutive firing cycles in one packet are too far apart in azimuth.
    #[error(
        "block {block}: azimuth steps from {from_raw} to {to_raw} (0.01 deg), more than 10 deg"
    )]
    AzimuthJump {
        /// Block index of the later cycle.
        block: u8,
        /// Azimuth of the earlier cycle.
        from_raw: u16,
        /// Azimuth of the later cycle.
        to_raw: u16,
    },
    /// In dual-return mode, the two blocks of a cycle carry different azimuths.
    #[error("dual return: blocks {block} and {} have azimuths {first_raw} and {second_raw}", block + 1)]
    DualPairMismatch {
        /// Even block index.
        block: u8,
        /// Its azimuth.
        first_raw: u16,
        /// The odd block's azimuth.
        second_raw: u16,
    },
}

impl DecodeError {
    /// A short stable name for counters and reports.
    pub const fn reason(&self) -> &'static str {
        match self {
            Self::Packet(PacketError::WrongLength { .. }) => "wrong-length",
            Self::Packet(PacketError::BadBlockFlag { .. }) => "bad-block-flag",
            Self::Packet(PacketError::AzimuthOutOfRange { .. }) => "azimuth-out-of-range",
            Self::Packet(PacketError::UnknownReturnMode(_)) => "unknown-return-mode",
            Self::Packet(PacketError::UnsupportedProduct(_)) => "unsupported-product",
            Self::AzimuthJump { .. } => "azimuth-jump",
            Self::DualPairMismatch { .. } => "dual-pair-mismatch",
        }
    }
}

/// Counters over everything pushed into a [`FrameAssembler`].
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct DecodeStats {
    /// Data packets decoded.
    pub data_packets: u64,
    /// Position packets parsed.
    pub position_packets: u64,
    /// Points emitted.
    pub points: u64,
    /// Channel records with distance 0 (no return).
    pub zero_returns: u64,
    /// Returns outside `[min_range_m, max_range_m]`.
    pub out_of_range: u64,
    /// Dual-mode second returns identical to the first (one echo only), not emitted twice.
    pub dual_duplicates: u64,
    /// Malformed data packets skipped, by [`DecodeError::reason`], in first-seen order.
    pub malformed_data: Vec<(&'static str, u64)>,
    /// Malformed position packets skipped.
    pub malformed_position: u64,
    /// Data packets per return mode: strongest, last, dual.
    pub return_modes: [u64; 3],
    /// Data packets with product byte 0x22 and 0x21.
    pub products: [u64; 2],
    /// Frames emitted.
    pub frames: u64,
}

impl DecodeStats {
    fn count_malformed(&mut self, reason: &'static str) {
        match self.malformed_data.iter_mut().find(|(r, _)| *r == reason) {
            Some((_, n)) => *n += 1,
            None => self.malformed_data.push((reason, 1)),
        }
    }

    /// Total malformed data packets.
    pub fn malformed_data_total(&self) -> u64 {
        self.malformed_data.iter().map(|(_, n)| n).sum()
    }
}

/// Per-laser constants.
#[derive(Debug, Clone, Copy)]
struct LaserTable {
    cos_w: [f32; LASERS],
    sin_w: [f32; LASERS],
    z_offset_m: [f32; LASERS],
    ring: [u8; LASERS],
}

impl LaserTable {
    fn new(vertical_offset: bool) -> Self {
        let mut table = Self {
            cos_w: [0.0; LASERS],
            sin_w: [0.0; LASERS],
            z_offset_m: [0.0; LASERS],
            ring: [0; LASERS],
        };
        for l in 0..LASERS {
            let w = f64::from(ELEVATION_DEG[l]).to_radians();
            table.cos_w[l] = w.cos() as f32;
            table.sin_w[l] = w.sin() as f32;
            table.z_offset_m[l] = if vertical_offset {
                VERTICAL_OFFSET_MM[l] * 1e-3
            } else {
                0.0
            };
            table.ring[l] = ring_of_laser(l);
        }
        table
    }
}

/// Firing time offset within a cycle as a fraction of the cycle, per channel 0..32.
fn channel_fractions() -> [f64; 32] {
    let mut f = [0.0; 32];
    for (c, slot) in f.iter_mut().enumerate() {
        let (seq, laser) = (c / LASERS, c % LASERS);
        *slot = (SEQUENCE_US * seq as f64 + FIRING_US * laser as f64) / CYCLE_US;
    }
    f
}

/// sin and cos of a small angle by fifth-order Taylor series (|d| < 0.2 rad: error < 1e-7).
/// Multiplications by reciprocals only: divisions here were the hottest instructions.
fn small_sin_cos(d: f64) -> (f64, f64) {
    let d2 = d * d;
    let sin = d * (1.0 - d2 * (1.0 / 6.0) * (1.0 - d2 * (1.0 / 20.0)));
    let cos = 1.0 - d2 * 0.5 * (1.0 - d2 * (1.0 / 12.0) * (1.0 - d2 * (1.0 / 30.0)));
    (sin, cos)
}

/// Wraps an azimuth in hundredths of a degree from `(-36000, 72000)` (all the decoder produces)
/// into `[0, 36000)` without the cost of `rem_euclid` (a libm `fmod` call, 13 % of the decoding
/// time when it was used per point).
fn wrap_raw(raw: f64) -> f64 {
    let full = f64::from(AZIMUTH_RAW_MAX);
    if raw < 0.0 {
        raw + full
    } else if raw >= full {
        raw - full
    } else {
        raw
    }
}

/// Hundredths of a degree to radians.
const RAW_TO_RAD: f64 = core::f64::consts::PI / 18_000.0;

/// The azimuth layout of one packet after validation: the first block of each firing cycle, its
/// azimuth and the step to the next cycle.
#[derive(Debug, Clone, Copy)]
struct Cycles {
    blocks_per_cycle: usize,
    count: usize,
    azimuth_raw: [u16; BLOCKS_PER_PACKET],
    step_raw: [f64; BLOCKS_PER_PACKET],
}

fn azimuth_step(from: u16, to: u16) -> u16 {
    ((u32::from(to) + u32::from(AZIMUTH_RAW_MAX) - u32::from(from)) % u32::from(AZIMUTH_RAW_MAX))
        as u16
}

fn cycles_of(
    packet: &Vlp16Packet<&[u8]>,
    mode: ReturnMode,
    interpolation: AzimuthInterpolation,
) -> Result<Cycles, DecodeError> {
    let blocks_per_cycle = if mode == ReturnMode::Dual { 2 } else { 1 };
    let count = BLOCKS_PER_PACKET / blocks_per_cycle;
    let mut cycles = Cycles {
        blocks_per_cycle,
        count,
        azimuth_raw: [0; BLOCKS_PER_PACKET],
        step_raw: [0.0; BLOCKS_PER_PACKET],
    };
    for k in 0..count {
        let block = k * blocks_per_cycle;
        // 36000 (sent now and then by real sensors) is 0.
        cycles.azimuth_raw[k] = packet.azimuth_raw(block) % AZIMUTH_RAW_MAX;
        if blocks_per_cycle == 2 {
            let second_raw = packet.azimuth_raw(block + 1) % AZIMUTH_RAW_MAX;
            if second_raw != cycles.azimuth_raw[k] {
                return Err(DecodeError::DualPairMismatch {
                    block: block as u8,
                    first_raw: cycles.azimuth_raw[k],
                    second_raw,
                });
            }
        }
    }
    for k in 1..count {
        let step = azimuth_step(cycles.azimuth_raw[k - 1], cycles.azimuth_raw[k]);
        if step > MAX_CYCLE_STEP_RAW {
            return Err(DecodeError::AzimuthJump {
                block: (k * blocks_per_cycle) as u8,
                from_raw: cycles.azimuth_raw[k - 1],
                to_raw: cycles.azimuth_raw[k],
            });
        }
        cycles.step_raw[k - 1] = f64::from(step);
    }
    cycles.step_raw[count - 1] = if count > 1 {
        cycles.step_raw[count - 2]
    } else {
        0.0
    };
    if interpolation == AzimuthInterpolation::PacketMeanRounded && count > 1 {
        let sweep: f64 = cycles.step_raw[..count - 1].iter().sum();
        cycles.step_raw = [sweep / (count - 1) as f64; BLOCKS_PER_PACKET];
    }
    Ok(cycles)
}

/// Signed difference `a - b` of two hour-wrapped microsecond stamps, in `(-HOUR/2, HOUR/2]`.
fn wrapped_diff_us(a: u32, b: u32) -> i64 {
    let d = (i64::from(a) - i64::from(b)).rem_euclid(HOUR_US);
    if d > HOUR_US / 2 { d - HOUR_US } else { d }
}

/// Decodes packets into points and cuts them into frames. Pure: see the module docs.
#[derive(Debug, Clone)]
pub struct FrameAssembler {
    config: DecoderConfig,
    lasers: LaserTable,
    fractions: [f64; 32],
    cut_raw: f64,
    min_range_raw: u16,
    max_range_raw: u16,
    current: Frame,
    /// Packet timestamp the current frame's point times are relative to, and the offset of the
    /// frame's first firing after it.
    frame_base_us: Option<(u32, f64)>,
    /// Azimuth from the cut (0.01 deg) and sensor time (us past the hour, unwrapped relative to
    /// the frame base) of the previous firing sequence.
    previous_sequence: Option<(f64, f64)>,
    /// Whether the packet being decoded has been counted in the current frame.
    packet_counted: bool,
    ready: VecDeque<Frame>,
    stats: DecodeStats,
    last_position: Option<PositionPacketRepr>,
    warned_old_firmware: bool,
}

impl FrameAssembler {
    /// A new assembler. Fails on a config out of its domain.
    pub fn new(config: DecoderConfig) -> Result<Self, ConfigError> {
        config.check()?;
        // Limits in 2 mm units, in f64 with a tolerance of 1e-4 units so that 1.0 m is exactly
        // 500 (in f32, 1.0 / 0.002 is 500.00003 and 0.002 itself is 0.0020000001).
        let resolution_m = 0.002_f64;
        let min_raw = (f64::from(config.min_range_m) / resolution_m - 1e-4)
            .ceil()
            .max(1.0);
        let max_raw = (f64::from(config.max_range_m) / resolution_m + 1e-4)
            .floor()
            .min(f64::from(u16::MAX));
        Ok(Self {
            config,
            lasers: LaserTable::new(config.vertical_offset),
            fractions: channel_fractions(),
            // Rounded to 0.0001 degree (the f32 resolution of the radians): the f32 radians of 90
            // degrees are 9000.0002 hundredths, which would put the cut one firing late.
            cut_raw: (f64::from(config.cut_azimuth_rad) / RAW_TO_RAD * 100.0).round() / 100.0,
            min_range_raw: min_raw as u16,
            max_range_raw: max_raw as u16,
            current: Frame::empty(0),
            frame_base_us: None,
            previous_sequence: None,
            packet_counted: false,
            ready: VecDeque::new(),
            stats: DecodeStats::default(),
            last_position: None,
            warned_old_firmware: false,
        })
    }

    /// The config in use.
    pub fn config(&self) -> &DecoderConfig {
        &self.config
    }

    /// Counters so far.
    pub fn stats(&self) -> &DecodeStats {
        &self.stats
    }

    /// The last valid position packet.
    pub fn last_position(&self) -> Option<&PositionPacketRepr> {
        self.last_position.as_ref()
    }

    /// Takes the next finished frame.
    pub fn pop_frame(&mut self) -> Option<Frame> {
        self.ready.pop_front()
    }

    /// Ends the stream: the frame in progress (if it has any firing) becomes ready, marked as not
    /// ending at a cut.
    pub fn finish(&mut self) {
        if self.current.packets > 0 {
            self.close_frame(false);
        }
    }

    /// Parses a position packet payload and keeps it as [`Self::last_position`].
    pub fn push_position(&mut self, payload: &[u8]) -> Result<PositionPacketRepr, PositionError> {
        let parsed = PositionPacket::new_checked(payload)
            .and_then(|packet| PositionPacketRepr::parse(&packet));
        match parsed {
            Ok(repr) => {
                self.stats.position_packets += 1;
                self.last_position = Some(repr);
                Ok(repr)
            }
            Err(err) => {
                self.stats.malformed_position += 1;
                Err(err)
            }
        }
    }

    /// Decodes one data packet payload received at `recv_host_ns`. A malformed packet is counted
    /// under its reason and skipped whole (no state changes besides the counter).
    pub fn push_data(&mut self, payload: &[u8], recv_host_ns: u64) -> Result<(), DecodeError> {
        let result = self.push_data_inner(payload, recv_host_ns);
        if let Err(err) = &result {
            self.stats.count_malformed(err.reason());
        }
        result
    }

    fn push_data_inner(&mut self, payload: &[u8], recv_host_ns: u64) -> Result<(), DecodeError> {
        let packet = Vlp16Packet::new_checked(payload)?;
        let (mode, product) = packet.check_fields()?;
        let cycles = cycles_of(&packet, mode, self.config.azimuth_interpolation)?;
        self.count_packet(mode, product);
        let timestamp_us = packet.timestamp_us();
        self.packet_counted = false;
        for k in 0..cycles.count {
            let azimuth_raw = f64::from(cycles.azimuth_raw[k]);
            let step_raw = cycles.step_raw[k];
            let (sin_b, cos_b) = (azimuth_raw * RAW_TO_RAD).sin_cos();
            let rotation = BlockRotation {
                sin_b,
                cos_b,
                azimuth_raw,
                step_raw,
            };
            for seq in 0..2 {
                let seq_azimuth_raw = azimuth_raw + step_raw * self.fractions[seq * LASERS];
                let seq_offset_us = CYCLE_US * k as f64 + SEQUENCE_US * seq as f64;
                self.begin_sequence(seq_azimuth_raw, timestamp_us, seq_offset_us, recv_host_ns);
                let time_base_us = self.time_since_frame_start(timestamp_us) + seq_offset_us;
                let block = k * cycles.blocks_per_cycle;
                self.decode_sequence(&packet, block, seq, mode, &rotation, time_base_us);
            }
        }
        Ok(())
    }

    fn count_packet(&mut self, mode: ReturnMode, product: Product) {
        self.stats.data_packets += 1;
        self.stats.return_modes[match mode {
            ReturnMode::Strongest => 0,
            ReturnMode::Last => 1,
            ReturnMode::Dual => 2,
        }] += 1;
        match product {
            Product::Vlp16 => self.stats.products[0] += 1,
            Product::Vlp16OldFirmware => {
                self.stats.products[1] += 1;
                if !self.warned_old_firmware {
                    self.warned_old_firmware = true;
                    tracing::warn!(
                        "VLP-16 product byte is 0x21 (firmware older than 3.0.29.0); decoding as a VLP-16"
                    );
                }
            }
        }
    }

    /// Bookkeeping before a firing sequence at `azimuth_raw`, fired `offset_us` after the packet
    /// stamp: closes the frame when the azimuth wrapped past the cut angle since the previous
    /// sequence, starts a frame when none is open, and sums the sweep for the rpm estimate.
    fn begin_sequence(
        &mut self,
        azimuth_raw: f64,
        timestamp_us: u32,
        offset_us: f64,
        recv_host_ns: u64,
    ) {
        let from_cut = wrap_raw(azimuth_raw - self.cut_raw);
        // A wrap past the cut shows as the angle from the cut dropping by more than half a turn;
        // a small drop is a late or repeated packet, not a new revolution.
        if let Some((previous_from_cut, _)) = self.previous_sequence
            && previous_from_cut - from_cut > f64::from(AZIMUTH_RAW_MAX / 2)
        {
            self.close_frame(true);
            self.current.starts_at_cut = true;
        }
        if self.frame_base_us.is_none() {
            self.frame_base_us = Some((timestamp_us, offset_us));
            self.current.start_sensor_us =
                (f64::from(timestamp_us) + offset_us).rem_euclid(HOUR_US as f64);
            self.current.start_host_ns = recv_host_ns;
        }
        let now_us = self.time_since_frame_start(timestamp_us) + offset_us;
        if let Some((previous_from_cut, previous_us)) = self.previous_sequence {
            self.current.sweep_raw += from_cut - previous_from_cut;
            self.current.duration_us += now_us - previous_us;
        }
        self.previous_sequence = Some((from_cut, now_us));
        if !self.packet_counted {
            self.current.packets += 1;
            self.packet_counted = true;
        }
    }

    /// Microseconds from the current frame's first firing to the packet stamped `timestamp_us`.
    fn time_since_frame_start(&self, timestamp_us: u32) -> f64 {
        match self.frame_base_us {
            Some((base_ts, base_offset)) => {
                wrapped_diff_us(timestamp_us, base_ts) as f64 - base_offset
            }
            None => 0.0,
        }
    }

    fn close_frame(&mut self, at_cut: bool) {
        let index = self.current.index + 1;
        let capacity = self.current.points.len();
        let mut frame = core::mem::replace(&mut self.current, Frame::empty(index));
        self.current.points.reserve(capacity);
        frame.ends_at_cut = at_cut;
        self.frame_base_us = None;
        self.previous_sequence = None;
        self.packet_counted = false;
        self.stats.frames += 1;
        self.ready.push_back(frame);
    }

    /// Decodes the 16 firings of sequence `seq` of `block` (and, in dual mode, of its partner
    /// block). The firings' azimuth trigonometry is computed first for all 16 lasers in a tight
    /// loop; the returns then only scale it.
    fn decode_sequence(
        &mut self,
        packet: &Vlp16Packet<&[u8]>,
        block: usize,
        seq: usize,
        mode: ReturnMode,
        rotation: &BlockRotation,
        time_base_us: f64,
    ) {
        let firings = self.firings(seq, rotation, time_base_us);
        let bytes = packet.block_bytes(block);
        let second = (mode == ReturnMode::Dual).then(|| packet.block_bytes(block + 1));
        let first_kind = if mode == ReturnMode::Strongest {
            ReturnKind::Strongest
        } else {
            ReturnKind::Last
        };
        for laser in 0..LASERS {
            let at = 4 + 3 * (seq * LASERS + laser);
            let record = Record::read(bytes, at);
            self.emit_return(record, first_kind, laser, &firings);
            if let Some(second) = second {
                let other = Record::read(second, at);
                if other.distance_raw == record.distance_raw && other.distance_raw != 0 {
                    self.stats.dual_duplicates += 1;
                    continue;
                }
                let kind = if other.reflectivity > record.reflectivity {
                    ReturnKind::Strongest
                } else {
                    ReturnKind::SecondStrongest
                };
                self.emit_return(other, kind, laser, &firings);
            }
        }
    }

    /// sin/cos of the azimuth, the azimuth and the time of each laser's firing in a sequence.
    fn firings(&self, seq: usize, rotation: &BlockRotation, time_base_us: f64) -> Firings {
        let mut f = Firings {
            sin_a: [0.0; LASERS],
            cos_a: [0.0; LASERS],
            azimuth_rad: [0.0; LASERS],
            time_us: [0.0; LASERS],
        };
        let mut offsets_raw = [0.0; LASERS];
        for (laser, offset_raw) in offsets_raw.iter_mut().enumerate() {
            *offset_raw = rotation.step_raw * self.fractions[seq * LASERS + laser];
        }
        // A loop of its own: inside the loop below, LLVM evaluated `round` (a libm call on
        // baseline x86-64) for both settings, 9 % of the decoding time.
        if self.config.azimuth_interpolation == AzimuthInterpolation::PacketMeanRounded {
            for offset_raw in &mut offsets_raw {
                *offset_raw = (rotation.azimuth_raw + *offset_raw).round() - rotation.azimuth_raw;
            }
        }
        for (laser, &offset_raw) in offsets_raw.iter().enumerate() {
            let (sin_d, cos_d) = small_sin_cos(offset_raw * RAW_TO_RAD);
            f.sin_a[laser] = (rotation.sin_b * cos_d + rotation.cos_b * sin_d) as f32;
            f.cos_a[laser] = (rotation.cos_b * cos_d - rotation.sin_b * sin_d) as f32;
            f.azimuth_rad[laser] =
                (wrap_raw(rotation.azimuth_raw + offset_raw) * RAW_TO_RAD) as f32;
            f.time_us[laser] = (time_base_us + FIRING_US * laser as f64) as f32;
        }
        f
    }

    fn emit_return(&mut self, record: Record, kind: ReturnKind, laser: usize, firings: &Firings) {
        if record.distance_raw == 0 {
            self.stats.zero_returns += 1;
            return;
        }
        if record.distance_raw < self.min_range_raw || record.distance_raw > self.max_range_raw {
            self.stats.out_of_range += 1;
            return;
        }
        let r = f32::from(record.distance_raw) * DISTANCE_RESOLUTION_M
            - self.config.range_offsets_m[laser];
        if r <= 0.0 {
            // Only a positive offset larger than the raw range gets here (below `min_range_m`).
            self.stats.out_of_range += 1;
            return;
        }
        let xy = r * self.lasers.cos_w[laser];
        self.current.points.push(Point {
            x_m: xy * firings.sin_a[laser],
            y_m: xy * firings.cos_a[laser],
            z_m: r * self.lasers.sin_w[laser] + self.lasers.z_offset_m[laser],
            time_us: firings.time_us[laser],
            azimuth_rad: firings.azimuth_rad[laser],
            intensity: record.reflectivity,
            ring: self.lasers.ring[laser],
            laser_id: laser as u8,
            return_kind: kind,
        });
        self.stats.points += 1;
    }
}

/// sin/cos of a block's azimuth, the azimuth and the step to the next cycle.
struct BlockRotation {
    sin_b: f64,
    cos_b: f64,
    azimuth_raw: f64,
    step_raw: f64,
}

/// The 16 firings of one sequence: azimuth sin/cos, azimuth and time since the frame start.
struct Firings {
    sin_a: [f32; LASERS],
    cos_a: [f32; LASERS],
    azimuth_rad: [f32; LASERS],
    time_us: [f32; LASERS],
}

#[derive(Debug, Clone, Copy)]
struct Record {
    distance_raw: u16,
    reflectivity: u8,
}

impl Record {
    fn read(block: &[u8], at: usize) -> Self {
        Self {
            distance_raw: u16::from_le_bytes([block[at], block[at + 1]]),
            reflectivity: block[at + 2],
        }
    }
}
