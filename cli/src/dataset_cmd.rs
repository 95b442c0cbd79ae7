//! `kitchen-r dataset generate`: regenerate the instruction set deterministically from the
//! scenes, catalogue and templates (the same seed gives byte-identical files).

use std::path::PathBuf;

use anyhow::Context;
use clap::{Args, Subcommand};
use kitchen_r_core::dataset;

#[derive(Args, Debug)]
pub struct DatasetArgs {
    #[command(subcommand)]
    command: DatasetCommand,
}

#[derive(Subcommand, Debug)]
enum DatasetCommand {
    /// Write dev.jsonl, test.jsonl, test_ground_truth.jsonl and manifest.json into DIR.
    Generate {
        /// Generator seed (the committed dataset uses 20241; organisers use a secret one).
        #[arg(long)]
        seed: u64,
        /// Output directory, created if missing.
        #[arg(long, value_name = "DIR")]
        out: PathBuf,
        /// Assets directory with scenes/, objects.toml and templates.toml [default: the
        /// KITCHEN_R_ASSETS lookup].
        #[arg(long, value_name = "DIR")]
        assets: Option<PathBuf>,
    },
}

pub fn dataset(args: DatasetArgs) -> anyhow::Result<()> {
    let DatasetCommand::Generate { seed, out, assets } = args.command;
    let assets = assets.unwrap_or_else(kitchen_r_core::assets::assets_dir);
    let ds =
        dataset::generate(seed, &assets).with_context(|| format!("generating from {}", assets.display()))?;
    dataset::write(&ds, &out).with_context(|| format!("writing {}", out.display()))?;
    println!(
        "wrote {} dev and {} test instructions (seed {seed}) to {}",
        ds.dev.len(),
        ds.test.len(),
        out.display()
    );
    Ok(())
}
