//! The real-time `passangle-sim demo` (threads, loopback UDP for the lidar, pseudo-terminal-like
//! pipes, the wall clock): the path the lockstep demo does not take. Its own test binary, so it
//! never shares the machine with the lockstep demos that `cargo test` runs beside each other.

use hil_sim::demo::{self, DemoOptions};
use hil_sim::lockstep::Faults;

/// The real-time demo (threads, loopback UDP, the wall clock) still delivers. Its angles depend
/// on the machine's load, so the bar is wide: this catches a broken wall-clock path, not a
/// regression (the lockstep tests above do that).
#[test]
#[cfg_attr(
    debug_assertions,
    ignore = "real time: needs the optimised build to keep up"
)]
fn realtime_demo_delivers() {
    let root = std::env::temp_dir().join(format!("passangle-demo-rt-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    let o = DemoOptions {
        scenario: demo::scenario_for("van"),
        run_root: root.clone(),
        radio_loss: 0.2,
        radio_corrupt: 0.05,
        seed: 1,
        realtime: true,
        faults: Faults::default(),
    };
    let report = demo::run(&o, true).unwrap_or_else(|e| panic!("{e:#}"));
    let (m, t) = (report.measured, report.truth);
    println!(
        "real time: measured {m:?} true {t:?}, robot at rest -> result {:?} s, {:.1} s",
        report.stop_to_result_s, report.wall_s
    );
    for (measured, truth) in [
        (m.approach_deg, t.approach_deg),
        (m.departure_deg, t.departure_deg),
        (m.breakover_deg, t.breakover_deg),
    ] {
        assert!((measured - truth).abs() < 3.0, "{measured} vs {truth}");
    }
    let _ = std::fs::remove_dir_all(&root);
}
