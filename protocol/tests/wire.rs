//! Wire-format tests over every message: golden bytes (committed snapshot), worst-case size bounds
//! against the links' buffers, and round trips through the whole framing path.
//!
//! Regenerate the snapshot (only together with a PROTOCOL_VERSION bump):
//!     UPDATE_SNAPSHOTS=1 cargo test -p protocol --test wire

#![allow(clippy::unwrap_used)] // test helpers outside #[test] fns

use std::fmt::Write as _;

use protocol::bounded::{List, Text};
use protocol::frame::{Deframer, Flags, Header, MAX_FRAME_LEN, MAX_PAYLOAD_LEN};
use protocol::mcu::{self, EscFaults, EscStatus, FromFirmware, Interlocks, ToFirmware};
use protocol::message::{Message, max_frame_len};
use protocol::radio::{self, ResultWarnings, ToHandheld, ToOnboard};
use protocol::{Heartbeat, Hello, LogLevel, LogLine, Role};

const SNAPSHOT: &str = "tests/snapshots/wire.snap";

fn config() -> mcu::McuConfig {
    mcu::McuConfig {
        wheel_radius_m: 0.0763,
        half_length_m: 0.1,
        half_width_m: 0.12,
        esc_ids: [1, 2, 3, 4],
        wheel_signs: [1, -1, 1, -1],
        current_limit_a: 10.0,
        speed_kp: 1.5,
        speed_ki: 20.0,
        speed_kd: 0.0,
        max_speed_mps: 0.5,
        max_accel_mps2: 0.5,
        heartbeat_timeout_ms: 100,
        feedback_timeout_ms: 10,
        odometry_period_ms: 10,
        over_temperature_c: 80,
        over_current_a: 18.0,
        stall_timeout_ms: 500,
    }
}

fn status() -> mcu::Status {
    let esc = |id| EscStatus {
        esc_id: id,
        faults: EscFaults::EMPTY,
        temperature_c: 31,
        current_a: 1.25,
        command_a: 1.5,
    };
    mcu::Status {
        stamp_us: 12_345_678,
        mode: mcu::DriveMode::Cruising,
        interlocks: Interlocks::EMPTY,
        esc: [esc(1), esc(2), esc(3), esc(4)],
        bus_off_count: 0,
        link_errors: 2,
        rejected_count: 1,
        battery_mv: 23_870,
        control_step_max_us: 87,
    }
}

fn start() -> radio::StartMeasurement {
    radio::StartMeasurement {
        vehicle_id: Text::new("TEST-0042").unwrap(),
        speed_mps: 0.2,
        distance_m: 6.0,
        zone: radio::Zone::Tyre,
        lab: radio::LabRef {
            upload: 0x1234,
            len: 512,
        },
    }
}

fn result() -> radio::MeasurementResult {
    radio::MeasurementResult {
        run_id: 7,
        vehicle_id: Text::new("TEST-0042").unwrap(),
        approach_rad: 0.3,
        departure_rad: 0.4,
        breakover_rad: f32::NAN,
        ground_clearance_m: 0.18,
        approach_u_rad: 0.012,
        departure_u_rad: 0.015,
        breakover_u_rad: f32::NAN,
        ground_clearance_u_m: 0.004,
        absent: [
            radio::Absence::Measured,
            radio::Absence::Measured,
            radio::Absence::NotCovered,
            radio::Absence::Measured,
        ],
        wheelbase_m: 2.7,
        track_m: 1.55,
        approach_support: 120,
        departure_support: 80,
        breakover_support: 300,
        tyre_fit_rms_m: 0.004,
        warnings: ResultWarnings::LOW_SUPPORT,
        cloud_points: 250_000,
        preview_chunks: 100,
        records: List::from_slice(&[
            radio::RecordInfo {
                file: radio::RecordFile::ResultJson,
                len: 13_837,
            },
            radio::RecordInfo {
                file: radio::RecordFile::ResultSig,
                len: 24_925,
            },
        ])
        .unwrap(),
    }
}

const SEQ: u16 = 0x1234;

fn frame_of<M: Message>(msg: &M, flags: Flags) -> Vec<u8> {
    let mut out = [0u8; MAX_FRAME_LEN];
    let n = msg
        .encode_frame(SEQ, flags, &mut out)
        .expect("exemplar encodes");
    out[..n].to_vec()
}

/// One exemplar frame per message: (name, id, worst-case frame length, frame bytes).
#[allow(clippy::too_many_lines)] // one flat list of exemplars reads best
fn exemplars() -> Vec<(&'static str, u16, usize, Vec<u8>)> {
    fn row<M: Message>(msg: &M, flags: Flags) -> (&'static str, u16, usize, Vec<u8>) {
        (M::NAME, M::ID, max_frame_len::<M>(), frame_of(msg, flags))
    }
    let ack = Flags::ACK_REQUESTED;
    let none = Flags::NONE;
    vec![
        row(&Hello::new(Role::Onboard), ack),
        row(&Heartbeat { counter: 99 }, none),
        row(
            &LogLine {
                level: LogLevel::Warn,
                text: Text::new("lidar: 3 malformed packets").unwrap(),
            },
            none,
        ),
        row(
            &mcu::Drive {
                vx_mps: 0.2,
                vy_mps: 0.0,
                wz_radps: 0.0,
                accel_mps2: 0.3,
                jerk_mps3: 1.0,
            },
            ack,
        ),
        row(&mcu::Stop { immediate: false }, ack),
        row(&config(), ack),
        row(&mcu::ClearFaults {}, ack),
        row(
            &mcu::Odometry {
                stamp_us: 12_345_678,
                x_m: 1.0,
                y_m: -0.01,
                yaw_rad: 0.002,
                vx_mps: 0.2,
                vy_mps: 0.0,
                wz_radps: 0.0,
                wheel_speed_radps: [2.62, 2.62, 2.62, 2.62],
            },
            none,
        ),
        row(&status(), none),
        row(
            &mcu::Rejected {
                msg_id: protocol::ids::DRIVE,
                seq: 3,
                reason: mcu::RejectReason::OutOfRange,
                field: Text::new("vx_mps").unwrap(),
            },
            none,
        ),
        row(&start(), ack),
        row(
            &radio::HandshakeInit {
                key_id: 0x1234_5678,
                noise: List::from_slice(&[0xa5; 48]).unwrap(),
            },
            none,
        ),
        row(
            &radio::HandshakeReply {
                key_id: 0x1234_5678,
                session: 0xbeef,
                noise: List::from_slice(&[0x5a; 48]).unwrap(),
            },
            none,
        ),
        row(&radio::Abort { run_id: 0 }, ack),
        row(&radio::ResultAck { run_id: 7 }, ack),
        row(
            &radio::ResendChunks {
                run_id: 7,
                indices: List::from_slice(&[3, 17, 99]).unwrap(),
            },
            ack,
        ),
        row(&radio::StatusRequest {}, ack),
        row(&radio::FetchRun { run_id: 6 }, ack),
        row(
            &radio::LabChunk {
                upload: 0x1234,
                index: 2,
                count: 3,
                bytes: List::from_slice(b"[vehicle]\nvin = \"WVW\"\n").unwrap(),
            },
            ack,
        ),
        row(
            &radio::ResendRecordChunks {
                run_id: 7,
                file: radio::RecordFile::ResultSig,
                indices: List::from_slice(&[0, 12]).unwrap(),
            },
            ack,
        ),
        row(
            &radio::Progress {
                run_id: 7,
                phase: radio::Phase::Driving,
                percent: 42,
                travelled_m: 2.5,
                lidar_frames: 125,
            },
            none,
        ),
        row(&result(), ack),
        row(
            &radio::CloudChunk {
                run_id: 7,
                index: 3,
                count: 100,
                points_mm: List::from_slice(&[[1500, -200, 250], [-32768, 32767, 0]]).unwrap(),
            },
            none,
        ),
        row(
            &radio::RobotStatus {
                phase: radio::Phase::Idle,
                run_id: 7,
                firmware_ok: true,
                lidar_ok: true,
                camera_ok: false,
                interlocks: Interlocks::NO_HOST,
                pending_results: 1,
                disk_free_mib: 51_200,
                battery_mv: 23_870,
            },
            none,
        ),
        row(
            &radio::Refused {
                msg_id: protocol::ids::START_MEASUREMENT,
                seq: 9,
                reason: radio::RefuseReason::Replay,
                detail: Text::new("counter 5 is not above 9").unwrap(),
            },
            none,
        ),
        row(
            &radio::RecordChunk {
                run_id: 7,
                file: radio::RecordFile::ResultJson,
                index: 1,
                count: 73,
                total_len: 13_837,
                bytes: List::from_slice(b"{\n  \"run_id\": 7,\n").unwrap(),
            },
            none,
        ),
    ]
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().fold(String::new(), |mut s, b| {
        let _ = write!(s, "{b:02x}");
        s
    })
}

fn render_snapshot() -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# passangle protocol wire snapshot, PROTOCOL_VERSION {}",
        protocol::PROTOCOL_VERSION
    );
    let _ = writeln!(
        s,
        "# Any drift fails CI. Regenerate only with a PROTOCOL_VERSION bump:"
    );
    let _ = writeln!(
        s,
        "#     UPDATE_SNAPSHOTS=1 cargo test -p protocol --test wire"
    );
    let _ = writeln!(
        s,
        "# Exemplars use seq 0x1234; the signed start uses key 0x42 x 32, counter 1700000000000000."
    );
    let _ = writeln!(
        s,
        "# name  msg_id  worst_case_frame_bytes  exemplar_frame_hex"
    );
    for (name, id, max, bytes) in exemplars() {
        let _ = writeln!(s, "{name} {id:#06x} {max} {}", hex(&bytes));
    }
    s
}

#[test]
fn golden_bytes_match_snapshot() {
    let rendered = render_snapshot();
    if std::env::var_os("UPDATE_SNAPSHOTS").is_some() {
        std::fs::write(SNAPSHOT, &rendered).unwrap();
        return;
    }
    let committed = std::fs::read_to_string(SNAPSHOT)
        .unwrap_or_else(|e| panic!("{SNAPSHOT}: {e} (create it with UPDATE_SNAPSHOTS=1)"));
    for (line_no, (want, got)) in committed.lines().zip(rendered.lines()).enumerate() {
        assert_eq!(
            got,
            want,
            "{SNAPSHOT}:{}: wire bytes drifted; bump PROTOCOL_VERSION",
            line_no + 1
        );
    }
    assert_eq!(
        committed.lines().count(),
        rendered.lines().count(),
        "{SNAPSHOT}: message count changed"
    );
}

#[test]
fn every_exemplar_decodes_in_its_set() {
    for (name, id, _, bytes) in exemplars() {
        let mut d = Deframer::<MAX_FRAME_LEN>::new();
        let mut seen = 0;
        d.feed_all(&bytes, |r| {
            let frame = r.unwrap();
            assert_eq!(frame.header.msg_id, id);
            assert_eq!(frame.header.seq, SEQ);
            // The handshake travels outside the sessions' message sets.
            let sets = [
                ToFirmware::decode(&frame).is_ok(),
                FromFirmware::decode(&frame).is_ok(),
                ToOnboard::decode(&frame).is_ok(),
                ToHandheld::decode(&frame).is_ok(),
                protocol::message::decode::<radio::HandshakeInit>(&frame).is_ok(),
                protocol::message::decode::<radio::HandshakeReply>(&frame).is_ok(),
            ];
            assert!(
                sets.iter().any(|&ok| ok),
                "{name} decodes in no message set"
            );
            seen += 1;
        });
        assert_eq!(seen, 1, "{name}");
    }
}

#[test]
fn ids_are_unique() {
    let mut ids: Vec<u16> = exemplars().iter().map(|e| e.1).collect();
    let n = ids.len();
    ids.sort_unstable();
    ids.dedup();
    assert_eq!(ids.len(), n, "duplicate message id");
}

/// Worst-case instances: longest texts, full lists, largest varints.
/// A worst-case message: its payload within its bound, the bound within the payload limit, its
/// frame within the link buffer; returns the frame's length.
fn check<M: Message>(msg: &M) -> usize {
    let mut payload = [0u8; 1024];
    let len = postcard::to_slice(msg, &mut payload).unwrap().len();
    assert!(
        len <= M::POSTCARD_MAX_SIZE,
        "{}: {len} > bound {}",
        M::NAME,
        M::POSTCARD_MAX_SIZE
    );
    assert!(
        M::POSTCARD_MAX_SIZE <= MAX_PAYLOAD_LEN,
        "{} bound exceeds the payload limit",
        M::NAME
    );
    let frame = frame_of(msg, Flags::ACK_REQUESTED);
    assert!(frame.len() <= max_frame_len::<M>());
    assert!(
        max_frame_len::<M>() <= MAX_FRAME_LEN,
        "{} does not fit the link buffer",
        M::NAME
    );
    frame.len()
}

#[test]
fn worst_case_record_messages_fit_their_bounds() {
    check(&radio::RecordChunk {
        run_id: u32::MAX,
        file: radio::RecordFile::ResultSig,
        index: u16::MAX,
        count: u16::MAX,
        total_len: u32::MAX,
        bytes: List::from_slice(&[0xff; radio::RECORD_CHUNK_LEN]).unwrap(),
    });
    check(&radio::LabChunk {
        upload: u16::MAX,
        index: u8::MAX,
        count: u8::MAX,
        bytes: List::from_slice(&[0xff; radio::LAB_CHUNK_LEN]).unwrap(),
    });
    check(&radio::ResendRecordChunks {
        run_id: u32::MAX,
        file: radio::RecordFile::ResultSig,
        indices: List::from_slice(&[u16::MAX; 32]).unwrap(),
    });
    // The largest record file fits the chunk count's u16.
    assert!(u16::try_from(radio::record_chunk_count(radio::MAX_RECORD_LEN)).is_ok());
    assert_eq!(radio::record_chunk_count(0), 1);
    assert_eq!(radio::record_chunk_count(190), 1);
    assert_eq!(radio::record_chunk_count(191), 2);
}

#[test]
fn worst_cases_fit_their_bounds_and_the_link_buffer() {
    let long = |n: usize| "\u{e9}".repeat(n / 2);
    check(&LogLine {
        level: LogLevel::Debug,
        text: Text::new(&long(160)).unwrap(),
    });
    check(&mcu::Odometry {
        stamp_us: u64::MAX,
        x_m: f32::MAX,
        y_m: f32::MIN,
        yaw_rad: 1.0,
        vx_mps: 1.0,
        vy_mps: 1.0,
        wz_radps: 1.0,
        wheel_speed_radps: [f32::MAX; 4],
    });
    let mut s = status();
    s.stamp_us = u64::MAX;
    s.interlocks = Interlocks(u32::MAX);
    s.bus_off_count = u16::MAX;
    s.link_errors = u16::MAX;
    s.rejected_count = u16::MAX;
    s.battery_mv = u16::MAX;
    s.control_step_max_us = u16::MAX;
    check(&s);
    check(&mcu::Rejected {
        msg_id: u16::MAX,
        seq: u16::MAX,
        reason: mcu::RejectReason::NotConfigured,
        field: Text::new(&"x".repeat(24)).unwrap(),
    });
    let mut st = start();
    st.vehicle_id = Text::new(&"W".repeat(32)).unwrap();
    check(&st);
    let mut r = result();
    r.run_id = u32::MAX;
    r.vehicle_id = Text::new(&"W".repeat(32)).unwrap();
    r.cloud_points = u32::MAX;
    r.approach_support = u16::MAX;
    r.records = List::from_slice(
        &[radio::RecordInfo {
            file: radio::RecordFile::ResultSig,
            len: u32::MAX,
        }; radio::MAX_RECORD_FILES],
    )
    .unwrap();
    check(&r);
    let pts = vec![[i16::MIN, i16::MIN, i16::MIN]; radio::CHUNK_POINTS];
    check(&radio::CloudChunk {
        run_id: u32::MAX,
        index: u16::MAX,
        count: u16::MAX,
        points_mm: List::from_slice(&pts).unwrap(),
    });
    check(&radio::ResendChunks {
        run_id: u32::MAX,
        indices: List::from_slice(&[u16::MAX; 32]).unwrap(),
    });
    check(&radio::Refused {
        msg_id: 1,
        seq: 1,
        reason: radio::RefuseReason::Malformed,
        detail: Text::new(&"d".repeat(48)).unwrap(),
    });
    check(&radio::HandshakeReply {
        key_id: u32::MAX,
        session: u16::MAX,
        noise: List::from_slice(&[0xff; 64]).unwrap(),
    });
    // Every radio message fits a sealed frame's inner payload (also a compile-time check in
    // radio.rs); the worst cases above reach their bounds.
    const { assert!(ToOnboard::MAX_PAYLOAD_LEN <= protocol::auth::MAX_INNER_PAYLOAD_LEN) };
    const { assert!(ToHandheld::MAX_PAYLOAD_LEN <= protocol::auth::MAX_INNER_PAYLOAD_LEN) };
}

#[test]
fn hello_decodes_across_versions_and_others_do_not() {
    let hello = frame_of(&Hello::new(Role::Firmware), Flags::NONE);
    let hb = frame_of(&Heartbeat { counter: 1 }, Flags::NONE);
    for bytes in [hello, hb] {
        // Re-frame with version 9 in the header.
        let mut d = Deframer::<MAX_FRAME_LEN>::new();
        let mut frames = Vec::new();
        d.feed_all(&bytes, |r| {
            frames.push((r.unwrap().header, r.unwrap().payload.to_vec()));
        });
        let (mut header, payload) = frames.pop().unwrap();
        header.version = 9;
        let mut out = [0u8; MAX_FRAME_LEN];
        let n = protocol::frame::encode_raw(header, &payload, &mut out).unwrap();
        d.feed_all(&out[..n], |r| {
            let f = r.unwrap();
            let decoded = ToFirmware::decode(&f);
            if f.header.msg_id == protocol::ids::HELLO {
                assert_eq!(
                    decoded,
                    Ok(ToFirmware::Hello(Hello {
                        version: protocol::PROTOCOL_VERSION,
                        role: Role::Firmware as u8
                    }))
                );
            } else {
                assert_eq!(
                    decoded,
                    Err(protocol::DecodeError::VersionMismatch { theirs: 9 })
                );
            }
        });
    }
}

#[test]
fn malformed_payloads_are_typed_errors() {
    use protocol::frame::Frame;
    let h = Header::new(protocol::ids::DRIVE, 1, Flags::NONE);
    let short = Frame {
        header: h,
        payload: &[0, 0, 0],
    };
    assert_eq!(
        ToFirmware::decode(&short),
        Err(protocol::DecodeError::Malformed { msg_id: 0x0101 })
    );
    let long = frame_of(&mcu::Stop { immediate: true }, Flags::NONE);
    let _ = long;
    let trailing = Frame {
        header: Header::new(protocol::ids::STOP, 1, Flags::NONE),
        payload: &[1, 0],
    };
    assert_eq!(
        ToFirmware::decode(&trailing),
        Err(protocol::DecodeError::TrailingBytes { msg_id: 0x0102 })
    );
    let bad_enum = Frame {
        header: Header::new(protocol::ids::LOG_LINE, 1, Flags::NONE),
        payload: &[9, 0],
    };
    assert_eq!(
        FromFirmware::decode(&bad_enum),
        Err(protocol::DecodeError::Malformed { msg_id: 0x0003 })
    );
    let unknown = Frame {
        header: Header::new(0x7777, 1, Flags::NONE),
        payload: &[],
    };
    assert_eq!(
        ToOnboard::decode(&unknown),
        Err(protocol::DecodeError::UnknownId { msg_id: 0x7777 })
    );
    let ack = Frame {
        header: h.ack(),
        payload: &[],
    };
    assert_eq!(ToFirmware::decode(&ack), Err(protocol::DecodeError::IsAck));
}

/// The worst-case frame size table of the interface control document (`docs/protocol.md`,
/// between its `size-table` markers) is generated from the messages themselves: this test fails
/// when the committed table differs, and `UPDATE_DOCS=1 cargo test -p protocol --test wire`
/// rewrites it.
#[test]
fn the_icd_size_table_matches_the_messages() {
    use std::fmt::Write as _;
    let mut rows = exemplars();
    rows.sort_by_key(|(_, id, _, _)| *id);
    let mut table = String::from("| message | id | worst case |\n|---|---|---|\n");
    for (name, id, max, _) in rows {
        let _ = writeln!(table, "| {name} | {id:#06x} | {max} B |");
    }
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/protocol.md");
    let text = std::fs::read_to_string(&path).expect("docs/protocol.md");
    let (start, end) = ("<!-- size-table:start -->\n", "<!-- size-table:end -->");
    let (Some(a), Some(b)) = (text.find(start), text.find(end)) else {
        panic!("docs/protocol.md lacks the size-table markers");
    };
    let committed = &text[a + start.len()..b];
    if std::env::var_os("UPDATE_DOCS").is_some() {
        let updated = format!("{}{table}{}", &text[..a + start.len()], &text[b..]);
        std::fs::write(&path, updated).expect("write docs/protocol.md");
        return;
    }
    assert!(
        committed == table,
        "docs/protocol.md's size table is stale; regenerate it with \
         UPDATE_DOCS=1 cargo test -p protocol --test wire\n{table}"
    );
}
