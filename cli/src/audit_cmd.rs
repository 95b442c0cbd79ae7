//! `kitchen-r dataset audit DIR`: the leak and feasibility audit an organiser runs on a test set
//! before a contest. The figures come from `kitchen_r_core::audit`; `--oracle` adds a run of the
//! privileged oracle over every test instruction through `kitchen_r_episode::eval`, the code path
//! of `kitchen-r eval --policy builtin:oracle --ground-truth FILE`.

use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::Args;
use kitchen_r_core::audit::{self, OracleCheck, OracleFailure, Thresholds};
use kitchen_r_core::dataset::Split;
use kitchen_r_episode::eval::{EvalConfig, EvalOptions, PolicyChoice, evaluate};

#[derive(Args, Debug)]
pub(super) struct AuditArgs {
    /// The test set to audit: a directory in the dataset layout (test_ground_truth.jsonl for the
    /// attack EM, shared plans and --oracle; else test.jsonl; manifest.json for its kind).
    #[arg(value_name = "DIR")]
    dir: PathBuf,
    /// Also run the privileged oracle over every test instruction and fail the audit if it cannot
    /// complete one (takes minutes; progress on stderr). Needs test_ground_truth.jsonl.
    #[arg(long)]
    oracle: bool,
    /// Largest acceptable EM of the built-in template-inversion attack (a planner made only of
    /// the public templates, scenes and dev split). Sets in unknown phrasings leave it its
    /// fallback (about 0.68 on sets with the public plan shapes); sets it inverts score about 1.
    #[arg(long, value_name = "F", default_value_t = audit::DEFAULT_MAX_ATTACK_EM)]
    max_attack_em: f64,
    /// Largest acceptable share (0 to 1) of test instructions phrased as a public template
    /// phrasing, as a phrasing abstracted from a dev instruction, or as a dev text verbatim.
    #[arg(long, value_name = "F", default_value_t = audit::DEFAULT_MAX_PUBLIC_PHRASING_SHARE)]
    max_public_phrasing_share: f64,
    /// Largest acceptable number of test instructions whose (scene, plan) pair also occurs in the
    /// public dev split.
    #[arg(long, value_name = "N", default_value_t = audit::DEFAULT_MAX_SHARED_PLANS)]
    max_shared_plans: usize,
    /// Print one JSON object (report, checks, verdict) instead of the summary.
    #[arg(long)]
    json: bool,
    /// The public material the attack may use: the assets directory with templates.toml,
    /// objects.toml, scenes/ and dataset/dev.jsonl [default: the KITCHEN_R_ASSETS lookup, i.e.
    /// the repository's assets].
    #[arg(long, value_name = "DIR")]
    assets: Option<PathBuf>,
    /// --oracle: parallel episodes [default: the number of cores].
    #[arg(long)]
    jobs: Option<usize>,
    /// --oracle: evaluation settings [default: configs/eval.toml].
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
}

pub(super) fn audit(args: AuditArgs) -> anyhow::Result<()> {
    let assets = args
        .assets
        .clone()
        .unwrap_or_else(kitchen_r_core::assets::assets_dir);
    let mut report = audit::audit(&args.dir, &assets)
        .with_context(|| format!("auditing {} against {}", args.dir.display(), assets.display()))?;
    if args.oracle {
        report.oracle = Some(run_oracle(&args)?);
    }
    let thresholds = Thresholds {
        max_attack_em: args.max_attack_em,
        max_public_phrasing_share: args.max_public_phrasing_share,
        max_shared_plans: args.max_shared_plans,
        max_oracle_failures: 0,
    };
    let checks = report.checks(&thresholds);
    let passed = checks.iter().all(|c| c.passed);
    if args.json {
        let out = serde_json::json!({
            "report": report,
            "thresholds": thresholds,
            "checks": checks,
            "passed": passed,
        });
        println!("{out}");
    } else {
        print!("{}", report.render(&checks));
    }
    if !passed {
        let failed: Vec<&str> = checks.iter().filter(|c| !c.passed).map(|c| c.name).collect();
        bail!("audit failed: {}", failed.join(", "));
    }
    Ok(())
}

/// Every test instruction through the privileged oracle; the failed ones with their reasons.
fn run_oracle(args: &AuditArgs) -> anyhow::Result<OracleCheck> {
    let ground_truth = args.dir.join("test_ground_truth.jsonl");
    if !ground_truth.is_file() {
        bail!(
            "--oracle needs the set's ground truth: {} is missing",
            ground_truth.display()
        );
    }
    let config = match &args.config {
        Some(p) => EvalConfig::load(p).with_context(|| format!("reading {}", p.display()))?,
        None => EvalConfig::load_default()?,
    };
    let opts = EvalOptions {
        policy: PolicyChoice::Oracle,
        split: Split::Test,
        episodes: None,
        seed: config.seed,
        jobs: args
            .jobs
            .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get())),
        ground_truth: Some(ground_truth),
        run: config.run_options(),
        trace: None,
        watch: None,
        grasp: None,
    };
    let mut done = 0;
    eprintln!("oracle: running every test instruction ({} jobs)", opts.jobs);
    let report = evaluate(&opts, &mut |_, o| {
        done += 1;
        let ok = o.tasks.iter().filter(|t| t.success).count();
        let verdict = if ok == o.tasks.len() { "ok" } else { "FAILED" };
        eprintln!(
            "[{done}] {} {}  {ok}/{} tasks  {verdict}",
            o.episode_id,
            o.scene,
            o.tasks.len()
        );
    })?;
    let failures = (report.episodes.iter())
        .filter(|e| e.tasks.iter().any(|t| !t.success))
        .map(|e| OracleFailure {
            id: e.episode_id.clone(),
            scene: e.scene.clone(),
            reasons: (e.tasks.iter())
                .filter(|t| !t.success)
                .map(|t| format!("{}: {}", t.step, t.failure.as_deref().unwrap_or("failed")))
                .collect(),
        })
        .collect();
    Ok(OracleCheck {
        episodes: report.episodes.len(),
        failures,
    })
}
