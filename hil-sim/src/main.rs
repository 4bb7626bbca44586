//! `passangle-sim`: the software-in-the-loop simulator's command line.

use clap::{Parser, Subcommand};

/// passangle software-in-the-loop simulator.
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
