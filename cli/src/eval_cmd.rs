//! `kitchen-r eval`: local evaluation through the workers' episode runner, with SR per task kind
//! and overall (online) or MSE against the expert (offline), and sim and wall times. Argument
//! parsing and printing only; the work is in `kitchen_r_episode::eval` (built-in policies) and
//! `kitchen_r_worker::job::local` (a policy endpoint, run as the server's workers run it).

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use kitchen_r_core::GraspMode;
use kitchen_r_core::dataset::Split;
use kitchen_r_episode::eval::{
    EvalConfig, EvalOptions, EvalReport, PolicyChoice, Sr, evaluate, evaluate_batch, instructions,
};
use kitchen_r_sim::EpisodeConfig;
use kitchen_r_worker::job::local::{
    LocalEpisode, LocalReport, LocalSettings, Mode, evaluate_endpoint, evaluate_endpoint_batch,
};

#[derive(Args, Debug)]
pub(crate) struct EvalArgs {
    /// Policy to evaluate: builtin:oracle (the privileged reference expert), or a policy server
    /// at http://HOST:PORT or https://HOST:PORT (gRPC), or ws://HOST:PORT or wss://HOST:PORT
    /// (openpi WebSocket), run exactly as the server's workers run it.
    #[arg(long, default_value = "builtin:oracle")]
    policy: String,
    /// openpi (`ws://`) endpoints: the key map, inline JSON or a JSON file; without it the
    /// default keys.
    #[arg(long, value_name = "JSON|FILE")]
    key_map: Option<String>,
    /// Endpoint policies: online (SR, the policy drives) or offline (MSE, the expert drives and
    /// the policy predicts).
    #[arg(long, default_value = "online")]
    mode: Mode,
    /// Bearer token the policy server expects.
    #[arg(
        long,
        env = "KITCHEN_R_POLICY_TOKEN",
        value_name = "T",
        hide_env_values = true
    )]
    token: Option<String>,
    /// Endpoint policies: send privileged world state, as organiser reference runs do (for
    /// reference policies such as `kitchen-r policy oracle`; participants' runs never get it).
    /// Not the privileged track: a policy that asks for privileged observations in GetSpec gets
    /// them (as on a server running the track) and the report says `observations privileged`.
    #[arg(long)]
    privileged: bool,
    /// Instruction split: dev (public plans) or test (needs --ground-truth).
    #[arg(long, default_value = "dev")]
    split: Split,
    /// Evaluate the first N instructions of the split (or episodes of --episodes-file)
    /// [default: all].
    #[arg(long)]
    episodes: Option<usize>,
    /// Run exactly the episodes of a saved batch (`kitchen-r episodes generate`) instead of one
    /// per split instruction.
    #[arg(long, value_name = "FILE", conflicts_with = "ground_truth")]
    episodes_file: Option<PathBuf>,
    /// Print one JSON object (with every episode's outcome) instead of the table.
    #[arg(long)]
    json: bool,
    /// Run seed: robot starts and background objects derive from it and each instruction id
    /// (a batch from --episodes-file keeps its own draws).
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
    /// Write each online episode's video to DIR/<episode key>.mp4, as the server's workers
    /// record it (both cameras at the control rate with the caption bar; H.264 MP4). The built-in
    /// oracle is then served on a loopback port and run through the workers' path.
    #[arg(long, value_name = "DIR")]
    record: Option<PathBuf>,
    /// Write each online episode's trace to DIR/<episode key>.trace.json: the episode's
    /// configuration, the run's settings and every answer of the policy, from which
    /// `kitchen-r replay` reproduces the episode bit for bit (and renders its video) later.
    #[arg(long, value_name = "DIR")]
    trace: Option<PathBuf>,
    /// Grasp mode of every episode: abstract or physical, as a server's `[control] grasp` sets it
    /// for its jobs [default: configs/sim.toml's `[grasp] mode`]. Named in the report.
    #[arg(long, value_name = "MODE")]
    grasp: Option<GraspMode>,
    /// The robot to evaluate with: a URDF or MJCF description (its sidecar beside it) or a
    /// mounting sidecar such as configs/robots/robosuite/panda.toml [default: configs/sim.toml's
    /// `[robot] file`, or KITCHEN_R_ROBOT]; a relative name is relative to the working directory
    #[arg(long, value_name = "FILE")]
    robot: Option<PathBuf>,
    /// Endpoint policies that declare `max_batch` > 1 in GetSpec: the most pending decisions
    /// sent in one ActBatch call; 1 sends every decision as its own Act, to compare
    /// [default: configs/eval.toml's `max_batch`, 64].
    #[arg(long, value_name = "N")]
    max_batch: Option<u32>,
    /// The gather window of batched decisions, milliseconds: how long the oldest pending
    /// decision waits for other episodes' before a partial batch goes
    /// [default: configs/eval.toml's `batch_gather_ms`, 2].
    #[arg(long, value_name = "MS")]
    batch_gather_ms: Option<f64>,
    #[command(flatten)]
    live: crate::live_view::LiveArgs,
}

pub(crate) fn eval(args: EvalArgs) -> anyhow::Result<()> {
    if let Some(file) = &args.robot {
        // Absolute, so the assets directory does not change what a relative name means here.
        let file = std::path::absolute(file).with_context(|| format!("resolving {}", file.display()))?;
        kitchen_r_sim::override_robot(file);
    }
    let config = match &args.config {
        Some(p) => EvalConfig::load(p).with_context(|| format!("reading {}", p.display()))?,
        None => EvalConfig::load_default()?,
    };
    let batch = match &args.episodes_file {
        Some(p) => Some(
            kitchen_r_sim::episode::load_batch(p)
                .with_context(|| format!("reading the episodes file {}", p.display()))?,
        ),
        None => None,
    };
    if kitchen_r_contract::Transport::of(&args.policy).is_some() {
        return eval_endpoint(args, &config, batch);
    }
    let policy: PolicyChoice = args.policy.parse()?;
    if args.record.is_some() {
        // Videos are recorded by the workers' runner: serve the oracle as an endpoint for it.
        let oracle = crate::eval_record::LoopbackOracle::start(args.grasp)?;
        let args = EvalArgs {
            policy: oracle.url().to_string(),
            privileged: true,
            ..args
        };
        return eval_endpoint(args, &config, batch);
    }
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
        trace: args.trace,
        watch: None,
        grasp: args.grasp,
    };
    let view = crate::live_view::LiveView::start(&args.live, &crate::live_view::default_sensors()?)?;
    let opts = EvalOptions {
        watch: view.as_ref().map(|v| v.wrap()),
        ..opts
    };
    let mut done = 0;
    let mut progress = |_, o: &kitchen_r_episode::runner::EpisodeOutcome| {
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
    };
    let report = match &batch {
        Some(b) => evaluate_batch(&opts, b, &mut progress)?,
        None => evaluate(&opts, &mut progress)?,
    };
    if let Some(v) = view {
        v.finish()?;
    }
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        print_table(&report);
    }
    Ok(())
}

fn print_table(r: &EvalReport) {
    println!(
        "policy {}  split {}  episodes {}  seed {}  jobs {}  grasp {}",
        r.policy,
        r.split,
        r.episodes.len(),
        r.seed,
        r.jobs,
        r.grasp_mode
    );
    print_kinds(&r.by_kind, &r.overall);
    println!(
        "mean episode wall time {:.3} s   total wall time {:.1} s",
        r.mean_episode_wall_s, r.total_wall_s
    );
}

/// SR and mean sim time per task kind and overall (`eval`'s table, and `replay`'s).
pub(crate) fn print_kinds(by_kind: &std::collections::BTreeMap<String, Sr>, overall: &Sr) {
    println!(
        "{:<14} {:>6} {:>8} {:>7} {:>15}",
        "task kind", "tasks", "success", "SR", "mean sim time"
    );
    let rows = ["navigation", "manipulation", "pick", "place"]
        .into_iter()
        .filter_map(|k| by_kind.get(k).map(|s| (k, s)))
        .chain(std::iter::once(("overall", overall)));
    for (k, s) in rows {
        println!(
            "{k:<14} {:>6} {:>8} {:>7.3} {:>13.1} s",
            s.tasks, s.succeeded, s.sr, s.mean_task_sim_time
        );
    }
}

/// `--policy http://…` or `ws://…`: every instruction as the job the server would lease for it.
fn eval_endpoint(
    args: EvalArgs,
    config: &EvalConfig,
    batch: Option<Vec<EpisodeConfig>>,
) -> anyhow::Result<()> {
    let ins = match &batch {
        Some(_) => Vec::new(),
        None => instructions(args.split, args.ground_truth.as_ref())?,
    };
    let settings = LocalSettings {
        mode: args.mode,
        seed: args.seed.unwrap_or(config.seed),
        run: config.run_options(),
        teleport_on_failure: config.teleport_on_failure,
        bearer_token: args.token,
        key_map: Some(crate::key_map_arg::text(args.key_map.as_deref())?),
        privileged: args.privileged,
        privileged_observations: None,
        jobs: args
            .jobs
            .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get())),
        record: args.record.clone(),
        trace: args.trace.clone(),
        watch: None,
        grasp: args.grasp,
        max_batch: args.max_batch.unwrap_or(config.max_batch),
        batch_gather_ms: args.batch_gather_ms.unwrap_or(config.batch_gather_ms),
    };
    let view = crate::live_view::LiveView::start(&args.live, &crate::live_view::default_sensors()?)?;
    let settings = LocalSettings {
        watch: view.as_ref().map(|v| v.wrap()),
        ..settings
    };
    for dir in [&args.record, &args.trace].into_iter().flatten() {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let n = args.episodes.unwrap_or(usize::MAX);
    let mut done = 0;
    let mut progress = |e: &LocalEpisode| {
        done += 1;
        if !e.platform_error.is_empty() {
            eprintln!(
                "[{done}] {} {}  platform error: {}",
                e.episode_key, e.scene, e.platform_error
            );
            return;
        }
        let ok = e.tasks.iter().filter(|t| t.success).count();
        let samples: u32 = e.tasks.iter().map(|t| t.mse_samples).sum();
        eprintln!(
            "[{done}] {} {}  {ok}/{} tasks  {samples} MSE samples  wall {:.2} s",
            e.episode_key,
            e.scene,
            e.tasks.len(),
            e.wall_s
        );
        for t in e.tasks.iter().filter(|t| !t.failure_reason.is_empty()) {
            eprintln!("    {:?}: {}", t.step, t.failure_reason);
        }
        crate::eval_record::print_video(e);
        if !e.trace_error.is_empty() {
            eprintln!("    no trace: {}", e.trace_error);
        }
    };
    let report = match &batch {
        Some(b) => {
            let b = &b[..n.min(b.len())];
            evaluate_endpoint_batch(&args.policy, args.split, b, &settings, &mut progress)?
        }
        None => evaluate_endpoint(
            &args.policy,
            args.split,
            &ins[..n.min(ins.len())],
            &settings,
            &mut progress,
        )?,
    };
    if let Some(v) = view {
        v.finish()?;
    }
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        print_local(&report);
    }
    Ok(())
}

fn print_local(r: &LocalReport) {
    println!(
        "policy {}  split {}  mode {:?}  episodes {}  seed {}  jobs {}",
        r.policy,
        r.split,
        r.mode,
        r.episodes.len(),
        r.seed,
        r.jobs
    );
    println!("spec {}", r.spec);
    println!("observations {}", r.observations);
    println!("grasp {}", r.grasp_mode);
    if let Some(o) = &r.overall {
        for (k, s) in r
            .by_kind
            .iter()
            .map(|(k, s)| (k.as_str(), s))
            .chain([("overall", o)])
        {
            println!(
                "{k:<14} {:>6} tasks {:>6} succeeded  SR {:.3}",
                s.tasks, s.succeeded, s.sr
            );
        }
    }
    if let Some(sr) = r.sr {
        println!("SR (mean over episodes of mean SR_j) {sr:.4}");
    }
    if let Some(mse) = r.mse {
        println!("MSE {mse:.6} over {} predictions", r.mse_samples);
    }
    if r.platform_errors > 0 {
        println!(
            "{} episode(s) hit a platform error and are not scored",
            r.platform_errors
        );
    }
    if r.batching.calls > 0 {
        println!(
            "batched decisions {} in {} ActBatch calls (mean batch {:.2})",
            r.batching.decisions, r.batching.calls, r.batching.mean_batch
        );
    }
    println!("total wall time {:.1} s", r.total_wall_s);
    crate::eval_record::print_video_totals(r);
}
