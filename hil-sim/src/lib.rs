//! passangle software-in-the-loop simulator (docs/architecture.md section 7): a parametric vehicle,
//! with parts or its whole body optionally given as triangle meshes, over a flat ground, true
//! passing angles from its geometry, and simulated VLP-16 and D435 sensors that see it
//! from a robot driving underneath.
//!
//! Module map, from the world outward:
//! - [`geometry`]: vectors, rotations, rigid transforms, poses.
//! - [`vehicle`]: the vehicle TOML format and its validation.
//! - [`mesh`]: triangle meshes (OBJ, STL, PLY loaders), their BVH, ray casting and distance.
//! - [`truth`]: true approach, departure and breakover angles by brute-force tangent rotation.
//! - [`world`]: the scene (ground, tyres, body prisms, parts) and its ray caster.
//! - [`trajectory`]: robot poses over time (a trait, the scenario's analytic motion, sampled paths).
//! - [`scenario`]: the scenario TOML format (vehicle, robot run, sensors, seed).
//! - [`vlp16`]: the VLP-16 sensor model (firing timing, noise, dropouts) producing packets.
//! - [`d435`]: the D435 depth camera model producing Z16 frames.
//! - [`wheel_odometry`]: the wheel odometry the firmware would report, with a mecanum error model.
//!
//! Firmware in the loop (docs/simulator.md): [`esc_model`] (C620 + M3508 with injectable faults),
//! [`robot`] (mecanum chassis dynamics with slip; its [`robot::PoseHistory`] is the odometry
//! truth), [`can_bus`] (the bus trait: in-process, SocketCAN), [`pty`] (the MCU link's byte pipe:
//! in memory, pseudo-terminal), [`fil`] (the runner stepping `control::Controller` on a 1 ms
//! clock) and [`fil_scenarios`] (the issue-8 scenarios with their figures and checks). The
//! SocketCAN and pty ends and the real-time pacing are the only parts of these that touch the OS.
//!
//! Everything here is a pure function of (scenario, seed, time); the command line in `main.rs` is
//! the only part that touches files, sockets and clocks.

pub mod can_bus;
pub mod d435;
pub mod demo;
pub mod esc_model;
pub mod feed;
pub mod fil;
pub mod fil_scenarios;
pub mod geometry;
pub mod lockstep;
pub mod mesh;
pub mod pty;
pub mod robot;
pub mod scenario;
pub mod trajectory;
pub mod truth;
pub mod vehicle;
pub mod vlp16;
pub mod wheel_odometry;
pub mod world;
