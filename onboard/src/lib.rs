//! passangle onboard library: sensor decoding, the point-cloud pipeline, the angle calculator, links
//! and the run recorder (DESIGN.md section 6). Everything here except the thin IO adapters is a pure
//! function of its inputs: no clocks, no IO in the pipeline or the angle calculator.

pub mod angles;
pub mod camera;
pub mod client;
pub mod cloud;
pub mod config;
pub mod link;
pub mod mcu_clock;
pub mod pcap;
pub mod pipeline;
pub mod process;
pub mod recorder;
pub mod run;
pub mod service;
pub mod vlp16;
