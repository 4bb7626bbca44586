//! End-to-end checks of the simulated sensors against the onboard decoder and the shipped files:
//! the decoder reads back what the simulator encoded, decoded points lie on the surfaces they were
//! cast on (to quantisation plus noise), shipped vehicles' true angles match the closed form and
//! their published figures, and a seeded run is reproducible bit for bit (through the binary).

mod common;

use std::path::Path;
use std::process::Command;

use common::{crate_dir, shipped_vehicle, temp_dir};
use hil_sim::geometry::Vec3;
use hil_sim::scenario::Scenario;
use hil_sim::trajectory::{StraightRun, Vibration};
use hil_sim::truth::{TruthOptions, closed_form_rad, true_angles};
use hil_sim::vehicle::Vehicle;
use hil_sim::vlp16::{FiringTruth, Vlp16Config, Vlp16Sim};
use hil_sim::world::Scene;
use vlp16::pcap::{PcapReader, PcapWriter, udp_in_frame};
use vlp16::{DecoderConfig, FrameAssembler, Point};

fn run_under(v: &Vehicle) -> StraightRun {
    StraightRun {
        start_m: Vec3::new(v.front_x_m() + 0.2, 0.08, 0.0),
        heading_rad: std::f64::consts::PI,
        yaw_misalignment_rad: 0.015,
        speed_mps: 0.3,
        accel_mps2: 0.0,
        slip: 0.0,
        vibration: Vibration::new(0.003, 0.002, 17),
        still_s: 0.0,
        stop_after_m: None,
    }
}

/// Decode `packets` data packets of `sim` and pair each decoded point with its firing's truth.
fn decode_with_truth<T: hil_sim::trajectory::Trajectory>(
    sim: &Vlp16Sim<'_, T>,
    packets: u64,
) -> Vec<(Point, f64, FiringTruth)> {
    let config = DecoderConfig {
        min_range_m: 0.0,
        ..DecoderConfig::default()
    };
    let mut assembler = FrameAssembler::new(config).expect("valid decoder config");
    let mut truths = Vec::new();
    for k in 0..packets {
        let repr = sim.data_packet_with_truth(k, |f| {
            if f.distance_raw > 0 {
                truths.push(*f);
            }
        });
        assembler
            .push_data(&repr.to_bytes(), k * 1_327_104)
            .expect("simulated packet decodes");
    }
    assembler.finish();
    let mut points = Vec::new();
    while let Some(frame) = assembler.pop_frame() {
        points.extend(frame.points.iter().map(|p| (*p, frame.start_sensor_us)));
    }
    assert_eq!(
        points.len(),
        truths.len(),
        "one decoded point per simulated return"
    );
    points
        .into_iter()
        .zip(truths)
        .map(|((p, start), t)| (p, start, t))
        .collect()
}

fn world_point(p: &Point, t: &FiringTruth) -> Vec3 {
    t.world_from_lidar.apply(Vec3::new(
        f64::from(p.x_m),
        f64::from(p.y_m),
        f64::from(p.z_m),
    ))
}

#[test]
fn decoder_reads_back_noiseless_points_on_the_surfaces_they_were_cast_on() {
    let v = shipped_vehicle("suv");
    let scene = Scene::from_vehicle(&v);
    let run = run_under(&v);
    let config = Vlp16Config {
        range_noise_sigma_m: 0.0,
        dropout_probability: 0.0,
        min_range_m: 0.0,
        clock_offset_us: 1_000_000,
        ..Vlp16Config::default()
    };
    let sim = Vlp16Sim::new(&scene, &run, config, 9);
    let pairs = decode_with_truth(&sim, 200);
    assert!(pairs.len() > 40_000, "{}", pairs.len());
    let mut kinds = std::collections::HashSet::new();
    for (p, frame_start_us, t) in &pairs {
        assert_eq!(usize::from(p.laser_id), t.channel % 16);
        let (surface, hit) = t.hit.expect("a return has a hit");
        let q = world_point(p, t);
        let range_m = (hit - t.world_from_lidar.translation).norm();
        // 1 mm range rounding, 0.005 degree block-azimuth rounding, f32 coordinates.
        let tolerance = 0.001 + range_m * 2e-4 + 1e-5;
        let d = scene.distance_to_surface(surface, q);
        assert!(
            d <= tolerance,
            "{surface:?}: point {q:?} is {d} m off (tolerance {tolerance})"
        );
        // Firing time: the decoder's per-point time equals the simulated firing time.
        let decoded_us = frame_start_us + f64::from(p.time_us);
        let simulated_us = 1_000_000.0 + t.time_s * 1e6;
        assert!(
            (decoded_us - simulated_us).abs() < 1.0,
            "{decoded_us} vs {simulated_us}"
        );
        kinds.insert(surface.kind);
    }
    assert_eq!(
        kinds.len(),
        4,
        "ground, tyres, body and parts were all seen: {kinds:?}"
    );
}

#[test]
fn noisy_points_stay_within_the_noise_limit_with_the_configured_spread() {
    let v = shipped_vehicle("offroader");
    let scene = Scene::from_vehicle(&v);
    let run = run_under(&v);
    let config = Vlp16Config {
        dropout_probability: 0.0,
        min_range_m: 0.0,
        ..Vlp16Config::default()
    };
    let sim = Vlp16Sim::new(&scene, &run, config.clone(), 21);
    let pairs = decode_with_truth(&sim, 150);
    let mut sum2 = 0.0;
    for (p, _, t) in &pairs {
        let (_, hit) = t.hit.expect("a return has a hit");
        let origin = t.world_from_lidar.apply(Vec3::new(
            0.0,
            0.0,
            hil_sim::vlp16::VERTICAL_OFFSET_MM[t.channel % 16] / 1000.0,
        ));
        let true_range = (hit - origin).norm();
        let measured = (world_point(p, t) - origin).norm();
        let error = measured - true_range;
        assert!(
            error.abs() <= config.range_noise_limit_m + 0.0011,
            "range error {error}"
        );
        sum2 += error * error;
    }
    // Gaussian sigma 1.5 cm clipped at +-3 cm (2 sigma) has an RMS of 0.96 sigma = 1.44 cm.
    let rms = (sum2 / pairs.len() as f64).sqrt();
    assert!((0.0135..0.0153).contains(&rms), "rms {rms}");
}

#[test]
fn pcap_written_with_onboard_writer_decodes_to_every_return() {
    let v = shipped_vehicle("van");
    let scene = Scene::from_vehicle(&v);
    let run = run_under(&v);
    let sim = Vlp16Sim::new(&scene, &run, Vlp16Config::default(), 4);
    let mut writer = PcapWriter::new(Vec::new()).expect("in memory");
    let mut returns = 0usize;
    let (src, dst) = (
        "192.168.1.201:2368".parse().expect("addr"),
        "255.255.255.255:2368".parse().expect("addr"),
    );
    for k in 0..100 {
        let repr = sim.data_packet(k);
        returns += repr
            .blocks
            .iter()
            .flat_map(|b| b.channels.iter())
            .filter(|c| c.distance_raw > 0)
            .count();
        writer
            .write_udp(k * 1_327_104, src, dst, &repr.to_bytes())
            .expect("in memory");
    }
    let bytes = writer.into_inner();
    let mut reader = PcapReader::new(&bytes[..]).expect("pcap header");
    let mut assembler = FrameAssembler::new(DecoderConfig {
        min_range_m: 0.0,
        ..DecoderConfig::default()
    })
    .expect("config");
    while let Some(record) = reader.next_record().expect("valid record") {
        let udp = udp_in_frame(record.link_type, record.data).expect("Ethernet/IPv4/UDP");
        assert_eq!(udp.dst.port(), 2368);
        assembler
            .push_data(udp.payload, record.stamp_ns)
            .expect("decodes");
    }
    assembler.finish();
    let mut decoded = 0;
    while let Some(frame) = assembler.pop_frame() {
        decoded += frame.points.len();
    }
    assert_eq!(decoded, returns);
    assert_eq!(assembler.stats().malformed_data_total(), 0);
}

#[test]
fn shipped_vehicles_match_the_closed_form_and_their_published_angles() {
    for name in ["sedan", "suv", "offroader", "pickup", "van"] {
        let v = shipped_vehicle(name);
        let t = true_angles(
            &v,
            &TruthOptions {
                spacing_m: 0.005,
                ..TruthOptions::default()
            },
        );
        let r = v.tyre.radius_m;
        let rear_x = -v.wheelbase_m;
        let verts = v.outline_vertices();
        let outside = |d: f64, z: f64| d > r && d.hypot(r - z) > r;
        let approach = verts
            .iter()
            .filter(|p| outside(p.x_m, p.z_m))
            .map(|p| closed_form_rad(p.x_m, p.z_m, r))
            .fold(f64::INFINITY, f64::min);
        let departure = verts
            .iter()
            .filter(|p| outside(rear_x - p.x_m, p.z_m))
            .map(|p| closed_form_rad(rear_x - p.x_m, p.z_m, r))
            .fold(f64::INFINITY, f64::min);
        assert!(
            (t.approach.angle_rad - approach).abs() < 1e-7,
            "{name} approach"
        );
        assert!(
            (t.departure.angle_rad - departure).abs() < 1e-7,
            "{name} departure"
        );
        if let Some(p) = &v.published {
            for (what, truth, published) in [
                ("approach", t.approach.angle_rad, p.approach_deg),
                ("breakover", t.breakover.angle_rad, p.breakover_deg),
                ("departure", t.departure.angle_rad, p.departure_deg),
            ] {
                assert!(
                    (truth.to_degrees() - published).abs() < 1.0,
                    "{name} {what}: {} vs {published}",
                    truth.to_degrees()
                );
            }
        }
    }
}

#[test]
fn shipped_scenarios_load() {
    let dir = crate_dir().join("scenarios");
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).expect("scenarios dir") {
        let path = entry.expect("entry").path();
        if path.extension().is_some_and(|e| e == "toml") {
            let s = Scenario::load(&path).unwrap_or_else(|e| panic!("{e}"));
            assert!(s.duration_s > 10.0, "{}", path.display());
            n += 1;
        }
    }
    assert!(n >= 5);
}

fn sim_bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_passangle-sim"))
}

fn run_ok(cmd: &mut Command) {
    let out = cmd.output().expect("binary runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn seeded_lidar_run_is_reproducible_bit_for_bit() {
    let dir = temp_dir("lidar");
    let scenario = crate_dir().join("scenarios/suv-offset.toml");
    for name in ["a", "b"] {
        run_ok(
            sim_bin()
                .args(["lidar"])
                .arg(&scenario)
                .arg("--pcap")
                .arg(dir.join(format!("{name}.pcap")))
                .args(["--duration-s", "0.5"]),
        );
    }
    let read = |p: &Path| std::fs::read(p).expect("output exists");
    let (a, b) = (read(&dir.join("a.pcap")), read(&dir.join("b.pcap")));
    assert!(a.len() > 300_000);
    assert_eq!(a, b, "same scenario and seed, different pcap bytes");
    assert_eq!(
        read(&dir.join("a.truth.csv")),
        read(&dir.join("b.truth.csv"))
    );
    // A different seed changes the noise.
    let text = std::fs::read_to_string(&scenario)
        .expect("scenario")
        .replace("seed = 2", "seed = 99");
    let other = dir.join("other.toml");
    std::fs::write(
        &other,
        text.replace(
            "../vehicles/",
            &format!("{}/", crate_dir().join("vehicles").display()),
        ),
    )
    .expect("write");
    run_ok(
        sim_bin()
            .args(["lidar"])
            .arg(&other)
            .arg("--pcap")
            .arg(dir.join("c.pcap"))
            .args(["--duration-s", "0.5"]),
    );
    assert_ne!(a, read(&dir.join("c.pcap")));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn depth_output_is_reproducible_and_documented() {
    let dir = temp_dir("depth");
    let scenario = dir.join("small.toml");
    let vehicles = crate_dir().join("vehicles");
    std::fs::write(
        &scenario,
        format!(
            "vehicle = \"{}\"\nseed = 3\n[robot]\nstart_x_m = 0.5\nspeed_mps = 0.3\ndistance_m = 2.0\n[depth]\nwidth = 212\nheight = 120\nfps = 10\n",
            vehicles.join("pickup.toml").display()
        ),
    )
    .expect("write scenario");
    for name in ["a", "b"] {
        run_ok(
            sim_bin()
                .args(["depth"])
                .arg(&scenario)
                .arg("--out")
                .arg(dir.join(name))
                .args(["--duration-s", "0.3"]),
        );
    }
    let index = std::fs::read_to_string(dir.join("a/depth.csv")).expect("index");
    let rows: Vec<&str> = index
        .lines()
        .filter(|l| !l.starts_with('#'))
        .skip(1)
        .collect();
    assert_eq!(
        rows,
        [
            "0,0,0.000000,depth/000000.z16",
            "1,100000,0.100000,depth/000001.z16",
            "2,200000,0.200000,depth/000002.z16"
        ]
    );
    for f in [
        "depth/000000.z16",
        "depth/000002.z16",
        "camera.toml",
        "truth.csv",
    ] {
        let (a, b) = (
            std::fs::read(dir.join("a").join(f)).expect("a"),
            std::fs::read(dir.join("b").join(f)).expect("b"),
        );
        assert_eq!(a, b, "{f} differs between identical runs");
    }
    let frame = std::fs::read(dir.join("a/depth/000001.z16")).expect("frame");
    assert_eq!(frame.len(), 212 * 120 * 2);
    let valid = frame
        .chunks(2)
        .filter(|c| u16::from_le_bytes([c[0], c[1]]) != 0)
        .count();
    assert!(valid > 212 * 120 / 2, "{valid} valid pixels");
    let camera = std::fs::read_to_string(dir.join("a/camera.toml")).expect("camera.toml");
    assert!(
        camera.contains("fx_px = 106.5") && camera.contains("depth_unit_m = 0.001"),
        "{camera}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn udp_output_reaches_a_loopback_listener_at_real_time_pace() {
    use std::net::UdpSocket;
    use std::time::{Duration, Instant};
    // Count datagrams of `len` bytes on a socket until it stays quiet for 1 s (read concurrently:
    // the loopback receive buffer cannot hold the whole burst).
    fn listen(len: usize) -> (std::net::SocketAddr, std::thread::JoinHandle<usize>) {
        let socket = UdpSocket::bind("127.0.0.1:0").expect("bind");
        socket
            .set_read_timeout(Some(Duration::from_secs(1)))
            .expect("timeout");
        let addr = socket.local_addr().expect("addr");
        let handle = std::thread::spawn(move || {
            let mut buf = [0u8; 2048];
            let mut count = 0;
            while let Ok(n) = socket.recv(&mut buf) {
                assert_eq!(n, len);
                count += 1;
            }
            count
        });
        (addr, handle)
    }
    let (data_addr, data) = listen(1206);
    let (position_addr, position) = listen(512);
    let started = Instant::now();
    run_ok(
        sim_bin()
            .args(["lidar"])
            .arg(crate_dir().join("scenarios/van-pass.toml"))
            .args(["--udp", &data_addr.to_string()])
            .args(["--udp-position", &position_addr.to_string()])
            .args(["--realtime", "--duration-s", "0.2"]),
    );
    let elapsed = started.elapsed();
    // 0.2 s of data is 151 packets (one every 1.327 ms) and 10 position packets (one per 14).
    assert!(
        elapsed >= Duration::from_millis(190),
        "--realtime finished after {elapsed:?}"
    );
    assert_eq!(data.join().expect("listener"), 151);
    assert_eq!(position.join().expect("listener"), 10);
}

#[test]
fn command_line_errors_name_what_is_wrong() {
    let stderr = |cmd: &mut Command| {
        let out = cmd
            .env("RUST_BACKTRACE", "0")
            .output()
            .expect("binary runs");
        assert!(!out.status.success());
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let e = stderr(sim_bin().args(["lidar", "no/such/scenario.toml", "--pcap", "x.pcap"]));
    assert!(e.contains("no/such/scenario.toml"), "{e}");
    let scenario = crate_dir().join("scenarios/van-pass.toml");
    let e = stderr(sim_bin().arg("lidar").arg(&scenario));
    assert!(e.contains("--pcap") && e.contains("--udp"), "{e}");
    let e =
        stderr(
            sim_bin()
                .arg("depth")
                .arg(&scenario)
                .args(["--out", "/tmp", "--duration-s=-1"]),
        );
    assert!(e.contains("--duration-s"), "{e}");
    let e = stderr(sim_bin().args(["truth", "hil-sim/vehicles/nope.toml"]));
    assert!(e.contains("nope.toml"), "{e}");
}

#[test]
fn a_trajectory_file_drives_the_sensor_and_caps_the_duration() {
    let dir = temp_dir("trajectory");
    let traj = dir.join("traj.csv");
    // The robot simulation's pose-history format: 0.15 m forward in 0.5 s, relative to the start.
    std::fs::write(
        &traj,
        "stamp_us,x_m,y_m,yaw_rad,vx_mps\n0,0,0,0,0.3\n500000,0.15,0,0,0.3\n",
    )
    .expect("write");
    let pcap = dir.join("out.pcap");
    let out = sim_bin()
        .arg("lidar")
        .arg(crate_dir().join("scenarios/sedan-pass.toml"))
        .arg("--pcap")
        .arg(&pcap)
        .arg("--trajectory")
        .arg(&traj)
        .arg("--trajectory-from-start")
        .output()
        .expect("binary runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stdout).starts_with("377 data + 26 position packets"));
    let truth = std::fs::read_to_string(dir.join("out.truth.csv")).expect("truth");
    let last: Vec<f64> = truth
        .lines()
        .last()
        .expect("a sample")
        .split(',')
        .map(|f| f.parse().expect("number"))
        .collect();
    // Scenario start (2.0, 0.0) heading 180 degrees: 0.15 m forward ends at x = 1.85.
    assert!(
        (last[0] - 0.5).abs() < 1e-9 && (last[1] - 1.85).abs() < 1e-6 && last[2].abs() < 1e-6,
        "{last:?}"
    );
    assert!((last[6].abs() - std::f64::consts::PI).abs() < 1e-6);
    let bad = dir.join("bad.csv");
    std::fs::write(&bad, "time_s,x_m,y_m\n0,0,0\n").expect("write");
    let out = sim_bin()
        .env("RUST_BACKTRACE", "0")
        .arg("lidar")
        .arg(crate_dir().join("scenarios/sedan-pass.toml"))
        .arg("--pcap")
        .arg(dir.join("bad.pcap"))
        .arg("--trajectory")
        .arg(&bad)
        .output()
        .expect("binary runs");
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && e.contains("bad.csv") && e.contains("yaw_rad"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).ok();
}
