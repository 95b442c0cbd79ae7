//! Local online evaluation (`kitchen-r eval`): one episode per split instruction, each run
//! through [`crate::runner::run_episode`], the same code path the server's workers
//! use, and the paper's SR per task kind and overall with sim and wall times.
//!
//! Episode configurations come from [`EpisodeConfig::from_instruction`] with a seed derived from
//! the run seed and the instruction id, so an instruction gets the same robot start and
//! background objects in every run with the same seed, whatever `--episodes` or `--jobs` are.
//! A saved batch (`--episodes-file`, [`evaluate_batch`]) runs exactly its configurations instead.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use kitchen_r_core::GraspMode;
use kitchen_r_core::dataset::{Instruction, Split, read_jsonl};
use kitchen_r_sim::seeds::instruction_seed;
use kitchen_r_sim::{Assets, EpisodeConfig, EpisodeParams, SensorsConfig, Sim, SimConfig, SimError};
use serde::{Deserialize, Serialize};

use crate::batch::run_batch;
use crate::hooks::WrapHook;
use crate::oracle::{ORACLE_NAME, OraclePolicy};
use crate::runner::{EpisodeOutcome, RunError, RunOptions, run_episode};
use crate::sim_slot::load;
use crate::trace::{self, TracingPolicy};

/// The policies `eval` can run in this build.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum PolicyChoice {
    /// The privileged oracle expert (organiser reference).
    Oracle,
}

/// Every accepted `--policy` value.
pub(crate) const ACCEPTED_POLICIES: &[&str] = &[ORACLE_NAME];

impl std::str::FromStr for PolicyChoice {
    type Err = EvalError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            ORACLE_NAME => Ok(PolicyChoice::Oracle),
            other => Err(EvalError::UnknownPolicy(other.to_string())),
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    #[error(
        "unknown policy {0:?}; accepted values: {list}, http://HOST:PORT, https://HOST:PORT",
        list = ACCEPTED_POLICIES.join(", ")
    )]
    UnknownPolicy(String),
    #[error(
        "the test split's plans are not public: pass the organiser's ground-truth file with \
         --ground-truth FILE (test_ground_truth.jsonl), or submit to the server to be scored on test"
    )]
    NoGroundTruth,
    #[error("dataset: {0}")]
    Content(#[from] kitchen_r_core::ContentError),
    #[error("{0}")]
    Sim(#[from] SimError),
    #[error("{0}")]
    Run(#[from] RunError),
    #[error("eval config: {0}")]
    Config(String),
    /// `--trace DIR`: a trace could not be written.
    #[error("{0}")]
    Trace(String),
    #[error("an evaluation thread panicked")]
    Panicked,
}

#[derive(Debug, Clone, PartialEq)]
pub struct EvalOptions {
    pub policy: PolicyChoice,
    pub split: Split,
    /// Evaluate the first N instructions of the split; `None` = all.
    pub episodes: Option<usize>,
    pub seed: u64,
    /// Parallel episodes (each thread owns a simulator).
    pub jobs: usize,
    /// Ground truth for the test split (JSON Lines of instructions with plans).
    pub ground_truth: Option<PathBuf>,
    pub run: RunOptions,
    /// `eval --trace DIR`: write each episode's trace ([`crate::trace`]) to
    /// `DIR/<episode key>.trace.json`.
    pub trace: Option<PathBuf>,
    /// `eval --foxglove`: the hook each episode also runs with (a live view).
    pub watch: Option<WrapHook>,
    /// `eval --grasp`: the simulator's grasp mode; `None` = configs/sim.toml's `[grasp] mode`.
    pub grasp: Option<GraspMode>,
}

impl Default for EvalOptions {
    fn default() -> Self {
        EvalOptions {
            policy: PolicyChoice::Oracle,
            split: Split::Dev,
            episodes: None,
            seed: 0,
            jobs: 1,
            ground_truth: None,
            run: RunOptions::default(),
            trace: None,
            watch: None,
            grasp: None,
        }
    }
}

/// `configs/eval.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EvalConfig {
    /// Sim seconds each plan step may take (the paper: 120).
    pub task_time_limit: f64,
    /// Actions of each chunk executed before the policy is asked again.
    pub execute: usize,
    /// Default run seed.
    pub seed: u64,
    /// Endpoint runs (`--policy http://…`): after a failed task, teleport to the expert's state
    /// at the start of the next one (the server's `control.teleport_on_failure`).
    pub teleport_on_failure: bool,
    /// Execute at most this many plan steps per episode; 0 = all.
    pub max_plan_steps: usize,
    /// Wall-clock budget of one episode, seconds; 0 = none.
    pub episode_budget_s: f64,
    /// Abort an episode after this many successive policy timeouts.
    pub max_successive_timeouts: u32,
    /// Largest |‖q‖ − 1| of an action's quaternion that is normalised (and counted as a
    /// warning) instead of failing the task (the server's `policy.quat_norm_tolerance`).
    pub quat_norm_tolerance: f64,
    /// Largest distance of a gripper value outside [0, 1] that is clamped (and counted) instead
    /// of failing the task (the server's `policy.gripper_margin`).
    pub gripper_margin: f64,
    /// Endpoint runs: the most decisions one ActBatch call carries when the policy declares
    /// `max_batch` > 1 (a worker's `policy.max_batch`); 0 or 1 = Acts only.
    pub max_batch: u32,
    /// Endpoint runs: the gather window of batched decisions, milliseconds (a worker's
    /// `policy.batch_gather_ms`).
    pub batch_gather_ms: f64,
}

impl Default for EvalConfig {
    fn default() -> Self {
        let r = RunOptions::default();
        EvalConfig {
            task_time_limit: r.task_time_limit,
            execute: r.execute,
            seed: 0,
            teleport_on_failure: true,
            max_plan_steps: 0,
            episode_budget_s: 600.0,
            max_successive_timeouts: r.max_consecutive_timeouts,
            quat_norm_tolerance: r.chunk_tolerance.quat_norm,
            gripper_margin: r.chunk_tolerance.gripper_margin,
            max_batch: 64,
            batch_gather_ms: 2.0,
        }
    }
}

impl EvalConfig {
    pub fn load(path: &std::path::Path) -> Result<EvalConfig, EvalError> {
        let bad = |m: String| EvalError::Config(format!("{}: {m}", path.display()));
        let text = std::fs::read_to_string(path).map_err(|e| bad(e.to_string()))?;
        let c: EvalConfig = toml::from_str(&text).map_err(|e| bad(e.to_string()))?;
        if c.task_time_limit.is_nan()
            || c.task_time_limit <= 0.0
            || c.execute == 0
            || c.execute > crate::policy::HORIZON
            || c.episode_budget_s.is_nan()
            || c.episode_budget_s < 0.0
        {
            return Err(bad(format!(
                "task_time_limit > 0, execute in 1..={} and episode_budget_s >= 0",
                crate::policy::HORIZON
            )));
        }
        c.chunk_tolerance().validate().map_err(bad)?;
        Ok(c)
    }

    /// `configs/eval.toml` when present, else the defaults.
    pub fn load_default() -> Result<EvalConfig, EvalError> {
        let path = kitchen_r_sim::config::configs_dir().join("eval.toml");
        if path.is_file() {
            EvalConfig::load(&path)
        } else {
            Ok(EvalConfig::default())
        }
    }

    fn chunk_tolerance(&self) -> crate::policy::ChunkTolerance {
        crate::policy::ChunkTolerance {
            quat_norm: self.quat_norm_tolerance,
            gripper_margin: self.gripper_margin,
        }
    }

    pub fn run_options(&self) -> RunOptions {
        RunOptions {
            chunk_tolerance: self.chunk_tolerance(),
            task_time_limit: self.task_time_limit,
            execute: self.execute,
            max_tasks: (self.max_plan_steps > 0).then_some(self.max_plan_steps),
            max_consecutive_timeouts: self.max_successive_timeouts.max(1),
            wall_budget: (self.episode_budget_s > 0.0)
                .then(|| std::time::Duration::from_secs_f64(self.episode_budget_s)),
            ..RunOptions::default()
        }
    }
}

/// SR and mean sim time over a set of tasks.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Sr {
    pub tasks: usize,
    pub succeeded: usize,
    pub sr: f64,
    /// Mean sim seconds per task (to success, or until failing).
    pub mean_task_sim_time: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EvalReport {
    pub policy: String,
    pub split: Split,
    pub seed: u64,
    pub overall: Sr,
    /// `navigation`, `manipulation`, `pick`, `place`.
    pub by_kind: BTreeMap<String, Sr>,
    pub mean_episode_wall_s: f64,
    pub total_wall_s: f64,
    pub jobs: usize,
    /// The grasp mode the episodes ran in (`abstract` or `physical`): part of what SR means.
    /// Absent from reports written before it existed (abstract).
    #[serde(default)]
    pub grasp_mode: GraspMode,
    pub episodes: Vec<EpisodeOutcome>,
}

/// The kinds a plan step counts under (none for a step that is not canonical).
pub fn task_kinds(step: &str) -> &'static [&'static str] {
    use kitchen_r_core::plan::Step;
    match step.parse::<Step>() {
        Ok(Step::MoveTo { .. }) => &["navigation"],
        Ok(Step::Pick { .. }) => &["manipulation", "pick"],
        Ok(Step::Place { .. }) => &["manipulation", "place"],
        Err(_) => &[],
    }
}

/// The instructions of `split` with their plans.
pub fn instructions(split: Split, ground_truth: Option<&PathBuf>) -> Result<Vec<Instruction>, EvalError> {
    match (split, ground_truth) {
        (_, Some(path)) => Ok(read_jsonl(path)?),
        (Split::Dev, None) => Ok(read_jsonl(
            &kitchen_r_core::assets::assets_dir().join("dataset/dev.jsonl"),
        )?),
        (Split::Test, None) => Err(EvalError::NoGroundTruth),
    }
}

/// One episode configuration per instruction (the first `n`, if given).
pub fn episode_configs(
    assets: &Assets,
    instructions: &[Instruction],
    seed: u64,
    n: Option<usize>,
) -> Result<Vec<EpisodeConfig>, EvalError> {
    let params = EpisodeParams::load_default()?;
    instructions
        .iter()
        .take(n.unwrap_or(usize::MAX))
        .map(|ins| {
            let scene = assets.scene(&ins.scene)?;
            let s = instruction_seed(seed, &ins.id);
            Ok(EpisodeConfig::from_instruction(
                ins,
                scene,
                &assets.catalogue,
                &params,
                s,
            )?)
        })
        .collect()
}

/// Run `configs` over `jobs` threads; `progress(index, outcome)` is called on the calling
/// thread as each episode finishes. Outcomes come back in config order.
#[allow(clippy::too_many_arguments)]
pub(crate) fn run_all(
    assets: &Assets,
    configs: &[EpisodeConfig],
    policy: PolicyChoice,
    run: &RunOptions,
    jobs: usize,
    sim_cfg: &SimConfig,
    (trace, watch): (Option<&Path>, Option<&WrapHook>),
    progress: &mut dyn FnMut(usize, &EpisodeOutcome),
) -> Result<Vec<EpisodeOutcome>, EvalError> {
    let mut run = run.clone();
    run.privileged = policy == PolicyChoice::Oracle;
    let sensors = SensorsConfig::load_default()?;
    let mut out: Vec<Option<EpisodeOutcome>> = vec![None; configs.len()];
    let world = (assets, sim_cfg, &sensors);
    run_batch(
        configs.len(),
        jobs,
        || {
            (
                OraclePolicy::new(assets).with_grasp_mode(sim_cfg.grasp.mode),
                None::<Sim>,
            )
        },
        |(oracle, sim), i| one(world, sim, &configs[i], oracle, &run, (trace, watch)),
        |i, r| {
            let o = r?;
            progress(i, &o);
            out[i] = Some(o);
            Ok::<(), EvalError>(())
        },
    )?;
    out.into_iter().map(|o| o.ok_or(EvalError::Panicked)).collect()
}

/// What every episode of a run is built from: assets and the simulator's configs.
type World<'a> = (&'a Assets, &'a SimConfig, &'a SensorsConfig);

fn one(
    (assets, sim_cfg, sensors): World<'_>,
    sim: &mut Option<Sim>,
    cfg: &EpisodeConfig,
    policy: &mut OraclePolicy,
    run: &RunOptions,
    (trace, watch): (Option<&Path>, Option<&WrapHook>),
) -> Result<EpisodeOutcome, EvalError> {
    let started = Instant::now();
    let s = load(sim, assets, sim_cfg, sensors, cfg)?;
    let mut o = match trace {
        None => WrapHook::around(watch, &mut (), |h| run_episode(s, policy, run, None, h))?,
        Some(dir) => {
            let mut tracing = TracingPolicy::new(policy);
            let o = WrapHook::around(watch, &mut (), |h| run_episode(s, &mut tracing, run, None, h))?;
            let path = dir.join(trace::file_name(&cfg.id));
            tracing
                .into_trace(cfg.clone(), run, sim_cfg.grasp.mode, false, &o)
                .save(&path)
                .map_err(EvalError::Trace)?;
            o
        }
    };
    // Count the reset (world build) in the episode's wall time too.
    o.wall_time_s = started.elapsed().as_secs_f64();
    Ok(o)
}

/// Aggregate outcomes into SR per kind and overall.
pub fn summarize(episodes: &[EpisodeOutcome]) -> (Sr, BTreeMap<String, Sr>) {
    let mut kinds: BTreeMap<String, (usize, usize, f64)> = BTreeMap::new();
    let mut all = (0, 0, 0.0);
    for t in episodes.iter().flat_map(|e| &e.tasks) {
        for k in task_kinds(&t.step) {
            let e = kinds.entry((*k).to_string()).or_default();
            *e = (e.0 + 1, e.1 + usize::from(t.success), e.2 + t.sim_time);
        }
        all = (all.0 + 1, all.1 + usize::from(t.success), all.2 + t.sim_time);
    }
    let sr = |(n, ok, time): (usize, usize, f64)| Sr {
        tasks: n,
        succeeded: ok,
        sr: if n == 0 { 0.0 } else { ok as f64 / n as f64 },
        mean_task_sim_time: if n == 0 { 0.0 } else { time / n as f64 },
    };
    (sr(all), kinds.into_iter().map(|(k, v)| (k, sr(v))).collect())
}

/// The whole `kitchen-r eval` run.
pub fn evaluate(
    opts: &EvalOptions,
    progress: &mut dyn FnMut(usize, &EpisodeOutcome),
) -> Result<EvalReport, EvalError> {
    let assets = Assets::load_default()?;
    let ins = instructions(opts.split, opts.ground_truth.as_ref())?;
    let configs = episode_configs(&assets, &ins, opts.seed, opts.episodes)?;
    evaluate_configs(&assets, opts, &configs, progress)
}

/// `kitchen-r eval --episodes-file`: exactly the episodes of a saved batch (the first
/// `opts.episodes`, if given), in its order; `opts.split` and `opts.seed` only label the report.
pub fn evaluate_batch(
    opts: &EvalOptions,
    batch: &[EpisodeConfig],
    progress: &mut dyn FnMut(usize, &EpisodeOutcome),
) -> Result<EvalReport, EvalError> {
    let assets = Assets::load_default()?;
    let configs = &batch[..opts.episodes.unwrap_or(usize::MAX).min(batch.len())];
    for cfg in configs {
        cfg.validate(assets.scene(&cfg.scene)?, &assets.catalogue)
            .map_err(|e| EvalError::Config(format!("batch episode {:?}: {e}", cfg.id)))?;
    }
    evaluate_configs(&assets, opts, configs, progress)
}

fn evaluate_configs(
    assets: &Assets,
    opts: &EvalOptions,
    configs: &[EpisodeConfig],
    progress: &mut dyn FnMut(usize, &EpisodeOutcome),
) -> Result<EvalReport, EvalError> {
    let started = Instant::now();
    if let Some(dir) = &opts.trace {
        std::fs::create_dir_all(dir)
            .map_err(|e| EvalError::Trace(format!("creating {}: {e}", dir.display())))?;
    }
    let trace = opts.trace.as_deref();
    let mut sim_cfg = SimConfig::load_default()?;
    if let Some(g) = opts.grasp {
        sim_cfg.grasp.mode = g;
    }
    let episodes = run_all(
        assets,
        configs,
        opts.policy,
        &opts.run,
        opts.jobs,
        &sim_cfg,
        (trace, opts.watch.as_ref()),
        progress,
    )?;
    let (overall, by_kind) = summarize(&episodes);
    let n = episodes.len().max(1) as f64;
    Ok(EvalReport {
        policy: ORACLE_NAME.to_string(),
        split: opts.split,
        seed: opts.seed,
        overall,
        by_kind,
        mean_episode_wall_s: episodes.iter().map(|e| e.wall_time_s).sum::<f64>() / n,
        total_wall_s: started.elapsed().as_secs_f64(),
        jobs: opts.jobs,
        grasp_mode: sim_cfg.grasp.mode,
        episodes,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_eval_config_documents_exactly_the_defaults_and_tolerances_reach_the_runner() {
        let file = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/eval.toml");
        let shipped = EvalConfig::load(&file).unwrap();
        assert_eq!(shipped, EvalConfig::default());
        let path = std::env::temp_dir().join(format!("kitchen-r-eval-{}.toml", std::process::id()));
        std::fs::write(&path, "quat_norm_tolerance = 0.0\ngripper_margin = 0.2\n").unwrap();
        let run = EvalConfig::load(&path).unwrap().run_options();
        assert_eq!(
            (run.chunk_tolerance.quat_norm, run.chunk_tolerance.gripper_margin),
            (0.0, 0.2)
        );
        std::fs::write(&path, "gripper_margin = 1.5\n").unwrap();
        let err = EvalConfig::load(&path).unwrap_err().to_string();
        let _ = std::fs::remove_file(&path);
        assert!(err.contains("gripper_margin"), "{err}");
    }
}
