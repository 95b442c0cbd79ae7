//! `kitchen-r eval --policy http://HOST:PORT`: local evaluation of a policy endpoint through the
//! workers' own path. Each instruction becomes the job the server would lease for it (same run
//! seed, same settings, same episode key) and runs through [`execute_job`], so the numbers a
//! participant gets here are the numbers the leaderboard will show for the same settings.
//!
//! Aggregation follows the server: SR is the mean over episodes of the mean over tasks of SR_j;
//! MSE weights every prediction equally (Σ mse·samples / Σ samples). Episodes that hit a platform
//! error (which the server would retry) are listed and left out of both.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use kitchen_r_core::dataset::{Instruction, Split};
use kitchen_r_proto::worker::v1 as pb;
use serde::{Deserialize, Serialize};

use super::execute::{JobControl, execute_job};
use super::{JobContext, JobError};
use crate::eval::{Sr, task_kinds};
use crate::remote::probe::{ProbeFailure, probe_endpoint};
use crate::remote::{AllowedNetworks, RemoteConfig};
use crate::runner::RunOptions;

/// Server-side settings a local run reproduces (the server's `[control]` and `[policy]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LocalSettings {
    pub mode: Mode,
    pub seed: u64,
    pub run: RunOptions,
    pub teleport_on_failure: bool,
    pub bearer_token: Option<String>,
    /// Organiser reference runs only: hand the policy privileged state.
    pub privileged: bool,
    /// Parallel episodes, capped by the endpoint's announced max concurrency.
    pub jobs: usize,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Mode {
    Online,
    Offline,
}

impl std::str::FromStr for Mode {
    type Err = String;
    fn from_str(s: &str) -> Result<Mode, String> {
        match s {
            "online" => Ok(Mode::Online),
            "offline" => Ok(Mode::Offline),
            o => Err(format!("mode {o:?}: accepted values are online, offline")),
        }
    }
}

/// One task as the server stores it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LocalTask {
    pub index: u32,
    pub step: String,
    pub success: bool,
    pub completion_time_s: f64,
    pub failure_reason: String,
    pub mse: f64,
    pub mse_samples: u32,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LocalEpisode {
    pub episode_key: String,
    pub scene: String,
    pub tasks: Vec<LocalTask>,
    pub platform_error: String,
    pub wall_s: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LocalReport {
    pub policy: String,
    /// The endpoint's one-line GetSpec summary.
    pub spec: String,
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
    pub total_wall_s: f64,
    pub episodes: Vec<LocalEpisode>,
}

#[derive(Debug, thiserror::Error)]
pub enum LocalError {
    #[error("policy endpoint: {0}")]
    Probe(#[from] ProbeFailure),
    #[error(transparent)]
    Job(#[from] JobError),
    #[error("could not start the runtime: {0}")]
    Runtime(String),
}

/// The job the server would lease for `ins` in `s.mode`.
pub fn local_job(ins: &Instruction, url: &str, s: &LocalSettings, remote: &RemoteConfig) -> pb::Job {
    let key = match s.mode {
        Mode::Online => ins.id.clone(),
        Mode::Offline => format!("{}/offline", ins.id),
    };
    pb::Job {
        job_id: 0,
        attempt: 1,
        lease_expires_at_ms: 0,
        run_id: 0,
        episode_key: key,
        episode: Some(pb::EpisodeSpec {
            scene_id: ins.scene.clone(),
            instruction_id: ins.id.clone(),
            plan: ins.plan.clone(),
            seed: s.seed,
            mode: match s.mode {
                Mode::Online => pb::EvalMode::Online,
                Mode::Offline => pb::EvalMode::Offline,
            } as i32,
            task_time_limit_s: s.run.task_time_limit,
            actions_executed_per_chunk: s.run.execute as u32,
            teleport_on_failure: s.teleport_on_failure,
            max_plan_steps: s.run.max_tasks.unwrap_or(0) as u32,
            privileged: s.privileged,
            place_targets: super::spec::place_targets(ins),
            policy_episode_id: String::new(),
        }),
        policy: Some(pb::PolicyEndpoint {
            url: url.to_string(),
            bearer_token: s.bearer_token.clone().unwrap_or_default(),
            call_deadline_ms: (remote.call_deadline_s * 1e3) as u32,
            startup_deadline_ms: (remote.startup_deadline_s * 1e3) as u32,
            episode_budget_ms: s.run.wall_budget.map_or(0, |d| d.as_millis() as u32),
            max_successive_timeouts: s.run.max_consecutive_timeouts,
        }),
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
    let started = Instant::now();
    // The participant's own machine: every address range is theirs to use.
    let remote = RemoteConfig {
        allowed_networks: AllowedNetworks::ALL,
        ..RemoteConfig::default()
    };
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| LocalError::Runtime(e.to_string()))?;
    let probed = rt.block_on(probe_endpoint(
        url,
        s.bearer_token.as_deref(),
        &AllowedNetworks::ALL,
        &remote,
    ))?;
    drop(rt);
    let ctx = JobContext::load(remote.clone(), AllowedNetworks::ALL, 1)?;
    let jobs: Vec<pb::Job> = instructions
        .iter()
        .map(|i| local_job(i, url, s, &remote))
        .collect();
    let workers = s
        .jobs
        .clamp(1, probed.max_concurrency.max(1) as usize)
        .min(jobs.len().max(1));
    let next = AtomicUsize::new(0);
    let (tx, rx) = std::sync::mpsc::channel::<(usize, LocalEpisode)>();
    let mut slots: Vec<Option<LocalEpisode>> = vec![None; jobs.len()];
    std::thread::scope(|scope| {
        for _ in 0..workers {
            let (tx, next, jobs, ctx) = (tx.clone(), &next, &jobs, &ctx);
            scope.spawn(move || {
                loop {
                    let i = next.fetch_add(1, Ordering::SeqCst);
                    let Some(job) = jobs.get(i) else { break };
                    let t = Instant::now();
                    let r = execute_job(job, ctx, &JobControl::default());
                    if tx.send((i, episode(job, &r, t.elapsed().as_secs_f64()))).is_err() {
                        break;
                    }
                }
            });
        }
        drop(tx);
        for (i, ep) in rx {
            progress(&ep);
            slots[i] = Some(ep);
        }
    });
    let episodes: Vec<LocalEpisode> = slots.into_iter().flatten().collect();
    Ok(report(url, probed.summary, split, s, workers, episodes, started))
}

fn episode(job: &pb::Job, r: &pb::EpisodeResult, wall_s: f64) -> LocalEpisode {
    LocalEpisode {
        episode_key: job.episode_key.clone(),
        scene: job
            .episode
            .as_ref()
            .map(|e| e.scene_id.clone())
            .unwrap_or_default(),
        tasks: r
            .tasks
            .iter()
            .map(|t| LocalTask {
                index: t.index,
                step: t.step.clone(),
                success: t.success,
                completion_time_s: t.completion_time_s,
                failure_reason: t.failure_reason.clone(),
                mse: t.mse,
                mse_samples: t.mse_samples,
            })
            .collect(),
        platform_error: r.platform_error.clone(),
        wall_s,
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
    let per_episode: Vec<f64> = scored
        .iter()
        .filter(|e| !e.tasks.is_empty())
        .map(|e| e.tasks.iter().filter(|t| t.success).count() as f64 / e.tasks.len() as f64)
        .collect();
    let samples: u64 = scored
        .iter()
        .flat_map(|e| &e.tasks)
        .map(|t| u64::from(t.mse_samples))
        .sum();
    let weighted: f64 = scored
        .iter()
        .flat_map(|e| &e.tasks)
        .map(|t| t.mse * f64::from(t.mse_samples))
        .sum();
    LocalReport {
        policy: url.to_string(),
        spec,
        split,
        mode: s.mode,
        seed: s.seed,
        overall: online.then(|| sr(all)),
        by_kind: if online {
            kinds.into_iter().map(|(k, v)| (k, sr(v))).collect()
        } else {
            BTreeMap::new()
        },
        sr: (online && !per_episode.is_empty())
            .then(|| per_episode.iter().sum::<f64>() / per_episode.len() as f64),
        mse: (!online && samples > 0).then(|| weighted / samples as f64),
        mse_samples: samples,
        platform_errors: episodes.len() - scored.len(),
        jobs,
        total_wall_s: started.elapsed().as_secs_f64(),
        episodes,
    }
}
