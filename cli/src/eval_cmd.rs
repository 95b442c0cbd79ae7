//! `kitchen-r eval`: local online evaluation through the workers' episode runner, with SR per
//! task kind and overall, and sim and wall times. Argument parsing and printing only; the work
//! is in `kitchen_r_worker::eval`.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use kitchen_r_core::dataset::Split;
use kitchen_r_worker::eval::{EvalConfig, EvalOptions, EvalReport, PolicyChoice, evaluate};

#[derive(Args, Debug)]
pub struct EvalArgs {
    /// Policy to evaluate; accepted values: builtin:oracle (the privileged reference expert).
    #[arg(long, default_value = "builtin:oracle")]
    policy: String,
    /// Instruction split: dev (public plans) or test (needs --ground-truth).
    #[arg(long, default_value = "dev")]
    split: Split,
    /// Evaluate the first N instructions of the split [default: all].
    #[arg(long)]
    episodes: Option<usize>,
    /// Print one JSON object (with every episode's outcome) instead of the table.
    #[arg(long)]
    json: bool,
    /// Run seed: robot starts and background objects derive from it and each instruction id.
    #[arg(long)]
    seed: Option<u64>,
    /// Parallel episodes [default: the number of cores].
    #[arg(long)]
    jobs: Option<usize>,
    /// The organiser's test ground truth (test_ground_truth.jsonl): required for --split test.
    #[arg(long, value_name = "FILE")]
    ground_truth: Option<PathBuf>,
    /// Evaluation settings [default: configs/eval.toml].
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
}

pub fn eval(args: EvalArgs) -> anyhow::Result<()> {
    let policy: PolicyChoice = args.policy.parse()?;
    let config = match &args.config {
        Some(p) => EvalConfig::load(p).with_context(|| format!("reading {}", p.display()))?,
        None => EvalConfig::load_default()?,
    };
    let opts = EvalOptions {
        policy,
        split: args.split,
        episodes: args.episodes,
        seed: args.seed.unwrap_or(config.seed),
        jobs: args
            .jobs
            .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get())),
        ground_truth: args.ground_truth,
        run: config.run_options(),
    };
    let mut done = 0;
    let report = evaluate(&opts, &mut |_, o| {
        done += 1;
        let ok = o.tasks.iter().filter(|t| t.success).count();
        eprintln!(
            "[{done}] {} {}  SR {:.2} ({ok}/{})  sim {:.1} s  wall {:.2} s",
            o.episode_id,
            o.scene,
            o.success_rate(),
            o.tasks.len(),
            o.sim_time,
            o.wall_time_s
        );
        for t in o.tasks.iter().filter(|t| !t.success) {
            eprintln!("    failed {:?}: {}", t.step, t.failure.as_deref().unwrap_or(""));
        }
    })?;
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        print_table(&report);
    }
    Ok(())
}

fn print_table(r: &EvalReport) {
    println!(
        "policy {}  split {}  episodes {}  seed {}  jobs {}",
        r.policy,
        r.split,
        r.episodes.len(),
        r.seed,
        r.jobs
    );
    println!(
        "{:<14} {:>6} {:>8} {:>7} {:>15}",
        "task kind", "tasks", "success", "SR", "mean sim time"
    );
    let rows = ["navigation", "manipulation", "pick", "place"]
        .into_iter()
        .filter_map(|k| r.by_kind.get(k).map(|s| (k, s)))
        .chain(std::iter::once(("overall", &r.overall)));
    for (k, s) in rows {
        println!(
            "{k:<14} {:>6} {:>8} {:>7.3} {:>13.1} s",
            s.tasks, s.succeeded, s.sr, s.mean_task_sim_time
        );
    }
    println!(
        "mean episode wall time {:.3} s   total wall time {:.1} s",
        r.mean_episode_wall_s, r.total_wall_s
    );
}
