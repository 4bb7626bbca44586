//! passangle onboard library: the configuration, the run state machine, the run recorder, the
//! processing of a run and the service around them (docs/architecture.md section 6).
//!
//! The point-cloud pipeline and the calculator (`pipeline`, `angles`) are crates of their own that
//! depend on no IO crate; so are the VLP-16 decoding and pcap files (`vlp16`), the cloud file
//! formats (`cloud_io`) and the links with the handheld's client (`link`). Users depend on those
//! crates directly. The rest is a pure function of its inputs except the thin IO adapters.

pub mod camera;
pub mod config;
pub mod frames;
pub mod mcu_clock;
pub mod process;
pub mod recorder;
pub mod report;
pub mod run;
pub mod scan_file;
#[cfg(feature = "service")]
pub mod service;
pub mod signed;
pub mod wheel_calibration;
pub use signing;
