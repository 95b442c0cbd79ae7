//! `kitchen-r sim …` and `kitchen-r bench sim`: the kitchen twin's tools.

use clap::{Args, Subcommand};

#[derive(Args, Debug)]
pub struct SimArgs {
    #[command(subcommand)]
    pub command: SimCommand,
}

#[derive(Subcommand, Debug)]
pub enum SimCommand {}

#[derive(Args, Debug)]
pub struct BenchArgs {
    #[command(subcommand)]
    pub command: BenchCommand,
}

#[derive(Subcommand, Debug)]
pub enum BenchCommand {}

pub fn sim(args: SimArgs) -> anyhow::Result<()> {
    match args.command {}
}

pub fn bench(args: BenchArgs) -> anyhow::Result<()> {
    match args.command {}
}
