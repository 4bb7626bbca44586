//! `passangle-sim`: the software-in-the-loop simulator's command line.

use clap::{Parser, Subcommand};

mod demo_cli;
mod fil_cli;
mod sensors_cli;

/// passangle software-in-the-loop simulator.
#[derive(Parser)]
#[command(version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Print a vehicle file's true approach, breakover and departure angles.
    Truth(sensors_cli::TruthArgs),
    /// Simulate the VLP-16 for a scenario into a pcap file and/or UDP.
    Lidar(sensors_cli::LidarArgs),
    /// Render the D435's Z16 depth frames for a scenario into a directory.
    Depth(sensors_cli::DepthArgs),
    /// Run the firmware-in-the-loop scenarios (simulated ESCs and robot, real firmware logic).
    Fil(fil_cli::FilArgs),
    /// Run the simulated robot and firmware in real time with the MCU link on a pty.
    Firmware(fil_cli::FirmwareArgs),
    /// A whole measurement in software: handheld, radio, onboard service, firmware, simulated
    /// robot and lidar; prints measured vs true angles.
    Demo(demo_cli::DemoArgs),
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Truth(args) => sensors_cli::truth(&args),
        Command::Lidar(args) => sensors_cli::lidar(&args),
        Command::Depth(args) => sensors_cli::depth(&args),
        Command::Fil(args) => fil_cli::fil(&args),
        Command::Firmware(args) => fil_cli::firmware(&args),
        Command::Demo(args) => demo_cli::demo(&args),
    }
}
