//! `passangle-sim demo` per example vehicle: the whole measurement in software (handheld, lossy
//! radio, onboard service, firmware in the loop, simulated robot and VLP-16), measured angles
//! against the vehicle's true angles.
//!
//! Each demo runs in real time (about 40 s on the sedan) and needs the optimised build to keep up
//! with the simulated sensors: in a debug test build (`cargo test --workspace`) they are ignored
//! with that reason; `cargo test --release -p passangle-tests --test demo` runs them. They take
//! turns ([`ONE_AT_A_TIME`]): two real-time demos competing for two cores would both fall behind.
//!
//! They run at 20 % radio loss and 5 % corruption (radio seed 1), laser + wheel odometry as on
//! the robot. `scripts/test.sh` runs them; the README's accuracy table comes from
//! `scripts/accuracy-table.sh`.

use std::sync::Mutex;

use hil_sim::demo::{self, DemoOptions};

/// Held for the whole of each demo, so the test harness's threads run them one after another.
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

/// One real-time run's bar: every angle within 1.5 degrees of the truth. The paper's Table 1
/// reads about 1 degree, but single real-time runs are not reproducible (they depend on the
/// machine's load) and spread by more than that; the spread itself is measured by the pipeline
/// bench's seed statistics, not here. This catches a broken run, not a 1-degree regression.
const BAR_DEG: f64 = 1.5;

fn run(vehicle: &str) {
    // A failed demo poisons the lock; the next one may still run.
    let _turn = ONE_AT_A_TIME
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    let root =
        std::env::temp_dir().join(format!("passangle-demo-{vehicle}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    let report = demo::run(
        &DemoOptions {
            scenario: demo::scenario_for(vehicle),
            run_root: root.clone(),
            radio_loss: 0.2,
            radio_corrupt: 0.05,
            // A fixed radio seed: the run's loss pattern is the same each time.
            seed: 1,
        },
        true,
    )
    .unwrap_or_else(|e| panic!("{vehicle}: {e:#}"));
    let (m, t) = (report.measured, report.truth);
    println!(
        "{vehicle}: measured {m:?} true {t:?} stop->result {:?} s, {} cloud points, warnings {}",
        report.stop_to_result_s, report.cloud_points, report.warnings
    );
    for (name, measured, truth) in [
        ("approach", m.approach_deg, t.approach_deg),
        ("departure", m.departure_deg, t.departure_deg),
        ("breakover", m.breakover_deg, t.breakover_deg),
    ] {
        assert!(
            (measured - truth).abs() < BAR_DEG,
            "{vehicle} {name}: measured {measured:.2} vs true {truth:.2} degrees (run dir {})",
            report.run_dir.display()
        );
    }
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
#[cfg_attr(
    debug_assertions,
    ignore = "real time: run with --release (module docs)"
)]
fn demo_sedan() {
    run("sedan");
}

#[test]
#[cfg_attr(
    debug_assertions,
    ignore = "real time: run with --release (module docs)"
)]
fn demo_suv() {
    run("suv");
}

#[test]
#[cfg_attr(
    debug_assertions,
    ignore = "real time: run with --release (module docs)"
)]
fn demo_pickup() {
    run("pickup");
}

#[test]
#[cfg_attr(
    debug_assertions,
    ignore = "real time: run with --release (module docs)"
)]
fn demo_van() {
    run("van");
}

#[test]
#[cfg_attr(
    debug_assertions,
    ignore = "real time: run with --release (module docs)"
)]
fn demo_offroader() {
    run("offroader");
}
