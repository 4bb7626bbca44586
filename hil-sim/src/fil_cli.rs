//! `passangle-sim fil` and `passangle-sim firmware`: the firmware-in-the-loop runner from the
//! command line (the imperative shell around `hil_sim::fil`).

use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Context as _, bail};
use clap::Args;
use hil_sim::can_bus::{CanBus, InProcessBus, SocketCanBus};
use hil_sim::fil::{Fil, FilConfig, Pacing};
use hil_sim::fil_scenarios::{self, BusChoice, LinkChoice};
use hil_sim::pty::{ByteLink, PtyLink};

/// Arguments of `passangle-sim fil`.
#[derive(Debug, Args)]
pub struct FilArgs {
    /// Scenario to run (cruise, heartbeat-loss, esc-silent, over-temperature, bus-off,
    /// link-flood) or `all`.
    #[arg(long, default_value = "all")]
    scenario: String,
    /// CAN bus: `inproc` (in memory) or a SocketCAN interface name such as `vcan0`.
    #[arg(long, default_value = "inproc")]
    bus: String,
    /// Carry the MCU link over a pseudo-terminal pair instead of memory (implies --realtime).
    #[arg(long)]
    pty: bool,
    /// Pace the simulation to the wall clock.
    #[arg(long)]
    realtime: bool,
    /// Seed of the ESC noise and the link flood.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Write the robot's true pose history (CSV, 1 kHz) of the last scenario run here.
    #[arg(long)]
    truth_csv: Option<PathBuf>,
    /// Write the bus traffic of the last scenario as a `candump -l` log (in-process bus only).
    #[arg(long)]
    candump: Option<PathBuf>,
}

fn bus_choice(bus: &str, record: bool) -> BusChoice {
    if bus == "inproc" {
        BusChoice::InProcess { record }
    } else {
        BusChoice::SocketCan(bus.to_owned())
    }
}

/// Runs the scenarios and prints their figures and checks; fails if any check failed.
pub fn fil(args: &FilArgs) -> anyhow::Result<()> {
    let names: Vec<&str> = if args.scenario == "all" {
        fil_scenarios::NAMES.to_vec()
    } else {
        vec![args.scenario.as_str()]
    };
    let config = FilConfig {
        seed: args.seed,
        pacing: if args.realtime || args.pty {
            Pacing::RealTime
        } else {
            Pacing::Virtual
        },
        ..FilConfig::default()
    };
    let link = if args.pty {
        LinkChoice::Pty
    } else {
        LinkChoice::Memory
    };
    let bus = bus_choice(&args.bus, args.candump.is_some());
    if args.candump.is_some() && !matches!(bus, BusChoice::InProcess { .. }) {
        bail!(
            "--candump records the in-process bus; on SocketCAN run `candump -L {}` instead",
            args.bus
        );
    }
    let mut failed = Vec::new();
    for name in names {
        let (mut runner, in_process) = fil_scenarios::build(config.clone(), &bus, link)
            .with_context(|| format!("cannot set up scenario {name} on bus {}", args.bus))?;
        let outcome = fil_scenarios::run_on(name, &mut runner, config.seed)?;
        println!("{outcome}");
        if !outcome.passed() {
            failed.push(name);
        }
        if let Some(path) = &args.truth_csv {
            std::fs::write(path, outcome.trace.truth.to_csv())
                .with_context(|| format!("cannot write {}", path.display()))?;
        }
        if let (Some(path), Some(bus)) = (&args.candump, in_process) {
            let mut text = bus.recorded().join("\n");
            text.push('\n');
            std::fs::write(path, text)
                .with_context(|| format!("cannot write {}", path.display()))?;
        }
    }
    if failed.is_empty() {
        Ok(())
    } else {
        bail!("scenarios failed: {}", failed.join(", "))
    }
}

/// Arguments of `passangle-sim firmware`.
#[derive(Debug, Args)]
pub struct FirmwareArgs {
    /// CAN bus: `inproc` or a SocketCAN interface such as `vcan0` (then the simulated ESCs and
    /// the firmware talk over it, and `candump vcan0` shows the traffic).
    #[arg(long, default_value = "inproc")]
    bus: String,
    /// How long to run, s.
    #[arg(long, default_value_t = 600.0)]
    duration_s: f64,
    /// Also make this symlink point to the pseudo-terminal (e.g. /tmp/passangle-mcu).
    #[arg(long)]
    link_symlink: Option<PathBuf>,
}

/// A link end that never carries anything (the onboard is an external program here).
struct Unconnected;

impl ByteLink for Unconnected {
    fn write_all(&mut self, _bytes: &[u8]) -> std::io::Result<()> {
        Ok(())
    }

    fn read_available(&mut self, _out: &mut Vec<u8>) -> std::io::Result<()> {
        Ok(())
    }
}

/// Runs the simulated robot and the firmware logic in real time, with the MCU link on a
/// pseudo-terminal an external onboard program can open as its serial port.
pub fn firmware(args: &FirmwareArgs) -> anyhow::Result<()> {
    let (fw_can, esc_can): (Box<dyn CanBus>, Box<dyn CanBus>) = if args.bus == "inproc" {
        let bus = InProcessBus::new();
        (Box::new(bus.node()), Box::new(bus.node()))
    } else {
        (
            Box::new(SocketCanBus::open(&args.bus)?),
            Box::new(SocketCanBus::open(&args.bus)?),
        )
    };
    let (master, slave) = PtyLink::pair().context("cannot open a pseudo-terminal pair")?;
    let path = slave
        .slave_path()
        .context("the pseudo-terminal has no device path")?;
    if let Some(link) = &args.link_symlink {
        let _ = std::fs::remove_file(link);
        std::os::unix::fs::symlink(&path, link)
            .with_context(|| format!("cannot create symlink {}", link.display()))?;
    }
    let config = FilConfig {
        pacing: Pacing::RealTime,
        can_wait: Duration::from_millis(20),
        ..FilConfig::default()
    };
    let mut fil = Fil::new(
        config,
        fw_can,
        esc_can,
        Box::new(master),
        Box::new(Unconnected),
    )?;
    println!(
        "simulated firmware on bus {}: MCU link at {path} (921600 8N1 is implied; a pty has no baud rate)",
        args.bus
    );
    // Keep the slave end open so the pty stays up while no client is connected.
    let _slave = slave;
    let end_us = (args.duration_s.max(0.0) * 1e6) as u64;
    let mut next_report_us = 1_000_000;
    while fil.now_us() < end_us {
        fil.tick()?;
        if fil.now_us() >= next_report_us {
            let t = fil.truth();
            println!(
                "t={:>7.1} s  mode {:<9} true pose x={:.3} m y={:.3} m yaw={:.2} deg v={:.3} m/s",
                t.stamp_us as f64 * 1e-6,
                fil.controller().machine().drive_mode().name(),
                t.x_m,
                t.y_m,
                t.yaw_rad.to_degrees(),
                t.vx_mps.hypot(t.vy_mps)
            );
            next_report_us += 1_000_000;
        }
    }
    Ok(())
}
