//! The `kitchen-r` binary: parses arguments and calls into the crates. Nothing else lives here.
//!
//! Each area's subcommands live in their own module (`sim_cmd` for the twin's tools); `main`
//! only dispatches.

mod sim_cmd;

use clap::{Parser, Subcommand};

#[derive(Parser, Debug)]
#[command(
    name = "kitchen-r",
    version,
    about = "Kitchen-R evaluation server, simulation worker and tools"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Kitchen twin tools (render what the robot sees).
    Sim(sim_cmd::SimArgs),
    /// Performance figures.
    Bench(sim_cmd::BenchArgs),
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Sim(args) => sim_cmd::sim(args),
        Command::Bench(args) => sim_cmd::bench(args),
    }
}
