//! Wheel-speed PID step response and constant-velocity ripple on the plant model
//! (tests/common/plant.rs: approximate, independent wheels). Figures are printed with
//! `cargo test -p control --test step_response -- --nocapture` and reported in docs/firmware.md (measured figures).
#![allow(clippy::cast_precision_loss, clippy::cast_possible_truncation)]

mod common;

use common::Sim;
use common::plant::{Plant, PlantParams};
use control::Config;
use control::odometry::rpm_to_wheel_radps;
use control::pid::Pid;

/// Step response figures of one wheel loop.
struct StepFigures {
    rise_10_90_ms: f32,
    overshoot_pct: f32,
    settle_2pct_ms: f32,
    final_error_pct: f32,
}

fn step_response(setpoint_radps: f32, params: PlantParams) -> StepFigures {
    let config = Config::default();
    let mut plant = Plant::new(params, 7);
    let mut pid = Pid::new();
    let mut speeds = Vec::new();
    let mut current = 0i16;
    for _ in 0..1000 {
        plant.advance([current, 0, 0, 0], 0.001);
        let fb = plant.feedback(0);
        let measured = rpm_to_wheel_radps(fb.speed_rpm);
        let amps = pid.update(&config.pid, setpoint_radps, measured, 0.001);
        current = protocol::esc::amps_to_raw(amps);
        speeds.push(plant.motors[0].speed_radps);
    }
    let t10 = speeds
        .iter()
        .position(|w| *w >= 0.1 * setpoint_radps)
        .expect("never reached 10 %");
    let t90 = speeds
        .iter()
        .position(|w| *w >= 0.9 * setpoint_radps)
        .expect("never reached 90 %");
    let peak = speeds.iter().copied().fold(f32::MIN, f32::max);
    let band = 0.02 * setpoint_radps;
    let settle = speeds
        .iter()
        .rposition(|w| (w - setpoint_radps).abs() > band)
        .map_or(0, |i| i + 1);
    let tail = &speeds[900..];
    let mean_tail = tail.iter().sum::<f32>() / tail.len() as f32;
    StepFigures {
        rise_10_90_ms: (t90 - t10) as f32,
        overshoot_pct: 100.0 * (peak - setpoint_radps).max(0.0) / setpoint_radps,
        settle_2pct_ms: settle as f32,
        final_error_pct: 100.0 * (mean_tail - setpoint_radps).abs() / setpoint_radps,
    }
}

#[test]
fn pid_step_response_on_motor_model() {
    // 8 rad/s at the wheel = 0.3 m/s with 38 mm wheels, the measuring speed.
    let quiet = PlantParams {
        disturbance_nm: 0.0,
        speed_noise_rpm: 0.0,
        ..PlantParams::default()
    };
    let f = step_response(8.0, quiet);
    println!(
        "PID step 0 -> 8 rad/s (noise-free plant): rise 10-90 % {:.0} ms, overshoot {:.1} %, \
         settle to 2 % {:.0} ms, final error {:.2} %",
        f.rise_10_90_ms, f.overshoot_pct, f.settle_2pct_ms, f.final_error_pct
    );
    assert!(f.rise_10_90_ms <= 40.0, "too slow: {} ms", f.rise_10_90_ms);
    assert!(f.overshoot_pct <= 10.0, "overshoot {} %", f.overshoot_pct);
    assert!(
        f.settle_2pct_ms <= 200.0,
        "settling {} ms",
        f.settle_2pct_ms
    );
    assert!(
        f.final_error_pct <= 0.5,
        "steady-state error {} %",
        f.final_error_pct
    );

    let noisy = step_response(8.0, PlantParams::default());
    println!(
        "PID step 0 -> 8 rad/s (disturbed plant): rise {:.0} ms, overshoot {:.1} %, final error {:.2} %",
        noisy.rise_10_90_ms, noisy.overshoot_pct, noisy.final_error_pct
    );
    assert!(
        noisy.final_error_pct <= 1.0,
        "steady-state error {} %",
        noisy.final_error_pct
    );
}

/// Ripple of the true forward speed at cruise: (rms deviation, peak-to-peak) relative to cruise.
fn cruise_ripple(vx_mps: f32, seed: u64) -> (f32, f32, f32) {
    let mut sim = Sim::default_seeded(seed);
    sim.start_forward(vx_mps);
    // S-curve at 0.5 m/s^2, 5 m/s^3: cruise reached in about 0.7 s; wait 1.5 s to settle.
    sim.run(1500);
    let mut samples = Vec::new();
    for _ in 0..3000 {
        sim.tick();
        samples.push(sim.true_twist().vx_mps);
    }
    let mean = samples.iter().sum::<f32>() / samples.len() as f32;
    let rms =
        (samples.iter().map(|v| (v - mean).powi(2)).sum::<f32>() / samples.len() as f32).sqrt();
    let (lo, hi) = samples
        .iter()
        .fold((f32::MAX, f32::MIN), |(lo, hi), v| (lo.min(*v), hi.max(*v)));
    (
        100.0 * rms / vx_mps,
        100.0 * (hi - lo) / vx_mps,
        100.0 * (mean - vx_mps) / vx_mps,
    )
}

#[test]
fn velocity_ripple_at_cruise() {
    for vx in [0.2f32, 0.3, 0.5] {
        let (rms_pct, p2p_pct, bias_pct) = cruise_ripple(vx, 11);
        println!(
            "cruise {vx:.1} m/s: velocity ripple rms {rms_pct:.2} %, peak-to-peak {p2p_pct:.2} %, mean error {bias_pct:+.2} %"
        );
        assert!(rms_pct < 2.0, "rms ripple {rms_pct} % at {vx} m/s");
        assert!(
            bias_pct.abs() < 1.0,
            "mean speed off by {bias_pct} % at {vx} m/s"
        );
    }
}

#[test]
fn ripple_figure_can_fail() {
    // The same measurement on a plant with ten times the load disturbance must read worse: the
    // figure responds to what it measures.
    let mut loud = Sim::new(
        Config::default(),
        PlantParams {
            disturbance_nm: 0.5,
            ..PlantParams::default()
        },
        11,
    );
    loud.start_forward(0.3);
    loud.run(1500);
    let mut samples = Vec::new();
    for _ in 0..3000 {
        loud.tick();
        samples.push(loud.true_twist().vx_mps);
    }
    let mean = samples.iter().sum::<f32>() / samples.len() as f32;
    let rms =
        (samples.iter().map(|v| (v - mean).powi(2)).sum::<f32>() / samples.len() as f32).sqrt();
    let (quiet_rms, _, _) = cruise_ripple(0.3, 11);
    assert!(
        100.0 * rms / 0.3 > 2.0 * quiet_rms,
        "loud {} vs quiet {}",
        100.0 * rms / 0.3,
        quiet_rms
    );
}
