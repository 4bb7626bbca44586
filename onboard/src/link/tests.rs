//! Session-level tests: the handheld and onboard radio sessions over seeded lossy pipes, and the
//! MCU session against a scripted firmware.

use protocol::auth::{KEY_LEN, Key};
use protocol::bounded::Text;
use protocol::mcu::{
    DriveMode, EscStatus, FromFirmware, Interlocks, McuConfig, Status, ToFirmware,
};
use protocol::radio::{MeasurementResult, RefuseReason, ResultWarnings, StartMeasurement, Zone};
use protocol::{Deframer, Flags, frame::MAX_FRAME_LEN};

use super::handheld::{HandheldConfig, HandheldEvent, HandheldRadio};
use super::mcu::{McuEvent, McuSession, McuSessionConfig, MotionIntent};
use super::radio::{OnboardRadio, RadioRequest};
use super::reliable::LinkConfig;
use super::sim::{LossyPipe, PipeConfig};

fn key(b: u8) -> Key {
    Key([b; KEY_LEN])
}

fn params() -> StartMeasurement {
    StartMeasurement {
        vehicle_id: Text::truncated("TEST-1"),
        speed_mps: 0.2,
        distance_m: 6.0,
        zone: Zone::Tyre,
    }
}

fn result(run_id: u32) -> MeasurementResult {
    MeasurementResult {
        run_id,
        vehicle_id: Text::truncated("TEST-1"),
        approach_rad: 0.3123,
        departure_rad: 0.2771,
        breakover_rad: 0.2012,
        ground_clearance_m: 0.181,
        wheelbase_m: 2.7,
        track_m: 1.55,
        approach_support: 40,
        departure_support: 31,
        breakover_support: 12,
        tyre_fit_rms_m: 0.004,
        warnings: ResultWarnings::EMPTY,
        cloud_points: 123_456,
        preview_chunks: 0,
    }
}

struct Pair {
    hh: HandheldRadio,
    ob: OnboardRadio,
    up: LossyPipe,
    down: LossyPipe,
    now: u64,
}

impl Pair {
    fn new(pipe: PipeConfig, seed: u64, hh_key: Key, ob_key: Key) -> Self {
        Self {
            hh: HandheldRadio::new(HandheldConfig::default(), hh_key, 1000),
            ob: OnboardRadio::new(LinkConfig::RADIO, ob_key, 0, 5000),
            up: LossyPipe::new(pipe, seed),
            down: LossyPipe::new(pipe, seed + 1),
            now: 0,
        }
    }

    /// Runs both ends for `us` microseconds in 2 ms steps.
    fn run(&mut self, us: u64) -> (Vec<HandheldEvent>, Vec<RadioRequest>) {
        let end = self.now + us;
        let (mut hev, mut req) = (Vec::new(), Vec::new());
        while self.now < end {
            let now = self.now;
            hev.extend(self.hh.poll(now));
            self.ob.poll(now);
            self.up.push(now, &self.hh.transmit(now));
            self.down.push(now, &self.ob.transmit(now));
            req.extend(self.ob.receive(now, &self.up.pop(now)));
            hev.extend(self.hh.receive(now, &self.down.pop(now)));
            self.now += 2_000;
        }
        (hev, req)
    }
}

fn starts(req: &[RadioRequest]) -> usize {
    req.iter()
        .filter(|r| matches!(r, RadioRequest::Start { .. }))
        .count()
}

#[test]
fn signed_start_arrives_once_over_a_lossy_radio() {
    for seed in 0..5 {
        let mut p = Pair::new(PipeConfig::radio_lossy(0.2, 0.2), seed * 10, key(1), key(1));
        p.hh.start(params(), 1_700_000_000_000_000).unwrap();
        let (_, req) = p.run(15_000_000);
        assert_eq!(starts(&req), 1, "seed {seed}: {req:?}");
        assert_eq!(p.ob.last_counter(), 1_700_000_000_000_000);
    }
}

#[test]
fn wrong_key_start_is_refused_and_never_reaches_the_run() {
    let mut p = Pair::new(PipeConfig::CLEAN, 0, key(2), key(1));
    p.hh.start(params(), 10).unwrap();
    let (hev, req) = p.run(2_000_000);
    assert_eq!(starts(&req), 0);
    assert!(req.iter().any(|r| matches!(
        r,
        RadioRequest::Refused {
            reason: RefuseReason::BadTag,
            ..
        }
    )));
    assert!(
        hev.iter()
            .any(|e| matches!(e, HandheldEvent::Refused(r) if r.reason == RefuseReason::BadTag))
    );
    assert_eq!(p.ob.last_counter(), 0);
}

#[test]
fn replayed_start_bytes_are_refused() {
    let mut p = Pair::new(PipeConfig::CLEAN, 0, key(1), key(1));
    p.hh.start(params(), 50).unwrap();
    // Capture the start frame as an eavesdropper would.
    let captured = p.hh.transmit(0);
    let req = p.ob.receive(0, &captured);
    assert_eq!(starts(&req), 1);
    // Much later (past the link's duplicate memory) the attacker replays the same bytes.
    let later = LinkConfig::RADIO.dedup_memory_us + 1_000_000;
    let req = p.ob.receive(later, &captured);
    assert_eq!(starts(&req), 0, "{req:?}");
    // The guard saw the same counter and tag: a duplicate of the accepted command, acked and
    // ignored. A replay of an *older* start is refused outright:
    let mut old_handheld = HandheldRadio::new(HandheldConfig::default(), key(1), 2000);
    old_handheld.start(params(), 40).unwrap();
    let old = old_handheld.transmit(0);
    let req = p.ob.receive(later + 10, &old);
    assert_eq!(starts(&req), 0);
    assert!(req.iter().any(|r| matches!(
        r,
        RadioRequest::Refused {
            reason: RefuseReason::Replay,
            ..
        }
    )));
}

#[test]
fn result_and_preview_arrive_exactly_over_20_percent_loss_and_corruption() {
    let preview: Vec<[i16; 3]> = (0..1_000)
        .map(|i: i16| [i, i.wrapping_mul(7) % 3000, -(i % 500)])
        .collect();
    for seed in 0..4 {
        let mut p = Pair::new(
            PipeConfig::radio_lossy(0.2, 0.2),
            100 + seed,
            key(1),
            key(1),
        );
        p.ob.deliver(result(7), &preview).unwrap();
        let (hev, req) = p.run(60_000_000);
        let complete: Vec<_> = hev
            .iter()
            .filter_map(|e| match e {
                HandheldEvent::Complete { result, preview_mm } => Some((result, preview_mm)),
                _ => None,
            })
            .collect();
        assert_eq!(complete.len(), 1, "seed {seed}");
        let mut expect = result(7);
        expect.preview_chunks = 42;
        assert_eq!(complete[0].0, &expect, "exact result");
        assert_eq!(complete[0].1, &preview, "exact preview");
        assert!(
            req.iter()
                .any(|r| matches!(r, RadioRequest::ResultAck { run_id: 7 }))
        );
        assert_eq!(p.ob.pending_results(), 0);
        assert!(p.up.stats().lost > 0 && p.down.stats().corrupted > 0);
    }
}

#[test]
fn result_is_held_until_the_handheld_comes_back() {
    let mut p = Pair::new(PipeConfig::radio_lossy(0.0, 0.0), 3, key(1), key(1));
    p.up.set_cut(true);
    p.down.set_cut(true);
    p.ob.deliver(result(9), &[[1, 2, 3]]).unwrap();
    p.run(30_000_000);
    assert_eq!(p.ob.pending_results(), 1, "still held");
    p.up.set_cut(false);
    p.down.set_cut(false);
    let (hev, _) = p.run(10_000_000);
    assert!(
        hev.iter()
            .any(|e| matches!(e, HandheldEvent::Complete { .. }))
    );
    assert_eq!(p.ob.pending_results(), 0);
}

#[test]
fn handheld_silence_is_visible_to_the_onboard() {
    let mut p = Pair::new(PipeConfig::CLEAN, 0, key(1), key(1));
    p.run(1_000_000);
    assert!(p.ob.handheld_silent_us(p.now).unwrap() <= 600_000);
    p.up.set_cut(true);
    p.run(3_000_000);
    assert!(p.ob.handheld_silent_us(p.now).unwrap() >= 2_400_000);
}

// ---- MCU session against a scripted firmware ----

fn status(mode: DriveMode, interlocks: Interlocks) -> Status {
    Status {
        stamp_us: 0,
        mode,
        interlocks,
        esc: [EscStatus::default(); 4],
        bus_off_count: 0,
        link_errors: 0,
        rejected_count: 0,
        battery_mv: 23_500,
        control_step_max_us: 0,
    }
}

fn mcu_config() -> McuSessionConfig {
    McuSessionConfig {
        link: LinkConfig::MCU,
        heartbeat_period_us: 20_000,
        resend_us: 200_000,
        firmware: McuConfig {
            wheel_radius_m: 0.076,
            half_length_m: 0.1,
            half_width_m: 0.12,
            esc_ids: [1, 2, 3, 4],
            wheel_signs: [1, -1, 1, -1],
            current_limit_a: 10.0,
            speed_kp: 1.0,
            speed_ki: 0.0,
            speed_kd: 0.0,
            max_speed_mps: 1.0,
            max_accel_mps2: 1.0,
            heartbeat_timeout_ms: 100,
            feedback_timeout_ms: 10,
            odometry_period_ms: 10,
            over_temperature_c: 80,
            over_current_a: 18.0,
            stall_timeout_ms: 500,
        },
        accel_mps2: 0.3,
        jerk_mps3: 1.0,
        status_timeout_us: 500_000,
    }
}

fn decode_all(bytes: &[u8]) -> Vec<ToFirmware> {
    let mut d = Deframer::<MAX_FRAME_LEN>::new();
    let mut out = Vec::new();
    d.feed_all(bytes, |f| {
        out.push(ToFirmware::decode(&f.unwrap()).unwrap());
    });
    out
}

fn firmware_frame(msg: &FromFirmware) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME_LEN];
    let n = msg.encode_frame(1, Flags::NONE, &mut buf).unwrap();
    buf[..n].to_vec()
}

#[test]
fn mcu_session_hello_config_drive_stop_and_heartbeats() {
    let mut s = McuSession::new(mcu_config(), 0);
    let mut sent = Vec::new();
    let step = |s: &mut McuSession, now: u64, sent: &mut Vec<(u64, ToFirmware)>| {
        s.poll(now);
        sent.extend(decode_all(&s.transmit(now)).into_iter().map(|m| (now, m)));
    };
    for now in (0..100_000).step_by(1_000) {
        step(&mut s, now, &mut sent);
    }
    let hb = sent
        .iter()
        .filter(|(_, m)| matches!(m, ToFirmware::Heartbeat(_)))
        .count();
    assert_eq!(hb, 5, "one heartbeat per 20 ms");
    assert!(sent.iter().any(|(_, m)| matches!(m, ToFirmware::Hello(_))));
    assert!(
        !sent
            .iter()
            .any(|(_, m)| matches!(m, ToFirmware::SetConfig(_))),
        "no config before the firmware's hello"
    );
    let hello = FromFirmware::Hello(protocol::Hello::new(protocol::Role::Firmware));
    let ev = s.receive(100_000, &firmware_frame(&hello));
    assert!(matches!(ev[0], McuEvent::Hello(_)));
    s.receive(
        100_000,
        &firmware_frame(&FromFirmware::Status(status(
            DriveMode::Idle,
            Interlocks::NOT_CONFIGURED,
        ))),
    );
    sent.clear();
    step(&mut s, 101_000, &mut sent);
    assert!(
        sent.iter()
            .any(|(_, m)| matches!(m, ToFirmware::SetConfig(_)))
    );
    s.receive(
        120_000,
        &firmware_frame(&FromFirmware::Status(status(
            DriveMode::Idle,
            Interlocks::EMPTY,
        ))),
    );
    assert!(s.firmware_ok(120_000));
    s.set_intent(MotionIntent::Drive { vx_mps: 0.2 });
    sent.clear();
    step(&mut s, 121_000, &mut sent);
    assert!(
        sent.iter()
            .any(|(_, m)| matches!(m, ToFirmware::Drive(d) if (d.vx_mps - 0.2).abs() < 1e-6))
    );
    // The drive frame was lost: the firmware still reports idle, so the session sends it again.
    sent.clear();
    for now in (122_000..400_000).step_by(1_000) {
        step(&mut s, now, &mut sent);
    }
    assert!(sent.iter().any(|(_, m)| matches!(m, ToFirmware::Drive(_))));
    s.receive(
        400_000,
        &firmware_frame(&FromFirmware::Status(status(
            DriveMode::Cruising,
            Interlocks::EMPTY,
        ))),
    );
    sent.clear();
    for now in (400_000..800_000).step_by(1_000) {
        step(&mut s, now, &mut sent);
    }
    assert!(
        !sent.iter().any(|(_, m)| matches!(m, ToFirmware::Drive(_))),
        "no resend while cruising"
    );
    s.set_intent(MotionIntent::Stop);
    sent.clear();
    step(&mut s, 800_000, &mut sent);
    assert!(
        sent.iter()
            .any(|(_, m)| matches!(m, ToFirmware::Stop(st) if !st.immediate))
    );
    assert!(!s.firmware_ok(2_000_000), "status too old");
}

/// The firmware's refusal of drive `seq`.
fn drive_rejected(seq: u16, reason: protocol::mcu::RejectReason, field: &str) -> Vec<u8> {
    firmware_frame(&FromFirmware::Rejected(protocol::mcu::Rejected {
        msg_id: protocol::ids::DRIVE,
        seq,
        reason,
        field: Text::truncated(field),
    }))
}

#[test]
fn rejected_drive_becomes_stop() {
    let mut s = McuSession::new(mcu_config(), 0);
    s.set_intent(MotionIntent::Drive { vx_mps: 5.0 });
    let rej = drive_rejected(3, protocol::mcu::RejectReason::OutOfRange, "vx_mps");
    let ev = s.receive(0, &rej);
    assert!(matches!(&ev[0], McuEvent::Rejected(r) if r.field.as_str() == "vx_mps"));
    assert_eq!(s.intent(), MotionIntent::Stop);
}

#[test]
fn a_drive_refused_for_a_late_heartbeat_is_sent_once_more() {
    use protocol::mcu::RejectReason::Interlocked;
    let heartbeat_lost = |seq| drive_rejected(seq, Interlocked, "HEARTBEAT_LOST");
    let mut s = McuSession::new(mcu_config(), 0);
    let hello = FromFirmware::Hello(protocol::Hello::new(protocol::Role::Firmware));
    s.receive(0, &firmware_frame(&hello));
    s.set_intent(MotionIntent::Drive { vx_mps: 0.3 });
    let ev = s.receive(1_000, &heartbeat_lost(3));
    assert!(matches!(&ev[0], McuEvent::DriveRetried(_)), "{ev:?}");
    assert_eq!(s.intent(), MotionIntent::Drive { vx_mps: 0.3 });
    // The drive leaves again after `resend_us` (200 ms), not before.
    let drives_until = |s: &mut McuSession, from: u64, to: u64| {
        let mut n = 0;
        for now in (from..to).step_by(1_000) {
            s.poll(now);
            let sent = decode_all(&s.transmit(now));
            n += sent
                .iter()
                .filter(|m| matches!(m, ToFirmware::Drive(_)))
                .count();
        }
        n
    };
    assert_eq!(drives_until(&mut s, 2_000, 200_000), 0);
    assert_eq!(drives_until(&mut s, 200_000, 210_000), 1);
    // The second refusal of the same intent ends it, reported as a rejection.
    let ev = s.receive(210_000, &heartbeat_lost(4));
    assert!(matches!(&ev[0], McuEvent::Rejected(_)), "{ev:?}");
    assert_eq!(s.intent(), MotionIntent::Stop);
    // A new drive intent gets its own retry; other interlocks get none.
    s.set_intent(MotionIntent::Drive { vx_mps: 0.3 });
    let ev = s.receive(220_000, &heartbeat_lost(5));
    assert!(matches!(&ev[0], McuEvent::DriveRetried(_)), "{ev:?}");
    s.set_intent(MotionIntent::Stop);
    s.set_intent(MotionIntent::Drive { vx_mps: 0.3 });
    let ev = s.receive(230_000, &drive_rejected(6, Interlocked, "ESC_TIMEOUT"));
    assert!(matches!(&ev[0], McuEvent::Rejected(_)), "{ev:?}");
    assert_eq!(s.intent(), MotionIntent::Stop);
}

// ---- never panics on arbitrary bytes (the fuzz target `link_sessions` does the same) ----

fn all_sessions_eat(data: &[u8], chunk: usize) {
    let mut onboard = OnboardRadio::new(LinkConfig::RADIO, key(3), 0, 0);
    let mut handheld = HandheldRadio::new(HandheldConfig::default(), key(3), 100);
    let mut mcu = McuSession::new(mcu_config(), 0);
    let mut now = 0u64;
    for c in data.chunks(chunk.max(1)) {
        now += u64::from(c[0]) * 1_000;
        onboard.receive(now, c);
        handheld.receive(now, c);
        mcu.receive(now, c);
        onboard.poll(now);
        handheld.poll(now);
        mcu.poll(now);
        onboard.transmit(now);
        handheld.transmit(now);
        mcu.transmit(now);
    }
    onboard.receive(now, &[0]);
    // After the junk (and past the duplicate memory) a genuine start still gets through.
    let mut sender = HandheldRadio::new(HandheldConfig::default(), key(3), 40_000);
    sender.start(params(), u64::MAX - 1).unwrap();
    let later = now + 120_000_000;
    let bytes = sender.transmit(later);
    assert_eq!(starts(&onboard.receive(later, &bytes)), 1);
}

proptest::proptest! {
    #[test]
    fn sessions_never_panic_on_arbitrary_bytes(
        data in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..2_000),
        chunk in 1usize..300,
    ) {
        all_sessions_eat(&data, chunk);
    }

    #[test]
    fn sessions_never_panic_on_mutated_frames(
        flips in proptest::collection::vec((0usize..4_000, proptest::prelude::any::<u8>()), 0..40),
    ) {
        // Real traffic (a start, a result with its preview, status) with bytes overwritten.
        let mut p = Pair::new(PipeConfig::CLEAN, 0, key(3), key(3));
        p.hh.start(params(), 9).unwrap();
        p.ob.deliver(result(2), &[[1, 2, 3]; 60]).unwrap();
        let mut bytes = p.hh.transmit(0);
        bytes.extend(p.ob.transmit(0));
        for (i, v) in flips {
            if !bytes.is_empty() {
                let n = bytes.len();
                bytes[i % n] = v;
            }
        }
        all_sessions_eat(&bytes, 17);
    }
}
