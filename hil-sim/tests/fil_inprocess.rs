//! Firmware-in-the-loop scenarios on the in-process CAN bus and an in-memory MCU link, virtual
//! time: the real `control::Controller` against the simulated ESCs and robot. Each test prints
//! its figures (run with `--nocapture` to see them) and fails with the full report if any check
//! fails. The same scenarios run over SocketCAN in `fil_vcan.rs`.

use hil_sim::fil::FilConfig;
use hil_sim::fil_scenarios::{self, BusChoice, LinkChoice, Outcome};

fn run(name: &str) -> Outcome {
    let outcome = fil_scenarios::run(
        name,
        FilConfig::default(),
        &BusChoice::InProcess { record: false },
        LinkChoice::Memory,
    )
    .expect("the in-process runner cannot fail to build");
    println!("{outcome}");
    assert!(outcome.passed(), "{outcome}");
    outcome
}

#[test]
fn cruise_constant_velocity() {
    let o = run("cruise");
    assert!(
        o.figure("cruise velocity ripple (std/mean)")
            .is_some_and(|r| r < 1.0)
    );
}

#[test]
fn heartbeat_loss_at_cruise() {
    run("heartbeat-loss");
}

#[test]
fn esc3_stops_answering() {
    run("esc-silent");
}

#[test]
fn over_temperature() {
    run("over-temperature");
}

#[test]
fn bus_off_recovery() {
    run("bus-off");
}

#[test]
fn stuck_over_current() {
    let o = run("stuck-current");
    // Zero commands cannot stop a stuck ESC; the contactor cuts its power, so the robot only
    // coasts from cruise (0.2 m/s) instead of being pushed on (0.64 m in 1.5 s without it).
    let travel = o.figure("travel in the 1.5 s after the fault");
    assert!(travel.is_some_and(|d| d < 0.1), "{travel:?}");
}

#[test]
fn battery_low_at_cruise() {
    run("battery-low");
}

#[test]
fn malformed_flood_on_the_mcu_link() {
    run("link-flood");
}

#[test]
fn same_seed_same_run() {
    let a = fil_scenarios::run(
        "esc-silent",
        FilConfig::default(),
        &BusChoice::InProcess { record: false },
        LinkChoice::Memory,
    )
    .unwrap();
    let b = fil_scenarios::run(
        "esc-silent",
        FilConfig::default(),
        &BusChoice::InProcess { record: false },
        LinkChoice::Memory,
    )
    .unwrap();
    assert_eq!(a.trace.commands, b.trace.commands);
    assert_eq!(a.trace.truth.samples, b.trace.truth.samples);
    assert_eq!(a.figures, b.figures);
}

#[test]
fn a_badly_tuned_firmware_fails_the_ripple_check() {
    // The checks must be able to fail: a sluggish, integral-free speed loop cannot hold 0.2 m/s.
    let mut config = FilConfig::default();
    config.firmware.pid.kp = 0.05;
    config.firmware.pid.ki = 0.0;
    let o = fil_scenarios::run(
        "cruise",
        config,
        &BusChoice::InProcess { record: false },
        LinkChoice::Memory,
    )
    .unwrap();
    println!("{o}");
    assert!(!o.passed(), "a kp=0.05, ki=0 loop passed:\n{o}");
}
