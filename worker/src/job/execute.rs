//! One leased job, start to finish: episode set-up, the participant's endpoint, the online or
//! offline run, and the result the server stores.
//!
//! Who pays for a failure decides where it goes: anything the policy does (unreachable, late,
//! bad chunk, refused address) fails tasks with a reason and is scored; anything the platform
//! does (simulator error, a job this worker cannot set up, cancellation, shutdown) is a
//! `platform_error`, which the server retries without charging the participant.

use std::sync::Arc;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::time::Instant;

use kitchen_r_proto::worker::v1 as pb;
use kitchen_r_sim::{Action, EpisodeConfig, Sim, StepInfo};

use super::cores::{Cores, YieldsCore};
use super::path::PathHook;
use super::spec;
use super::{JobContext, JobError};
use kitchen_r_contract::{Credentials, Remote, SimCamera};
use kitchen_r_episode::hooks::WrapHook;
use kitchen_r_episode::offline::{OfflineOutcome, run_offline};
use kitchen_r_episode::oracle::OraclePolicy;
use kitchen_r_episode::policy::{Corrections, Policy, Unreachable};
use kitchen_r_episode::runner::{EpisodeOutcome, StepHook, run_episode};
use kitchen_r_episode::teleport::expert_starts;
use kitchen_r_episode::trace::{Trace, TracingPolicy};
use kitchen_r_record::video::episode::{EpisodeVideo, RecordedVideo, VideoHook};

/// The log tail kept with a result (the contract's cap).
const LOG_CAP: usize = 64 << 10;

/// Shared between a running job and whoever supervises it (heartbeats, shutdown).
#[derive(Debug, Clone, Default)]
pub struct JobControl {
    cancelled: Arc<AtomicBool>,
    why: Arc<Mutex<String>>,
    tasks_done: Arc<AtomicU32>,
    /// The worker's simulation cores; unlimited by default.
    cores: Cores,
}

impl JobControl {
    /// A control whose episode simulates only while it holds one of `cores`.
    pub fn with_cores(cores: Cores) -> JobControl {
        JobControl {
            cores,
            ..JobControl::default()
        }
    }

    /// Stop the episode at its next control step; `why` becomes the platform error.
    pub fn cancel(&self, why: &str) {
        if let Ok(mut w) = self.why.lock()
            && w.is_empty()
        {
            *w = why.to_string();
        }
        self.cancelled.store(true, Ordering::SeqCst);
    }

    pub(crate) fn is_cancelled(&self) -> bool {
        self.cancelled.load(Ordering::SeqCst)
    }

    fn reason(&self) -> String {
        self.why.lock().map(|w| w.clone()).unwrap_or_default()
    }

    /// Tasks finished so far, for heartbeats.
    pub(crate) fn tasks_done(&self) -> u32 {
        self.tasks_done.load(Ordering::Relaxed)
    }
}

/// Aborts the run when cancelled, counts finished tasks.
struct Watch<'a>(&'a JobControl);

impl StepHook for Watch<'_> {
    fn on_step(&mut self, _: &Sim, _: &Action, info: &StepInfo) -> Result<(), String> {
        if let Some(t) = &info.task {
            let done = t.index as u32 + u32::from(t.success);
            self.0.tasks_done.store(done, Ordering::Relaxed);
        }
        if self.0.is_cancelled() {
            return Err(format!("cancelled: {}", self.0.reason()));
        }
        Ok(())
    }
}

/// A bounded log of the episode, sent back as `log_tail`.
#[derive(Default)]
struct Log(String);

impl Log {
    fn line(&mut self, s: impl AsRef<str>) {
        self.0.push_str(s.as_ref());
        self.0.push('\n');
        if self.0.len() > 2 * LOG_CAP {
            self.trim();
        }
    }
    fn trim(&mut self) {
        if self.0.len() > LOG_CAP {
            let mut cut = self.0.len() - LOG_CAP;
            while !self.0.is_char_boundary(cut) {
                cut += 1;
            }
            self.0.drain(..cut);
        }
    }
    fn into_tail(mut self) -> String {
        self.trim();
        self.0
    }
}

/// The id the policy sees: the server's opaque one, or a random one. Unique per job attempt, so
/// a participant's server serving two runs (or a retried attempt) never mixes their state, and
/// it names neither the instruction nor the run: an endpoint that logs its traffic learns nothing
/// it could map back to the hidden test split.
pub(crate) fn policy_episode_id(job: &pb::Job) -> String {
    match job.episode.as_ref().map(|e| e.policy_episode_id.as_str()) {
        Some(id) if !id.is_empty() => id.to_string(),
        _ => random_episode_id(),
    }
}

/// `ep-` and 24 random hex digits.
pub(crate) fn random_episode_id() -> String {
    let bytes: [u8; 12] = rand::random();
    let hex: String = bytes.iter().map(|b| format!("{b:02x}")).collect();
    format!("ep-{hex}")
}

/// Run `job` to its result. Never panics on what the policy does; the simulator is built here
/// (a fresh world per job).
pub fn execute_job(job: &pb::Job, ctx: &JobContext, control: &JobControl) -> pb::EpisodeResult {
    execute_job_recording(job, ctx, control).0
}

/// As [`execute_job`], with the episode video (MP4) when the job asks for one
/// (`record_video`, online episodes). The video never changes the result: a recording that
/// failed is a line in the log tail and no video.
pub fn execute_job_recording(
    job: &pb::Job,
    ctx: &JobContext,
    control: &JobControl,
) -> (pb::EpisodeResult, Option<RecordedVideo>) {
    let e = execute_job_traced(job, ctx, control, false);
    (e.result, e.video)
}

/// What a job left: its result, the episode video if it asked for one, and the trace that
/// reproduces the episode (when asked for: online episodes that ran and were not cancelled;
/// [`Trace`]).
pub struct Executed {
    pub result: pb::EpisodeResult,
    pub video: Option<RecordedVideo>,
    pub trace: Option<Trace>,
}

/// As [`execute_job_recording`]; with `trace`, also the episode's trace (`eval --trace`). Only
/// callers that keep the trace ask for it: recording copies every chunk the policy returns. A
/// job that wants its video on demand (`record_video` and `video_on_demand`) always leaves its
/// trace and no video.
pub fn execute_job_traced(job: &pb::Job, ctx: &JobContext, control: &JobControl, trace: bool) -> Executed {
    let started = Instant::now();
    let mut log = Log::default();
    let result = run(job, ctx, control, trace, &mut log);
    let (mut out, mut video, mut trace) = match result {
        Ok(Ran {
            tasks,
            path,
            video,
            trace,
        }) => (
            pb::EpisodeResult {
                tasks,
                path,
                ..Default::default()
            },
            video,
            trace,
        ),
        Err(e) => {
            log.line(format!("platform error: {e}"));
            let out = pb::EpisodeResult {
                platform_error: e.to_string(),
                ..Default::default()
            };
            (out, None, None)
        }
    };
    // A cancelled episode's tasks were cut short by us, not by the policy: never score them.
    if control.is_cancelled() && out.platform_error.is_empty() {
        out.tasks.clear();
        out.path = None;
        video = None;
        trace = None;
        out.platform_error = format!("cancelled: {}", control.reason());
    }
    out.wall_ms = started.elapsed().as_millis() as u64;
    out.log_tail = log.into_tail();
    Executed {
        result: out,
        video,
        trace,
    }
}

/// What an episode that ran hands back.
struct Ran {
    tasks: Vec<pb::TaskResult>,
    path: Option<pb::EpisodePath>,
    video: Option<RecordedVideo>,
    trace: Option<Trace>,
}

impl Ran {
    fn tasks(tasks: Vec<pb::TaskResult>) -> Ran {
        Ran {
            tasks,
            path: None,
            video: None,
            trace: None,
        }
    }
}

fn run(
    job: &pb::Job,
    ctx: &JobContext,
    control: &JobControl,
    trace: bool,
    log: &mut Log,
) -> Result<Ran, JobError> {
    let spec = job
        .episode
        .as_ref()
        .ok_or_else(|| JobError::Spec("the job has no episode".into()))?;
    let ep = job.policy.clone().unwrap_or_default();
    let mode = pb::EvalMode::try_from(spec.mode).unwrap_or(pb::EvalMode::Unspecified);
    if mode == pb::EvalMode::Unspecified {
        return Err(JobError::Spec(format!("unknown evaluation mode {}", spec.mode)));
    }
    let run = spec::run_options(spec, &ep)?;
    let id = policy_episode_id(job);
    let cfg = spec::episode_config(spec, &ctx.assets, &ctx.params, &id)?;
    log.line(format!(
        "episode {id} scene {} instruction {} seed {} mode {} grasp {} tasks {} policy {}",
        cfg.scene,
        spec.instruction_id,
        cfg.seed,
        mode.as_str_name(),
        spec.grasp().map_err(JobError::Spec)?,
        run.max_tasks.map_or(cfg.plan.len(), |m| m.min(cfg.plan.len())),
        ep.url
    ));
    let n_tasks = run.max_tasks.map_or(cfg.plan.len(), |m| m.min(cfg.plan.len()));
    // A core while simulating only: not for the handshake, not during policy calls.
    let mut core = control.cores.core();
    core.hold();
    let sim_cfg = spec::sim_config(spec, &ctx.sim)?;
    let grasp = sim_cfg.grasp.mode;
    let mut sim = Sim::new(ctx.assets.clone(), sim_cfg, ctx.sensors.clone(), &cfg)?.0;
    let granted = run.privileged_observations.is_some();
    let remote_cfg = spec::remote_config(&ctx.remote, &ep, run.execute, granted);
    let creds = Credentials {
        token: Some(ep.bearer_token.clone()).filter(|t| !t.is_empty()),
        ca_pem: None,
    };
    let mut remote;
    let mut timed;
    let mut dead;
    let camera = SimCamera::from_sensors(&ctx.sensors);
    let connected = core
        .without(|| Remote::connect(&ep.url, &creds, &remote_cfg, &camera, &ep.key_map))
        .and_then(|p| match p.spec().privileged_observations && !granted {
            true => Err(standard_run_refusal(&ep.url)),
            false => Ok(p),
        });
    let policy: &mut dyn Policy = match connected {
        Ok(p) => {
            remote = p;
            remote.set_scene(&cfg.scene);
            log.line(format!("policy {} connected", remote.describe()));
            timed = crate::metrics::Timed(&mut remote);
            &mut timed
        }
        Err(e) => {
            let reason = format!("policy unreachable: {e}");
            log.line(&reason);
            if mode != pb::EvalMode::Offline {
                return Ok(Ran::tasks(all_failed(&cfg, n_tasks, &reason)));
            }
            // The expert still drives and every decision point is a failed prediction, so an
            // endpoint that refuses its MSE episodes pays as much as one answering badly.
            dead = Unreachable::new(reason);
            &mut dead
        }
    };
    let policy = &mut YieldsCore {
        policy,
        core: &mut core,
    };
    let watch = &mut Watch(control);
    if mode == pb::EvalMode::Offline {
        let mut expert = OraclePolicy::new(&ctx.assets).with_grasp_mode(grasp);
        let opts = spec::offline_options(&run, ctx.sample_every);
        let out = run_offline(&mut sim, &mut expert, policy, &opts, watch)?;
        return Ok(Ran::tasks(offline_results(&out, log)));
    }
    let starts = if spec.teleport_on_failure {
        Some(expert_starts(&mut sim, &cfg, &ctx.assets)?)
    } else {
        None
    };
    let mut hook = PathHook::new(watch);
    let live = live_view(spec, ctx, log);
    let mut tracing = None;
    // A video wanted on demand: the trace, which renders it later, instead of the video now.
    let on_demand = spec.record_video && spec.video_on_demand;
    let policy: &mut dyn Policy = match trace || on_demand {
        true => tracing.insert(TracingPolicy::new(policy)),
        false => policy,
    };
    let (out, recording) = if spec.record_video && !on_demand {
        let video = EpisodeVideo::new(&cfg.plan, n_tasks, spec.video_max_bytes as usize);
        let mut recorder = VideoHook::new(&mut hook, video);
        let out = WrapHook::around(live.as_ref(), &mut recorder, |h| {
            run_episode(&mut sim, policy, &run, starts.as_deref(), h)
        })?;
        (out, Some(recorder.into_video()))
    } else {
        let out = WrapHook::around(live.as_ref(), &mut hook, |h| {
            run_episode(&mut sim, policy, &run, starts.as_deref(), h)
        })?;
        (out, None)
    };
    let trace = tracing.map(|t| t.into_trace(cfg, &run, grasp, starts.is_some(), &out));
    // A cancelled episode is not scored, so its video is not worth the encoder's flush.
    let video = match control.is_cancelled() {
        true => None,
        false => recording.and_then(|r| finish_video(r, log)),
    };
    Ok(Ran {
        tasks: online_results(&out, log),
        path: Some(hook.into_path()),
        video,
        trace,
    })
}

/// The live view the online episode runs with: the command line's (`eval --foxglove`,
/// `--ros2`), else live ROS 2 topics when the job asks for them (`live_ros2`, the server's
/// `[live] ros2`, dev split only).
fn live_view(spec: &pb::EpisodeSpec, ctx: &JobContext, log: &mut Log) -> Option<WrapHook> {
    if ctx.watch.is_some() || !spec.live_ros2 {
        return ctx.watch.clone();
    }
    let watch = ctx.live.watch(&ctx.sensors);
    log.line(match &watch {
        Some(_) => "published live as ROS 2 topics (server [live] ros2)",
        None => "live ROS 2 topics asked for, not published: the DDS participant did not start (worker log)",
    });
    watch
}

/// The episode's MP4, its cost logged; a failed recording is logged and dropped.
fn finish_video(video: EpisodeVideo, log: &mut Log) -> Option<RecordedVideo> {
    match video.finish() {
        Ok(v) => {
            log.line(format!(
                "video: {} frames, {} bytes, composed and encoded in {:.2} s",
                v.frames,
                v.mp4.len(),
                v.encode_time.as_secs_f64()
            ));
            Some(v)
        }
        Err(e) => {
            log.line(format!("{e} (the result is not affected)"));
            None
        }
    }
}

/// A policy registered on the standard track that now asks for privileged observations: it
/// would be scored as standard on what it did not expect, so its tasks fail with what to do.
fn standard_run_refusal(url: &str) -> kitchen_r_contract::RemoteError {
    kitchen_r_contract::RemoteError::Handshake {
        endpoint: url.to_string(),
        reason: "the policy asks for privileged observations (PolicySpec.privileged_observations), \
                 but this run is on the standard track: its GetSpec did not ask when it was \
                 registered. Register the endpoint again to run it on the privileged track"
            .into(),
    }
}

fn all_failed(cfg: &EpisodeConfig, n: usize, reason: &str) -> Vec<pb::TaskResult> {
    cfg.plan
        .iter()
        .take(n)
        .enumerate()
        .map(|(i, step)| pb::TaskResult {
            index: i as u32,
            step: step.clone(),
            failure_reason: reason.to_string(),
            ..Default::default()
        })
        .collect()
}

fn online_results(out: &EpisodeOutcome, log: &mut Log) -> Vec<pb::TaskResult> {
    out.tasks
        .iter()
        .map(|t| {
            let why = t.failure.clone().unwrap_or_default();
            log.line(format!(
                "task {} {:?}: {} after {:.1} s sim, {} calls{}",
                t.index,
                t.step,
                if t.success { "success" } else { "failed" },
                t.sim_time,
                t.policy_calls,
                if why.is_empty() {
                    String::new()
                } else {
                    format!(": {why}")
                }
            ));
            let warning = warn(log, t.index, &t.corrections);
            pb::TaskResult {
                index: t.index as u32,
                step: t.step.clone(),
                success: t.success,
                completion_time_s: if t.success { t.sim_time } else { 0.0 },
                failure_reason: why,
                mse: 0.0,
                mse_samples: 0,
                corrections: t.corrections.total(),
                warning,
            }
        })
        .collect()
}

/// The task's correction warning, logged (participants read the log tail) and returned for
/// the wire result; empty when nothing was corrected.
fn warn(log: &mut Log, index: usize, c: &Corrections) -> String {
    let w = c.warning().unwrap_or_default();
    if !w.is_empty() {
        log.line(format!(
            "task {index} warning: {w} (chunk values corrected within tolerance)"
        ));
    }
    w
}

fn offline_results(out: &OfflineOutcome, log: &mut Log) -> Vec<pb::TaskResult> {
    out.tasks
        .iter()
        .map(|t| {
            log.line(format!(
                "task {} {:?}: mse {:.6} over {} samples ({} failed){}{}",
                t.index,
                t.step,
                t.mse,
                t.samples,
                t.failed,
                t.failure.as_ref().map_or(String::new(), |f| format!(": {f}")),
                t.expert_failure
                    .as_ref()
                    .map_or(String::new(), |f| format!(" [expert did not finish: {f}]"))
            ));
            let warning = warn(log, t.index, &t.corrections);
            // SR is not measured offline: `success` stays false and the server reads SR from
            // online episodes only.
            pb::TaskResult {
                index: t.index as u32,
                step: t.step.clone(),
                success: false,
                completion_time_s: 0.0,
                failure_reason: t.failure.clone().unwrap_or_default(),
                mse: t.mse,
                mse_samples: t.samples,
                corrections: t.corrections.total(),
                warning,
            }
        })
        .collect()
}
