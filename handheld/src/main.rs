//! `passangle`: the operator's command line (measurement over the radio link) and the test engineer's
//! offline commands.

mod angles;
mod lidar;

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
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Lidar(args) => lidar::run(&args, &mut std::io::stdout().lock()),
        Command::Angles(args) => angles::run(&args, &mut std::io::stdout().lock()),
    }
}
