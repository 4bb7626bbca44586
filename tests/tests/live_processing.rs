//! Live processing (the service builds the cloud during the drive) gives exactly the cloud that
//! processing the run's recording gives (`passangle replay`, or the service's fallback), whatever
//! the arrival order of the streams within the reorder window.
//!
//! A simulated straight run under the sedan (VLP-16 packets and 100 Hz wheel odometry) is written
//! by the real `RunRecorder` in arrival order and fed to a `RunBuilder` in the same order, as the
//! service does (odometry stamped with a seeded arrival jitter of up to 40 ms). A lidar frame is
//! stamped at its first firing but complete a revolution later, so the frames reach the builder
//! behind the odometry of their interval, out of stamp order. (Lidar and wheel odometry alone
//! would survive any interleaving: the pipeline queues a frame until the odometry covers it. The
//! reorder window matters for depth frames, whose visual-odometry prior depends on the odometry
//! present when they are pushed; depth is left out here because rendering it costs minutes in a
//! debug build.)
#![allow(clippy::unwrap_used)]

use std::path::Path;

use hil_sim::scenario::Scenario;
use hil_sim::trajectory::Trajectory;
use hil_sim::vlp16::{Datagram, Vlp16Sim};
use onboard::process::{ProcessConfig, REORDER_WINDOW_S, RunBuilder, build_cloud};
use onboard::recorder::{RecordedOutcome, RunRecorder};
use passangle_tests::temp_root;
use protocol::bounded::Text;
use protocol::mcu::Odometry;
use protocol::radio::{StartMeasurement, Zone};

const BASE_US: u64 = 1_790_000_000_000_000;

enum Arrival {
    Packet {
        wall_ns: u64,
        payload: Vec<u8>,
        position: bool,
    },
    Odometry {
        wall_us: u64,
        odometry: Odometry,
    },
}

impl Arrival {
    fn at_us(&self) -> u64 {
        match self {
            Arrival::Packet { wall_ns, .. } => wall_ns / 1_000,
            Arrival::Odometry { wall_us, .. } => *wall_us,
        }
    }
}

/// The streams of `duration_s` of the sedan scenario, in arrival order. `batched`: the service
/// reads the odometry reports two at a time, so each pair shares one arrival stamp.
fn arrivals(duration_s: f64, batched: bool) -> Vec<Arrival> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../hil-sim/scenarios/sedan-pass.toml");
    let scenario = Scenario::load(&path).unwrap();
    let scene = scenario.scene();
    let motion = scenario.motion();
    let sim = Vlp16Sim::new(
        &scene,
        &motion,
        scenario.lidar_config(),
        scenario.lidar_seed(),
    );
    let to_us = |s: f64| BASE_US + (s * 1e6) as u64;
    let mut out: Vec<Arrival> = sim
        .datagrams(duration_s)
        .map(|d| match d {
            Datagram::Data { send_s, payload } => Arrival::Packet {
                wall_ns: to_us(send_s) * 1_000,
                payload: payload.to_vec(),
                position: false,
            },
            Datagram::Position { send_s, payload } => Arrival::Packet {
                wall_ns: to_us(send_s) * 1_000,
                payload: payload.to_vec(),
                position: true,
            },
        })
        .collect();
    // Seeded jitter (a small LCG): each report arrives 0..40 ms after it was sent.
    let mut state = 0x2545_f491_4f6c_dd1d_u64;
    for i in 0..=(duration_s * 100.0) as u32 {
        let t = f64::from(i) * 0.01;
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        let jitter_s = (state >> 40) as f64 / f64::from(1u32 << 24) * 0.040;
        let d = scenario.run.wheel_distance_at(t);
        let wall_us = if batched {
            // Read 1 ms after the odd-numbered report of the pair was sent.
            to_us(f64::from(i | 1) * 0.01) + 1_000
        } else {
            to_us(t + jitter_s)
        };
        out.push(Arrival::Odometry {
            wall_us,
            odometry: Odometry {
                stamp_us: (t * 1e6) as u64,
                x_m: d as f32,
                y_m: 0.0,
                yaw_rad: 0.0,
                vx_mps: scenario.file.robot.speed_mps as f32,
                vy_mps: 0.0,
                wz_radps: 0.0,
                wheel_speed_radps: [0.0; 4],
            },
        });
    }
    out.sort_by_key(Arrival::at_us);
    out
}

/// What the service does with one arrival.
fn push(live: &mut RunBuilder, a: &Arrival) {
    match a {
        Arrival::Packet {
            wall_ns,
            payload,
            position,
        } => live.push_lidar_packet(*wall_ns, payload, *position),
        Arrival::Odometry { wall_us, odometry } => live.push_odometry(*wall_us, odometry),
    }
    live.release(REORDER_WINDOW_S);
}

fn config() -> ProcessConfig {
    let mut c = ProcessConfig {
        min_cloud_points: 0,
        ..ProcessConfig::default()
    };
    // Wheel odometry only keeps the debug-build test quick; the reordering is what is tested.
    c.pipeline.fusion.use_laser = false;
    c.pipeline.map.refine = false;
    c
}

#[test]
fn live_processing_builds_the_same_cloud_as_the_recording() {
    let root = temp_root("live");
    let params = StartMeasurement {
        vehicle_id: Text::truncated("live test"),
        speed_mps: 0.2,
        distance_m: 1.0,
        zone: Zone::Tyre,
        lab: protocol::radio::LabRef::NONE,
    };
    let mut recorder = RunRecorder::begin(&root, 1, &params, BASE_US, "").unwrap();
    let mut live = RunBuilder::new(&config()).unwrap();
    let src = "192.168.1.201:2368".parse().unwrap();
    let data_dst = "192.168.1.100:2368".parse().unwrap();
    let position_dst = "192.168.1.100:8308".parse().unwrap();
    for a in &arrivals(3.0, false) {
        match a {
            Arrival::Packet {
                wall_ns,
                payload,
                position,
            } => {
                let dst = if *position { position_dst } else { data_dst };
                recorder.lidar_packet(*wall_ns, src, dst, payload);
            }
            Arrival::Odometry { wall_us, odometry } => recorder.odometry(*wall_us, odometry),
        }
        push(&mut live, a);
    }
    let dir = recorder.dir().to_owned();
    assert!(recorder.finish(RecordedOutcome::Completed).is_empty());

    let (from_recording, read) = build_cloud(&dir, &config()).unwrap();
    let (from_live, counted) = live.finish().unwrap();
    assert!(read.lidar_frames >= 25, "{read:?}");
    assert_eq!(read, counted);
    assert!(from_recording.points_m.len() > 10_000);
    assert_eq!(from_live.points_m.len(), from_recording.points_m.len());
    assert!(
        from_live.points_m == from_recording.points_m,
        "live and recorded clouds differ"
    );
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
fn live_processing_keeps_up_during_the_drive() {
    // Frames are processed as they arrive: at the last arrival only the reorder window's frames
    // (0.5 s at 10 Hz: about 5) and the last partial revolutions are still waiting.
    let mut live = RunBuilder::new(&config()).unwrap();
    for a in arrivals(3.0, false) {
        push(&mut live, &a);
    }
    let frames = live.counts().lidar_frames;
    let done = live.frames_processed();
    assert!(frames >= 25, "{frames} frames");
    assert!(
        frames - done <= 7,
        "{done} of {frames} frames processed before the stop"
    );
}

#[test]
fn odometry_read_in_pairs_is_placed_at_its_mcu_stamps() {
    // Two reports per serial read share one arrival stamp. On the arrival clock the second of each
    // pair is "not after the previous one" and the pipeline would drop it (half the odometry);
    // mapped from the MCU's stamps, none is dropped.
    let mut live = RunBuilder::new(&config()).unwrap();
    let arrivals = arrivals(3.0, true);
    let shared = arrivals
        .windows(2)
        .filter(|w| {
            matches!(
                w,
                [Arrival::Odometry { wall_us: a, .. }, Arrival::Odometry { wall_us: b, .. }]
                    if a == b
            )
        })
        .count();
    assert!(shared >= 100, "{shared} pairs share an arrival stamp");
    for a in &arrivals {
        push(&mut live, a);
    }
    let (_, counts) = live.finish().unwrap();
    assert_eq!(counts.out_of_order, 0, "{counts:?}");
    assert_eq!(counts.mcu_clock_resets, 0, "{counts:?}");
    assert!(counts.odometry >= 300, "{counts:?}");
}
