//! passangle software-in-the-loop simulator (DESIGN.md section 7): a parametric vehicle over a flat
//! ground, true passing angles from its geometry, and simulated VLP-16 and D435 sensors that see it
//! from a robot driving underneath.
//!
//! Module map, from the world outward:
//! - [`geometry`]: vectors, rotations, rigid transforms, poses.
//! - [`vehicle`]: the vehicle TOML format and its validation.
//! - [`truth`]: true approach, departure and breakover angles by brute-force tangent rotation.
//! - [`world`]: the scene (ground, tyres, body prisms, parts) and its ray caster.
//! - [`trajectory`]: robot poses over time (a trait, the scenario's analytic motion, sampled paths).
//! - [`scenario`]: the scenario TOML format (vehicle, robot run, sensors, seed).
//! - [`vlp16`]: the VLP-16 sensor model (firing timing, noise, dropouts) producing packets.
//! - [`d435`]: the D435 depth camera model producing Z16 frames.
//!
//! Everything here is a pure function of (scenario, seed, time); the command line in `main.rs` is
//! the only part that touches files, sockets and clocks.

pub mod can_bus;
pub mod esc_model;
pub mod fil;
pub mod fil_scenarios;
pub mod pty;
pub mod robot;
pub mod d435;
pub mod geometry;
pub mod scenario;
pub mod trajectory;
pub mod truth;
pub mod vehicle;
pub mod vlp16;
pub mod world;
