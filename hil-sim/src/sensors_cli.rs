//! The sensor commands of `passangle-sim`: `truth`, `lidar` and `depth` (the imperative shell around
//! the pure models in the `hil_sim` library: files, sockets and the wall clock live only here).
//!
//! # Outputs
//! - `lidar SCENARIO --pcap OUT.pcap`: classic pcap (Ethernet/IPv4/UDP, opens in Wireshark and
//!   VeloView) with data packets from 192.168.1.201:2368 and position packets from
//!   192.168.1.201:8308 to 255.255.255.255, stamped [`hil_sim::vlp16::PCAP_EPOCH_S`] + simulation time. The sensor
//!   clock (microseconds past the hour) is `lidar.clock_offset_us` + simulation time, so with the
//!   default offset 0 it agrees with the pcap stamps' position in the hour. `--udp HOST:PORT` sends
//!   the same datagrams (position packets to `--udp-position`, default port 8308 of the same host),
//!   as fast as possible or, with `--realtime`, paced by the wall clock.
//! - `depth SCENARIO --out DIR`: `DIR/depth/NNNNNN.z16` (raw Z16: little-endian u16 millimetres,
//!   row-major, 0 = invalid), `DIR/depth.csv` (`frame,stamp_us,time_s,file`), `DIR/camera.toml`
//!   (intrinsics, depth unit, mount `robot_from_camera`, clock offset, fps, scenario path).
//! - Both write the ground-truth trajectory CSV (see `hil_sim::trajectory`): next to the pcap as
//!   `OUT.truth.csv` (or `--truth PATH`), or `DIR/truth.csv`.

use std::fmt::Write as _;
use std::fs::{self, File};
use std::io::{BufWriter, Write};
use std::net::{SocketAddr, UdpSocket};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use clap::Args;
use hil_sim::d435::D435Sim;
use hil_sim::geometry::Pose;
use hil_sim::scenario::Scenario;
use hil_sim::trajectory::{
    SampledTrajectory, StraightRun, Trajectory, parse_trajectory_csv, write_truth_csv,
};
use hil_sim::truth::{TruthOptions, Zone, true_angles};
use hil_sim::vehicle::Vehicle;
use hil_sim::vlp16::Vlp16Sim;
use hil_sim::world::{Floor, OnFloor};
use vlp16::pcap::PcapWriter;

/// Ground-truth sampling step, seconds.
const TRUTH_STEP_S: f64 = 0.005;

/// Arguments of `passangle-sim truth`.
#[derive(Args)]
pub struct TruthArgs {
    /// Vehicle TOML file.
    vehicle: PathBuf,
    /// Outline sampling step, millimetres.
    #[arg(long, default_value_t = 1.0)]
    spacing_mm: f64,
    /// Count points ahead of the axle (EU) instead of ahead of the tyre (CFR/SAE).
    #[arg(long)]
    eu_zone: bool,
    /// Ignore flexible parts (EU: rigid parts only).
    #[arg(long)]
    rigid_only: bool,
}

/// Arguments of `passangle-sim lidar`.
#[derive(Args)]
pub struct LidarArgs {
    /// Scenario TOML file.
    scenario: PathBuf,
    /// Write the packets into this pcap file.
    #[arg(long)]
    pcap: Option<PathBuf>,
    /// Send the packets over UDP to this address (e.g. 127.0.0.1:2368).
    #[arg(long)]
    udp: Option<SocketAddr>,
    /// Send position packets here (default: port 8308 of the --udp host).
    #[arg(long)]
    udp_position: Option<SocketAddr>,
    /// Pace UDP output at the sensor's real rate instead of as fast as possible.
    #[arg(long)]
    realtime: bool,
    /// Drive the sensor along this trajectory CSV (ground-truth or robot pose-history format)
    /// instead of the scenario's straight run; the recording ends with the file.
    #[arg(long)]
    trajectory: Option<PathBuf>,
    /// The trajectory file's poses are relative to the scenario's start pose (default: they are in
    /// the vehicle frame already).
    #[arg(long)]
    trajectory_from_start: bool,
    /// Ground-truth CSV path (default: next to the pcap, `.truth.csv`).
    #[arg(long)]
    truth: Option<PathBuf>,
    /// Override the scenario's duration, seconds.
    #[arg(long)]
    duration_s: Option<f64>,
}

/// Arguments of `passangle-sim depth`.
#[derive(Args)]
pub struct DepthArgs {
    /// Scenario TOML file.
    scenario: PathBuf,
    /// Output directory (created).
    #[arg(long)]
    out: PathBuf,
    /// Drive the sensor along this trajectory CSV (ground-truth or robot pose-history format)
    /// instead of the scenario's straight run; the recording ends with the file.
    #[arg(long)]
    trajectory: Option<PathBuf>,
    /// The trajectory file's poses are relative to the scenario's start pose (default: they are in
    /// the vehicle frame already).
    #[arg(long)]
    trajectory_from_start: bool,
    /// Override the scenario's duration, seconds.
    #[arg(long)]
    duration_s: Option<f64>,
}

/// `passangle-sim truth VEHICLE`: print the true angles and what limits them.
pub fn truth(args: &TruthArgs) -> anyhow::Result<()> {
    let vehicle = Vehicle::load(&args.vehicle)?;
    if !(args.spacing_mm > 0.0 && args.spacing_mm <= 100.0) {
        bail!("--spacing-mm must lie in (0, 100], got {}", args.spacing_mm);
    }
    let options = TruthOptions {
        zone: if args.eu_zone { Zone::Axle } else { Zone::Tyre },
        include_flexible: !args.rigid_only,
        spacing_m: args.spacing_mm / 1000.0,
    };
    let t = true_angles(&vehicle, &options);
    println!("{} ({})", vehicle.name, args.vehicle.display());
    for (name, angle) in [
        ("approach", &t.approach),
        ("breakover", &t.breakover),
        ("departure", &t.departure),
    ] {
        let witness = angle.witness.as_ref().map_or_else(
            || "no point in the zone".to_owned(),
            |w| {
                format!(
                    "limited by {} at x = {:.3} m, z = {:.3} m",
                    w.source, w.x_m, w.z_m
                )
            },
        );
        println!(
            "  {name:<10} {:7.3} deg  {witness}",
            angle.angle_rad.to_degrees()
        );
    }
    if let Some(p) = &vehicle.published {
        println!(
            "  published  {:.1} / {:.1} / {:.1} deg (approach / breakover / departure; {})",
            p.approach_deg, p.breakover_deg, p.departure_deg, p.source
        );
    }
    Ok(())
}

fn load_scenario(path: &Path, duration_override: Option<f64>) -> anyhow::Result<Scenario> {
    let mut scenario = Scenario::load(path)?;
    if let Some(d) = duration_override {
        if !(d > 0.0 && d <= 3600.0) {
            bail!("--duration-s must lie in (0, 3600], got {d}");
        }
        scenario.duration_s = d;
    }
    Ok(scenario)
}

/// The robot's motion: the scenario's straight run (on its hall's floor, if any) or a
/// trajectory file.
enum Motion {
    Scenario(StraightRun, Option<Box<Floor>>),
    File(SampledTrajectory),
}

impl Trajectory for Motion {
    fn pose_at(&self, t_s: f64) -> Pose {
        match self {
            Motion::Scenario(r, floor) => OnFloor {
                inner: r,
                floor: floor.as_deref(),
            }
            .pose_at(t_s),
            Motion::File(f) => f.pose_at(t_s),
        }
    }

    fn wheel_distance_at(&self, t_s: f64) -> f64 {
        match self {
            Motion::Scenario(r, _) => r.wheel_distance_at(t_s),
            Motion::File(f) => f.wheel_distance_at(t_s),
        }
    }
}

/// The motion to simulate; a trajectory file also caps the scenario's duration at its end.
fn load_motion(
    file: Option<&Path>,
    from_start: bool,
    scenario: &mut Scenario,
) -> anyhow::Result<Motion> {
    let Some(path) = file else {
        return Ok(Motion::Scenario(
            scenario.run.clone(),
            scenario.hall.as_ref().map(|h| Box::new(h.floor.clone())),
        ));
    };
    let text = fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut trajectory = parse_trajectory_csv(&text)
        .with_context(|| format!("trajectory file {}", path.display()))?;
    if from_start {
        let start = scenario.run.pose_at(0.0);
        trajectory = trajectory.relative_to(&Pose {
            roll_rad: 0.0,
            pitch_rad: 0.0,
            ..start
        });
    }
    if trajectory.end_time_s() <= 0.0 {
        bail!(
            "trajectory file {}: it ends at t = 0; nothing to simulate",
            path.display()
        );
    }
    scenario.duration_s = scenario.duration_s.min(trajectory.end_time_s());
    Ok(Motion::File(trajectory))
}

fn write_truth(path: &Path, motion: &Motion, duration_s: f64) -> anyhow::Result<()> {
    let mut out =
        BufWriter::new(File::create(path).with_context(|| format!("creating {}", path.display()))?);
    write_truth_csv(&mut out, motion, duration_s, TRUTH_STEP_S)?;
    out.flush()
        .with_context(|| format!("writing {}", path.display()))
}

/// `passangle-sim lidar SCENARIO`: simulate the VLP-16 into a pcap and/or UDP.
pub fn lidar(args: &LidarArgs) -> anyhow::Result<()> {
    if args.pcap.is_none() && args.udp.is_none() {
        bail!("give --pcap FILE and/or --udp HOST:PORT");
    }
    let mut scenario = load_scenario(&args.scenario, args.duration_s)?;
    let motion = load_motion(
        args.trajectory.as_deref(),
        args.trajectory_from_start,
        &mut scenario,
    )?;
    let scene = scenario.scene();
    let sim = Vlp16Sim::new(
        &scene,
        &motion,
        scenario.lidar_config(),
        scenario.lidar_seed(),
    );
    let mut pcap = match &args.pcap {
        Some(p) => Some(PcapWriter::new(BufWriter::new(
            File::create(p).with_context(|| format!("creating {}", p.display()))?,
        ))?),
        None => None,
    };
    let udp = match args.udp {
        Some(_) => Some(UdpSocket::bind("0.0.0.0:0").context("binding a UDP socket")?),
        None => None,
    };
    let truth_path = args
        .truth
        .clone()
        .or_else(|| args.pcap.as_ref().map(|p| p.with_extension("truth.csv")));
    let started = Instant::now();
    let (mut data, mut position) = (0u64, 0u64);
    for datagram in sim.datagrams(scenario.duration_s) {
        let send_s = datagram.send_s();
        let (payload, port) = datagram.payload_and_port();
        if port == 2368 {
            data += 1;
        } else {
            position += 1;
        }
        if let Some(w) = pcap.as_mut() {
            datagram.write_pcap(w)?;
        }
        if let (Some(sock), Some(addr)) = (&udp, args.udp) {
            if args.realtime {
                let due = Duration::from_secs_f64(send_s);
                if let Some(wait) = due.checked_sub(started.elapsed()) {
                    std::thread::sleep(wait);
                }
            }
            let target = if port == 2368 {
                addr
            } else {
                args.udp_position
                    .unwrap_or_else(|| SocketAddr::new(addr.ip(), 8308))
            };
            sock.send_to(payload, target)
                .with_context(|| format!("sending to {target}"))?;
        }
    }
    if let Some(w) = pcap.as_mut() {
        w.flush()?;
    }
    let wall_s = started.elapsed().as_secs_f64();
    if let Some(p) = &truth_path {
        write_truth(p, &motion, scenario.duration_s)?;
    }
    println!(
        "{data} data + {position} position packets, {:.2} s simulated in {wall_s:.2} s ({:.1}x real time)",
        scenario.duration_s,
        scenario.duration_s / wall_s.max(1e-9)
    );
    if let Some(p) = &truth_path {
        println!("ground truth: {}", p.display());
    }
    Ok(())
}

/// `passangle-sim depth SCENARIO --out DIR`: render the D435's Z16 frames.
pub fn depth(args: &DepthArgs) -> anyhow::Result<()> {
    let mut scenario = load_scenario(&args.scenario, args.duration_s)?;
    let motion = load_motion(
        args.trajectory.as_deref(),
        args.trajectory_from_start,
        &mut scenario,
    )?;
    let scene = scenario.scene();
    let config = scenario.file.depth.clone();
    let sim = D435Sim::new(&scene, &motion, config.clone(), scenario.depth_seed());
    let frames_dir = args.out.join("depth");
    fs::create_dir_all(&frames_dir)
        .with_context(|| format!("creating {}", frames_dir.display()))?;
    let n = sim.frames_in(scenario.duration_s);
    let workers = std::thread::available_parallelism()
        .map_or(1, usize::from)
        .min(8) as u64;
    let started = Instant::now();
    std::thread::scope(|s| -> anyhow::Result<()> {
        let handles: Vec<_> = (0..workers)
            .map(|w| {
                let (sim, frames_dir) = (&sim, &frames_dir);
                s.spawn(move || -> anyhow::Result<()> {
                    for i in (w..n).step_by(workers as usize) {
                        let path = frames_dir.join(format!("{i:06}.z16"));
                        fs::write(&path, sim.frame(i).to_z16_bytes())
                            .with_context(|| format!("writing {}", path.display()))?;
                    }
                    Ok(())
                })
            })
            .collect();
        for h in handles {
            h.join()
                .map_err(|_| anyhow::anyhow!("a render thread panicked"))??;
        }
        Ok(())
    })?;
    let mut index = String::from(
        "# passangle-sim D435 depth frames: raw Z16, see camera.toml\nframe,stamp_us,time_s,file\n",
    );
    for i in 0..n {
        let stamp_us = config.clock_offset_us + (sim.frame_time_s(i) * 1e6).round() as u64;
        let _ = writeln!(
            index,
            "{i},{stamp_us},{:.6},depth/{i:06}.z16",
            sim.frame_time_s(i)
        );
    }
    fs::write(args.out.join("depth.csv"), index).context("writing depth.csv")?;
    fs::write(args.out.join("camera.toml"), camera_toml(&scenario)?)
        .context("writing camera.toml")?;
    write_truth(&args.out.join("truth.csv"), &motion, scenario.duration_s)?;
    let wall_s = started.elapsed().as_secs_f64();
    println!(
        "{n} frames {}x{} in {} ({wall_s:.1} s, {:.1} frames/s on {workers} threads)",
        config.width,
        config.height,
        args.out.display(),
        n as f64 / wall_s.max(1e-9)
    );
    Ok(())
}

/// The `camera.toml` written next to the frames.
fn camera_toml(scenario: &Scenario) -> anyhow::Result<String> {
    #[derive(serde::Serialize)]
    struct Camera {
        scenario: String,
        fps: f64,
        depth_unit_m: f64,
        clock_offset_us: u64,
        intrinsics: hil_sim::d435::Intrinsics,
        robot_from_camera_xyz_m: [f64; 3],
        robot_from_camera_rotation: [[f64; 3]; 3],
    }
    let c = &scenario.file.depth;
    let m = c.robot_from_camera();
    let camera = Camera {
        scenario: scenario.path.display().to_string(),
        fps: c.fps,
        depth_unit_m: 0.001,
        clock_offset_us: c.clock_offset_us,
        intrinsics: c.intrinsics(),
        robot_from_camera_xyz_m: [m.translation.x, m.translation.y, m.translation.z],
        robot_from_camera_rotation: std::array::from_fn(|i| {
            std::array::from_fn(|j| m.rotation[(i, j)])
        }),
    };
    let header = "# passangle-sim D435 stream: frames are <width>x<height> little-endian u16, row-major, depth in\n\
                  # depth_unit_m, 0 = invalid. Optical frame x right, y down, z forward; robot_from_camera maps it into\n\
                  # the robot frame (x forward, y left, z up; rotation row-major).\n";
    Ok(format!("{header}{}", toml::to_string(&camera)?))
}
