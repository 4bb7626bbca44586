//! The firmware-in-the-loop runner in real-time mode with the MCU link over a real
//! pseudo-terminal pair (the device kind a USB-UART adapter is): start, drive, and check that the
//! robot moves, that the firmware's reports cross the pty and that the run kept wall-clock pace.

use std::time::Instant;

use hil_sim::fil::{FilConfig, Pacing};
use hil_sim::fil_scenarios::{self, BusChoice, LinkChoice};

#[test]
fn drives_over_a_pty_in_real_time() {
    let config = FilConfig {
        pacing: Pacing::RealTime,
        ..FilConfig::default()
    };
    let (mut fil, _) = fil_scenarios::build(
        config,
        &BusChoice::InProcess { record: false },
        LinkChoice::Pty,
    )
    .expect("a pty pair opens on Linux");
    fil.schedule(fil_scenarios::start_events(50_000));
    let started = Instant::now();
    fil.run_until(1_200_000).unwrap();
    let wall_s = started.elapsed().as_secs_f64();
    let trace = fil.take_trace();
    let truth = trace.truth.at(1_200_000).unwrap();
    println!(
        "pty real-time run: {wall_s:.3} s wall for 1.2 s simulated; v = {:.4} m/s; {} reports, {} acks",
        truth.vx_mps,
        trace.received.len(),
        trace.acks
    );
    assert!(
        wall_s >= 1.19,
        "real-time pacing ran ahead of the wall clock: {wall_s} s"
    );
    assert!((truth.vx_mps - 0.2).abs() < 0.01, "not cruising: {truth:?}");
    assert!(
        trace.odometry().count() > 100,
        "odometry did not cross the pty"
    );
    assert!(
        trace.acks >= 2,
        "Hello and Drive were not acked over the pty"
    );
    assert_eq!(trace.host_decode_errors, 0);
}
