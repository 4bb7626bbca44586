//! `passangle`: the operator's command line (measurement over the radio link) and the test engineer's
//! offline commands.

mod angles;
mod export;
mod field;
mod lidar;
mod replay;
mod report;
mod verify;
mod wheels;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// passangle: automatic approach, departure and ramp breakover angles.
#[derive(Parser)]
#[command(version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Summarise a VLP-16 capture (pcap/pcapng), or dump one frame as CSV.
    Lidar(lidar::LidarArgs),
    /// Approach, departure and ramp breakover angles of a vehicle's underside point cloud.
    Angles(angles::AnglesArgs),
    /// Create a new pairing key for the radio link (copy it to the robot).
    Pair(field::PairArgs),
    /// Run a measurement: drive under the vehicle, show progress, print and save the angles.
    Measure(field::MeasureArgs),
    /// Show the robot's state: phase, sensors, firmware interlocks, results waiting, disk space.
    Status(field::StatusArgs),
    /// Abort the running measurement (the robot stops first).
    Abort(field::AbortArgs),
    /// Fetch the result and preview of an earlier run from the robot.
    Fetch(field::FetchArgs),
    /// Rebuild a recorded run's point cloud offline (optionally with another pipeline config).
    Replay(replay::ReplayArgs),
    /// Write a recorded run as MCAP with Foxglove schemas (lidar frames, fused cloud, transforms,
    /// depth images, odometry).
    Export(export::ExportArgs),
    /// Check a signed record (result.json, a run directory...) against the robot's public key,
    /// offline; say what was changed if it fails (exit 3 changed, 4 not the robot's key, 5 not
    /// signed).
    Verify(verify::VerifyArgs),
    /// Write a recorded run's lab report: one self-contained HTML file (prints to PDF) with the
    /// results and U, the witnesses, tyres, floor, lab and vehicle details and every file's hash.
    Report(report::ReportArgs),
    /// The wheels' distance scale from a recorded calibration drive between walls: prints the
    /// line for the robot's config.
    Wheels(wheels::WheelsArgs),
}

fn main() -> anyhow::Result<ExitCode> {
    let cli = Cli::parse();
    let done = |r: anyhow::Result<()>| r.map(|()| ExitCode::SUCCESS);
    match cli.command {
        Command::Lidar(args) => done(lidar::run(&args, &mut std::io::stdout().lock())),
        Command::Angles(args) => done(angles::run(&args, &mut std::io::stdout().lock())),
        Command::Pair(args) => done(field::pair(&args, &mut std::io::stdout().lock())),
        Command::Measure(args) => done(field::measure(&args, &mut std::io::stdout().lock())),
        Command::Status(args) => done(field::status(&args, &mut std::io::stdout().lock())),
        Command::Abort(args) => done(field::abort(&args, &mut std::io::stdout().lock())),
        Command::Fetch(args) => done(field::fetch(&args, &mut std::io::stdout().lock())),
        Command::Replay(args) => done(replay::run(&args, &mut std::io::stdout().lock())),
        Command::Export(args) => done(export::run(&args, &mut std::io::stdout().lock())),
        Command::Verify(args) => verify::run(&args, &mut std::io::stdout().lock()),
        Command::Report(args) => done(report::run(&args, &mut std::io::stdout().lock())),
        Command::Wheels(args) => done(wheels::run(&args, &mut std::io::stdout().lock())),
    }
}
