//! Fault paths, each pinned to what goes on the CAN bus (the 0x200 frame's 8 data bytes) and in
//! how many 1 ms steps. The robot cruises at 0.3 m/s on the plant model when each fault hits.
#![allow(clippy::cast_possible_truncation)]

mod common;

use common::{Patch, STEP_US, Sim};
use control::machine::{Command, DriveCommand};
use control::{BusState, EscFaults, Interlocks, Mode, Reject, Twist};
use protocol::esc::{amps_to_raw, encode_command};
use protocol::mcu::DriveMode;

const ZERO_FRAME: [u8; 8] = [0; 8];

/// A sim cruising at 0.3 m/s, every wheel driven (non-zero current) at the last step.
fn cruising() -> Sim {
    let mut sim = Sim::default_seeded(3);
    sim.start_forward(0.3);
    sim.run(1500);
    assert_eq!(sim.machine.mode(), Mode::Driving);
    assert!(
        sim.last.currents_raw.iter().all(|c| *c != 0),
        "{:?}",
        sim.last.currents_raw
    );
    sim
}

/// Ticks until the 0x200 frame is all zero; returns how many ticks that took (1 = the next tick).
fn ticks_until_zero_frame(sim: &mut Sim, max: usize) -> usize {
    for n in 1..=max {
        let out = sim.tick();
        if encode_command(out.currents_raw) == ZERO_FRAME {
            return n;
        }
    }
    panic!(
        "currents still {:?} after {max} steps",
        sim.last.currents_raw
    );
}

fn assert_zero_for(sim: &mut Sim, steps: usize) {
    for _ in 0..steps {
        let out = sim.tick();
        assert_eq!(
            encode_command(out.currents_raw),
            ZERO_FRAME,
            "mode {:?}",
            sim.machine.mode()
        );
    }
}

#[test]
fn esc_feedback_missing_zeroes_on_the_tenth_step() {
    let mut sim = cruising();
    // ESC 3's last frame arrived in the step just run; from now on it is silent.
    sim.silent[2] = true;
    // Steps 1..=9 after its last frame: still driving (9 ms < 10 ms timeout).
    let n = ticks_until_zero_frame(&mut sim, 50);
    assert_eq!(
        n, 10,
        "zero frame must go out in the step 10 ms after the last feedback"
    );
    let status = sim.machine.status(sim.now_us);
    assert_eq!(status.esc[2].faults, EscFaults::MISSING);
    assert!(status.esc[0].faults.is_empty() && status.esc[1].faults.is_empty());
    assert!(status.interlocks.contains(Interlocks::ESC_FEEDBACK_MISSING));
    assert_eq!(status.mode, DriveMode::Faulted);
    assert_eq!(sim.machine.mode(), Mode::Faulted);
    assert!(
        !sim.machine.contactor_closed(),
        "the fault opens the contactor"
    );
    assert_zero_for(&mut sim, 500);
    // With the contactor open a silent ESC may just be unpowered: clearing restarts it as never
    // seen, closes the contactor, and drives stay refused until ESC 3 reports again.
    assert_eq!(sim.command(Command::ClearFaults), Ok(()));
    assert_eq!(sim.machine.mode(), Mode::Idle);
    assert!(sim.machine.contactor_closed());
    assert_zero_for(&mut sim, 20);
    let drive = Command::Drive(DriveCommand {
        twist: Twist::new(0.3, 0.0, 0.0),
        accel_mps2: 0.5,
        jerk_mps3: 0.0,
    });
    match sim.command(drive) {
        Err(Reject::Interlocked(i)) => assert!(i.contains(Interlocks::ESC_FEEDBACK_MISSING)),
        other => panic!("drive with ESC 3 silent: {other:?}"),
    }
    assert!(
        sim.machine
            .status(sim.now_us)
            .interlocks
            .contains(Interlocks::ESC_FEEDBACK_MISSING)
    );
    sim.silent[2] = false;
    sim.tick();
    assert!(sim.machine.status(sim.now_us).esc[2].faults.is_empty());
    // Idle: still zero until a new drive command.
    assert_zero_for(&mut sim, 20);
}

#[test]
fn contactor_is_closed_without_faults_and_opens_in_the_step_a_fault_latches() {
    let mut sim = cruising();
    assert!(sim.machine.contactor_closed());
    sim.patch[0] = Patch {
        current_raw: Some(amps_to_raw(18.0)),
        ..Patch::default()
    };
    let mut steps = 0;
    while sim.machine.contactor_closed() {
        let out = sim.tick();
        steps += 1;
        assert!(steps <= 10, "contactor still closed after {steps} steps");
        if !sim.machine.contactor_closed() {
            assert_eq!(encode_command(out.currents_raw), ZERO_FRAME);
        }
    }
    assert_eq!(sim.machine.mode(), Mode::Faulted);
    // It stays open while nothing clears the fault.
    for _ in 0..100 {
        sim.tick();
        assert!(!sim.machine.contactor_closed());
    }
    // ClearFaults clears an over-current; if the current is still stuck it latches again within
    // the over-current time and the contactor opens again.
    assert_eq!(sim.command(Command::ClearFaults), Ok(()));
    assert!(sim.machine.contactor_closed());
    let mut reopened = false;
    for _ in 0..10 {
        sim.tick();
        reopened |= !sim.machine.contactor_closed();
    }
    assert!(reopened, "a still-stuck ESC must open the contactor again");
    sim.patch[0] = Patch::default();
    sim.tick();
    assert_eq!(sim.command(Command::ClearFaults), Ok(()));
    assert!(sim.machine.contactor_closed());
}

#[test]
fn over_temperature_zeroes_in_the_same_step() {
    let mut sim = cruising();
    sim.patch[1] = Patch {
        temperature_c: Some(80),
        ..Patch::default()
    };
    assert_eq!(ticks_until_zero_frame(&mut sim, 10), 1);
    assert_eq!(
        sim.machine.status(sim.now_us).esc[1].faults,
        EscFaults::OVER_TEMPERATURE
    );
    assert_zero_for(&mut sim, 100);
    // 75 C is not cool enough (10 C hysteresis); 69 C is.
    sim.patch[1].temperature_c = Some(75);
    sim.tick();
    assert!(matches!(
        sim.command(Command::ClearFaults),
        Err(Reject::FaultsPersist(_))
    ));
    sim.patch[1].temperature_c = Some(69);
    sim.tick();
    assert_eq!(sim.command(Command::ClearFaults), Ok(()));
}

#[test]
fn over_current_zeroes_after_three_ms() {
    let mut sim = cruising();
    sim.patch[0] = Patch {
        current_raw: Some(amps_to_raw(16.0)),
        ..Patch::default()
    };
    // Frames at t, t+1, t+2, t+3 ms: the condition has lasted 3 ms at the fourth.
    assert_eq!(ticks_until_zero_frame(&mut sim, 20), 4);
    assert_eq!(
        sim.machine.status(sim.now_us).esc[0].faults,
        EscFaults::OVER_CURRENT
    );
    assert_zero_for(&mut sim, 100);
}

#[test]
fn stalled_wheel_zeroes_after_the_stall_time() {
    let mut sim = cruising();
    sim.plant.motors[3].locked = true;
    // The PID drives the locked wheel into its 10 A limit within a few ms; the stall fault needs
    // >= 7 A at < 0.3 rad/s for 400 ms.
    let n = ticks_until_zero_frame(&mut sim, 1000);
    assert!((400..=410).contains(&n), "stall detected after {n} steps");
    assert_eq!(
        sim.machine.status(sim.now_us).esc[3].faults,
        EscFaults::STALLED
    );
    assert_zero_for(&mut sim, 100);
}

#[test]
fn bus_off_zeroes_at_once_asks_for_recovery_and_latches() {
    let mut sim = cruising();
    sim.bus = BusState::BusOff;
    let out = sim.tick();
    assert_eq!(encode_command(out.currents_raw), ZERO_FRAME);
    assert!(out.recover_bus);
    let status = sim.machine.status(sim.now_us);
    assert!(status.interlocks.contains(Interlocks::CAN_BUS_OFF));
    assert_eq!(status.bus_off_count, 1);
    // No feedback while bus-off: after 10 ms every ESC also reports a feedback timeout.
    sim.run(20);
    let status = sim.machine.status(sim.now_us);
    assert!(
        status
            .esc
            .iter()
            .all(|e| e.faults.contains(EscFaults::MISSING))
    );
    assert!(matches!(
        sim.command(Command::ClearFaults),
        Err(Reject::FaultsPersist(_))
    ));
    // The bus recovers: no more recovery requests, faults clear, robot idle and still.
    sim.bus = BusState::Active;
    let out = sim.tick();
    assert!(!out.recover_bus);
    assert_eq!(sim.command(Command::ClearFaults), Ok(()));
    assert_eq!(sim.machine.status(sim.now_us).bus_off_count, 1);
    assert_zero_for(&mut sim, 20);
}

#[test]
fn heartbeat_loss_ramps_to_zero_and_latches_until_a_new_start() {
    let mut sim = cruising();
    // Heartbeats come every 20 ms; the last one was at the most recent multiple of 20 ms.
    let last_hb_us = sim.now_us / 20_000 * 20_000;
    sim.heartbeat_every = 0;
    let mut lost_at = None;
    let mut last_sp = sim.machine.setpoint().vx_mps;
    for _ in 0..2000 {
        sim.tick();
        if lost_at.is_none() && sim.machine.mode() != Mode::Driving {
            lost_at = Some(sim.now_us);
        }
        let sp = sim.machine.setpoint().vx_mps;
        assert!(
            sp <= last_sp + 1e-6,
            "setpoint must only decrease: {sp} after {last_sp}"
        );
        last_sp = sp;
        if sim.machine.mode() == Mode::Idle {
            break;
        }
    }
    assert_eq!(
        lost_at,
        Some(last_hb_us + 100_000),
        "ramp starts exactly at the 100 ms timeout"
    );
    assert_eq!(sim.machine.mode(), Mode::Idle);
    let stopped_after_ms = (sim.now_us - last_hb_us - 100_000) / STEP_US;
    // Ramp 0.3 m/s -> 0 at 1 m/s^2 and 10 m/s^3 (about 0.4 s), then 0.5 s hold.
    assert!(
        (850..=1000).contains(&stopped_after_ms),
        "{stopped_after_ms} ms"
    );
    assert_zero_for(&mut sim, 200);
    let il = sim.machine.interlocks(sim.now_us);
    assert!(il.contains(Interlocks::HEARTBEAT_LOST) && il.contains(Interlocks::HEARTBEAT_LOST));
    let drive = Command::Drive(DriveCommand {
        twist: Twist::new(0.3, 0.0, 0.0),
        accel_mps2: 0.5,
        jerk_mps3: 5.0,
    });
    assert_eq!(
        sim.command(drive),
        Err(Reject::Interlocked(Interlocks::HEARTBEAT_LOST))
    );
    // Heartbeats resume: still latched (reported) and not moving, until a new drive command.
    sim.heartbeat_every = 20;
    sim.command(Command::Heartbeat).unwrap();
    sim.run(100);
    assert!(
        sim.machine
            .interlocks(sim.now_us)
            .contains(Interlocks::HEARTBEAT_LOST)
    );
    assert_eq!(encode_command(sim.last.currents_raw), ZERO_FRAME);
    assert_eq!(sim.command(drive), Ok(()));
    assert!(sim.machine.interlocks(sim.now_us).is_empty());
    sim.run(1000);
    assert!((sim.true_twist().vx_mps - 0.3).abs() < 0.01);
}

#[test]
fn stop_ramps_down_with_the_commanded_ramp_then_goes_idle() {
    let mut sim = cruising();
    sim.command(Command::Stop { immediate: false }).unwrap();
    sim.run(1);
    assert_eq!(sim.machine.mode(), Mode::Stopping);
    // 0.3 m/s at 0.5 m/s^2 and 5 m/s^3: about 0.7 s; then a 0.5 s hold.
    sim.run(1400);
    assert_eq!(sim.machine.mode(), Mode::Idle);
    assert!(sim.true_twist().vx_mps.abs() < 0.01);
    assert_zero_for(&mut sim, 10);
}

#[test]
fn immediate_stop_zeroes_in_the_next_step_and_needs_a_new_drive() {
    let mut sim = cruising();
    sim.command(Command::Stop { immediate: true }).unwrap();
    assert_eq!(sim.machine.mode(), Mode::Idle);
    assert_eq!(ticks_until_zero_frame(&mut sim, 5), 1);
    assert!(
        sim.machine
            .interlocks(sim.now_us)
            .contains(Interlocks::STOP_REQUESTED)
    );
    assert_zero_for(&mut sim, 100);
    let drive = Command::Drive(DriveCommand {
        twist: Twist::new(0.2, 0.0, 0.0),
        accel_mps2: 0.5,
        jerk_mps3: 5.0,
    });
    assert_eq!(sim.command(drive), Ok(()));
    assert!(
        !sim.machine
            .interlocks(sim.now_us)
            .contains(Interlocks::STOP_REQUESTED)
    );
    sim.run(10);
    assert!(sim.last.currents_raw.iter().any(|c| *c != 0));
}

#[test]
fn start_is_blocked_until_escs_and_heartbeat_are_present() {
    let mut sim = Sim::default_seeded(1);
    sim.heartbeat_every = 0;
    let drive = Command::Drive(DriveCommand {
        twist: Twist::new(0.3, 0.0, 0.0),
        accel_mps2: 0.5,
        jerk_mps3: 0.0,
    });
    let all = Interlocks::NO_HOST
        .union(Interlocks::HEARTBEAT_LOST)
        .union(Interlocks::ESC_FEEDBACK_MISSING);
    assert_eq!(sim.command(drive), Err(Reject::Interlocked(all)));
    sim.silent = [false, false, true, false];
    sim.run(5);
    sim.command(Command::Heartbeat).unwrap();
    let status = sim.machine.status(sim.now_us);
    assert_eq!(
        status.esc[2].faults,
        EscFaults::MISSING,
        "never-seen ESC 3 reported missing"
    );
    assert_eq!(status.esc[2].esc_id, 3);
    assert_eq!(
        sim.command(drive),
        Err(Reject::Interlocked(
            Interlocks::NO_HOST.union(Interlocks::ESC_FEEDBACK_MISSING)
        ))
    );
    sim.command(Command::Hello).unwrap();
    sim.silent = [false; 4];
    sim.run(1);
    sim.command(Command::Heartbeat).unwrap();
    assert_eq!(sim.command(drive), Ok(()));
}

#[test]
fn out_of_range_commands_are_rejected_by_field() {
    let mut sim = Sim::default_seeded(1);
    sim.start_forward(0.1);
    let mk = |vx, vy, wz, a, j| {
        Command::Drive(DriveCommand {
            twist: Twist::new(vx, vy, wz),
            accel_mps2: a,
            jerk_mps3: j,
        })
    };
    assert_eq!(
        sim.command(mk(1.5, 0.0, 0.0, 0.5, 5.0)),
        Err(Reject::OutOfRange("vx_mps"))
    );
    assert_eq!(
        sim.command(mk(f32::NAN, 0.0, 0.0, 0.5, 5.0)),
        Err(Reject::OutOfRange("vx_mps"))
    );
    assert_eq!(
        sim.command(mk(0.1, -1.1, 0.0, 0.5, 5.0)),
        Err(Reject::OutOfRange("vy_mps"))
    );
    assert_eq!(
        sim.command(mk(0.1, 0.0, 9.0, 0.5, 5.0)),
        Err(Reject::OutOfRange("wz_radps"))
    );
    assert_eq!(
        sim.command(mk(0.1, 0.0, 0.0, 0.0, 5.0)),
        Err(Reject::OutOfRange("accel_mps2"))
    );
    assert_eq!(
        sim.command(mk(0.1, 0.0, 0.0, 0.5, -1.0)),
        Err(Reject::OutOfRange("jerk_mps3"))
    );
    // Config changes are refused while moving.
    assert_eq!(
        sim.command(Command::SetConfig(control::Config::default())),
        Err(Reject::Busy)
    );
    let bad = control::Config {
        over_temperature_c: 200,
        ..control::Config::default()
    };
    sim.command(Command::Stop { immediate: false }).unwrap();
    sim.run(2000);
    assert_eq!(
        sim.command(Command::SetConfig(bad)),
        Err(Reject::BadConfig(control::ConfigError::OutOfRange(
            "over_temperature_c"
        )))
    );
}

#[test]
fn wheel_map_changes_only_when_idle_and_restart_the_monitors() {
    let mut sim = cruising();
    sim.patch[1] = Patch {
        temperature_c: Some(90),
        ..Patch::default()
    };
    sim.tick();
    assert_eq!(sim.machine.mode(), Mode::Faulted);
    let mut remapped = control::Config::default();
    remapped.wheels.esc_id = [2, 1, 4, 3];
    remapped.wheels.sign = [-1, 1, -1, 1];
    // Faulted: tuning is allowed, a new wheel map is not (it would drop the latched fault).
    let tuned = control::Config {
        over_current_a: 12.0,
        ..control::Config::default()
    };
    assert_eq!(sim.command(Command::SetConfig(tuned)), Ok(()));
    assert_eq!(sim.command(Command::SetConfig(remapped)), Err(Reject::Busy));
    sim.patch[1] = Patch::default();
    sim.plant.motors[1].temperature_c = 40;
    sim.tick();
    assert_eq!(sim.command(Command::ClearFaults), Ok(()));
    assert_eq!(sim.command(Command::SetConfig(remapped)), Ok(()));
    // The monitors restart: until every ESC reports again, motion is blocked.
    let status = sim.machine.status(sim.now_us);
    assert!(status.interlocks.contains(Interlocks::ESC_FEEDBACK_MISSING));
    assert_eq!(status.esc[0].esc_id, 2);
    sim.tick();
    assert!(
        !sim.machine
            .interlocks(sim.now_us)
            .contains(Interlocks::ESC_FEEDBACK_MISSING)
    );
}

#[test]
fn odometry_tracks_a_straight_run() {
    let mut sim = cruising();
    let start = sim.machine.pose();
    let mut true_x = 0.0f32;
    for _ in 0..2000 {
        sim.tick();
        true_x += sim.true_twist().vx_mps * 1e-3;
    }
    let end = sim.machine.pose();
    assert!(
        ((end.x_m - start.x_m) - true_x).abs() < 0.002,
        "{} vs {true_x}",
        end.x_m - start.x_m
    );
    assert!((end.y_m - start.y_m).abs() < 0.002 && end.yaw_rad.abs() < 0.01);
}
