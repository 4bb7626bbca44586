//! `passangle`: the operator's command line (measurement over the radio link) and the test engineer's
//! offline commands.

use clap::{Parser, Subcommand};

/// passangle: automatic approach, departure and ramp breakover angles.
#[derive(Parser)]
#[command(version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {}
}
