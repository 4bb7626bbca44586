//! Benchmark: simulated D435 depth frames (default 848x480) per second on one core, under the SUV
//! of `scenarios/suv-offset.toml`, against the camera's real 30 frames per second.
//!
//! Run: `cargo run --release -p hil-sim --example bench_depth [FRAMES]` (default 30).

use std::path::PathBuf;
use std::time::Instant;

use hil_sim::d435::{D435Config, D435Sim};
use hil_sim::scenario::Scenario;
use hil_sim::world::Scene;

fn main() -> anyhow::Result<()> {
    /// Simulated D435 frames per second on one core.
    #[derive(clap::Parser)]
    struct Args {
        /// Frames to render.
        #[arg(default_value_t = 30)]
        frames: u64,
    }
    let frames = <Args as clap::Parser>::parse().frames;
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenarios/suv-offset.toml");
    let scenario = Scenario::load(&path)?;
    let scene = Scene::from_vehicle(&scenario.vehicle);
    let config = D435Config {
        fps: 30.0,
        ..scenario.file.depth.clone()
    };
    let sim = D435Sim::new(&scene, &scenario.run, config.clone(), scenario.depth_seed());
    let first = 150; // 5 s in: under the vehicle's front
    let t0 = Instant::now();
    let mut valid = 0usize;
    for i in first..first + frames {
        valid += sim.frame(i).depth_mm.iter().filter(|&&d| d != 0).count();
    }
    let wall = t0.elapsed().as_secs_f64();
    let pixels = (config.width * config.height) as usize * frames as usize;
    println!(
        "{frames} frames {}x{} in {wall:.2} s: {:.1} frames/s ({:.2}x the camera's 30 fps), {:.1} Mrays/s, {:.1} % valid pixels",
        config.width,
        config.height,
        frames as f64 / wall,
        frames as f64 / wall / 30.0,
        pixels as f64 / wall / 1e6,
        100.0 * valid as f64 / pixels as f64
    );
    Ok(())
}
