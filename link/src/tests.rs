//! Session-level tests: the handheld and onboard radio sessions over seeded lossy pipes, and the
//! MCU session against a scripted firmware.

use protocol::auth::{KEY_LEN, Key};
use protocol::bounded::Text;
use protocol::mcu::{
    DriveMode, EscStatus, FromFirmware, Interlocks, McuConfig, Status, ToFirmware,
};
use protocol::radio::{
    LabRef, MeasurementResult, RefuseReason, ResultWarnings, StartMeasurement, Zone,
};
use protocol::{Deframer, Flags, frame::MAX_FRAME_LEN};

use super::handheld::{HandheldConfig, HandheldEvent, HandheldRadio};
use super::mcu::{McuEvent, McuSession, McuSessionConfig, MotionIntent};
use super::radio::{OnboardRadio, RadioRequest};
use super::reliable::LinkConfig;
use super::session::Entropy;
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
        lab: LabRef::NONE,
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
        approach_u_rad: 0.01,
        departure_u_rad: 0.01,
        breakover_u_rad: 0.01,
        ground_clearance_u_m: 0.003,
        absent: [
            protocol::radio::Absence::Measured,
            protocol::radio::Absence::Measured,
            protocol::radio::Absence::Measured,
            protocol::radio::Absence::Measured,
        ],
        wheelbase_m: 2.7,
        track_m: 1.55,
        approach_support: 40,
        departure_support: 31,
        breakover_support: 12,
        tyre_fit_rms_m: 0.004,
        warnings: ResultWarnings::EMPTY,
        cloud_points: 123_456,
        preview_chunks: 0,
        records: protocol::bounded::List::default(),
    }
}

struct Pair {
    hh: HandheldRadio,
    ob: OnboardRadio,
    up: LossyPipe,
    down: LossyPipe,
    now: u64,
    /// Longest handheld silence the onboard saw once it had heard the handheld.
    max_silence_us: u64,
}

fn onboard(keys: Vec<Key>, seed: u64) -> OnboardRadio {
    OnboardRadio::new(LinkConfig::RADIO, keys, Entropy::from_test_seed(seed), 5000)
}

fn handheld(key: Key, seed: u64) -> HandheldRadio {
    HandheldRadio::new(
        HandheldConfig::default(),
        key,
        Entropy::from_test_seed(seed),
        1000,
    )
}

impl Pair {
    fn new(pipe: PipeConfig, seed: u64, hh_key: Key, ob_key: Key) -> Self {
        Self::with_keys(pipe, seed, hh_key, vec![ob_key])
    }

    fn with_keys(pipe: PipeConfig, seed: u64, hh_key: Key, ob_keys: Vec<Key>) -> Self {
        Self {
            hh: handheld(hh_key, seed + 7),
            ob: onboard(ob_keys, seed + 8),
            up: LossyPipe::new(pipe, seed),
            down: LossyPipe::new(pipe, seed + 1),
            now: 0,
            max_silence_us: 0,
        }
    }

    /// A pair whose session is open (over a clean line).
    fn connected(seed: u64) -> Self {
        let mut p = Self::new(PipeConfig::CLEAN, seed, key(1), key(1));
        p.hh.connect(0).unwrap();
        let (hev, _) = p.run(200_000);
        assert!(
            hev.iter()
                .any(|e| matches!(e, HandheldEvent::Connected { .. }))
        );
        p
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
            if let Some(s) = self.ob.handheld_silent_us(now) {
                self.max_silence_us = self.max_silence_us.max(s);
            }
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

fn aborts(req: &[RadioRequest]) -> usize {
    req.iter()
        .filter(|r| matches!(r, RadioRequest::Abort { .. }))
        .count()
}

/// A plain (unsealed) frame of `msg`, as an attacker without the key builds it: right version,
/// valid CRC, ack requested.
fn plain<M: protocol::Message>(msg: &M, seq: u16, flags: Flags) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME_LEN];
    let n = msg.encode_frame(seq, flags, &mut buf).unwrap();
    buf[..n].to_vec()
}

fn sealed_frames(bytes: &[u8]) -> Vec<Vec<u8>> {
    let mut frames = Vec::new();
    let mut cur = Vec::new();
    for &b in bytes {
        cur.push(b);
        if b == 0 {
            frames.push(std::mem::take(&mut cur));
        }
    }
    frames
}

#[test]
fn start_arrives_once_over_a_lossy_radio() {
    for seed in 0..5 {
        let mut p = Pair::new(PipeConfig::radio_lossy(0.2, 0.2), seed * 10, key(1), key(1));
        p.hh.connect(0).unwrap();
        p.hh.start(&params()).unwrap();
        let (hev, req) = p.run(15_000_000);
        assert!(
            hev.iter()
                .any(|e| matches!(e, HandheldEvent::Connected { .. }))
        );
        assert_eq!(starts(&req), 1, "seed {seed}: {req:?}");
        assert!(matches!(
            req.iter().find(|r| matches!(r, RadioRequest::Start { .. })),
            Some(RadioRequest::Start { key_id, .. }) if *key_id == protocol::auth::key_id(&key(1))
        ));
    }
}

#[test]
fn a_handheld_with_another_key_never_connects_and_changes_nothing() {
    let mut p = Pair::new(PipeConfig::CLEAN, 0, key(2), key(1));
    p.hh.connect(0).unwrap();
    p.hh.start(&params()).unwrap();
    p.hh.abort(0).unwrap();
    let (hev, req) = p.run(5_000_000);
    assert!(req.is_empty(), "{req:?}");
    assert!(!p.hh.is_connected());
    assert!(
        !hev.iter()
            .any(|e| matches!(e, HandheldEvent::Connected { .. }))
    );
    assert_eq!(p.ob.session_count(), 0);
    assert!(p.ob.stats().inits_refused >= 5, "{:?}", p.ob.stats());
    assert_eq!(p.ob.handheld_silent_us(p.now), None, "not liveness");
    assert!(p.ob.transmit(p.now).is_empty(), "nothing answered");
}

/// Every message of the handheld's set, and acks, as plain frames (what protocol version 2
/// accepted unauthenticated): none reaches the run machine, none is acked, none is liveness,
/// and the pending result stays pending.
#[test]
fn unauthenticated_frames_of_every_kind_change_nothing() {
    use protocol::common::Heartbeat;
    use protocol::radio::{
        Abort, FetchRun, HandshakeReply, ResendChunks, ResultAck, StatusRequest,
    };
    let mut ob = onboard(vec![key(1)], 1);
    ob.deliver(result(4), &[[1, 2, 3]; 30]).unwrap();
    let ack = Flags::ACK_REQUESTED;
    let mut attack = Vec::new();
    for seq in 0..50u16 {
        attack.extend(plain(&Abort { run_id: 0 }, seq, ack));
        attack.extend(plain(&ResultAck { run_id: 4 }, seq, ack));
        attack.extend(plain(&params(), seq, ack));
        attack.extend(plain(
            &ResendChunks {
                run_id: 4,
                indices: protocol::bounded::List::from_slice(&[0, 1]).unwrap(),
            },
            seq,
            ack,
        ));
        attack.extend(plain(&StatusRequest {}, seq, ack));
        attack.extend(plain(&FetchRun { run_id: 4 }, seq, ack));
        attack.extend(plain(&Heartbeat { counter: 1 }, seq, Flags::NONE));
        attack.extend(plain(
            &protocol::Hello::new(protocol::Role::Handheld),
            seq,
            ack,
        ));
        // Acks of every seq the onboard could have used for the result.
        let ack_header =
            protocol::Header::new(protocol::ids::RESULT, seq.wrapping_add(4990), Flags::IS_ACK);
        let mut buf = [0u8; MAX_FRAME_LEN];
        let n = protocol::frame::encode_raw(ack_header, &[], &mut buf).unwrap();
        attack.extend(&buf[..n]);
        // Sealed-looking frames with garbage, for sessions that do not exist.
        let mut junk = [0u8; 60];
        junk[..8].copy_from_slice(&u64::from(seq).to_le_bytes());
        let h = protocol::Header::new(protocol::ids::SEALED, seq, Flags::NONE);
        let n = protocol::frame::encode_raw(h, &junk, &mut buf).unwrap();
        attack.extend(&buf[..n]);
        // A handshake reply sent to the robot.
        let reply = HandshakeReply {
            key_id: 0,
            session: seq,
            noise: protocol::bounded::List::from_slice(&[7; 48]).unwrap(),
        };
        attack.extend(plain(&reply, seq, Flags::NONE));
    }
    let mut req = Vec::new();
    for (i, chunk) in attack.chunks(97).enumerate() {
        req.extend(ob.receive(i as u64 * 1_000, chunk));
    }
    assert!(req.is_empty(), "{req:?}");
    assert_eq!(ob.pending_results(), 1, "the result is still owed");
    assert_eq!(ob.handheld_silent_us(1_000_000), None, "no liveness");
    assert_eq!(ob.link().stats().frames_received, 0);
    assert!(ob.stats().unauthenticated >= 450, "{:?}", ob.stats());
    assert!(ob.stats().unopened >= 50, "{:?}", ob.stats());
    assert_eq!(
        ob.transmit(2_000_000),
        Vec::<u8>::new(),
        "no acks, no replies"
    );
}

#[test]
fn forged_results_and_frames_to_the_handheld_are_dropped() {
    let mut p = Pair::connected(3);
    let sid = p.hh.session_id().unwrap();
    let mut attack = plain(&result(66), 1, Flags::ACK_REQUESTED);
    attack.extend(plain(
        &protocol::radio::Refused {
            msg_id: 0,
            seq: 0,
            reason: RefuseReason::Busy,
            detail: Text::truncated("x"),
        },
        2,
        Flags::NONE,
    ));
    // A sealed frame claiming the real session id, with a made-up nonce and ciphertext.
    let mut junk = [0x55u8; 80];
    junk[..8].copy_from_slice(&7u64.to_le_bytes());
    let mut buf = [0u8; MAX_FRAME_LEN];
    let h = protocol::Header::new(protocol::ids::SEALED, sid, Flags::NONE);
    let n = protocol::frame::encode_raw(h, &junk, &mut buf).unwrap();
    attack.extend(&buf[..n]);
    let hev = p.hh.receive(p.now, &attack);
    assert!(hev.is_empty(), "{hev:?}");
    assert_eq!(p.hh.stats().unauthenticated, 2);
    assert_eq!(p.hh.stats().unopened, 1);
    // The real session still works.
    p.ob.deliver(result(5), &[[1, 2, 3]]).unwrap();
    let (hev, _) = p.run(3_000_000);
    assert!(
        hev.iter()
            .any(|e| matches!(e, HandheldEvent::Complete { result, .. } if result.run_id == 5))
    );
    assert!(
        !hev.iter()
            .any(|e| matches!(e, HandheldEvent::Result(r) if r.run_id == 66))
    );
}

#[test]
fn replayed_sealed_frames_and_sessions_change_nothing() {
    let mut p = Pair::connected(4);
    p.hh.abort(0).unwrap();
    // Capture the sealed abort as an eavesdropper would, and let the onboard see it once.
    let captured = p.hh.transmit(p.now);
    assert_eq!(aborts(&p.ob.receive(p.now, &captured)), 1);
    // Much later (past the link's duplicate memory) the attacker replays the same bytes.
    let later = p.now + LinkConfig::RADIO.dedup_memory_us + 1_000_000;
    assert_eq!(aborts(&p.ob.receive(later, &captured)), 0);
    assert!(p.ob.stats().unopened >= 1);

    // A whole recorded session (handshake init and sealed commands) replayed to a restarted
    // robot: the init is answered with a new session the attacker cannot use, and no sealed
    // frame of the old session opens (no counter file is involved).
    let mut hh = handheld(key(1), 50);
    let mut ob = onboard(vec![key(1)], 51);
    hh.connect(0).unwrap();
    hh.poll(0);
    let init = hh.transmit(0);
    ob.receive(0, &init);
    ob.poll(0);
    hh.receive(0, &ob.transmit(0));
    hh.start(&params()).unwrap();
    hh.abort(0).unwrap();
    hh.poll(1_000);
    let commands = hh.transmit(1_000);
    let req = ob.receive(1_000, &commands);
    assert_eq!(
        (starts(&req), aborts(&req)),
        (1, 1),
        "the genuine session works"
    );
    let mut restarted = onboard(vec![key(1)], 52);
    let mut req = restarted.receive(5_000_000, &init);
    for f in sealed_frames(&commands) {
        req.extend(restarted.receive(5_000_100, &f));
    }
    assert!(req.is_empty(), "{req:?}");
    assert_eq!(restarted.handheld_silent_us(6_000_000), None);
    assert!(restarted.stats().unopened >= 2);
}

#[test]
fn a_replayed_init_does_not_disturb_the_confirmed_session() {
    let mut p = Pair::new(PipeConfig::CLEAN, 9, key(1), key(1));
    p.hh.connect(0).unwrap();
    p.hh.poll(0);
    let init = p.hh.transmit(0);
    p.ob.receive(0, &init);
    p.run(300_000);
    assert!(p.hh.is_connected());
    p.hh.request_status().unwrap();
    p.run(300_000);
    let refused = p.ob.stats().inits_refused;
    p.ob.receive(p.now, &init);
    assert_eq!(
        p.ob.stats().inits_refused,
        refused + 1,
        "a late copy is refused"
    );
    p.hh.abort(0).unwrap();
    let (_, req) = p.run(1_000_000);
    assert_eq!(aborts(&req), 1);
    assert_eq!(p.ob.stats().sessions_opened, 1);
}

#[test]
fn connect_succeeds_when_the_first_replies_are_lost() {
    let mut p = Pair::new(PipeConfig::radio_lossy(0.0, 0.0), 11, key(1), key(1));
    p.hh.connect(0).unwrap();
    p.down.set_cut(true);
    p.run(2_000_000);
    assert!(!p.hh.is_connected());
    assert!(p.hh.stats().inits_sent >= 3);
    p.down.set_cut(false);
    let (hev, _) = p.run(2_000_000);
    assert!(
        hev.iter()
            .any(|e| matches!(e, HandheldEvent::Connected { .. }))
    );
    assert_eq!(
        p.ob.stats().sessions_opened,
        1,
        "repeats answered, not new sessions"
    );
    p.hh.request_status().unwrap();
    let (_, req) = p.run(1_000_000);
    assert!(req.iter().any(|r| matches!(r, RadioRequest::Status)));
}

#[test]
fn two_paired_handhelds_each_hear_their_answers_and_either_aborts() {
    // One shared radio channel: both handhelds hear everything the robot sends.
    let mut ob = onboard(vec![key(1), key(2)], 20);
    let mut a = handheld(key(1), 21);
    let mut b = handheld(key(2), 22);
    a.connect(0).unwrap();
    b.connect(100_000).unwrap();
    let (mut ha, mut hb, mut req) = (Vec::new(), Vec::new(), Vec::new());
    let mut now = 0;
    let mut step =
        |ob: &mut OnboardRadio, a: &mut HandheldRadio, b: &mut HandheldRadio, now: u64| {
            ha.extend(a.poll(now));
            hb.extend(b.poll(now));
            ob.poll(now);
            let mut up = a.transmit(now);
            up.extend(b.transmit(now));
            req.extend(ob.receive(now, &up));
            let down = ob.transmit(now);
            ha.extend(a.receive(now, &down));
            hb.extend(b.receive(now, &down));
        };
    while now < 1_000_000 {
        step(&mut ob, &mut a, &mut b, now);
        now += 2_000;
    }
    assert!(a.is_connected() && b.is_connected());
    a.request_status().unwrap();
    let abort_seq = b.abort(0).unwrap();
    while now < 3_000_000 {
        step(&mut ob, &mut a, &mut b, now);
        now += 2_000;
    }
    assert!(ha.iter().any(|e| matches!(e, HandheldEvent::Acked { .. })));
    assert!(hb.iter().any(|e| matches!(e, HandheldEvent::Acked { msg_id, seq } if *msg_id == protocol::ids::ABORT && *seq == abort_seq)));
    assert_eq!(
        req.iter()
            .filter(|r| matches!(r, RadioRequest::Status))
            .count(),
        1
    );
    assert_eq!(aborts(&req), 1);
}

#[test]
fn a_flood_of_commands_from_one_session_is_rate_limited_but_abort_is_not() {
    let mut p = Pair::connected(12);
    for _ in 0..200 {
        p.hh.request_status().unwrap();
    }
    p.hh.abort(0).unwrap();
    let (_, req) = p.run(3_000_000);
    let statuses = req
        .iter()
        .filter(|r| matches!(r, RadioRequest::Status))
        .count();
    // Burst 20 plus 10 per second.
    assert!(statuses <= 51, "{statuses} status requests passed in 3 s");
    assert!(
        statuses >= 40,
        "{statuses}: the limit lets the rate through"
    );
    assert_eq!(aborts(&req), 1);
    assert!(p.ob.stats().rate_limited > 0);
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
        p.hh.connect(0).unwrap();
        p.ob.deliver(result(7), &preview).unwrap();
        let (hev, req) = p.run(60_000_000);
        let complete: Vec<_> = hev
            .iter()
            .filter_map(|e| match e {
                HandheldEvent::Complete {
                    result, preview_mm, ..
                } => Some((result, preview_mm)),
                _ => None,
            })
            .collect();
        assert_eq!(complete.len(), 1, "seed {seed}");
        let mut expect = result(7);
        expect.preview_chunks = 1_000usize.div_ceil(protocol::radio::CHUNK_POINTS) as u16;
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

/// The record files follow the result byte-exact over a lossy radio: lost chunks are asked for
/// again, the ack waits for every file, a missing signature is simply not announced, and a file
/// beyond the bound is announced with its length, not sent, and reported by name.
#[test]
fn record_files_arrive_byte_exact_over_20_percent_loss_and_corruption() {
    use super::record_files::{OutgoingRecord, RecordError};
    use protocol::radio::{MAX_RECORD_LEN, RecordFile};
    let json: Vec<u8> = (0..14_000u32)
        .map(|i| b"{}\n 0123456789"[(i % 14) as usize])
        .collect();
    let sig: Vec<u8> = (0..9_000u32).map(|i| (i * 31 % 251) as u8).collect();
    for seed in 0..3 {
        let mut p = Pair::new(
            PipeConfig::radio_lossy(0.2, 0.2),
            200 + seed,
            key(1),
            key(1),
        );
        p.hh.connect(0).unwrap();
        let records = [
            OutgoingRecord::new(RecordFile::ResultJson, json.clone()),
            OutgoingRecord::new(RecordFile::ResultSig, sig.clone()),
        ];
        p.ob.deliver_with_records(result(8), &[[1, 2, 3]; 50], &records)
            .unwrap();
        let (hev, req) = p.run(120_000_000);
        let complete: Vec<_> = hev
            .iter()
            .filter_map(|e| match e {
                HandheldEvent::Complete {
                    result, records, ..
                } => Some((result, records)),
                _ => None,
            })
            .collect();
        assert_eq!(complete.len(), 1, "seed {seed}");
        let (r, got) = complete[0];
        assert_eq!(r.records.as_slice().len(), 2);
        assert_eq!(got.len(), 2);
        assert_eq!(got[0].file, RecordFile::ResultJson);
        assert!(got[0].bytes.as_ref().unwrap() == &json, "seed {seed}: json");
        assert_eq!(got[1].file, RecordFile::ResultSig);
        assert!(got[1].bytes.as_ref().unwrap() == &sig, "seed {seed}: sig");
        assert!(
            req.iter()
                .any(|r| matches!(r, RadioRequest::ResultAck { run_id: 8 }))
        );
        assert_eq!(p.ob.pending_results(), 0);
    }

    // Unsigned (no sig announced) and oversize (named, not sent).
    let mut p = Pair::new(PipeConfig::radio_lossy(0.0, 0.0), 5, key(1), key(1));
    p.hh.connect(0).unwrap();
    let big = MAX_RECORD_LEN as usize + 10;
    p.ob.deliver_with_records(
        result(9),
        &[[1, 2, 3]],
        &[OutgoingRecord::too_large(
            RecordFile::ResultJson,
            big as u64,
        )],
    )
    .unwrap();
    let (hev, _) = p.run(20_000_000);
    let records = hev
        .iter()
        .find_map(|e| match e {
            HandheldEvent::Complete { records, .. } => Some(records.clone()),
            _ => None,
        })
        .expect("complete without the oversize file");
    assert_eq!(
        records[0].bytes,
        Err(RecordError::TooLarge {
            file: RecordFile::ResultJson,
            len: big as u32
        })
    );
    assert!(
        records[0]
            .bytes
            .as_ref()
            .unwrap_err()
            .to_string()
            .starts_with(&format!("result.json is {big} bytes"))
    );
}

#[test]
fn result_is_held_until_the_handheld_comes_back() {
    let mut p = Pair::new(PipeConfig::radio_lossy(0.0, 0.0), 3, key(1), key(1));
    p.hh.connect(0).unwrap();
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
    let mut p = Pair::connected(0);
    p.run(1_000_000);
    assert!(p.ob.handheld_silent_us(p.now).unwrap() <= 300_000);
    p.up.set_cut(true);
    p.run(3_000_000);
    assert!(p.ob.handheld_silent_us(p.now).unwrap() >= 2_700_000);
}

/// One cell of the lossy-radio matrix: connect, start, a result with a 1000-point preview, then
/// an abort, all over the impaired line in simulated time. Returns (connect time, whole exchange
/// time, longest handheld silence the onboard saw after connecting), or what did not arrive.
fn matrix_cell(pipe: PipeConfig, seed: u64) -> Result<(u64, u64, u64), String> {
    let preview: Vec<[i16; 3]> = (0..1_000).map(|i: i16| [i, 2 * i, -i]).collect();
    let mut p = Pair::new(pipe, seed, key(1), key(1));
    p.hh.connect(0).unwrap();
    let mut connected_at = None;
    let (mut started, mut complete, mut aborted, mut abort_acked) = (false, false, false, false);
    let mut abort_seq = None;
    while p.now < 120_000_000 {
        let (hev, req) = p.run(100_000);
        if connected_at.is_none()
            && hev
                .iter()
                .any(|e| matches!(e, HandheldEvent::Connected { .. }))
        {
            connected_at = Some(p.now);
            p.max_silence_us = 0;
            p.hh.start(&params()).unwrap();
        }
        if starts(&req) > 0 {
            assert!(!started, "start delivered twice");
            started = true;
            p.ob.deliver(result(3), &preview).unwrap();
        }
        if hev.iter().any(|e| matches!(e, HandheldEvent::Complete { result, preview_mm, .. } if result.run_id == 3 && *preview_mm == preview)) {
            complete = true;
            abort_seq = Some(p.hh.abort(3).unwrap());
        }
        if aborts(&req) > 0 {
            assert!(!aborted, "abort delivered twice");
            aborted = true;
        }
        if hev
            .iter()
            .any(|e| matches!(e, HandheldEvent::Acked { seq, .. } if Some(*seq) == abort_seq))
        {
            abort_acked = true;
        }
        if hev.iter().any(|e| matches!(e, HandheldEvent::Lost { .. })) {
            return Err(format!("a command was given up at {} ms", p.now / 1000));
        }
        if abort_acked && p.ob.pending_results() == 0 {
            return Ok((connected_at.unwrap_or(0), p.now, p.max_silence_us));
        }
    }
    Err(format!(
        "connected {connected_at:?}, started {started}, complete {complete}, aborted {aborted}, abort acked {abort_acked}, pending {}",
        p.ob.pending_results()
    ))
}

/// The lossy-radio matrix: loss 0-40 %, corruption 0-20 %, independent and burst losses, three
/// seeds each. Everything arrives exactly once; up to 30 % loss and 10 % corruption the onboard
/// never misses 12 heartbeats in a row (the run's default `handheld-missed-beats`).
#[test]
fn lossy_radio_matrix() {
    let mut report = Vec::new();
    for &loss in &[0.0, 0.1, 0.2, 0.3, 0.4] {
        for &corrupt in &[0.0, 0.1, 0.2] {
            for &burst in &[1, 4] {
                for seed in 0..3 {
                    let pipe = PipeConfig::radio_lossy(loss, corrupt).with_bursts(burst);
                    let cell = matrix_cell(pipe, 1_000 + seed);
                    let (connect, total, silence) = cell.unwrap_or_else(|e| {
                        panic!("loss {loss} corrupt {corrupt} burst {burst} seed {seed}: {e}")
                    });
                    if loss <= 0.3 && corrupt <= 0.1 && burst == 1 {
                        assert!(
                            silence < 12 * LinkConfig::RADIO.heartbeat_period_us,
                            "loss {loss} corrupt {corrupt} seed {seed}: silent {silence} us"
                        );
                    }
                    report.push(format!(
                        "loss {loss:.1} corrupt {corrupt:.1} burst {burst} seed {seed}: connect {:.1} s, all {:.1} s, longest silence {:.1} s",
                        connect as f64 * 1e-6,
                        total as f64 * 1e-6,
                        silence as f64 * 1e-6
                    ));
                }
            }
        }
    }
    println!("{}", report.join("\n"));
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
    let mut onboard = onboard(vec![key(3)], 0);
    let mut hh = handheld(key(3), 100);
    hh.connect(0).unwrap();
    let mut mcu = McuSession::new(mcu_config(), 0);
    let mut now = 0u64;
    for c in data.chunks(chunk.max(1)) {
        now += u64::from(c[0]) * 1_000;
        onboard.receive(now, c);
        hh.receive(now, c);
        mcu.receive(now, c);
        onboard.poll(now);
        hh.poll(now);
        mcu.poll(now);
        onboard.transmit(now);
        hh.transmit(now);
        mcu.transmit(now);
    }
    onboard.receive(now, &[0]);
    // After the junk a genuine handheld still connects and its start gets through.
    let mut sender = handheld(key(3), 40_000);
    let later = now + 120_000_000;
    sender.connect(later).unwrap();
    sender.poll(later);
    onboard.receive(later, &sender.transmit(later));
    onboard.poll(later);
    sender.receive(later, &onboard.transmit(later + 1_000_000));
    assert!(sender.is_connected());
    sender.start(&params()).unwrap();
    sender.poll(later + 1);
    assert_eq!(
        starts(&onboard.receive(later + 2, &sender.transmit(later + 2))),
        1
    );
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
        p.hh.connect(0).unwrap();
        let (_, _) = p.run(100_000);
        p.hh.start(&params()).unwrap();
        p.ob.deliver(result(2), &[[1, 2, 3]; 60]).unwrap();
        p.hh.poll(p.now);
        let mut bytes = p.hh.transmit(p.now);
        bytes.extend(p.ob.transmit(p.now));
        for (i, v) in flips {
            if !bytes.is_empty() {
                let n = bytes.len();
                bytes[i % n] = v;
            }
        }
        all_sessions_eat(&bytes, 17);
    }
}

#[test]
fn result_json_carries_the_profiles_and_older_files_still_parse() {
    use crate::record::{ProfileQuantityRecord, ProfileRecord, ResultRecord};
    let mut record = ResultRecord::from_wire(&result(7));
    assert!(record.profiles.is_empty());
    record.profiles.push(ProfileRecord {
        standard: "eu".into(),
        title: "EU type approval: off-road vehicle criteria".into(),
        citation: "Regulation (EU) 2018/858 Annex I".into(),
        notes: vec!["steps count unless excluded".into()],
        quantities: vec![
            ProfileQuantityRecord {
                id: "approach".into(),
                name: "approach angle".into(),
                unit: "deg".into(),
                value: Some(24.5),
                u: Some(0.3),
                not_measured: None,
            },
            ProfileQuantityRecord {
                id: "clearance_under_front_axle".into(),
                name: "ground clearance under the front axle".into(),
                unit: "m".into(),
                value: None,
                u: None,
                not_measured: Some("no underside seen under the front axle".into()),
            },
        ],
    });
    let text = serde_json::to_string(&record).unwrap();
    let back: ResultRecord = serde_json::from_str(&text).unwrap();
    assert_eq!(back.profiles, record.profiles);
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    let q = &v["profiles"][0]["quantities"][1];
    assert!(q["value"].is_null() && q["u"].is_null(), "{q}");
    // A result.json written before the profiles: no `profiles` key.
    let mut old = v.clone();
    old.as_object_mut().unwrap().remove("profiles");
    let back: ResultRecord = serde_json::from_value(old).unwrap();
    assert!(back.profiles.is_empty());
    // The radio's form is unchanged: the profiles stay in result.json.
    assert_eq!(
        record.to_wire(),
        ResultRecord::from_wire(&result(7)).to_wire()
    );
}

/// The lab file the first start of `req` carries.
fn start_lab(req: &[RadioRequest]) -> Option<Result<Vec<u8>, String>> {
    req.iter().find_map(|r| match r {
        RadioRequest::Start { lab, .. } => Some(lab.clone()),
        _ => None,
    })?
}

#[test]
fn a_lab_file_arrives_whole_over_a_lossy_radio_with_its_start() {
    let lab: Vec<u8> = (0..1000u32).map(|i| b'a' + (i % 26) as u8).collect();
    for seed in 0..3 {
        let mut p = Pair::new(PipeConfig::radio_lossy(0.2, 0.2), seed * 10, key(1), key(1));
        p.hh.connect(0).unwrap();
        let (lab_ref, seqs) = p.hh.send_lab(0x55, &lab).unwrap();
        assert_eq!(seqs.len(), 6, "1000 bytes in chunks of 190");
        let (hev, _) = p.run(20_000_000);
        let acked = seqs
            .iter()
            .filter(|s| {
                hev.iter().any(|e| {
                    matches!(e, HandheldEvent::Acked { msg_id, seq }
                        if *msg_id == protocol::ids::LAB_CHUNK && seq == *s)
                })
            })
            .count();
        assert_eq!(acked, 6, "seed {seed}");
        p.hh.start(&StartMeasurement {
            lab: lab_ref,
            ..params()
        })
        .unwrap();
        let (_, req) = p.run(15_000_000);
        assert_eq!(start_lab(&req), Some(Ok(lab.clone())), "seed {seed}");
    }
}

impl Pair {
    /// Sends a start naming `lab` and returns the lab file its request carries.
    fn start_naming(&mut self, lab: LabRef) -> Option<Result<Vec<u8>, String>> {
        self.hh
            .start(&StartMeasurement { lab, ..params() })
            .unwrap();
        let (_, req) = self.run(1_000_000);
        start_lab(&req)
    }
}

#[test]
fn a_start_naming_a_lab_file_that_did_not_arrive_whole_says_so() {
    let mut p = Pair::connected(3);
    let e = p
        .start_naming(LabRef {
            upload: 9,
            len: 500,
        })
        .unwrap()
        .unwrap_err();
    assert!(e.contains("none of its 3 chunks"), "{e}");

    // The chunks of another length, or of another upload, are not the file the start names.
    let (lab_ref, _) = p.hh.send_lab(10, &[b'x'; 1000]).unwrap();
    p.run(2_000_000);
    let e = p
        .start_naming(LabRef {
            len: 999,
            ..lab_ref
        })
        .unwrap()
        .unwrap_err();
    assert!(e.contains("1000 bytes arrived, the start names 999"), "{e}");

    p.hh.send_lab(11, &[b'x'; 400]).unwrap();
    p.run(2_000_000);
    let other = p.start_naming(LabRef {
        upload: 12,
        len: 400,
    });
    assert!(other.unwrap().is_err());

    // A file longer than the protocol allows is refused by the sender.
    assert!(p.hh.send_lab(13, &[0; 4097]).is_err());
    // No lab file: the start carries none.
    assert_eq!(p.start_naming(LabRef::NONE), None);
}
