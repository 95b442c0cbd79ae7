//! `kitchen-r dataset audit DIR`: the leak and feasibility audit an organiser runs on a test set
//! before a contest. The figures come from `kitchen_r_core::audit`; `--oracle` adds a run of the
//! privileged oracle over every test instruction through `kitchen_r_episode::eval`, the code path
//! of `kitchen-r eval --policy builtin:oracle --ground-truth FILE`. The starter kit's parser is
//! Python: the audit runs `starter-kit/baselines/planner/plan_file.py` with `python3` on the
//! set's instructions and the scenes' briefs (as the server serves them) and says so in the
//! report, or scores a plan file given with `--parser-plans`; without python3 it says why the
//! figure is missing rather than failing.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Context, bail};
use clap::Args;
use kitchen_r_core::audit::{self, OracleCheck, OracleFailure, Thresholds};
use kitchen_r_core::catalogue::Catalogue;
use kitchen_r_core::dataset::{Split, read_jsonl};
use kitchen_r_core::scene::Scene;
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
    /// Largest acceptable EM of the bag-of-mentions guess (the attack's fallback alone: the
    /// mentioned objects and places, in order, in the most common public plan shape).
    #[arg(long, value_name = "F", default_value_t = audit::DEFAULT_MAX_BAG_OF_MENTIONS_EM)]
    max_bag_of_mentions_em: f64,
    /// Largest acceptable EM of the starter kit's rule-based parser (checked when it ran).
    #[arg(long, value_name = "F", default_value_t = audit::DEFAULT_MAX_PARSER_EM)]
    max_parser_em: f64,
    /// Score this plan file (JSON Lines `{"id", "plan"}`, e.g. from
    /// `starter-kit/baselines/planner/plan_file.py`) as the starter kit's parser instead of
    /// running it.
    #[arg(long, value_name = "FILE", conflicts_with = "no_parser")]
    parser_plans: Option<PathBuf>,
    /// Do not run the starter kit's parser. By default the audit runs it when `python3` is on
    /// PATH and the planner folder is found, and says so; otherwise it reports why not.
    #[arg(long)]
    no_parser: bool,
    /// The starter kit's planner folder (holding plan_file.py) [default:
    /// starter-kit/baselines/planner beside the assets directory].
    #[arg(long, value_name = "DIR")]
    planner: Option<PathBuf>,
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
    if report.ground_truth {
        let (plans, note) = parser_plans(&args, &assets)?;
        report.parser = match plans {
            Some(plans) => audit::score_plans(&args.dir, &plans)?,
            None => None,
        };
        report.parser_note = Some(note);
    }
    if args.oracle {
        report.oracle = Some(run_oracle(&args)?);
    }
    let thresholds = Thresholds {
        max_attack_em: args.max_attack_em,
        max_public_phrasing_share: args.max_public_phrasing_share,
        max_shared_plans: args.max_shared_plans,
        max_oracle_failures: 0,
        max_bag_of_mentions_em: args.max_bag_of_mentions_em,
        max_parser_em: args.max_parser_em,
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

/// Plans by instruction id.
type Plans = HashMap<String, Vec<String>>;

/// The starter kit's parser's plans for the test split, and how they were got (or why not).
fn parser_plans(args: &AuditArgs, assets: &Path) -> anyhow::Result<(Option<Plans>, String)> {
    if let Some(file) = &args.parser_plans {
        let plans = read_plans(file)?;
        return Ok((Some(plans), format!("plans read from {}", file.display())));
    }
    if args.no_parser {
        return Ok((None, "--no-parser".into()));
    }
    let planner = (args.planner.clone()).unwrap_or_else(|| assets.join("../starter-kit/baselines/planner"));
    let script = planner.join("plan_file.py");
    let script = script.canonicalize().unwrap_or(script);
    if !script.is_file() {
        return Ok((
            None,
            format!(
                "{} not found (--planner DIR names the starter kit's planner folder)",
                script.display()
            ),
        ));
    }
    let instructions = ["test.jsonl", "test_ground_truth.jsonl"]
        .map(|f| args.dir.join(f))
        .into_iter()
        .find(|p| p.is_file())
        .context("the set has no test.jsonl")?;
    let scratch = tempfile::tempdir().context("a scratch folder for the parser")?;
    let briefs = scratch.path().join("briefs");
    std::fs::create_dir(&briefs)?;
    let catalogue = Catalogue::load(&assets.join("objects.toml"))?;
    for scene in Scene::load_all(&assets.join("scenes"), &catalogue)? {
        std::fs::write(briefs.join(format!("{}.txt", scene.id)), scene.planner_brief())?;
    }
    let out = scratch.path().join("plans.jsonl");
    let started = std::time::Instant::now();
    let run = Command::new("python3")
        .arg(&script)
        .arg("--instructions")
        .arg(&instructions)
        .arg("--briefs")
        .arg(&briefs)
        .arg("--out")
        .arg(&out)
        .output();
    let run = match run {
        Ok(run) => run,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Ok((
                None,
                "python3 is not on PATH (or give --parser-plans FILE)".into(),
            ));
        }
        Err(e) => return Err(e).context("running python3"),
    };
    if !run.status.success() {
        bail!(
            "the starter kit's parser failed ({}): {}",
            script.display(),
            String::from_utf8_lossy(&run.stderr).trim()
        );
    }
    let note = format!(
        "ran python3 {} in {:.1} s",
        script.display(),
        started.elapsed().as_secs_f64()
    );
    Ok((Some(read_plans(&out)?), note))
}

/// A plan file: JSON Lines `{"id": ..., "plan": [...]}`.
fn read_plans(path: &Path) -> anyhow::Result<HashMap<String, Vec<String>>> {
    #[derive(serde::Deserialize)]
    struct Line {
        id: String,
        plan: Vec<String>,
    }
    let lines: Vec<Line> = read_jsonl(path).with_context(|| format!("reading plans {}", path.display()))?;
    Ok(lines.into_iter().map(|l| (l.id, l.plan)).collect())
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
