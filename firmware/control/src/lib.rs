//! passangle firmware logic (docs/architecture.md section 5): everything the STM32 does except touching
//! hardware. `no_std`, no alloc, no clocks: time and received data come in, wheel currents and
//! MCU-link bytes go out, so the same code runs on the board, in `hil-sim` and in host tests.
//!
//! Layers, bottom up (each module has its own docs and tests):
//! - [`kinematics`]: mecanum inverse/forward kinematics (x forward, y left, k = lx + ly);
//! - [`pid`]: wheel-speed PID with anti-windup and a current limit;
//! - [`profile`]: jerk-limited (S-curve) or trapezoid setpoint ramps to a constant cruise speed;
//! - [`odometry`]: rotor-angle unwrapping, gear ratio, integrated pose and twist;
//! - [`safety`]: per-ESC fault monitors, named interlocks, bus state;
//! - [`config`]: the tuning knobs and their validation;
//! - [`busload`]: exact CAN frame lengths (bit stuffing) for the bus-load figure;
//! - [`machine`]: the drive state machine tying the above together (`command` + `step`);
//! - [`link`]: MCU-link frames in (shared deframer, `protocol::mcu`), replies and rejections out;
//! - [`controller`]: [`Controller::step`]`(now_us, &Inputs) -> Outputs`, the one call the
//!   embassy shell and the simulator make every millisecond.
//!
//! Units are SI with the unit in the name (`vx_mps`, `stamp_us`); wheel speeds are output-shaft
//! rad/s, positive when the wheel rolls the robot forward; rpm only at the ESC boundary. All times
//! are on the MCU clock in microseconds.
#![cfg_attr(not(test), no_std)]
#![warn(clippy::cast_possible_truncation, clippy::cast_sign_loss)]

pub mod battery;
pub mod busload;
pub mod config;
pub mod controller;
pub mod kinematics;
pub mod link;
pub mod machine;
pub mod odometry;
pub mod pid;
pub mod profile;
pub mod safety;

pub use config::{Config, ConfigError, WheelMap};
pub use controller::{Controller, Inputs, LedPattern, Outputs};
pub use kinematics::{Geometry, Twist, Wheel};
pub use machine::{Command, DriveCommand, EscSample, Machine, Mode, Reject, StepOutput};
pub use safety::{BusState, EscFaults, Interlocks};
