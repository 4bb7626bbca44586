//! Property tests: every message round-trips through the whole framing path; the deframer never
//! panics, never accepts a frame that was not sent, and loses only frames that were damaged.
//! These are the stable-toolchain equivalents of the cargo-fuzz targets in `fuzz/`.

#![allow(clippy::unwrap_used)] // test helpers outside #[test] fns

use proptest::prelude::*;
use protocol::auth::{REPLAY_WINDOW, Replay, ReplayWindow};
use protocol::bounded::{List, Text};
use protocol::frame::{Deframer, Flags, Frame, Header, MAX_FRAME_LEN, encode_raw};
use protocol::mcu::{self, EscFaults, EscStatus, FromFirmware, Interlocks, ToFirmware};
use protocol::radio::{self, ResultWarnings, ToHandheld, ToOnboard};
use protocol::{Heartbeat, Hello, LogLevel, LogLine};

fn f() -> impl Strategy<Value = f32> {
    -1.0e4f32..1.0e4
}

fn absence() -> impl Strategy<Value = radio::Absence> {
    prop_oneof![
        Just(radio::Absence::Measured),
        Just(radio::Absence::NothingInZone),
        Just(radio::Absence::NotCovered),
    ]
}

fn text<const N: usize>() -> impl Strategy<Value = Text<N>> {
    "[a-zA-Z0-9 \u{e9}\u{4e2d}-]{0,40}".prop_map(|s| Text::truncated(&s))
}

fn to_firmware() -> impl Strategy<Value = ToFirmware> {
    prop_oneof![
        (any::<u8>(), any::<u8>()).prop_map(|(version, role)| Hello { version, role }.into()),
        any::<u32>().prop_map(|counter| Heartbeat { counter }.into()),
        (f(), f(), f(), f(), f()).prop_map(|(vx_mps, vy_mps, wz_radps, accel_mps2, jerk_mps3)| {
            mcu::Drive {
                vx_mps,
                vy_mps,
                wz_radps,
                accel_mps2,
                jerk_mps3,
            }
            .into()
        }),
        any::<bool>().prop_map(|immediate| mcu::Stop { immediate }.into()),
        Just(mcu::ClearFaults {}.into()),
        (
            f(),
            f(),
            f(),
            any::<[u8; 4]>(),
            any::<[i8; 4]>(),
            any::<[u16; 5]>(),
            any::<u8>(),
            f()
        )
            .prop_map(|(r, lx, ly, esc_ids, wheel_signs, ms, t, i)| {
                mcu::McuConfig {
                    wheel_radius_m: r,
                    half_length_m: lx,
                    half_width_m: ly,
                    esc_ids,
                    wheel_signs,
                    current_limit_a: i,
                    speed_kp: r,
                    speed_ki: lx,
                    speed_kd: ly,
                    max_speed_mps: i,
                    max_accel_mps2: r,
                    heartbeat_timeout_ms: ms[0],
                    feedback_timeout_ms: ms[1],
                    odometry_period_ms: ms[2],
                    over_temperature_c: t,
                    over_current_a: i,
                    stall_timeout_ms: ms[3],
                }
                .into()
            }),
    ]
}

fn from_firmware() -> impl Strategy<Value = FromFirmware> {
    let esc =
        (any::<u8>(), any::<u8>(), any::<u8>(), f(), f()).prop_map(|(id, faults, t, c, cmd)| {
            EscStatus {
                esc_id: id,
                faults: EscFaults(faults),
                temperature_c: t,
                current_a: c,
                command_a: cmd,
            }
        });
    prop_oneof![
        (any::<u64>(), f(), f(), f(), proptest::array::uniform4(f())).prop_map(
            |(t, x, y, w, wheels)| {
                mcu::Odometry {
                    stamp_us: t,
                    x_m: x,
                    y_m: y,
                    yaw_rad: w,
                    vx_mps: x,
                    vy_mps: y,
                    wz_radps: w,
                    wheel_speed_radps: wheels,
                }
                .into()
            }
        ),
        (
            any::<u64>(),
            proptest::sample::select(mcu::DriveMode::ALL),
            any::<u32>(),
            proptest::array::uniform4(esc),
            any::<[u16; 5]>()
        )
            .prop_map(|(t, mode, il, esc, counts)| {
                mcu::Status {
                    stamp_us: t,
                    mode,
                    interlocks: Interlocks(il),
                    esc,
                    bus_off_count: counts[0],
                    link_errors: counts[1],
                    rejected_count: counts[2],
                    battery_mv: counts[3],
                    control_step_max_us: counts[4],
                }
                .into()
            }),
        (
            any::<u16>(),
            any::<u16>(),
            proptest::sample::select(mcu::RejectReason::ALL),
            text::<24>()
        )
            .prop_map(|(msg_id, seq, reason, field)| mcu::Rejected {
                msg_id,
                seq,
                reason,
                field
            }
            .into()),
        (proptest::sample::select(LogLevel::ALL), text::<160>())
            .prop_map(|(level, text)| LogLine { level, text }.into()),
    ]
}

fn to_onboard() -> impl Strategy<Value = ToOnboard> {
    prop_oneof![
        (
            text::<32>(),
            f(),
            f(),
            proptest::sample::select(radio::Zone::ALL),
            any::<u16>(),
            any::<u16>(),
        )
            .prop_map(|(vehicle_id, speed_mps, distance_m, zone, upload, len)| {
                radio::StartMeasurement {
                    vehicle_id,
                    speed_mps,
                    distance_m,
                    zone,
                    lab: radio::LabRef { upload, len },
                }
                .into()
            }),
        (
            any::<u16>(),
            any::<u8>(),
            any::<u8>(),
            proptest::collection::vec(any::<u8>(), 0..=radio::LAB_CHUNK_LEN)
        )
            .prop_map(|(upload, index, count, bytes)| {
                radio::LabChunk {
                    upload,
                    index,
                    count,
                    bytes: List::from_slice(&bytes).unwrap(),
                }
                .into()
            }),
        any::<u32>().prop_map(|run_id| radio::Abort { run_id }.into()),
        any::<u32>().prop_map(|run_id| radio::ResultAck { run_id }.into()),
        (
            any::<u32>(),
            proptest::collection::vec(any::<u16>(), 0..=32)
        )
            .prop_map(|(run_id, idx)| {
                radio::ResendChunks {
                    run_id,
                    indices: List::from_slice(&idx).unwrap(),
                }
                .into()
            }),
        Just(radio::StatusRequest {}.into()),
        any::<u32>().prop_map(|run_id| radio::FetchRun { run_id }.into()),
        (
            any::<u32>(),
            proptest::sample::select(radio::RecordFile::ALL),
            proptest::collection::vec(any::<u16>(), 0..=32)
        )
            .prop_map(|(run_id, file, idx)| {
                radio::ResendRecordChunks {
                    run_id,
                    file,
                    indices: List::from_slice(&idx).unwrap(),
                }
                .into()
            }),
    ]
}

fn measurement_result() -> impl Strategy<Value = radio::MeasurementResult> {
    (
        any::<u32>(),
        text::<32>(),
        proptest::array::uniform6(f()),
        any::<[u16; 4]>(),
        any::<u32>(),
        proptest::array::uniform4(absence()),
        proptest::collection::vec(
            (
                proptest::sample::select(radio::RecordFile::ALL),
                any::<u32>(),
            ),
            0..=radio::MAX_RECORD_FILES,
        ),
    )
        .prop_map(
            |(run_id, vehicle_id, a, s, cloud_points, absent, records)| {
                let records: Vec<radio::RecordInfo> = records
                    .into_iter()
                    .map(|(file, len)| radio::RecordInfo { file, len })
                    .collect();
                radio::MeasurementResult {
                    run_id,
                    vehicle_id,
                    approach_rad: a[0],
                    departure_rad: a[1],
                    breakover_rad: a[2],
                    ground_clearance_m: a[3],
                    approach_u_rad: a[4],
                    departure_u_rad: a[5],
                    breakover_u_rad: a[1],
                    ground_clearance_u_m: a[2],
                    absent,
                    wheelbase_m: a[4],
                    track_m: a[5],
                    approach_support: s[0],
                    departure_support: s[1],
                    breakover_support: s[2],
                    tyre_fit_rms_m: a[0],
                    warnings: ResultWarnings(s[3]),
                    cloud_points,
                    preview_chunks: s[3],
                    records: List::from_slice(&records).unwrap(),
                }
            },
        )
}

fn to_handheld() -> impl Strategy<Value = ToHandheld> {
    prop_oneof![
        (
            any::<u32>(),
            proptest::sample::select(radio::Phase::ALL),
            any::<u8>(),
            f(),
            any::<u32>()
        )
            .prop_map(|(run_id, phase, percent, travelled_m, lidar_frames)| {
                radio::Progress {
                    run_id,
                    phase,
                    percent,
                    travelled_m,
                    lidar_frames,
                }
                .into()
            }),
        measurement_result().prop_map(Into::into),
        (
            any::<u32>(),
            proptest::sample::select(radio::RecordFile::ALL),
            any::<[u16; 2]>(),
            any::<u32>(),
            proptest::collection::vec(any::<u8>(), 0..=radio::RECORD_CHUNK_LEN)
        )
            .prop_map(|(run_id, file, ic, total_len, bytes)| {
                radio::RecordChunk {
                    run_id,
                    file,
                    index: ic[0],
                    count: ic[1],
                    total_len,
                    bytes: List::from_slice(&bytes).unwrap(),
                }
                .into()
            }),
        (
            any::<u32>(),
            any::<u16>(),
            any::<u16>(),
            proptest::collection::vec(any::<[i16; 3]>(), 0..=radio::CHUNK_POINTS)
        )
            .prop_map(|(run_id, index, count, pts)| {
                radio::CloudChunk {
                    run_id,
                    index,
                    count,
                    points_mm: List::from_slice(&pts).unwrap(),
                }
                .into()
            }),
        (
            proptest::sample::select(radio::Phase::ALL),
            any::<u32>(),
            any::<[bool; 3]>(),
            any::<u32>(),
            any::<u16>(),
            any::<u32>(),
            any::<u16>()
        )
            .prop_map(
                |(phase, run_id, ok, il, pending_results, disk_free_mib, battery_mv)| {
                    radio::RobotStatus {
                        phase,
                        run_id,
                        firmware_ok: ok[0],
                        lidar_ok: ok[1],
                        camera_ok: ok[2],
                        interlocks: Interlocks(il),
                        pending_results,
                        disk_free_mib,
                        battery_mv,
                    }
                    .into()
                }
            ),
        (
            any::<u16>(),
            any::<u16>(),
            proptest::sample::select(radio::RefuseReason::ALL),
            text::<48>()
        )
            .prop_map(|(msg_id, seq, reason, detail)| radio::Refused {
                msg_id,
                seq,
                reason,
                detail
            }
            .into()),
        any::<u32>().prop_map(|counter| Heartbeat { counter }.into()),
    ]
}

macro_rules! round_trip {
    ($msg:expr, $set:ty, $seq:expr) => {{
        let mut out = [0u8; MAX_FRAME_LEN];
        let n = $msg
            .encode_frame($seq, Flags::ACK_REQUESTED, &mut out)
            .unwrap();
        prop_assert!(n <= <$set>::MAX_FRAME_LEN);
        let mut d = Deframer::<MAX_FRAME_LEN>::new();
        let mut got = Vec::new();
        d.feed_all(&out[..n], |r| {
            got.push(r.map(|f| (f.header, <$set>::decode(&f))))
        });
        prop_assert_eq!(got.len(), 1);
        let (header, decoded) = got.pop().unwrap().unwrap();
        prop_assert_eq!(header.seq, $seq);
        prop_assert_eq!(header.msg_id, $msg.msg_id());
        prop_assert_eq!(decoded, Ok($msg));
    }};
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn to_firmware_round_trips(m in to_firmware(), seq: u16) { round_trip!(m, ToFirmware, seq); }

    #[test]
    fn from_firmware_round_trips(m in from_firmware(), seq: u16) { round_trip!(m, FromFirmware, seq); }

    #[test]
    fn to_onboard_round_trips(m in to_onboard(), seq: u16) { round_trip!(m, ToOnboard, seq); }

    #[test]
    fn to_handheld_round_trips(m in to_handheld(), seq: u16) { round_trip!(m, ToHandheld, seq); }

    /// Frames split at random points, with garbage (zeros included) between them, each garbage run
    /// closed by a delimiter: every frame arrives exactly once, in order, and nothing else does.
    #[test]
    fn deframer_random_splits_and_garbage(
        payloads in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 0..200), 1..12),
        garbage in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 0..40), 12),
        cuts in proptest::collection::vec(1usize..64, 1..40),
    ) {
        let mut stream = Vec::new();
        let mut sent = Vec::new();
        for (i, p) in payloads.iter().enumerate() {
            stream.extend(&garbage[i]);
            stream.push(0);
            let header = Header::new(0x0100 + i as u16, i as u16, Flags::NONE);
            let mut out = [0u8; MAX_FRAME_LEN];
            let n = encode_raw(header, p, &mut out).unwrap();
            stream.extend(&out[..n]);
            sent.push((header, p.clone()));
        }
        let mut d = Deframer::<MAX_FRAME_LEN>::new();
        let mut got = Vec::new();
        let mut rest = &stream[..];
        for cut in cuts.iter().cycle() {
            if rest.is_empty() { break; }
            let (piece, tail) = rest.split_at((*cut).min(rest.len()));
            d.feed_all(piece, |r| if let Ok(f) = r { got.push((f.header, f.payload.to_vec())); });
            rest = tail;
        }
        prop_assert_eq!(got, sent);
    }

    /// Random bit flips anywhere in a stream of frames: no frame is accepted that was not sent,
    /// and each flip loses at most two frames (the hit one and, via a damaged delimiter, its neighbour).
    #[test]
    fn deframer_bit_flips_never_yield_a_wrong_frame(
        payloads in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 0..120), 1..10),
        flips in proptest::collection::vec((any::<prop::sample::Index>(), 0u8..8), 1..4),
    ) {
        let mut stream = Vec::new();
        let mut sent = Vec::new();
        for (i, p) in payloads.iter().enumerate() {
            let header = Header::new(0x0200, i as u16, Flags::NONE);
            let mut out = [0u8; MAX_FRAME_LEN];
            let n = encode_raw(header, p, &mut out).unwrap();
            stream.extend(&out[..n]);
            sent.push((header, p.clone()));
        }
        for (at, bit) in &flips {
            let i = at.index(stream.len());
            stream[i] ^= 1 << bit;
        }
        let mut d = Deframer::<MAX_FRAME_LEN>::new();
        let mut got = Vec::new();
        d.feed_all(&stream, |r| if let Ok(f) = r { got.push((f.header, f.payload.to_vec())); });
        for g in &got {
            prop_assert!(sent.contains(g), "accepted a frame that was never sent: {:?}", g);
        }
        prop_assert!(got.len() + 2 * flips.len() >= sent.len());
    }

    #[test]
    fn deframer_never_panics_on_noise(
        noise in proptest::collection::vec(any::<u8>(), 0..2000),
        chunk in 1usize..300,
    ) {
        let mut d = Deframer::<MAX_FRAME_LEN>::new();
        for piece in noise.chunks(chunk) {
            d.feed_all(piece, |r| {
                if let Ok(f) = r {
                    let _ = ToFirmware::decode(&f);
                    let _ = FromFirmware::decode(&f);
                    let _ = ToOnboard::decode(&f);
                    let _ = ToHandheld::decode(&f);
                }
            });
        }
        prop_assert!(d.pending() <= MAX_FRAME_LEN);
    }

    #[test]
    fn message_decoders_never_panic(msg_id: u16, version: u8, payload in proptest::collection::vec(any::<u8>(), 0..250)) {
        let frame = Frame { header: Header { version, msg_id, seq: 0, flags: Flags::NONE }, payload: &payload };
        let _ = ToFirmware::decode(&frame);
        let _ = FromFirmware::decode(&frame);
        let _ = ToOnboard::decode(&frame);
        let _ = ToHandheld::decode(&frame);
    }

    /// The replay window accepts each nonce at most once, whatever the order, and only nonces
    /// within the window below the highest one.
    #[test]
    fn replay_window_accepts_each_nonce_once(nonces in proptest::collection::vec(0u64..3_000, 1..400)) {
        let mut w = ReplayWindow::new();
        let mut accepted = std::collections::BTreeSet::new();
        let mut highest: Option<u64> = None;
        for n in nonces {
            // The model: fresh when never accepted and not REPLAY_WINDOW or more below the highest.
            let expect = !accepted.contains(&n) && highest.is_none_or(|h: u64| n > h || h - n < REPLAY_WINDOW);
            let verdict = w.check(n);
            prop_assert_eq!(verdict == Replay::Fresh, expect, "nonce {}", n);
            prop_assert_eq!(w.mark(n), expect);
            if expect {
                accepted.insert(n);
                highest = Some(highest.map_or(n, |h| h.max(n)));
            }
        }
    }
}
