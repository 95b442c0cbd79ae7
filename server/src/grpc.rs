//! The gRPC adapter (tonic) for `kitchen_r.submission.v1.Submissions`: converts messages and
//! calls the same service functions as the HTTP routes, so both transports apply one set of rules.

use kitchen_r_core::dataset::Split;
use kitchen_r_proto::submission::v1 as pb;
use pb::submissions_server::Submissions;
use tonic::{Request, Response, Status};

use crate::error::ServiceError;
use crate::leaderboard::Track;
use crate::service::{AppState, EpisodeView, RegisterPolicy, Scores, SubmissionView};

#[derive(Debug, Clone)]
pub struct SubmissionsService {
    state: AppState,
}

impl SubmissionsService {
    pub fn new(state: AppState) -> Self {
        SubmissionsService { state }
    }

    /// The tonic server, with the decoding cap raised to the configured body limit (plus room
    /// for the envelope) so a file over the limit gets the service's own error and line.
    pub fn into_server(self) -> pb::submissions_server::SubmissionsServer<Self> {
        let cap = self.state.config().max_body_bytes.saturating_mul(2);
        pb::submissions_server::SubmissionsServer::new(self).max_decoding_message_size(cap)
    }
}

pub(crate) fn bearer<T>(req: &Request<T>) -> Option<String> {
    let v = req.metadata().get("authorization")?.to_str().ok()?;
    let t = v
        .strip_prefix("Bearer ")
        .or_else(|| v.strip_prefix("bearer "))?
        .trim();
    (!t.is_empty()).then(|| t.to_string())
}

fn split(s: &str, default: Option<Split>) -> Result<Split, Status> {
    match (s, default) {
        ("", Some(d)) => Ok(d),
        _ => s.parse().map_err(|e: String| ServiceError::BadRequest(e).into()),
    }
}

fn scores(s: Scores) -> pb::Scores {
    pb::Scores {
        em: s.em,
        sr: s.sr,
        mse: s.mse,
        m: s.m,
        p: s.p,
    }
}

fn episode(e: EpisodeView) -> pb::EpisodeSummary {
    pb::EpisodeSummary {
        key: e.key,
        mode: e.mode,
        success_rate: e.success_rate,
        mse: e.mse,
        failure: e.failure.unwrap_or_default(),
        failure_reasons: e.failure_reasons,
    }
}

fn submission(v: SubmissionView) -> pb::Submission {
    pb::Submission {
        id: v.id,
        team: v.team,
        split: v.split,
        kind: v.kind,
        created_at: v.created_at,
        runs: v.runs as u32,
        ranked: v.ranked,
        unranked_reason: v.unranked_reason.unwrap_or_default(),
        latest_run: v.latest_run.map(|r| {
            let eval = r.evaluation;
            pb::ScoringRun {
                failure_counts: eval.as_ref().map_or_else(Vec::new, |e| {
                    (e.failure_counts.iter())
                        .map(|c| pb::ReasonCount {
                            reason: c.reason.clone(),
                            count: c.count as u32,
                        })
                        .collect()
                }),
                instructions_total: r.instructions_total.unwrap_or(0) as u32,
                instructions_present: r.instructions_present.unwrap_or(0) as u32,
                state: eval.as_ref().map_or_else(String::new, |e| e.state.to_string()),
                episodes_total: eval.as_ref().map_or(0, |e| e.episodes_total as u32),
                episodes_done: eval.as_ref().map_or(0, |e| e.episodes_done as u32),
                episodes_running: eval.as_ref().map_or(0, |e| e.episodes_running as u32),
                episodes: eval.map_or_else(Vec::new, |e| e.episodes.into_iter().map(episode).collect()),
                id: r.id,
                scorer_version: r.scorer_version,
                created_at: r.created_at,
                scores: Some(scores(r.scores)),
                instructions: r
                    .instructions
                    .into_iter()
                    .map(|i| pb::InstructionResult {
                        id: i.id,
                        present: i.present,
                        correct_steps: i.correct_steps as u32,
                        total_steps: i.total_steps as u32,
                        em: i.em,
                    })
                    .collect(),
            }
        }),
    }
}

#[tonic::async_trait]
impl Submissions for SubmissionsService {
    async fn submit_plans(
        &self,
        req: Request<pb::SubmitPlansRequest>,
    ) -> Result<Response<pb::SubmitPlansResponse>, Status> {
        let token = bearer(&req);
        let msg = req.into_inner();
        let split = split(&msg.split, None)?;
        let done = self
            .state
            .submit_plans(token.as_deref(), split, &msg.body)
            .await?;
        Ok(Response::new(pb::SubmitPlansResponse {
            id: done.id,
            scores: Some(scores(done.scores)),
            warnings: done.warnings,
        }))
    }

    async fn register_policy(
        &self,
        req: Request<pb::RegisterPolicyRequest>,
    ) -> Result<Response<pb::RegisterPolicyResponse>, Status> {
        let token = bearer(&req);
        let m = req.into_inner();
        let request = RegisterPolicy {
            endpoint: m.endpoint,
            split: split(&m.split, None)?,
            token: Some(m.endpoint_token).filter(|t| !t.is_empty()),
            plans: (m.plans_submission_id != 0).then_some(m.plans_submission_id),
            episodes: m.episodes,
            reference: m.reference,
        };
        let done = self.state.register_policy(token.as_deref(), request).await?;
        Ok(Response::new(pb::RegisterPolicyResponse {
            id: done.id,
            episodes: done.episodes as u32,
            run_id: done.run_id,
            instructions: done.instructions as u32,
            max_concurrency: done.max_concurrency,
            policy: done.policy,
        }))
    }

    async fn get_submission(
        &self,
        req: Request<pb::GetSubmissionRequest>,
    ) -> Result<Response<pb::Submission>, Status> {
        let token = bearer(&req);
        let view = self
            .state
            .get_submission(token.as_deref(), req.into_inner().id)
            .await?;
        Ok(Response::new(submission(view)))
    }

    async fn get_leaderboard(
        &self,
        req: Request<pb::GetLeaderboardRequest>,
    ) -> Result<Response<pb::Leaderboard>, Status> {
        let msg = req.into_inner();
        let track: Track = msg.track.parse()?;
        let split = split(&msg.split, Some(Split::Test))?;
        let board = self.state.leaderboard(track, split).await?;
        Ok(Response::new(pb::Leaderboard {
            track: track.as_str().into(),
            split: split.to_string(),
            rows: board
                .rows
                .into_iter()
                .map(|r| pb::LeaderboardRow {
                    rank: r.rank.map_or(0, |n| n as u32),
                    team: r.team,
                    submission_id: r.submission_id,
                    scores: Some(scores(r.scores)),
                    submitted_at: r.submitted_at,
                    baseline: r.baseline,
                })
                .collect(),
        }))
    }
}
