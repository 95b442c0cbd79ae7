//! `kitchen-r eval --policy http://HOST:PORT` (or `ws://HOST:PORT`, openpi): local evaluation of
//! a policy endpoint through the workers' own path. Each instruction becomes the job the server would lease for it (same run
//! seed, same settings, same episode key) and runs through [`execute_job_traced`], so the numbers a
//! participant gets here are the numbers the leaderboard will show for the same settings.
//!
//! Aggregation is the server's own (`kitchen_r_core::scoring::aggregate`): SR is the mean over
//! episodes of the mean over the plan's tasks of SR_j (an unreported task fails), MSE weights
//! every prediction equally with a failed prediction for a task left without a sample. Episodes
//! that hit a platform error (which the server would retry) are listed and left out.
//!
//! A saved batch of episodes (`eval --episodes-file`) runs through the same jobs: each episode's
//! configuration reaches the job's set-up through the context's episode parameters.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use kitchen_r_core::GraspMode;
use kitchen_r_core::dataset::{Instruction, Split};
pub use kitchen_r_core::scoring::Mode;
use kitchen_r_core::scoring::{self, TaskOutcome};
use kitchen_r_proto::worker::v1 as pb;
use serde::{Deserialize, Serialize};

use super::execute::{JobControl, execute_job_traced};
use super::{JobContext, JobError};
use kitchen_r_contract::probe::{ProbeFailure, probe_endpoint};
use kitchen_r_contract::{AllowedNetworks, BatchStats, RemoteConfig, batch_stats};
pub use kitchen_r_core::observations::ObservationTrack as Track;
use kitchen_r_episode::batch::run_batch;
use kitchen_r_episode::eval::{Sr, task_kinds};
use kitchen_r_episode::policy::PrivilegedScope;
use kitchen_r_episode::runner::RunOptions;
use kitchen_r_episode::trace;
use kitchen_r_proto::convert::EpisodeRules;
use kitchen_r_record::video::episode::RecordedVideo;
use kitchen_r_sim::EpisodeConfig;
use kitchen_r_sim::episode::as_instruction;

/// Server-side settings a local run reproduces (the server's `[control]` and `[policy]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LocalSettings {
    pub mode: Mode,
    pub seed: u64,
    pub run: RunOptions,
    pub teleport_on_failure: bool,
    pub bearer_token: Option<String>,
    /// An openpi endpoint's key map (JSON; empty or absent: the convention). Replaced by the
    /// probe's checked, spelt-out map before the jobs are made, as a server stores it.
    #[serde(default)]
    pub key_map: Option<String>,
    /// Organiser reference runs only: hand the policy privileged state.
    pub privileged: bool,
    /// The privileged track: the scope of the privileged observations every job grants (set
    /// from the endpoint's GetSpec and the split by [`evaluate_endpoint`]); `None` = standard.
    #[serde(default)]
    pub privileged_observations: Option<PrivilegedScope>,
    /// Parallel episodes, capped by the endpoint's announced max concurrency.
    pub jobs: usize,
    /// `eval --record DIR`: write each online episode's video, as the workers record it, to
    /// `DIR/<episode key>.mp4`.
    #[serde(default)]
    pub record: Option<PathBuf>,
    /// `eval --trace DIR`: write each online episode's trace (what reproduces it for a later
    /// video, `kitchen_r_episode::trace`) to `DIR/<episode key>.trace.json`.
    #[serde(default)]
    pub trace: Option<PathBuf>,
    /// `eval --foxglove`: the live view each online episode also runs with.
    #[serde(skip)]
    pub watch: Option<kitchen_r_episode::hooks::WrapHook>,
    /// `eval --grasp`: the grasp mode every job carries, as a server's `[control] grasp` does;
    /// `None` = configs/sim.toml's `[grasp] mode`.
    #[serde(default)]
    pub grasp: Option<GraspMode>,
    /// Batched decisions (`policy.max_batch` of a worker): the most decisions per ActBatch
    /// call from this side; 0 or 1 = Acts only, whatever the policy declares.
    #[serde(default = "default_max_batch")]
    pub max_batch: u32,
    /// The gather window of batched decisions, milliseconds (`policy.batch_gather_ms`).
    #[serde(default = "default_gather_ms")]
    pub batch_gather_ms: f64,
}

fn default_max_batch() -> u32 {
    RemoteConfig::default().max_batch
}

fn default_gather_ms() -> f64 {
    RemoteConfig::default().batch_gather_ms
}

impl LocalSettings {
    /// How every job of this run is run and scored, as a server's job would carry it.
    fn rules(&self) -> EpisodeRules {
        EpisodeRules {
            seed: self.seed,
            mode: self.mode,
            task_time_limit_s: self.run.task_time_limit,
            actions_executed_per_chunk: self.run.execute as u32,
            teleport_on_failure: self.teleport_on_failure,
            max_plan_steps: self.run.max_tasks.unwrap_or(0) as u32,
            privileged: self.privileged,
            privileged_observations: self.privileged_observations,
            grasp: self.grasp.unwrap_or_default(),
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LocalEpisode {
    pub episode_key: String,
    pub scene: String,
    /// The tasks as the server would store them.
    pub tasks: Vec<TaskOutcome>,
    pub platform_error: String,
    pub wall_s: f64,
    /// `--record`: the episode video written, and what it cost.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub video: Option<LocalVideo>,
    /// `--record`: why the video could not be written (the episode's result is not affected).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub video_error: String,
    /// `--trace`: the trace file written.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trace: Option<PathBuf>,
    /// `--trace`: why no trace was written (the episode's result is not affected).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub trace_error: String,
    /// What scoring needs of the job (not printed).
    #[serde(skip)]
    pub scoring: Option<scoring::Episode>,
}

/// One episode video written by `eval --record`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LocalVideo {
    pub path: PathBuf,
    pub bytes: u64,
    pub frames: usize,
    /// Composing the frames and encoding them (rendering the cameras is the simulator's).
    pub encode_s: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LocalReport {
    pub policy: String,
    /// The endpoint's one-line GetSpec summary.
    pub spec: String,
    /// `standard`, or `privileged` when the policy asked for privileged observations in
    /// GetSpec and got them: the leaderboard ranks such runs apart.
    pub observations: Track,
    pub split: Split,
    pub mode: Mode,
    pub seed: u64,
    /// Online: SR over all tasks and per task kind.
    pub overall: Option<Sr>,
    pub by_kind: BTreeMap<String, Sr>,
    /// Online: mean over episodes of the mean SR_j (the leaderboard's SR).
    pub sr: Option<f64>,
    /// Offline: Σ mse·samples / Σ samples.
    pub mse: Option<f64>,
    pub mse_samples: u64,
    pub platform_errors: usize,
    pub jobs: usize,
    /// The grasp mode the episodes ran in (`abstract` or `physical`): part of what SR means.
    #[serde(default)]
    pub grasp_mode: GraspMode,
    pub total_wall_s: f64,
    /// How the decisions went out: ActBatch calls and the decisions they carried (both 0 when
    /// every decision was its own Act).
    #[serde(default)]
    pub batching: Batching,
    pub episodes: Vec<LocalEpisode>,
}

/// The ActBatch calls of a local run.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Batching {
    pub calls: u64,
    pub decisions: u64,
    /// Decisions per call, on average (0 without calls).
    pub mean_batch: f64,
}

impl Batching {
    fn between(before: BatchStats, after: BatchStats) -> Batching {
        let calls = after.calls - before.calls;
        let decisions = after.decisions - before.decisions;
        Batching {
            calls,
            decisions,
            mean_batch: if calls == 0 {
                0.0
            } else {
                decisions as f64 / calls as f64
            },
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum LocalError {
    #[error("policy endpoint: {0}")]
    Probe(#[from] ProbeFailure),
    #[error(transparent)]
    Job(#[from] JobError),
    #[error("could not start the runtime: {0}")]
    Runtime(String),
    #[error("episodes file: {0}")]
    Batch(String),
}

/// The job the server would lease for `ins` in `s.mode`.
pub(crate) fn local_job(ins: &Instruction, url: &str, s: &LocalSettings, remote: &RemoteConfig) -> pb::Job {
    let key = s.mode.episode_key(&ins.id);
    pb::Job {
        job_id: 0,
        attempt: 1,
        lease_expires_at_ms: 0,
        run_id: 0,
        episode_key: key,
        episode: Some(pb::EpisodeSpec {
            record_video: s.record.is_some(),
            ..pb::EpisodeSpec::build(&ins.scene, &ins.id, &ins.plan, &ins.place_targets, &s.rules())
        }),
        policy: Some(pb::PolicyEndpoint {
            url: url.to_string(),
            bearer_token: s.bearer_token.clone().unwrap_or_default(),
            call_deadline_ms: (remote.call_deadline_s * 1e3) as u32,
            startup_deadline_ms: (remote.startup_deadline_s * 1e3) as u32,
            episode_budget_ms: s.run.wall_budget.map_or(0, |d| d.as_millis() as u32),
            max_successive_timeouts: s.run.max_consecutive_timeouts,
            min_actions_executed_per_chunk: remote.min_actions_executed_per_chunk,
            quat_norm_tolerance: Some(s.run.chunk_tolerance.quat_norm),
            gripper_margin: Some(s.run.chunk_tolerance.gripper_margin),
            key_map: s.key_map.clone().unwrap_or_default(),
        }),
        render: None,
    }
}

/// Evaluate the endpoint at `url` on `instructions`; `progress` sees each episode as it ends.
pub fn evaluate_endpoint(
    url: &str,
    split: Split,
    instructions: &[Instruction],
    s: &LocalSettings,
    progress: &mut dyn FnMut(&LocalEpisode),
) -> Result<LocalReport, LocalError> {
    evaluate_endpoint_with(url, split, instructions, None, s, progress)
}

/// Evaluate the endpoint at `url` on exactly the episodes of a saved batch
/// (`eval --episodes-file`). Each episode runs as the job of the instruction its task amounts to
/// ([`as_instruction`]), and the job's episode set-up returns the batch's configuration for it
/// (`EpisodeParams::batch`) instead of drawing one: the rest is the workers' path unchanged.
pub fn evaluate_endpoint_batch(
    url: &str,
    split: Split,
    batch: &[EpisodeConfig],
    s: &LocalSettings,
    progress: &mut dyn FnMut(&LocalEpisode),
) -> Result<LocalReport, LocalError> {
    let instructions: Vec<Instruction> = batch.iter().map(as_instruction).collect();
    let by_id: BTreeMap<String, EpisodeConfig> = batch.iter().map(|c| (c.id.clone(), c.clone())).collect();
    if by_id.len() != batch.len() {
        return Err(LocalError::Batch("the batch has two episodes with one id".into()));
    }
    evaluate_endpoint_with(url, split, &instructions, Some(Arc::new(by_id)), s, progress)
}

fn evaluate_endpoint_with(
    url: &str,
    split: Split,
    instructions: &[Instruction],
    batch: Option<Arc<BTreeMap<String, EpisodeConfig>>>,
    s: &LocalSettings,
    progress: &mut dyn FnMut(&LocalEpisode),
) -> Result<LocalReport, LocalError> {
    let started = Instant::now();
    // The participant's own machine: every address range is theirs to use, and the privileged
    // track is offered (the policy's GetSpec decides, as at registration on a server running it).
    let remote = RemoteConfig {
        allowed_networks: AllowedNetworks::ALL,
        privileged_track: true,
        max_batch: s.max_batch,
        batch_gather_ms: s.batch_gather_ms,
        ..RemoteConfig::default()
    };
    let batched_before = batch_stats();
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| LocalError::Runtime(e.to_string()))?;
    let probed = rt.block_on(probe_endpoint(
        url,
        s.bearer_token.as_deref(),
        s.key_map.as_deref().unwrap_or_default(),
        &AllowedNetworks::ALL,
        &remote,
    ))?;
    drop(rt);
    let mut ctx = JobContext::load(remote.clone(), AllowedNetworks::ALL, 1)?;
    let s = &LocalSettings {
        privileged_observations: (s.privileged_observations).or(probed
            .privileged_observations
            .then(|| PrivilegedScope::for_split(split))),
        // The jobs carry the mode, as a server's do; sim.toml's unless asked for another.
        grasp: Some(s.grasp.unwrap_or(ctx.sim.grasp.mode)),
        key_map: probed.key_map.clone(),
        ..s.clone()
    };
    ctx.params.batch = batch;
    ctx.watch = s.watch.clone();
    let jobs: Vec<pb::Job> = instructions
        .iter()
        .map(|i| local_job(i, url, s, &remote))
        .collect();
    let workers = s
        .jobs
        .clamp(1, probed.max_concurrency.max(1) as usize)
        .min(jobs.len().max(1));
    let mut slots: Vec<Option<LocalEpisode>> = vec![None; jobs.len()];
    let ran = run_batch(
        jobs.len(),
        workers,
        || (),
        |(), i| {
            let job = &jobs[i];
            let t = Instant::now();
            let done = execute_job_traced(job, &ctx, &JobControl::default(), s.trace.is_some());
            let (r, video) = (&done.result, done.video);
            let mut ep = episode(job, r, t.elapsed().as_secs_f64());
            if let (Some(dir), Some(trace)) = (&s.trace, &done.trace) {
                let path = dir.join(trace::file_name(&job.episode_key));
                match trace.save(&path) {
                    Ok(()) => ep.trace = Some(path),
                    Err(e) => ep.trace_error = e,
                }
            }
            if let (Some(dir), Some(v)) = (&s.record, video) {
                match write_video(dir, &job.episode_key, v) {
                    Ok(v) => ep.video = Some(v),
                    Err(e) => ep.video_error = e,
                }
            }
            ep
        },
        |i, ep| {
            progress(&ep);
            slots[i] = Some(ep);
            Ok::<(), std::convert::Infallible>(())
        },
    );
    let Ok(()) = ran;
    let episodes: Vec<LocalEpisode> = slots.into_iter().flatten().collect();
    let mut r = report(url, probed.summary, split, s, workers, episodes, started);
    r.batching = Batching::between(batched_before, batch_stats());
    Ok(r)
}

fn episode(job: &pb::Job, r: &pb::EpisodeResult, wall_s: f64) -> LocalEpisode {
    let spec = job.episode.clone().unwrap_or_default();
    let tasks: Vec<TaskOutcome> = r.tasks.iter().map(TaskOutcome::from).collect();
    let mode = pb::EvalMode::try_from(spec.mode)
        .ok()
        .and_then(pb::EvalMode::mode)
        .unwrap_or(Mode::Online);
    LocalEpisode {
        episode_key: job.episode_key.clone(),
        scene: spec.scene_id.clone(),
        scoring: Some(scoring::Episode {
            mode,
            instruction_id: spec.instruction_id,
            task_count: scoring::task_count(spec.plan.len(), spec.max_plan_steps),
            plan: spec.plan,
            tasks: tasks.clone(),
            failure: None,
        }),
        tasks,
        platform_error: r.platform_error.clone(),
        wall_s,
        video: None,
        video_error: String::new(),
        trace: None,
        trace_error: String::new(),
    }
}

/// Write `v` as `DIR/<key>.mp4`.
fn write_video(dir: &Path, key: &str, v: RecordedVideo) -> Result<LocalVideo, String> {
    let path = dir.join(format!("{key}.mp4"));
    match std::fs::write(&path, &v.mp4) {
        Ok(()) => Ok(LocalVideo {
            path,
            bytes: v.mp4.len() as u64,
            frames: v.frames,
            encode_s: v.encode_time.as_secs_f64(),
        }),
        Err(e) => Err(format!("writing the video {}: {e}", path.display())),
    }
}

fn report(
    url: &str,
    spec: String,
    split: Split,
    s: &LocalSettings,
    jobs: usize,
    episodes: Vec<LocalEpisode>,
    started: Instant,
) -> LocalReport {
    let scored: Vec<&LocalEpisode> = episodes.iter().filter(|e| e.platform_error.is_empty()).collect();
    let mut kinds: BTreeMap<String, (usize, usize, f64)> = BTreeMap::new();
    let mut all = (0usize, 0usize, 0.0f64);
    for t in scored.iter().flat_map(|e| &e.tasks) {
        for k in std::iter::once("overall").chain(task_kinds(&t.step).iter().copied()) {
            let e = if k == "overall" {
                &mut all
            } else {
                kinds.entry(k.to_string()).or_default()
            };
            *e = (e.0 + 1, e.1 + usize::from(t.success), e.2 + t.completion_time_s);
        }
    }
    let sr = |(n, ok, time): (usize, usize, f64)| Sr {
        tasks: n,
        succeeded: ok,
        sr: if n == 0 { 0.0 } else { ok as f64 / n as f64 },
        mean_task_sim_time: if ok == 0 { 0.0 } else { time / ok as f64 },
    };
    let online = s.mode == Mode::Online;
    let scoring: Vec<scoring::Episode> = scored.iter().filter_map(|e| e.scoring.clone()).collect();
    let scores = scoring::aggregate(&scoring, None);
    LocalReport {
        policy: url.to_string(),
        spec,
        observations: Track::of(s.privileged_observations.is_some()),
        split,
        mode: s.mode,
        seed: s.seed,
        overall: online.then(|| sr(all)),
        by_kind: if online {
            kinds.into_iter().map(|(k, v)| (k, sr(v))).collect()
        } else {
            BTreeMap::new()
        },
        sr: scores.sr,
        mse: scores.mse,
        mse_samples: scoring::mse_sample_count(&scoring),
        platform_errors: episodes.len() - scored.len(),
        jobs,
        grasp_mode: s.grasp.unwrap_or_default(),
        total_wall_s: started.elapsed().as_secs_f64(),
        batching: Batching::default(),
        episodes,
    }
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;

    /// `(plan length, max_plan_steps, reported tasks: (index, success, mse, samples, failed))`.
    type Case = (usize, u32, Vec<(u32, bool, f64, u32, bool)>);

    fn case() -> impl Strategy<Value = Case> {
        (
            4usize..=8,
            0u32..=9,
            prop::collection::vec(
                (0u32..9, any::<bool>(), 0.0f64..4.0, 0u32..5, any::<bool>()),
                0..9,
            ),
        )
    }

    fn settings(mode: Mode) -> LocalSettings {
        LocalSettings {
            mode,
            seed: 0,
            run: RunOptions::default(),
            teleport_on_failure: false,
            bearer_token: None,
            key_map: None,
            privileged: false,
            privileged_observations: None,
            jobs: 1,
            record: None,
            trace: None,
            watch: None,
            grasp: None,
            max_batch: 0,
            batch_gather_ms: 0.0,
        }
    }

    /// The local report of `cases` run in `mode`, and the server's view of the same outcomes
    /// (tasks = the plan's steps capped by `max_plan_steps`, as `JobSpec::task_count` says).
    fn both(mode: Mode, cases: &[Case]) -> (LocalReport, scoring::RunScores) {
        let mut local = Vec::new();
        let mut server = Vec::new();
        for (n, (len, cap, reported)) in cases.iter().enumerate() {
            let ins = Instruction {
                id: format!("dev-{n:04}"),
                scene: "kitchen_a".into(),
                instruction: String::new(),
                plan: (0..*len).map(|j| format!("move to the zone {j}")).collect(),
                template: String::new(),
                place_targets: Vec::new(),
            };
            let s = LocalSettings {
                run: RunOptions {
                    max_tasks: (*cap > 0).then_some(*cap as usize),
                    ..RunOptions::default()
                },
                ..settings(mode)
            };
            let job = local_job(&ins, "http://127.0.0.1:1", &s, &RemoteConfig::default());
            let tasks: Vec<TaskOutcome> = (reported.iter())
                .map(|&(index, success, mse, samples, failed)| TaskOutcome {
                    index,
                    step: String::new(),
                    success: mode == Mode::Online && success,
                    completion_time_s: 1.0,
                    failure_reason: if failed { "bad chunk".into() } else { String::new() },
                    mse: if mode == Mode::Offline { mse } else { 0.0 },
                    mse_samples: if mode == Mode::Offline { samples } else { 0 },
                })
                .collect();
            let result = pb::EpisodeResult {
                tasks: tasks.iter().map(pb::TaskResult::from).collect(),
                ..Default::default()
            };
            local.push(episode(&job, &result, 0.1));
            let task_count = match cap {
                0 => *len,
                c => (*len).min(*c as usize),
            };
            server.push(scoring::Episode {
                mode,
                instruction_id: ins.id.clone(),
                plan: ins.plan.clone(),
                task_count,
                tasks,
                failure: None,
            });
        }
        let r = report(
            "x",
            String::new(),
            Split::Dev,
            &settings(mode),
            1,
            local,
            Instant::now(),
        );
        (r, scoring::aggregate(&server, None))
    }

    proptest! {
        /// Local evaluation gives the leaderboard's numbers on any outcome set, including
        /// episodes that report fewer (or other) tasks than their plan has.
        #[test]
        fn local_eval_and_the_server_aggregate_alike(
            cases in prop::collection::vec(case(), 1..6),
        ) {
            let (online, server) = both(Mode::Online, &cases);
            prop_assert_eq!(online.sr, server.sr);
            let (offline, server) = both(Mode::Offline, &cases);
            prop_assert_eq!(offline.mse, server.mse);
            prop_assert_eq!(offline.sr, None);
        }
    }
}
