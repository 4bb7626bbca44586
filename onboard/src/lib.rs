//! passangle onboard library: sensor decoding, links, the run recorder and the service around the
//! point-cloud pipeline and the angle calculator (docs/architecture.md section 6).
//!
//! The pipeline and the calculator are crates of their own (`pipeline`, `angles`) that depend on no
//! IO crate; they are re-exported here so `onboard::pipeline` and `onboard::angles` name them. The
//! rest is a pure function of its inputs except the thin IO adapters.

pub use angles;
pub mod camera;
pub mod client;
pub mod cloud;
pub mod config;
pub mod frames;
pub mod link;
pub mod mcu_clock;
pub mod pcap;
pub use pipeline;
pub mod process;
pub mod recorder;
pub mod run;
pub mod service;
pub mod signed;
pub use signing;
pub mod vlp16;
