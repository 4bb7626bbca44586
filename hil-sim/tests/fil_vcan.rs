//! The firmware-in-the-loop scenarios over real SocketCAN, and the decoding of a `candump` log of
//! them. This kernel has no CAN: `hil-sim/vcan-vm/ci.sh` runs this binary inside a qemu guest with
//! `vcan0` up and `candump -L vcan0` recording. Outside such a guest every test prints a SKIPPED
//! line naming why and returns (the same scenarios run in-process in `fil_inprocess.rs`).
//!
//! Environment: `SIL_CAN_IFACE` (default `vcan0`); `SIL_CANDUMP_LOG`, the candump log to decode
//! (written by ci.sh while the scenarios ran).

use hil_sim::can_bus::{CanBus as _, CanFrame, SocketCanBus, parse_candump_log};
use hil_sim::fil::FilConfig;
use hil_sim::fil_scenarios::{self, BusChoice, LinkChoice};

/// Prints a SKIPPED line straight to stderr (past libtest's output capture, so it shows in
/// every test run).
fn skipped(why: &str) {
    use std::io::Write as _;
    let _ = writeln!(std::io::stderr(), "SKIPPED: {why}");
}

fn iface() -> Option<String> {
    let iface = std::env::var("SIL_CAN_IFACE").unwrap_or_else(|_| "vcan0".to_owned());
    if SocketCanBus::interface_up(&iface) {
        Some(iface)
    } else {
        skipped(&format!(
            "SocketCAN interface `{iface}` is not up on this machine (no AF_CAN in this \
             kernel?); run hil-sim/vcan-vm/ci.sh to run these tests in a guest with vcan0"
        ));
        None
    }
}

fn scenario(name: &str) {
    let Some(iface) = iface() else { return };
    let outcome = fil_scenarios::run(
        name,
        FilConfig::default(),
        &BusChoice::SocketCan(iface),
        LinkChoice::Memory,
    )
    .unwrap_or_else(|e| panic!("scenario {name} could not start: {e}"));
    println!("{outcome}");
    assert!(outcome.passed(), "{outcome}");
    assert_eq!(
        outcome.trace.feedback_frames_lost, 0,
        "feedback frames lost on a clean bus"
    );
}

#[test]
fn vcan_cruise() {
    scenario("cruise");
}

#[test]
fn vcan_heartbeat_loss() {
    scenario("heartbeat-loss");
}

#[test]
fn vcan_esc_silent() {
    scenario("esc-silent");
}

#[test]
fn vcan_over_temperature() {
    scenario("over-temperature");
}

#[test]
fn vcan_bus_off() {
    scenario("bus-off");
}

#[test]
fn vcan_stuck_current() {
    scenario("stuck-current");
}

#[test]
fn vcan_battery_low() {
    scenario("battery-low");
}

#[test]
fn vcan_link_flood() {
    scenario("link-flood");
}

#[test]
fn vcan_socket_round_trip() {
    let Some(iface) = iface() else { return };
    let mut a = SocketCanBus::open(&iface).unwrap();
    let mut b = SocketCanBus::open(&iface).unwrap();
    let f = CanFrame::standard(0x123, &[1, 2, 3]).unwrap();
    a.send(&f).unwrap();
    let got =
        hil_sim::can_bus::recv_expected(&mut b, 1, std::time::Duration::from_secs(1)).unwrap();
    assert_eq!(got, [f]);
    assert_eq!(
        a.try_recv().unwrap(),
        None,
        "a socket must not receive its own frames"
    );
}

/// Decodes the candump log of the scenarios above with `protocol::esc` and checks it is what the
/// firmware and the ESCs put on the bus: only C620 frames, every one decodes, feedback at 1 kHz
/// from each ESC while it answers, one 0x200 command per millisecond.
#[test]
fn candump_log_decodes() {
    let Ok(path) = std::env::var("SIL_CANDUMP_LOG") else {
        skipped(
            "SIL_CANDUMP_LOG is not set (hil-sim/vcan-vm/ci.sh sets it to the log candump wrote)",
        );
        return;
    };
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("cannot read candump log {path}: {e}"));
    let records = parse_candump_log(&text).unwrap_or_else(|e| panic!("{path}: {e}"));
    assert!(
        records.len() > 10_000,
        "{path}: only {} frames",
        records.len()
    );
    let mut commands = 0usize;
    let mut nonzero_commands = 0usize;
    let mut feedback = [0usize; 4];
    let mut last_t = 0;
    for (t, _, frame) in &records {
        assert!(*t >= last_t, "{path}: time goes backwards at {t}");
        last_t = *t;
        match frame.raw_id() {
            0x200 => {
                let (_, currents) = protocol::esc::parse_command_frame(frame)
                    .unwrap_or_else(|e| panic!("{path}: bad command frame {frame:?}: {e}"));
                commands += 1;
                nonzero_commands += usize::from(currents != [0; 4]);
            }
            0x201..=0x204 => {
                let (id, fb) = protocol::esc::parse_feedback_frame(frame)
                    .unwrap_or_else(|e| panic!("{path}: bad feedback frame {frame:?}: {e}"));
                assert!(fb.angle_raw < 8192);
                feedback[usize::from(id - 1)] += 1;
            }
            0x123 => {} // vcan_socket_round_trip
            other => panic!("{path}: unexpected CAN id {other:#x}"),
        }
    }
    println!(
        "candump log {path}: {} frames, {commands} commands ({nonzero_commands} non-zero), \
         feedback per ESC {feedback:?}",
        records.len()
    );
    assert!(
        nonzero_commands > 1000,
        "the robot was never driven on the bus"
    );
    // Every frame of every scenario must be in the log: each ESC sends one frame per simulated
    // millisecond while it has power and answers (the same scenarios on the in-process bus count
    // them: the motor contactor cuts the ESCs' power while a fault is latched, and ESC 3 falls
    // silent in `esc-silent`), the firmware one command per millisecond except while its
    // controller is bus-off (about 22 ms in `bus-off`).
    let mut expected = [0usize; 4];
    for name in fil_scenarios::NAMES {
        let o = fil_scenarios::run(
            name,
            FilConfig::default(),
            &BusChoice::InProcess { record: false },
            LinkChoice::Memory,
        )
        .unwrap_or_else(|e| panic!("scenario {name} in-process: {e}"));
        for (&id, &n) in &o.trace.feedback_frames_sent {
            expected[usize::from(id - 1)] += usize::try_from(n).unwrap();
        }
    }
    assert_eq!(feedback, expected, "feedback frames per ESC");
    let total_ms: u64 = fil_scenarios::NAMES
        .iter()
        .map(|n| fil_scenarios::duration_us(n).unwrap() / 1000)
        .sum();
    let total = usize::try_from(total_ms).unwrap();
    assert!(
        (total - 30..=total - 15).contains(&commands),
        "{commands} command frames, expected {total} minus the bus-off gap"
    );
}
