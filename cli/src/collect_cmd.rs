//! `kitchen-r collect`: expert trajectory collection into MCAP, HDF5 and/or a LeRobotDataset
//! with the Monitoring Module's checks. Argument parsing and printing only; the work is in
//! `kitchen_r_record::collect`.

use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::Args;
use kitchen_r_core::dataset::Split;
use kitchen_r_record::collect::{CollectConfig, CollectOptions, DepthUnit, Formats, collect};
use kitchen_r_record::video::Codec;

#[derive(Args, Debug)]
pub(crate) struct CollectArgs {
    /// Episodes to collect (episode i uses dev instruction i mod 163).
    #[arg(
        long,
        required_unless_present = "episodes_file",
        conflicts_with = "episodes_file"
    )]
    episodes: Option<usize>,
    /// Run exactly the episodes of a batch file (`kitchen-r episodes generate --out FILE`):
    /// episode i is the batch's i-th configuration.
    #[arg(long, value_name = "FILE")]
    episodes_file: Option<PathBuf>,
    /// Instruction split; only dev has public plans to drive.
    #[arg(long, default_value = "dev")]
    split: Split,
    /// Output directory (created; rerunning resumes, skipping finished episodes).
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Comma-separated formats: mcap, hdf5, lerobot (a LeRobotDataset v3.0 in DIR/lerobot).
    #[arg(long, default_value = "mcap,hdf5")]
    format: Formats,
    /// Comma-separated cameras to record [default: every camera of configs/sensors.toml].
    #[arg(long, value_delimiter = ',', value_name = "NAMES")]
    cameras: Option<Vec<String>>,
    /// Record no depth images (MCAP and HDF5; the LeRobotDataset has none anyway).
    #[arg(long)]
    no_depth: bool,
    /// HDF5 depth unit: `mm` (uint16 millimetres) or `m` (float32 metres).
    #[arg(long, value_enum, default_value = "mm", value_name = "UNIT")]
    depth_unit: DepthArg,
    /// The LeRobotDataset's video codec: `h264` (OpenH264, about four times the episodes a
    /// minute here) or `av1` (rav1e: royalty-free, LeRobot's own default) [default: the
    /// dataset's codec when appending to one, else h264].
    #[arg(long, value_name = "CODEC")]
    video_codec: Option<Codec>,
    /// Parallel episodes [default: the number of cores].
    #[arg(long)]
    jobs: Option<usize>,
    /// Collection seed: each episode's robot start, background objects and colours derive from it.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Monitor thresholds [default: configs/collect.toml].
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Grasp mode of every collected episode (abstract or physical): the expert drives the twin
    /// in this mode [default: configs/sim.toml's `[grasp] mode`]. Written to manifest.jsonl.
    #[arg(long, value_name = "MODE")]
    grasp: Option<kitchen_r_core::GraspMode>,
    /// Print the summary as one JSON object.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    live: crate::live_view::LiveArgs,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug)]
enum DepthArg {
    Mm,
    M,
}

pub(crate) fn collect_cmd(args: CollectArgs) -> anyhow::Result<()> {
    if args.split != Split::Dev {
        bail!("collect drives the public plans of the dev split only (--split dev)");
    }
    let config = match &args.config {
        Some(p) => CollectConfig::load(p).with_context(|| format!("reading {}", p.display()))?,
        None => CollectConfig::load_default()?,
    };
    let batch = match &args.episodes_file {
        Some(p) => {
            Some(kitchen_r_sim::episode::load_batch(p).with_context(|| format!("reading {}", p.display()))?)
        }
        None => None,
    };
    let depth = match (args.no_depth, args.depth_unit) {
        (true, _) => None,
        (false, DepthArg::Mm) => Some(DepthUnit::Millimetres),
        (false, DepthArg::M) => Some(DepthUnit::Metres),
    };
    let opts = CollectOptions {
        formats: args.format,
        jobs: args
            .jobs
            .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get())),
        seed: args.seed,
        config,
        cameras: args.cameras,
        depth,
        batch,
        video_codec: args.video_codec,
        grasp: args.grasp,
        progress: !args.json,
        ..CollectOptions::new(args.out, args.episodes.unwrap_or(0))
    };
    let view =
        crate::live_view::LiveView::start(&args.live, &kitchen_r_record::collect::live_sensors(&opts)?)?;
    let opts = CollectOptions {
        live: view.as_ref().map(|v| v.queue()),
        ..opts
    };
    let s = collect(&opts);
    if let Some(v) = view {
        v.finish()?;
    }
    let s = s?;
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
