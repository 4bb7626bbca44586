//! The whole controller over real MCU-link bytes and the plant: handshake, drive, report rates,
//! fault reporting with the ESC id and interlock names, rejections, LED.
#![allow(clippy::cast_possible_truncation)]

mod common;

use common::plant::{Plant, PlantParams};
use control::machine::EscSample;
use control::{BusState, Config, Controller, Inputs, LedPattern};
use protocol::frame::{Flags, MAX_FRAME_LEN};
use protocol::mcu::{Drive, DriveMode, EscFaults, FromFirmware, Interlocks, RejectReason};
use protocol::{Deframer, Heartbeat, Hello, Message, Role};

/// Controller + plant + an onboard-side deframer collecting what the firmware sends.
struct Bench {
    ctl: Controller,
    plant: Plant,
    now_us: u64,
    currents: [i16; 4],
    rx: Deframer<MAX_FRAME_LEN>,
    received: Vec<(u64, FromFirmware)>,
    seq: u16,
    silent: [bool; 4],
    led: LedPattern,
    battery_mv: u16,
}

impl Bench {
    fn new() -> Self {
        Self {
            ctl: Controller::new(Config::default()).expect("default config is valid"),
            plant: Plant::new(PlantParams::default(), 5),
            now_us: 0,
            currents: [0; 4],
            rx: Deframer::new(),
            received: Vec::new(),
            seq: 0,
            silent: [false; 4],
            led: LedPattern::Idle,
            battery_mv: 24_000,
        }
    }

    fn frame<M: Message>(&mut self, msg: &M) -> Vec<u8> {
        let mut buf = [0u8; MAX_FRAME_LEN];
        self.seq += 1;
        let len = msg
            .encode_frame(self.seq, Flags::NONE, &mut buf)
            .expect("fits");
        buf[..len].to_vec()
    }

    fn tick_with(&mut self, link_rx: &[u8]) {
        self.plant.advance(self.currents, 1e-3);
        self.now_us += 1000;
        let mut esc = Vec::new();
        for slot in 0..4 {
            if !self.silent[slot] {
                let feedback = self.plant.feedback(slot);
                esc.push(EscSample {
                    esc_id: slot as u8 + 1,
                    feedback,
                    stamp_us: self.now_us,
                });
            }
        }
        let out = self.ctl.step(
            self.now_us,
            &Inputs {
                esc: &esc,
                link_rx,
                bus: BusState::Active,
                battery_mv: self.battery_mv,
            },
        );
        self.currents = out.currents_raw;
        self.led = out.led;
        let now = self.now_us;
        let received = &mut self.received;
        self.rx.feed_all(&out.link_tx, |f| {
            let f = f.expect("firmware frames are well-formed");
            received.push((now, FromFirmware::decode(&f).expect("decodes")));
        });
    }

    /// One tick, with a heartbeat every 20 ms.
    fn tick(&mut self) {
        let bytes = if self.now_us.is_multiple_of(20_000) {
            self.frame(&Heartbeat { counter: 0 })
        } else {
            Vec::new()
        };
        self.tick_with(&bytes);
    }

    fn count(&self, from_us: u64, pred: impl Fn(&FromFirmware) -> bool) -> usize {
        self.received
            .iter()
            .filter(|(t, m)| *t > from_us && pred(m))
            .count()
    }
}

fn drive(vx_mps: f32) -> Drive {
    Drive {
        vx_mps,
        vy_mps: 0.0,
        wz_radps: 0.0,
        accel_mps2: 0.5,
        jerk_mps3: 5.0,
    }
}

#[test]
fn handshake_drive_and_report_rates() {
    let mut b = Bench::new();
    b.tick();
    assert_eq!(b.led, LedPattern::WaitingForHost);
    let hello = b.frame(&Hello::new(Role::Onboard));
    b.tick_with(&hello);
    assert!(b.count(0, |m| *m == FromFirmware::Hello(Hello::new(Role::Firmware))) == 1);
    b.tick();
    let d = b.frame(&drive(0.3));
    b.tick_with(&d);
    let t0 = b.now_us;
    for _ in 0..2000 {
        b.tick();
    }
    // 2 s of reports: odometry at 100 Hz, status at 10 Hz plus one per change (ramping -> cruising).
    let odo = b.count(t0, |m| matches!(m, FromFirmware::Odometry(_)));
    assert!((199..=201).contains(&odo), "{odo} odometry reports in 2 s");
    let status = b.count(t0, |m| matches!(m, FromFirmware::Status(_)));
    assert!(
        (20..=23).contains(&status),
        "{status} status reports in 2 s"
    );
    let Some((_, FromFirmware::Odometry(last))) = b
        .received
        .iter()
        .rev()
        .find(|(_, m)| matches!(m, FromFirmware::Odometry(_)))
    else {
        panic!("no odometry")
    };
    assert!((last.vx_mps - 0.3).abs() < 0.01, "{last:?}");
    assert!(last.x_m > 0.4, "{last:?}");
    assert!(last.stamp_us > t0);
    let s = last_status(&b);
    assert_eq!(s.mode, DriveMode::Cruising);
    assert!(s.interlocks.is_empty(), "{}", s.interlocks);
    assert_eq!(b.led, LedPattern::Driving);
}

#[test]
fn fault_is_reported_by_esc_id_and_name_in_the_step_it_latches() {
    let mut b = Bench::new();
    let hello = b.frame(&Hello::new(Role::Onboard));
    b.tick_with(&hello);
    b.tick();
    let d = b.frame(&drive(0.3));
    b.tick_with(&d);
    for _ in 0..1000 {
        b.tick();
    }
    b.silent[3] = true;
    let t0 = b.now_us;
    for _ in 0..10 {
        b.tick();
    }
    // The 10th step latches the timeout, zeroes the currents and reports it in the same step.
    assert_eq!(b.currents, [0; 4]);
    let faulted: Vec<_> = b
        .received
        .iter()
        .filter_map(|(t, m)| match m {
            FromFirmware::Status(s) if *t > t0 && s.mode == DriveMode::Faulted => Some((*t, *s)),
            _ => None,
        })
        .collect();
    let (t, s) = faulted.first().expect("a faulted status");
    assert_eq!(*t, t0 + 10_000);
    assert_eq!(s.esc[3].esc_id, 4);
    assert_eq!(s.esc[3].faults, EscFaults::MISSING);
    assert!(s.interlocks.contains(Interlocks::ESC_FEEDBACK_MISSING));
    assert!(s.interlocks.names().any(|n| n == "ESC_FEEDBACK_MISSING"));
    b.tick();
    assert_eq!(b.led, LedPattern::EscFault);
}

fn last_status(b: &Bench) -> protocol::mcu::Status {
    let Some((_, FromFirmware::Status(s))) = b
        .received
        .iter()
        .rev()
        .find(|(_, m)| matches!(m, FromFirmware::Status(_)))
    else {
        panic!("no status")
    };
    *s
}

#[test]
fn a_flat_battery_ramps_the_robot_to_rest_and_refuses_drives_until_it_recovers() {
    let mut b = Bench::new();
    b.tick();
    let hello = b.frame(&Hello::new(Role::Onboard));
    b.tick_with(&hello);
    b.tick();
    let d = b.frame(&drive(0.3));
    b.tick_with(&d);
    for _ in 0..1000 {
        b.tick();
    }
    assert_eq!(last_status(&b).battery_mv, 24_000, "{:?}", last_status(&b));
    assert_eq!(
        last_status(&b).mode,
        DriveMode::Cruising,
        "{:?}",
        last_status(&b)
    );
    // A 150 ms sag to 17 V (a hard acceleration on a tired pack) does not stop the run.
    b.battery_mv = 17_000;
    for _ in 0..150 {
        b.tick();
    }
    b.battery_mv = 24_000;
    for _ in 0..300 {
        b.tick();
    }
    assert_eq!(last_status(&b).mode, DriveMode::Cruising);
    // The pack collapses to 19 V: BATTERY_LOW within about 1.8 s, then a ramp to rest.
    b.battery_mv = 19_000;
    let t0 = b.now_us;
    while !last_status(&b).interlocks.contains(Interlocks::BATTERY_LOW) {
        assert!(b.now_us - t0 < 2_500_000, "BATTERY_LOW never raised");
        b.tick();
    }
    let s = last_status(&b);
    assert!(s.battery_mv <= 19_800, "{s:?}");
    assert!(s.interlocks.names().any(|n| n == "BATTERY_LOW"));
    for _ in 0..1500 {
        b.tick();
    }
    assert_eq!(b.currents, [0; 4], "at rest with zero current");
    assert_eq!(last_status(&b).mode, DriveMode::Idle);
    // A new drive is refused, naming the interlock.
    let d = b.frame(&drive(0.3));
    b.tick_with(&d);
    let rejected = b.received.iter().rev().find_map(|(_, m)| match m {
        FromFirmware::Rejected(r) => Some(r.clone()),
        _ => None,
    });
    let r = rejected.expect("the drive is rejected");
    assert_eq!(r.reason, RejectReason::Interlocked);
    assert!(r.field.as_str().contains("BATTERY_LOW"), "{r:?}");
    // A fresh pack (swapped, or the sag was load): accepted again once above 20.4 V.
    b.battery_mv = 25_000;
    for _ in 0..5000 {
        b.tick();
    }
    assert!(!last_status(&b).interlocks.contains(Interlocks::BATTERY_LOW));
    let d = b.frame(&drive(0.3));
    b.tick_with(&d);
    for _ in 0..1500 {
        b.tick();
    }
    assert_eq!(last_status(&b).mode, DriveMode::Cruising);
}

#[test]
fn refused_commands_come_back_as_rejected_with_reason_and_field() {
    let mut b = Bench::new();
    // Before Hello: drive is refused, naming the first blocking interlock.
    let d = b.frame(&drive(0.3));
    let seq = b.seq;
    b.tick_with(&d);
    let rejected: Vec<_> = b
        .received
        .iter()
        .filter_map(|(_, m)| match m {
            FromFirmware::Rejected(r) => Some(r.clone()),
            _ => None,
        })
        .collect();
    assert_eq!(rejected.len(), 1);
    assert_eq!(
        (rejected[0].msg_id, rejected[0].seq),
        (protocol::ids::DRIVE, seq)
    );
    assert_eq!(rejected[0].reason, RejectReason::Interlocked);
    assert_eq!(rejected[0].field.as_str(), "HEARTBEAT_LOST");
    // Out of range speed.
    let hello = b.frame(&Hello::new(Role::Onboard));
    b.tick_with(&hello);
    b.tick();
    let d = b.frame(&drive(3.0));
    b.tick_with(&d);
    let last = b.received.iter().rev().find_map(|(_, m)| match m {
        FromFirmware::Rejected(r) => Some(r.clone()),
        _ => None,
    });
    let last = last.unwrap();
    assert_eq!(
        (last.reason, last.field.as_str()),
        (RejectReason::OutOfRange, "vx_mps")
    );
    // A config with a bad wheel radius, named by its McuConfig field.
    let mut cfg = Config::default().to_mcu();
    cfg.wheel_radius_m = 0.0;
    let c = b.frame(&cfg);
    b.tick_with(&c);
    let last = b.received.iter().rev().find_map(|(_, m)| match m {
        FromFirmware::Rejected(r) => Some(r.clone()),
        _ => None,
    });
    let last = last.unwrap();
    assert_eq!(
        (last.reason, last.field.as_str()),
        (RejectReason::OutOfRange, "wheel_radius_m")
    );
    assert_eq!(b.ctl.link().rejected_count(), 3);
}

#[test]
fn config_over_the_link_changes_the_report_rate() {
    let mut b = Bench::new();
    let mut cfg = Config::default().to_mcu();
    cfg.odometry_period_ms = 5;
    let c = b.frame(&cfg);
    b.tick_with(&c);
    assert_eq!(b.ctl.machine().config().odometry_period_us, 5_000);
    let t0 = b.now_us;
    for _ in 0..1000 {
        b.tick();
    }
    let odo = b.count(t0, |m| matches!(m, FromFirmware::Odometry(_)));
    assert!(
        (199..=201).contains(&odo),
        "{odo} odometry reports in 1 s at 200 Hz"
    );
}

#[test]
fn led_patterns_blink_as_documented() {
    assert_eq!(LedPattern::BusOff.rgb(0), [true, false, false]);
    assert_eq!(LedPattern::EscFault.rgb(0), [true, false, false]);
    assert_eq!(LedPattern::EscFault.rgb(100_000), [false, false, false]);
    assert_eq!(LedPattern::WaitingForHost.rgb(0), [false, false, true]);
    assert_eq!(
        LedPattern::WaitingForHost.rgb(600_000),
        [false, false, false]
    );
    assert_eq!(LedPattern::Idle.rgb(50_000), [false, true, false]);
    assert_eq!(LedPattern::Idle.rgb(500_000), [false, false, false]);
    assert_eq!(LedPattern::Driving.rgb(123_456), [false, true, false]);
}

#[test]
fn status_reports_the_longest_step_the_shell_recorded() {
    let mut b = Bench::new();
    for _ in 0..200 {
        b.tick();
    }
    assert_eq!(
        last_status(&b).control_step_max_us,
        0,
        "nothing recorded yet"
    );
    b.ctl.record_step_time(87);
    b.ctl.record_step_time(41);
    for _ in 0..200 {
        b.tick();
    }
    assert_eq!(last_status(&b).control_step_max_us, 87);
    b.ctl.record_step_time(1_000_000);
    for _ in 0..200 {
        b.tick();
    }
    assert_eq!(last_status(&b).control_step_max_us, u16::MAX, "saturates");
}
