//! Benchmark: simulated VLP-16 seconds per wall-clock second on one core, for every shipped
//! scenario, with the default sensor model (noise, dropouts, motion, packet emit). The reference is
//! the real sensor, which produces one second of data per second: the printed figure is the ratio.
//!
//! Run: `cargo run --release -p hil-sim --example bench_lidar [SECONDS]` (default 10 simulated s
//! per scenario). The last column is the same work without the per-packet wedge culling of the
//! ray caster (the peer measured in the same run; both must produce the same returns). CPU time (from /proc/self/schedstat, Linux) is printed next to wall time because
//! a shared machine's load inflates wall time; the goal (>= 20x) is stated for one free core.

use std::path::PathBuf;
use std::time::Instant;

use hil_sim::scenario::Scenario;
use hil_sim::vlp16::{PACKET_S, Vlp16Sim};
use hil_sim::world::Scene;

/// CPU time of this thread's process so far, seconds (None where /proc is unavailable).
fn cpu_time_s() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/self/schedstat").ok()?;
    let ns: f64 = text.split_whitespace().next()?.parse().ok()?;
    Some(ns / 1e9)
}

/// Produce and emit packets `first..first + n`; returns (returns, wall s, CPU s).
fn run<T: hil_sim::trajectory::Trajectory>(
    sim: &Vlp16Sim<'_, T>,
    first: u64,
    n: u64,
) -> (u64, f64, f64) {
    let (cpu0, t0) = (cpu_time_s(), Instant::now());
    let mut returns = 0u64;
    for k in first..first + n {
        let bytes = sim.data_packet(k).to_bytes();
        // Count returns from the emitted bytes so the work cannot be optimised away.
        returns += (0..12)
            .flat_map(|b| (0..32).map(move |c| 4 + b * 100 + c * 3))
            .filter(|&o| bytes[o] != 0 || bytes[o + 1] != 0)
            .count() as u64;
    }
    let wall = t0.elapsed().as_secs_f64();
    let cpu = cpu_time_s().zip(cpu0).map_or(f64::NAN, |(a, b)| a - b);
    (returns, wall, cpu)
}

fn main() -> anyhow::Result<()> {
    /// Simulated VLP-16 seconds per CPU second, per scenario.
    #[derive(clap::Parser)]
    struct Args {
        /// Simulated seconds per scenario.
        #[arg(default_value_t = 10.0)]
        seconds: f64,
    }
    let seconds = <Args as clap::Parser>::parse().seconds;
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenarios");
    let mut paths: Vec<PathBuf> = std::fs::read_dir(&dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    paths.sort();
    println!("simulated VLP-16, {seconds} s per scenario, one thread");
    println!(
        "{:<16} {:>7} {:>9} {:>8} {:>12} {:>11} {:>22}",
        "scenario",
        "packets",
        "returns",
        "wall s",
        "sim s/wall s",
        "sim s/CPU s",
        "sim s/CPU s no culling"
    );
    let (mut total_wall, mut total_cpu, mut total_sim, mut total_cpu_full) = (0.0, 0.0, 0.0, 0.0);
    for path in &paths {
        let scenario = Scenario::load(path)?;
        let scene = Scene::from_vehicle(&scenario.vehicle);
        let sim = Vlp16Sim::new(
            &scene,
            &scenario.run,
            scenario.lidar_config(),
            scenario.lidar_seed(),
        );
        let full = Vlp16Sim::new(
            &scene,
            &scenario.run,
            scenario.lidar_config(),
            scenario.lidar_seed(),
        )
        .without_culling();
        // Start a quarter into the run, under the vehicle's front, so the scene is busy.
        let first = (scenario.duration_s * 0.25 / PACKET_S) as u64;
        let n = Vlp16Sim::<hil_sim::trajectory::StraightRun>::packets_in(seconds);
        let (returns, wall, cpu) = run(&sim, first, n);
        let (returns_full, _, cpu_full) = run(&full, first, n);
        assert_eq!(returns, returns_full, "culling changed the output");
        let sim_s = n as f64 * PACKET_S;
        total_wall += wall;
        total_sim += sim_s;
        total_cpu += cpu;
        total_cpu_full += cpu_full;
        let name = path
            .file_stem()
            .map_or_else(String::new, |s| s.to_string_lossy().into_owned());
        println!(
            "{name:<16} {n:>7} {returns:>9} {wall:>8.3} {:>12.1} {:>11.1} {:>22.1}",
            sim_s / wall,
            sim_s / cpu,
            sim_s / cpu_full
        );
    }
    println!(
        "{:<16} {:>7} {:>9} {total_wall:>8.3} {:>12.1} {:>11.1} {:>22.1}   (goal >= 20 on one core)",
        "all",
        "",
        "",
        total_sim / total_wall,
        total_sim / total_cpu,
        total_sim / total_cpu_full
    );
    Ok(())
}
