//! What a policy run's page shows: progress while it evaluates, then per-episode and per-task
//! results with failure reasons.
//!
//! Policy: test-split feedback is aggregate only: progress counts, the run's scores and how often
//! each kind of failure happened, never a row per episode, task or instruction (episode keys are
//! instruction ids, and per-episode success rates would let a team probe the hidden plans one
//! instruction at a time). And the aggregate appears only once the run has ended: while a test
//! run is in progress a participant sees how far it got (episodes done, running, total, ETA)
//! and nothing else, because two views a moment apart that differ by one episode would give
//! that episode's failure kinds by subtraction (docs/integrity.md; an outside review polled every
//! 0.25 s and differenced 134 of 151 increments to single episodes). Dev runs show everything,
//! live: per-episode, per-task results and logs.

use kitchen_r_core::GraspMode;
use serde::Serialize;

use super::AppState;
use crate::episodes::TaskOutcome;
use crate::error::ServiceError;
use crate::states::RunState;
use crate::store::RunRow;
use crate::store::runs::{self as run_store, ResultRow};

#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub(crate) struct PolicyRunView {
    /// `queued` (no episode started), `running`, `finished`, `platform_failed` or `cancelled`
    /// (stopped by the organiser).
    pub state: &'static str,
    /// The grasp mode the run's episodes ran in (`abstract` or `physical`, the organiser's
    /// `[control] grasp` when it was queued): part of what its scores mean.
    #[schema(value_type = crate::schema::GraspModeName)]
    pub grasp_mode: GraspMode,
    pub episodes_total: i64,
    /// Episodes with a recorded result (including ones the platform gave up on).
    pub episodes_done: i64,
    /// Episodes being simulated right now.
    pub episodes_running: i64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub finished_at: Option<String>,
    /// The ground truth changed under this run's episodes since they were simulated: its scores
    /// are those of the old ground truth until an organiser has it simulated again.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub needs_resimulation: bool,
    /// A rescore: the run whose recorded episodes these scores were recomputed from.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rescored_from_run: Option<i64>,
    /// Dev split: one entry per recorded episode. Empty on the test split.
    pub episodes: Vec<EpisodeView>,
    /// How often each kind of failure happened over the run's tasks and episodes, most frequent
    /// first (numbers in a reason replaced by `N`, so counts group). Test split: empty until
    /// the run has ended (see the module documentation).
    pub failure_counts: Vec<ReasonCount>,
    /// When a queued or running evaluation should finish, from its pace so far (absent before
    /// its first episode has finished).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub eta: Option<super::portal::Eta>,
    /// Dev split: episodes not finished yet whose earlier attempt failed on the platform side,
    /// and why (they are retried without counting against the participant).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub retrying: Vec<RetryView>,
    /// Episodes being retried after a platform failure (both splits).
    pub episodes_retrying: usize,
}

#[derive(Debug, Clone, PartialEq, Eq, Serialize, utoipa::ToSchema)]
pub(crate) struct ReasonCount {
    pub reason: String,
    pub count: usize,
}

#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub(crate) struct RetryView {
    pub key: String,
    /// Leases so far.
    pub attempt: i64,
    pub last_error: String,
}

#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub(crate) struct EpisodeView {
    /// `dev-0007` (online) or `dev-0007/offline`.
    pub key: String,
    pub mode: String,
    /// Online: the episode's mean SR_j over the reported tasks.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub success_rate: Option<f64>,
    /// Offline: the episode's sample-weighted MSE.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mse: Option<f64>,
    /// Why the episode never ran (the platform gave up after its attempts).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub failure: Option<String>,
    /// Distinct task failure reasons, in plan order.
    pub failure_reasons: Vec<String>,
    pub wall_ms: i64,
    pub attempt: i64,
    /// Online: each task of the plan, in order (sub-task, success, failure reason, time).
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(value_type = Option<Vec<Object>>)]
    pub tasks: Option<Vec<TaskOutcome>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub log_tail: Option<String>,
    /// The top-down plot of where the robot went (dev split, online episodes with a stored path).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub plot_url: Option<String>,
    /// Where the episode video is served (dev split, online episodes with a stored video or a
    /// trace to render it from; `[video]`). Without a stored video, asking for it renders it
    /// first: `202` with the render's progress until it is ready (`video.status`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub video_url: Option<String>,
    /// The episode video's state: ready, available (rendered when asked for), queued,
    /// rendering (with progress) or failed (with why).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub video: Option<VideoView>,
    /// Why the episode has no video any more, where `video_url` would be: removed to keep a
    /// storage budget (`[video] team_max_bytes` or `total_max_bytes`), or not stored.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub video_note: Option<String>,
}

/// An episode's video as the API shows it (`EpisodeView.video`).
#[derive(Debug, Clone, PartialEq, Serialize, utoipa::ToSchema)]
pub(crate) struct VideoView {
    /// `ready` (stored: `url` plays it), `available` (a trace is stored: asking for `url` renders
    /// the video), `queued` or `rendering` (asked for; poll `url` or this view), `failed`
    /// (`error` says why: the replay disagreed with the stored result, say).
    pub status: String,
    /// Share of the render done, 0 to 1 (`rendering`; 1 when `ready`).
    pub progress: f64,
    /// Where the video is served (202 while it renders).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub url: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// `queued`: why the render waits (its video found no room in the storage budgets).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub waiting: Option<String>,
}

impl AppState {
    pub(crate) async fn policy_run_view(
        &self,
        run: &RunRow,
        hidden: bool,
        submission: i64,
    ) -> Result<PolicyRunView, ServiceError> {
        let source = run.episodes_run();
        let counts = run_store::job_counts(self.read_pool(), source).await?;
        let results = run_store::results(self.read_pool(), source).await?;
        let mut notes = match hidden {
            true => Default::default(),
            false => self.video_keys(source).await?,
        };
        let mut videos = match hidden {
            true => Default::default(),
            false => self.video_views(source, |k| video_url(submission, k)).await?,
        };
        let state = match run.state {
            RunState::Finished => "finished",
            RunState::PlatformFailed => "platform_failed",
            RunState::Cancelled => "cancelled",
            RunState::Active if counts.started == 0 => "queued",
            _ => "running",
        };
        let episodes: Vec<EpisodeView> = (results.into_iter())
            .map(|r| {
                let plot = !hidden && r.has_path;
                let mut e = episode_view(r);
                if plot {
                    e.plot_url = Some(plot_url(submission, &e.key));
                }
                match videos.remove(&e.key) {
                    Some(v) if v.status == "failed" => {
                        let why = v.error.clone().unwrap_or_default();
                        e.video_note = Some(format!("no video: {why}"));
                        e.video = Some(v);
                    }
                    Some(v) => {
                        e.video_url = v.url.clone();
                        // Rendered once and removed since (a budget): why, until asked again.
                        if v.status == "available" {
                            e.video_note = notes.remove(&e.key).flatten();
                        }
                        e.video = Some(v);
                    }
                    // No video and no trace to render one from: why, when known.
                    None => e.video_note = notes.remove(&e.key).flatten(),
                }
                e
            })
            .collect();
        let ended = !matches!(state, "queued" | "running");
        // Test split: nothing but progress until the run has ended.
        let failure_counts = match hidden && !ended {
            true => Vec::new(),
            false => failure_counts(&episodes, hidden),
        };
        let retrying: Vec<RetryView> = run_store::retrying(self.read_pool(), source)
            .await?
            .into_iter()
            .map(|j| RetryView {
                key: j.episode_key,
                attempt: j.attempt,
                last_error: j.last_error,
            })
            .collect();
        let episodes_done = episodes.len() as i64;
        let episodes_retrying = retrying.len();
        let eta = match ended {
            true => None,
            false => self.run_eta(run.id, episodes_done, run.episodes_total).await?,
        };
        Ok(PolicyRunView {
            retrying: if hidden { Vec::new() } else { retrying },
            episodes_retrying,
            state,
            grasp_mode: run.grasp_mode,
            episodes_total: run.episodes_total,
            episodes_done,
            episodes_running: counts.leased,
            finished_at: run.finished_at.map(super::rfc3339),
            needs_resimulation: run.needs_resimulation,
            rescored_from_run: run.source_run_id,
            episodes: if hidden { Vec::new() } else { episodes },
            failure_counts,
            eta,
        })
    }
}

/// What a test-split page says of an episode the platform gave up on.
const PLATFORM_GAVE_UP: &str = "the platform gave up on the episode after its retries";

/// Every task failure and platform give-up of the run, grouped by [`reason_kind`].
///
/// On the test split (`hidden`) a platform give-up counts under one generic kind: its message
/// comes from the platform and may name the instruction or its plan (a job a worker refused says
/// which instruction and how many place steps it has).
fn failure_counts(episodes: &[EpisodeView], hidden: bool) -> Vec<ReasonCount> {
    let mut counts: std::collections::BTreeMap<String, usize> = Default::default();
    for e in episodes {
        let tasks = e.tasks.iter().flatten().map(|t| reason_kind(&t.failure_reason));
        let platform = e.failure.as_deref().map(|f| match hidden {
            true => PLATFORM_GAVE_UP.to_string(),
            false => reason_kind(f),
        });
        for kind in tasks.chain(platform).filter(|r| !r.is_empty()) {
            *counts.entry(kind).or_default() += 1;
        }
    }
    let mut out: Vec<ReasonCount> = (counts.into_iter())
        .map(|(reason, count)| ReasonCount { reason, count })
        .collect();
    out.sort_by(|a, b| b.count.cmp(&a.count).then_with(|| a.reason.cmp(&b.reason)));
    out
}

/// The kind of a failure reason: its text with every number replaced by `N`, capped at 160
/// characters, so "time limit of 120 s reached" on two tasks counts twice under one kind.
pub(super) fn reason_kind(reason: &str) -> String {
    let mut out = String::new();
    let mut in_number = false;
    for c in reason.chars() {
        let digit = c.is_ascii_digit() || (in_number && matches!(c, '.' | 'e' | '-'));
        if digit && !in_number {
            out.push('N');
        } else if !digit {
            out.push(c);
        }
        in_number = digit;
        if out.len() >= 160 {
            break;
        }
    }
    out
}

/// Where an episode's video is served.
pub(crate) fn video_url(submission: i64, episode_key: &str) -> String {
    format!("/api/v1/submissions/{submission}/episodes/{episode_key}/video.mp4")
}

/// Where an episode's path plot is served.
pub(crate) fn plot_url(submission: i64, episode_key: &str) -> String {
    format!("/api/v1/submissions/{submission}/episodes/{episode_key}/path.png")
}

fn episode_view(r: ResultRow) -> EpisodeView {
    let tasks = r.tasks;
    let online = r.mode == "online";
    let success_rate = (online && !tasks.is_empty())
        .then(|| tasks.iter().filter(|t| t.success).count() as f64 / tasks.len() as f64);
    let samples: u64 = tasks.iter().map(|t| u64::from(t.mse_samples)).sum();
    let mse = (!online && samples > 0).then(|| {
        tasks
            .iter()
            .map(|t| t.mse * f64::from(t.mse_samples))
            .sum::<f64>()
            / samples as f64
    });
    let mut failure_reasons: Vec<String> = Vec::new();
    for t in &tasks {
        if !t.failure_reason.is_empty() && !failure_reasons.contains(&t.failure_reason) {
            failure_reasons.push(t.failure_reason.clone());
        }
    }
    EpisodeView {
        key: r.episode_key,
        mode: r.mode,
        success_rate,
        mse,
        failure: r.failure,
        failure_reasons,
        wall_ms: r.wall_ms,
        attempt: r.attempt,
        tasks: Some(tasks),
        log_tail: Some(r.log_tail),
        plot_url: None,
        video_url: None,
        video: None,
        video_note: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn test_split_counts_do_not_quote_platform_messages() {
        let given_up = EpisodeView {
            key: "test-0001".into(),
            mode: "online".into(),
            success_rate: None,
            mse: None,
            failure: Some("the platform gave up: instruction \"test-0001\": 2 place steps".into()),
            failure_reasons: Vec::new(),
            wall_ms: 0,
            attempt: 3,
            tasks: Some(Vec::new()),
            log_tail: None,
            plot_url: None,
            video_url: None,
            video: None,
            video_note: None,
        };
        let hidden = failure_counts(std::slice::from_ref(&given_up), true);
        assert_eq!(hidden[0].reason, PLATFORM_GAVE_UP);
        let shown = failure_counts(&[given_up], false);
        assert!(shown[0].reason.contains("test-N"), "{shown:?}");
    }

    #[test]
    fn reasons_group_by_kind_with_numbers_masked() {
        assert_eq!(
            reason_kind("time limit of 120 s reached"),
            "time limit of N s reached"
        );
        assert_eq!(
            reason_kind("invalid action chunk: action 3: gripper 1.7 outside [0, 1]"),
            "invalid action chunk: action N: gripper N outside [N, N]"
        );
        assert_eq!(reason_kind("policy unreachable"), "policy unreachable");
    }
}
