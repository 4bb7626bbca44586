//! The real-time `passangle-sim demo` (threads, loopback UDP for the lidar, pseudo-terminal-like
//! pipes, the wall clock): the path the lockstep demo does not take. Its own test binary, so it
//! never shares the machine with the lockstep demos that `cargo test` runs beside each other.

use hil_sim::demo::{self, DemoOptions};
use hil_sim::lockstep::Faults;
use passangle_tests::scratch;

/// The real-time demo (threads, loopback UDP, the wall clock) still delivers. Its angles depend
/// on the machine's load, so the bar is wide: this catches a broken wall-clock path, not a
/// regression (the lockstep tests above do that).
#[test]
#[cfg_attr(
    debug_assertions,
    ignore = "real time: needs the optimised build to keep up"
)]
fn realtime_demo_delivers() {
    let root = scratch("demo-rt");
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
    // Timing on the wall clock, with generous bounds: the lidar path loses almost nothing, and
    // the result follows the stop within seconds (None: the Processing progress was lost on the
    // lossy radio, so there is no start to time from).
    let (sent, received) = (report.lidar_packets_sent, report.lidar_packets_received);
    println!(
        "lidar packets: {sent} sent, {received} received ({} dropped)",
        sent.saturating_sub(received)
    );
    assert!(sent > 10_000, "{sent}");
    assert!(
        sent.saturating_sub(received) * 100 <= sent,
        "more than 1 % of the lidar packets dropped: {received} of {sent}"
    );
    if let Some(s) = report.stop_to_result_s {
        assert!(s < 30.0, "robot at rest -> result took {s} s");
    }
    for (measured, truth) in [
        (m.approach_deg, t.approach_deg),
        (m.departure_deg, t.departure_deg),
        (m.breakover_deg, t.breakover_deg),
    ] {
        assert!((measured - truth).abs() < 3.0, "{measured} vs {truth}");
    }
    let _ = std::fs::remove_dir_all(&root);
}
