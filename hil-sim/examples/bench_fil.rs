//! How fast the firmware-in-the-loop runner simulates, against real time (the pace of the robot,
//! and of `Pacing::RealTime`). Run with `cargo run --release -p hil-sim --example bench_fil`.
//! Prints, per scenario on the in-process bus: simulated seconds, wall seconds and the speed-up
//! over real time; then the cost of one 1 ms tick split into physics + bus + firmware.

use std::time::Instant;

use hil_sim::fil::FilConfig;
use hil_sim::fil_scenarios::{self, BusChoice, LinkChoice};

fn main() {
    let bus = BusChoice::InProcess { record: false };
    let mut total_sim_s = 0.0;
    let mut total_wall_s = 0.0;
    println!(
        "{:<18} {:>8} {:>9} {:>12}",
        "scenario", "sim s", "wall ms", "x real time"
    );
    for name in fil_scenarios::NAMES {
        let sim_s = fil_scenarios::duration_us(name).unwrap_or(0) as f64 * 1e-6;
        // Best of 3 runs, to keep other processes' noise out.
        let wall_s = (0..3)
            .map(|_| {
                let started = Instant::now();
                let outcome =
                    fil_scenarios::run(name, FilConfig::default(), &bus, LinkChoice::Memory)
                        .expect("in-process runs cannot fail to start");
                assert!(outcome.passed(), "{outcome}");
                started.elapsed().as_secs_f64()
            })
            .fold(f64::INFINITY, f64::min);
        total_sim_s += sim_s;
        total_wall_s += wall_s;
        println!(
            "{name:<18} {sim_s:>8.1} {:>9.1} {:>12.0}",
            wall_s * 1e3,
            sim_s / wall_s
        );
    }
    println!(
        "{:<18} {total_sim_s:>8.1} {:>9.1} {:>12.0}",
        "all",
        total_wall_s * 1e3,
        total_sim_s / total_wall_s
    );
    println!(
        "mean cost of one simulated 1 ms tick (judging included): {:.2} us",
        total_wall_s / (total_sim_s * 1e3) * 1e6
    );

    // Sensitivity of the cruise figures to the C620's speed-reading noise (an assumption of the
    // ESC model: 3 rpm by default) and to the wheels' slip stiffness.
    println!();
    println!(
        "{:<34} {:>12} {:>14}",
        "cruise variant", "ripple %", "odometry err %"
    );
    let mut variants: Vec<(String, FilConfig)> = Vec::new();
    for noise_rpm in [0.0, 3.0, 10.0, 30.0] {
        let mut c = FilConfig::default();
        c.esc.speed_noise_rpm = noise_rpm;
        variants.push((format!("speed noise {noise_rpm} rpm"), c));
    }
    for stiffness in [200.0, 800.0, 3200.0] {
        let mut c = FilConfig::default();
        c.robot.slip_stiffness_n_per_mps = stiffness;
        variants.push((format!("slip stiffness {stiffness} N/(m/s)"), c));
    }
    for (label, config) in variants {
        let o = fil_scenarios::run("cruise", config, &bus, LinkChoice::Memory)
            .expect("in-process runs cannot fail to start");
        println!(
            "{label:<34} {:>12.3} {:>14.3}",
            o.figure("cruise velocity ripple (std/mean)")
                .unwrap_or(f64::NAN),
            o.figure("odometry error / distance").unwrap_or(f64::NAN)
        );
    }
}
