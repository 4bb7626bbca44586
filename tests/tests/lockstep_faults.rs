//! Faults in lockstep (`hil_sim::lockstep::Faults`): the onboard service killed, the radio cut,
//! an ESC fault and malformed lidar packets, each at a simulated time or by seed, on the sedan's
//! demo run with the whole product in the loop. Each fault's consequence is checked on the
//! simulated robot's true motion and on what the robot recorded; being lockstep, every run is
//! reproducible (one test runs a fault twice and compares the robot's whole path).
//!
//! Release only, like the lockstep demos (`demo.rs`): the pipeline is too slow in debug.

// Test helpers outside #[test] fns: unwrap is the right failure.
#![allow(clippy::unwrap_used)]

use std::path::PathBuf;

use hil_sim::demo::{self, DemoOptions};
use hil_sim::esc_model::EscFault;
use hil_sim::lockstep::{self, Faults, Observed};
use onboard::recorder::{RecordedOutcome, Recording};
use passangle_tests::scratch;

/// The fault time: the robot drives by then (about 2 s after the start).
const FAULT_S: f64 = 6.0;

fn observe(name: &str, faults: Faults) -> (Observed, PathBuf) {
    let root = scratch(&format!("faults-{name}"));
    let o = DemoOptions {
        scenario: demo::scenario_for("sedan"),
        run_root: root.clone(),
        radio_loss: 0.0,
        radio_corrupt: 0.0,
        seed: 3,
        realtime: false,
        faults,
    };
    let observed = lockstep::observe(&o, true).unwrap_or_else(|e| panic!("{name}: {e:#}"));
    (observed, root)
}

/// Speed at `t_s` and the first time after `t_s` from which the robot stays at rest.
fn speed_at(o: &Observed, t_s: f64) -> f64 {
    o.path.iter().find(|p| p.0 >= t_s).map_or(0.0, |p| p.3)
}

fn at_rest_from(o: &Observed, t_s: f64) -> Option<f64> {
    let moving_last = o
        .path
        .iter()
        .filter(|p| p.0 >= t_s && p.3 > 0.005)
        .map(|p| p.0)
        .fold(None, |_, t| Some(t));
    match moving_last {
        None => Some(t_s),
        Some(t) if t < o.sim_s - 1.0 => Some(t),
        Some(_) => None,
    }
}

fn recording(root: &std::path::Path) -> Recording {
    Recording::open_run(&root.join("runs"), 1).unwrap()
}

#[test]
#[cfg_attr(debug_assertions, ignore = "slow in debug: run with --release")]
fn a_killed_onboard_leaves_an_incomplete_recording_and_the_firmware_stops_the_robot() {
    let faults = Faults {
        onboard_crash_at_s: Some(FAULT_S),
        ..Faults::default()
    };
    let (o, root) = observe("crash", faults.clone());
    assert!(o.report.is_err(), "no result: {:?}", o.report);
    assert!(speed_at(&o, FAULT_S) > 0.2, "driving at the crash");
    let rest = at_rest_from(&o, FAULT_S).expect("the robot comes to rest");
    println!(
        "onboard killed at {FAULT_S} s: robot at rest {:.3} s later; the handheld: {}",
        rest - FAULT_S,
        o.report.as_ref().unwrap_err()
    );
    // The firmware's heartbeat timeout (100 ms), then its ramp down.
    assert!(
        rest - FAULT_S < 1.5,
        "at rest {:.3} s after",
        rest - FAULT_S
    );
    let rec = recording(&root);
    assert!(rec.incomplete, "INCOMPLETE left by the dead service");
    assert_eq!(rec.meta.outcome, RecordedOutcome::Running);
    assert!(
        !rec.odometry().unwrap().0.is_empty(),
        "what was flushed is readable"
    );

    // The same fault and seed again: the same robot path, sample for sample.
    let (again, root2) = observe("crash-again", faults);
    assert_eq!(o.path, again.path, "a fault run is reproducible");
    let _ = std::fs::remove_dir_all(&root);
    let _ = std::fs::remove_dir_all(&root2);
}

#[test]
#[cfg_attr(debug_assertions, ignore = "slow in debug: run with --release")]
fn a_cut_radio_aborts_the_run_and_stops_the_robot() {
    let (o, root) = observe(
        "cut",
        Faults {
            radio_cut_at_s: Some(FAULT_S),
            ..Faults::default()
        },
    );
    assert!(o.report.is_err(), "no result: {:?}", o.report);
    let rest = at_rest_from(&o, FAULT_S).expect("the robot comes to rest");
    println!(
        "radio cut at {FAULT_S} s: robot at rest {:.3} s later",
        rest - FAULT_S
    );
    // The handheld counts as silent after 12 missed heartbeats (2.4 s), then the ramp.
    assert!(rest - FAULT_S > 2.0 && rest - FAULT_S < 4.5, "{rest}");
    let rec = recording(&root);
    assert!(
        matches!(&rec.meta.outcome, RecordedOutcome::Aborted(r) if r.contains("handheld silent")),
        "{:?}",
        rec.meta.outcome
    );
    assert!(!rec.incomplete);
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
#[cfg_attr(debug_assertions, ignore = "slow in debug: run with --release")]
fn an_esc_stuck_above_the_current_limit_fails_the_run_and_the_robot_stops() {
    // 18 A: above the firmware's 15 A over-current limit, so it latches ESC_OVER_CURRENT and
    // opens the contactor.
    let (o, root) = observe(
        "esc",
        Faults {
            esc_fault: Some((FAULT_S, 2, EscFault::StuckCurrent(18.0))),
            ..Faults::default()
        },
    );
    let e = o.report.as_ref().unwrap_err();
    let rest = at_rest_from(&o, FAULT_S).expect("the robot comes to rest");
    println!(
        "ESC 2 stuck at 18 A at {FAULT_S} s: robot at rest {:.3} s later; the handheld: {e}",
        rest - FAULT_S
    );
    assert!(rest - FAULT_S < 2.0, "{rest}");
    assert!(e.contains("Failed") || e.contains("Aborted"), "{e}");
    assert!(
        e.contains("first fault: ESC 2 OVER_CURRENT"),
        "the cause named: {e}"
    );
    let rec = recording(&root);
    assert!(
        matches!(
            &rec.meta.outcome,
            RecordedOutcome::Failed(_) | RecordedOutcome::Aborted(_)
        ),
        "{:?}",
        rec.meta.outcome
    );
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
#[cfg_attr(debug_assertions, ignore = "slow in debug: run with --release")]
fn malformed_lidar_packets_are_counted_exactly_and_the_run_still_measures() {
    let (o, root) = observe(
        "malformed",
        Faults {
            malformed_lidar: 0.03,
            ..Faults::default()
        },
    );
    let r = o.report.as_ref().unwrap();
    println!(
        "{} malformed packets sent, {} counted, {} good; measured {:?} true {:?}",
        o.malformed_sent, o.service.lidar_malformed, o.service.lidar_packets, r.measured, r.truth
    );
    assert!(o.malformed_sent > 100);
    assert_eq!(
        o.service.lidar_malformed, o.malformed_sent,
        "each one counted"
    );
    for (m, t) in [
        (r.measured.approach_deg, r.truth.approach_deg),
        (r.measured.departure_deg, r.truth.departure_deg),
        (r.measured.breakover_deg, r.truth.breakover_deg),
    ] {
        assert!((m - t).abs() < 1.0, "{m} vs {t}");
    }
    let _ = std::fs::remove_dir_all(&root);
}

/// An ESC stuck at 6 A: below the over-current (15 A) and stall (7 A) limits, so only the
/// firmware's not-following monitor catches it; without it the stopped robot turned in a slow
/// circle for as long as it was watched.
#[test]
#[cfg_attr(debug_assertions, ignore = "slow in debug: run with --release")]
fn an_esc_stuck_below_the_limits_is_caught_as_not_following_and_the_robot_stops() {
    let (o, root) = observe(
        "esc-6a",
        Faults {
            esc_fault: Some((FAULT_S, 2, EscFault::StuckCurrent(6.0))),
            ..Faults::default()
        },
    );
    let e = o.report.as_ref().unwrap_err();
    let rest = at_rest_from(&o, FAULT_S).expect("the robot comes to rest and stays there");
    println!(
        "ESC 2 stuck at 6 A at {FAULT_S} s: robot at rest {:.3} s later; the handheld: {e}",
        rest - FAULT_S
    );
    assert!(rest - FAULT_S < 2.0, "{rest}");
    assert!(
        e.contains("first fault: ESC 2 NOT_FOLLOWING"),
        "the cause named: {e}"
    );
    let end = o.path.last().unwrap();
    let at_fault = o.path.iter().find(|p| p.0 >= FAULT_S).unwrap();
    assert!(
        (end.1 - at_fault.1).hypot(end.2 - at_fault.2) < 0.5,
        "pushed from {at_fault:?} to {end:?}"
    );
    let _ = std::fs::remove_dir_all(&root);
}
