//! MCU link: onboard computer <-> STM32 firmware, UART 921600 baud, fast and nearly clean.
//!
//! The onboard sends [`Hello`], [`SetConfig`](ToFirmware::SetConfig) (a [`McuConfig`]), then
//! [`Drive`] / [`Stop`] and a [`Heartbeat`] every 20 ms. The firmware answers `Hello`, sends
//! [`Odometry`] at the configured rate (default 100 Hz), [`Status`] at 10 Hz and on every change,
//! and [`Rejected`] for any command it refuses, naming the reason and the field.

use postcard::experimental::max_size::MaxSize;
use serde::{Deserialize, Serialize};

use crate::bounded::Text;
use crate::common::{Heartbeat, Hello, LogLine};
use crate::message::{bit_set, message_set, wire_enum};

/// Drive at a constant body velocity, reached along a jerk-limited profile.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, MaxSize)]
pub struct Drive {
    /// Forward velocity, m/s (robot frame, x forward).
    pub vx_mps: f32,
    /// Leftward velocity, m/s (y left).
    pub vy_mps: f32,
    /// Yaw rate, rad/s (counter-clockwise seen from above).
    pub wz_radps: f32,
    /// Acceleration limit of the setpoint profile, m/s^2.
    pub accel_mps2: f32,
    /// Jerk limit of the setpoint profile, m/s^3 (0 = trapezoid, no jerk limit).
    pub jerk_mps3: f32,
}

/// Stop: ramp to zero along the profile, or at once.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
pub struct Stop {
    /// `true`: zero currents immediately (the wheels coast); `false`: ramp down, then hold zero.
    pub immediate: bool,
}

/// Clear latched faults (only accepted once the cause is gone; motion needs a new [`Drive`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
pub struct ClearFaults {}

/// The firmware's configuration (the firmware starts from built-in defaults; see docs/firmware.md).
///
/// The same type is the onboard service's `[mcu.firmware]` table (`onboard::config`), so the
/// file and the wire cannot drift apart. The serde attributes serve that file only: postcard
/// encodes a struct as its fields in order, without names, so renaming and refusing unknown keys
/// leave the wire format as it is (`tests/wire.rs` pins its bytes).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, MaxSize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct McuConfig {
    /// Wheel radius, m.
    pub wheel_radius_m: f32,
    /// Half the wheelbase (centre to axle), m: `lx`.
    pub half_length_m: f32,
    /// Half the track (centre to wheel), m: `ly`.
    pub half_width_m: f32,
    /// ESC id (1..=8) of each wheel, in the order front-left, front-right, rear-left, rear-right.
    pub esc_ids: [u8; 4],
    /// Mounting sign (+1 or -1) of each wheel, same order: -1 where positive current drives the
    /// robot backwards.
    pub wheel_signs: [i8; 4],
    /// Current limit per wheel, A (at most 20).
    pub current_limit_a: f32,
    /// Wheel-speed PID proportional gain, A per rad/s of wheel speed error.
    pub speed_kp: f32,
    /// Integral gain, A per rad.
    pub speed_ki: f32,
    /// Derivative gain, A per rad/s^2.
    pub speed_kd: f32,
    /// Largest accepted body speed, m/s.
    pub max_speed_mps: f32,
    /// Largest accepted acceleration, m/s^2.
    pub max_accel_mps2: f32,
    /// Heartbeat timeout, ms.
    pub heartbeat_timeout_ms: u16,
    /// ESC feedback timeout, ms.
    pub feedback_timeout_ms: u16,
    /// Odometry report period, ms.
    pub odometry_period_ms: u16,
    /// Motor temperature that latches an over-temperature fault, degrees C.
    pub over_temperature_c: u8,
    /// Measured current that latches an over-current fault, A.
    pub over_current_a: f32,
    /// Time at high current with the rotor not turning that latches a stall fault, ms.
    pub stall_timeout_ms: u16,
}

/// Odometry from the wheel encoders (MCU clock).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, MaxSize)]
pub struct Odometry {
    /// MCU clock, microseconds since boot.
    pub stamp_us: u64,
    /// Integrated pose in the odometry frame (origin and heading at the last reset), m.
    pub x_m: f32,
    /// Integrated pose, m.
    pub y_m: f32,
    /// Integrated heading, rad.
    pub yaw_rad: f32,
    /// Body velocity, m/s (robot frame).
    pub vx_mps: f32,
    /// Body velocity, m/s (robot frame).
    pub vy_mps: f32,
    /// Yaw rate, rad/s.
    pub wz_radps: f32,
    /// Wheel (output shaft) speeds, rad/s, order FL, FR, RL, RR, signs corrected to "forward positive".
    pub wheel_speed_radps: [f32; 4],
}

wire_enum! {
    /// The drive state machine's mode.
    pub enum DriveMode {
        /// Zero currents, waiting for a drive command.
        Idle = 1,
        /// Following the setpoint profile towards the commanded velocity.
        Ramping = 2,
        /// At the commanded constant velocity.
        Cruising = 3,
        /// Ramping down to zero (stop, or heartbeat lost).
        Stopping = 4,
        /// A fault is latched: zero currents until cleared.
        Faulted = 5,
    }
}

bit_set! {
    /// Interlocks that currently block motion, each reported by name.
    pub struct Interlocks(u32) {
        /// No heartbeat within the timeout: ramped to zero and latched until a new drive command.
        const HEARTBEAT_LOST = 0;
        /// An ESC's feedback is missing (see the per-ESC faults for which).
        const ESC_FEEDBACK_MISSING = 1;
        /// An ESC reports over-temperature.
        const ESC_OVER_TEMPERATURE = 2;
        /// An ESC's current exceeded the limit.
        const ESC_OVER_CURRENT = 3;
        /// A motor stalled (high current, no rotation).
        const ESC_STALLED = 4;
        /// The CAN controller went bus-off (recovering).
        const CAN_BUS_OFF = 5;
        /// No valid configuration yet.
        const NOT_CONFIGURED = 6;
        /// The onboard has not said `Hello` yet.
        const NO_HOST = 7;
        /// A stop was requested and no new drive command has arrived.
        const STOP_REQUESTED = 8;
        /// The battery is below the firmware's cutoff (low-pass filtered, so the sag of an
        /// acceleration does not trip it): ramped to zero, drives refused until it recovers.
        const BATTERY_LOW = 9;
        /// An ESC's torque current does not follow its command (see the per-ESC faults for
        /// which).
        const ESC_NOT_FOLLOWING = 10;
    }
}

bit_set! {
    /// Faults of one ESC.
    pub struct EscFaults(u8) {
        /// No feedback within the feedback timeout.
        const MISSING = 0;
        /// Temperature above the limit.
        const OVER_TEMPERATURE = 1;
        /// Current above the limit.
        const OVER_CURRENT = 2;
        /// Stalled.
        const STALLED = 3;
        /// Its torque current does not follow the commanded current.
        const NOT_FOLLOWING = 4;
    }
}

/// One wheel's ESC as the firmware sees it.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize, MaxSize)]
pub struct EscStatus {
    /// The ESC id (1..=8).
    pub esc_id: u8,
    /// Latched faults.
    pub faults: EscFaults,
    /// Last reported temperature, degrees C.
    pub temperature_c: u8,
    /// Last reported torque current, A.
    pub current_a: f32,
    /// Current commanded in the last control step, A.
    pub command_a: f32,
}

/// Firmware state, at 10 Hz and on every change.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, MaxSize)]
pub struct Status {
    /// MCU clock, microseconds since boot.
    pub stamp_us: u64,
    /// Drive mode.
    pub mode: DriveMode,
    /// What blocks motion now.
    pub interlocks: Interlocks,
    /// Per wheel, order FL, FR, RL, RR.
    pub esc: [EscStatus; 4],
    /// CAN bus-off events since boot.
    pub bus_off_count: u16,
    /// MCU-link frames dropped (CRC, COBS, oversize, malformed) since boot.
    pub link_errors: u16,
    /// Commands rejected since boot.
    pub rejected_count: u16,
    /// Battery voltage at the board's supply input, low-pass filtered, millivolts (0: not
    /// measured).
    pub battery_mv: u16,
    /// Longest control step since boot, microseconds (the firmware's DWT cycle counter; 0: not
    /// measured). The step runs every 1000 us: this is the real board's timing margin.
    pub control_step_max_us: u16,
}

wire_enum! {
    /// Why a command was refused.
    pub enum RejectReason {
        /// The sender speaks another protocol version.
        VersionMismatch = 1,
        /// The id is not a command the firmware accepts.
        UnknownMessage = 2,
        /// The payload did not decode.
        Malformed = 3,
        /// A field is outside its allowed range (named in `field`).
        OutOfRange = 4,
        /// An interlock blocks motion (see [`Status`]).
        Interlocked = 5,
        /// Motion commanded before a valid configuration.
        NotConfigured = 6,
    }
}

/// A command was refused.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
pub struct Rejected {
    /// Id of the refused message.
    pub msg_id: u16,
    /// Its sequence number.
    pub seq: u16,
    /// Why.
    pub reason: RejectReason,
    /// The offending field (e.g. `vx_mps`) or interlock name; empty if none applies.
    pub field: Text<24>,
}

crate::message::impl_message! {
    Drive => crate::ids::DRIVE,
    Stop => crate::ids::STOP,
    McuConfig => crate::ids::SET_CONFIG,
    ClearFaults => crate::ids::CLEAR_FAULTS,
    Odometry => crate::ids::ODOMETRY,
    Status => crate::ids::STATUS,
    Rejected => crate::ids::REJECTED,
}

message_set! {
    /// Everything the firmware accepts from the onboard computer.
    pub enum ToFirmware {
        /// Handshake.
        Hello(Hello),
        /// Liveness.
        Heartbeat(Heartbeat),
        /// Drive command.
        Drive(Drive),
        /// Stop command.
        Stop(Stop),
        /// Configuration.
        SetConfig(McuConfig),
        /// Clear latched faults.
        ClearFaults(ClearFaults),
    }
}

message_set! {
    /// Everything the onboard computer accepts from the firmware.
    pub enum FromFirmware {
        /// Handshake answer.
        Hello(Hello),
        /// Encoder odometry.
        Odometry(Odometry),
        /// State and faults.
        Status(Status),
        /// A refused command.
        Rejected(Rejected),
        /// Firmware log line.
        LogLine(LogLine),
    }
}

// Every message of every set fits the links' receive buffer (a compile-time check).
const _: () = assert!(ToFirmware::MAX_FRAME_LEN <= crate::frame::MAX_FRAME_LEN);
const _: () = assert!(FromFirmware::MAX_FRAME_LEN <= crate::frame::MAX_FRAME_LEN);
