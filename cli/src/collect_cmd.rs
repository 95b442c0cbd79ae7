//! `kitchen-r collect`: expert trajectory collection into MCAP and/or HDF5 with the Monitoring
//! Module's checks. Argument parsing and printing only; the work is in
//! `kitchen_r_record::collect`.

use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::Args;
use kitchen_r_core::dataset::Split;
use kitchen_r_record::collect::{CollectConfig, CollectOptions, Formats, collect};

#[derive(Args, Debug)]
pub(crate) struct CollectArgs {
    /// Episodes to collect (episode i uses dev instruction i mod 163).
    #[arg(long)]
    episodes: usize,
    /// Instruction split; only dev has public plans to drive.
    #[arg(long, default_value = "dev")]
    split: Split,
    /// Output directory (created; rerunning resumes, skipping finished episodes).
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Comma-separated file formats: mcap, hdf5.
    #[arg(long, default_value = "mcap,hdf5")]
    format: Formats,
    /// Parallel episodes [default: the number of cores].
    #[arg(long)]
    jobs: Option<usize>,
    /// Collection seed: each episode's robot start, background objects and colours derive from it.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Monitor thresholds [default: configs/collect.toml].
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Print the summary as one JSON object.
    #[arg(long)]
    json: bool,
}

pub(crate) fn collect_cmd(args: CollectArgs) -> anyhow::Result<()> {
    if args.split != Split::Dev {
        bail!("collect drives the public plans of the dev split only (--split dev)");
    }
    let config = match &args.config {
        Some(p) => CollectConfig::load(p).with_context(|| format!("reading {}", p.display()))?,
        None => CollectConfig::load_default()?,
    };
    let opts = CollectOptions {
        episodes: args.episodes,
        out: args.out,
        formats: args.format,
        jobs: args
            .jobs
            .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get())),
        seed: args.seed,
        config,
        sensors: None,
        progress: !args.json,
    };
    let s = collect(&opts)?;
    if args.json {
        println!("{}", serde_json::to_string(&s)?);
        return Ok(());
    }
    let discarded: usize = s.discarded.values().sum();
    println!(
        "kept {} / discarded {} / skipped (already collected) {} of {} episodes into {}",
        s.kept,
        discarded,
        s.skipped,
        s.requested,
        opts.out.display()
    );
    for (reason, n) in &s.discarded {
        println!("  discarded {n:>4}  {reason}");
    }
    println!(
        "{} frames, {:.1} s wall, {:.2} episodes/min ({} jobs)",
        s.frames, s.wall_s, s.episodes_per_min, opts.jobs
    );
    Ok(())
}
