//! Policy registration (control and integrated tracks) and what a policy submission's page shows.
//!
//! Policy: an endpoint is accepted only after the injected [`crate::probe::PolicyProbe`] found it
//! allowed, SERVING and speaking our protocol; then the submission, its scoring run and one job
//! per episode are inserted in one transaction. Quotas (per day, concurrent runs) are checked
//! before the probe (a cheap refusal) and again under the submit lock at insert time; the
//! upload rate (`quota.per_minute`, [`super::limits`]) before anything else. Organiser
//! reference runs are exempt from quotas, are filed under a reserved `(baseline)` team, and are
//! the only runs whose episodes carry `privileged = true` (the oracle's full world state).
//!
//! The privileged-information track is another thing: a policy whose GetSpec asks for privileged
//! observations is accepted only when the organiser enabled `control.privileged_track` (else
//! refused with [`ServiceError::PrivilegedTrackOff`], which names the key); its jobs then grant
//! them with the split's scope ([`PrivilegedScope::for_split`]: dev shows the episode's key
//! objects, test only what the current sub-task names), and the submission is stored as
//! privileged, so the boards rank it apart from standard runs. The track is fixed at
//! registration: a re-simulation keeps it.

use kitchen_r_core::GraspMode;
use kitchen_r_core::dataset::{Instruction, Split};
use kitchen_r_core::observations::{ObservationTrack, PrivilegedScope};
use serde::{Deserialize, Serialize};

use super::{AppState, Caller, Organiser, now_ms};
use crate::config::ControlConfig;
use crate::episodes::{EndpointSpec, JobSpec, Mode};
use crate::error::ServiceError;
use crate::probe::ProbedSpec;
use crate::states::{RunState, SubmissionKind};
use crate::store::runs::{self as run_store, NewPolicyRun};
use crate::store::{self, Team};

/// Version of the control scorer; part of every policy run's `scorer_version`.
pub(crate) const CONTROL_SCORER: &str = "control/1";

const MAX_URL_CHARS: usize = 2048;
const MAX_TOKEN_CHARS: usize = 4096;
/// Longest key map accepted, as compact JSON (a full map is about 300 characters).
const MAX_KEY_MAP_CHARS: usize = 4096;

/// `POST /api/v1/submissions/policies` and `RegisterPolicy`.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub(crate) struct RegisterPolicy {
    /// `http://host:port` or `https://host:port` (gRPC), or `ws://host:port` or
    /// `wss://host:port` (openpi WebSocket).
    pub endpoint: String,
    #[schema(value_type = crate::schema::SplitName)]
    pub split: Split,
    /// Bearer token the evaluator sends to the endpoint; stored sealed, never shown back.
    #[serde(default)]
    pub token: Option<String>,
    /// Plan submission (same team, same split) for the integrated track.
    #[serde(default)]
    pub plans: Option<i64>,
    /// Dev split only: evaluate the first N instructions.
    #[serde(default)]
    pub episodes: Option<u32>,
    /// Organiser only: a reference (baseline) run.
    #[serde(default)]
    pub reference: bool,
    /// openpi (`ws://`, `wss://`) endpoints only: the key map, a JSON object (`cameras`,
    /// `image_size`, `state`, `prompt`, `actions`, `actions_executed_per_chunk`,
    /// `max_concurrency`; every field optional, the defaults are the documented convention).
    #[serde(default)]
    #[schema(value_type = Option<Object>)]
    pub key_map: Option<serde_json::Value>,
}

/// The answer to an accepted registration.
#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub(crate) struct Registered {
    pub id: i64,
    pub run_id: i64,
    #[schema(value_type = crate::schema::SplitName)]
    pub split: Split,
    /// Instructions evaluated.
    pub instructions: usize,
    /// Jobs queued (online, plus offline when MSE is measured).
    pub episodes: usize,
    pub max_concurrency: u32,
    pub policy: String,
    /// `standard`, or `privileged` when the policy asked for privileged observations: the
    /// boards rank it apart.
    #[schema(value_type = String)]
    pub observations: ObservationTrack,
    /// The grasp mode the run's episodes run in (the organiser's `[control] grasp`).
    #[schema(value_type = crate::schema::GraspModeName)]
    pub grasp_mode: GraspMode,
    pub state: &'static str,
}

/// What `submissions.body` holds for a policy submission.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub(crate) struct PolicyBody {
    pub endpoint: String,
    /// The bearer token workers present to the endpoint, sealed ([`super::secrets`]): the plain
    /// text is never stored nor shown back.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub token_sealed: Option<String>,
    pub plans: Option<i64>,
    pub reference: bool,
    pub protocol_version: u32,
    pub max_concurrency: u32,
    /// The probe's one-line summary of GetSpec.
    pub spec: String,
    pub instructions: usize,
    pub offline_mse: bool,
    /// The privileged track: the policy asked for privileged observations and its jobs grant
    /// them. Absent (false) in every body stored before the track existed.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub privileged_observations: bool,
    /// An openpi endpoint's key map as the probe checked it (JSON); absent for gRPC.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub key_map: Option<String>,
}

/// The endpoint as the submission page shows it: everything but the token.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, utoipa::ToSchema)]
pub(crate) struct PolicyInfo {
    pub endpoint: String,
    pub has_token: bool,
    pub plans: Option<i64>,
    pub reference: bool,
    pub max_concurrency: u32,
    pub spec: String,
    /// `standard` or `privileged`: the boards this run is ranked on.
    #[schema(value_type = String)]
    pub observations: ObservationTrack,
}

pub(crate) fn parse_body(body: &str) -> Result<PolicyBody, ServiceError> {
    serde_json::from_str(body).map_err(|e| ServiceError::Internal(anyhow::anyhow!("stored policy body: {e}")))
}

pub(crate) fn policy_info(body: &str) -> Result<PolicyInfo, ServiceError> {
    let b = parse_body(body)?;
    Ok(PolicyInfo {
        endpoint: b.endpoint,
        has_token: b.token_sealed.is_some(),
        plans: b.plans,
        reference: b.reference,
        max_concurrency: b.max_concurrency,
        spec: b.spec,
        observations: ObservationTrack::of(b.privileged_observations),
    })
}

impl AppState {
    /// Probe and register a policy endpoint, queueing its episodes.
    pub(crate) async fn register_policy(
        &self,
        caller: &Caller,
        req: RegisterPolicy,
    ) -> Result<Registered, ServiceError> {
        let team = if req.reference {
            caller.organiser()?;
            run_store::baseline_team(self.pool(), now_ms()).await?
        } else {
            let team = caller.team()?.clone();
            // Every attempt takes a slot: a probe is a connection made on the team's behalf.
            self.check_rate(&team, req.split)?;
            team
        };
        let endpoint = validate_endpoint(&req.endpoint)?;
        let bearer = validate_bearer(req.token.as_deref())?;
        let key_map = validate_key_map(&endpoint, req.key_map.as_ref())?;
        let instructions = self.run_instructions(req.split, req.episodes)?;
        if let Some(plans) = req.plans {
            self.check_linked_plans(&team, req.reference, req.split, plans)
                .await?;
        }
        if !req.reference {
            self.check_policy_quota(&team, req.split).await?;
        }
        let probed = (self.inner.probe)
            .probe(&endpoint, bearer.as_deref(), key_map.as_deref())
            .await?;
        if probed.protocol_version != kitchen_r_proto::POLICY_PROTOCOL_VERSION {
            return Err(ServiceError::ProbeFailed(format!(
                "GetSpec announced protocol version {}, this server speaks {}",
                probed.protocol_version,
                kitchen_r_proto::POLICY_PROTOCOL_VERSION
            )));
        }
        let cfg = self.config();
        check_contract_v1_1(&probed, &cfg.control)?;
        if probed.privileged_observations && !cfg.control.privileged_track {
            return Err(ServiceError::PrivilegedTrackOff);
        }
        let track = ObservationTrack::of(probed.privileged_observations);
        // policy.proto: 0 is read as 1.
        let max_concurrency = probed.max_concurrency.max(1);
        let sealed = bearer.as_deref().map(|t| self.seal_token(t));
        let endpoint_spec = self.endpoint_spec(&endpoint, sealed.clone(), probed.key_map.clone());
        let scope = probed
            .privileged_observations
            .then(|| PrivilegedScope::for_split(req.split));
        let jobs = self.job_specs(instructions, &endpoint_spec, req.reference, scope)?;
        let body = PolicyBody {
            endpoint,
            token_sealed: sealed,
            plans: req.plans,
            reference: req.reference,
            protocol_version: probed.protocol_version,
            max_concurrency,
            spec: probed.summary.clone(),
            instructions: instructions.len(),
            offline_mse: cfg.control.offline_mse,
            privileged_observations: probed.privileged_observations,
            key_map: probed.key_map.clone(),
        };
        let body = serde_json::to_string(&body).map_err(anyhow::Error::from)?;
        let scorer = format!("{CONTROL_SCORER}+{}", self.content().dataset_tag());
        let new = NewPolicyRun {
            team: team.id,
            split: req.split,
            body: &body,
            scorer_version: &scorer,
            max_concurrency,
            max_attempts: cfg.control.max_attempts,
            grasp: cfg.control.grasp,
            jobs: &jobs,
        };
        let (id, run_id) = {
            let _guard = self.inner.submit_lock.lock().await;
            if !req.reference {
                self.check_policy_quota(&team, req.split).await?;
            }
            run_store::insert_policy_submission(self.pool(), &new, now_ms()).await?
        };
        self.inner.jobs_ready.notify_waiters();
        self.leaderboard_cache().invalidate();
        tracing::info!(submission = id, run = run_id, team = %team.name, split = %req.split,
            episodes = jobs.len(), reference = req.reference, observations = %track, "policy registered");
        Ok(Registered {
            id,
            run_id,
            split: req.split,
            instructions: instructions.len(),
            episodes: jobs.len(),
            max_concurrency,
            policy: probed.summary,
            observations: track,
            grasp_mode: cfg.control.grasp,
            state: "queued",
        })
    }

    /// Organiser: simulate a finished policy submission again against the current ground truth
    /// (after `rescore` flagged it `needs_resimulation`), as a new run on the same submission.
    /// The endpoint is not probed and no quota is used: it is the organiser's request, and an
    /// endpoint that is gone fails its tasks like any unreachable policy.
    pub(crate) async fn resimulate(&self, _: Organiser, id: i64) -> Result<Registered, ServiceError> {
        let sub = store::submission(self.pool(), id)
            .await?
            .filter(|s| s.kind == SubmissionKind::Policy)
            .ok_or_else(|| ServiceError::not_found(format!("policy submission {id}")))?;
        if let Some(run) = store::latest_run(self.pool(), id).await?
            && run.state == RunState::Active
        {
            return Err(ServiceError::Conflict(format!(
                "submission {id} is still evaluating (run {}); re-simulate once it has finished",
                run.id
            )));
        }
        let split: Split = sub.split.parse().map_err(|e: String| anyhow::anyhow!(e))?;
        let body = parse_body(&store::submission_body(self.pool(), id).await?.body)?;
        let episodes = (split == Split::Dev).then_some(body.instructions as u32);
        let instructions = self.run_instructions(split, episodes)?;
        let cfg = self.config();
        let endpoint = self.endpoint_spec(&body.endpoint, body.token_sealed.clone(), body.key_map.clone());
        let scope = (body.privileged_observations).then(|| PrivilegedScope::for_split(split));
        let jobs = self.job_specs(instructions, &endpoint, body.reference, scope)?;
        let scorer = format!("{CONTROL_SCORER}+{}", self.content().dataset_tag());
        let new = NewPolicyRun {
            team: sub.team_id,
            split,
            body: "",
            scorer_version: &scorer,
            max_concurrency: body.max_concurrency,
            max_attempts: cfg.control.max_attempts,
            grasp: cfg.control.grasp,
            jobs: &jobs,
        };
        let run_id = run_store::insert_policy_run(self.pool(), id, &new, now_ms()).await?;
        self.inner.jobs_ready.notify_waiters();
        self.leaderboard_cache().invalidate();
        tracing::info!(
            submission = id,
            run = run_id,
            episodes = jobs.len(),
            "policy run re-simulated"
        );
        Ok(Registered {
            id,
            run_id,
            split,
            instructions: instructions.len(),
            episodes: jobs.len(),
            max_concurrency: body.max_concurrency,
            policy: body.spec,
            observations: ObservationTrack::of(body.privileged_observations),
            grasp_mode: cfg.control.grasp,
            state: "queued",
        })
    }

    /// Where a run's jobs call the policy, with the deadlines configured now; the token stays
    /// sealed until a job is leased.
    fn endpoint_spec(
        &self,
        url: &str,
        sealed_bearer: Option<String>,
        key_map: Option<String>,
    ) -> EndpointSpec {
        let (p, c) = (&self.config().policy, &self.config().control);
        EndpointSpec {
            url: url.to_string(),
            bearer_token: String::new(),
            bearer_token_sealed: sealed_bearer,
            call_deadline_ms: p.call_deadline_ms,
            startup_deadline_ms: p.startup_deadline_ms,
            episode_budget_ms: p.episode_budget_ms,
            max_successive_timeouts: p.max_successive_timeouts,
            min_actions_executed_per_chunk: c.min_actions_executed_per_chunk,
            quat_norm_tolerance: Some(p.quat_norm_tolerance),
            gripper_margin: Some(p.gripper_margin),
            key_map,
        }
    }

    /// The instructions a run evaluates: the whole test split; on dev, the first
    /// `control.dev_episodes` (0 = all), further limited by the request's `episodes`.
    fn run_instructions(&self, split: Split, episodes: Option<u32>) -> Result<&[Instruction], ServiceError> {
        let all = self.content().ground_truth(split);
        match (split, episodes) {
            (Split::Test, Some(_)) => Err(ServiceError::BadRequest(
                "`episodes` applies to the dev split only: the test split always runs in full".into(),
            )),
            (_, Some(0)) => Err(ServiceError::BadRequest("`episodes` must be at least 1".into())),
            (Split::Test, None) => Ok(all),
            (Split::Dev, asked) => {
                let cap = match self.config().control.dev_episodes {
                    0 => all.len(),
                    n => all.len().min(n as usize),
                };
                Ok(&all[..asked.map_or(cap, |n| cap.min(n as usize))])
            }
        }
    }

    /// `(episode_key, spec JSON)` for every job of a run: one online job per instruction, and
    /// one offline job when `control.offline_mse` is on. `privileged`: an organiser reference
    /// run (full world state); `scope`: the privileged track's observations, if any.
    fn job_specs(
        &self,
        instructions: &[Instruction],
        endpoint: &EndpointSpec,
        privileged: bool,
        scope: Option<PrivilegedScope>,
    ) -> Result<Vec<(String, String)>, ServiceError> {
        let c = &self.config().control;
        let modes: &[Mode] = if c.offline_mse {
            &[Mode::Online, Mode::Offline]
        } else {
            &[Mode::Online]
        };
        let mut jobs = Vec::with_capacity(instructions.len() * modes.len());
        for inst in instructions {
            for &mode in modes {
                let spec = JobSpec {
                    mode,
                    scene_id: inst.scene.clone(),
                    instruction_id: inst.id.clone(),
                    plan: inst.plan.clone(),
                    seed: c.seed,
                    task_time_limit_s: c.task_time_limit_s,
                    actions_executed_per_chunk: c.actions_executed_per_chunk,
                    teleport_on_failure: c.teleport_on_failure,
                    max_plan_steps: c.max_plan_steps,
                    privileged,
                    privileged_observations: scope,
                    endpoint: endpoint.clone(),
                    place_targets: inst.place_targets.clone(),
                    grasp: c.grasp,
                };
                let json = serde_json::to_string(&spec).map_err(anyhow::Error::from)?;
                jobs.push((mode.episode_key(&inst.id), json));
            }
        }
        Ok(jobs)
    }

    async fn check_linked_plans(
        &self,
        team: &Team,
        any_team: bool,
        split: Split,
        id: i64,
    ) -> Result<(), ServiceError> {
        // Another team's submission is "not found", so ids cannot be probed for existence.
        let sub = store::submission(self.pool(), id)
            .await?
            .filter(|s| any_team || s.team_id == team.id)
            .ok_or_else(|| ServiceError::not_found(format!("plans submission {id}")))?;
        if sub.kind != SubmissionKind::Plans {
            return Err(ServiceError::BadRequest(format!(
                "submission {id} is a {} submission; `plans` must name a plan file submission",
                sub.kind.as_str()
            )));
        }
        if sub.split != split.as_str() {
            return Err(ServiceError::BadRequest(format!(
                "plans submission {id} is for the {} split, the policy for {split}",
                sub.split
            )));
        }
        // From a team's first test policy run on, its endpoint has seen the test plans' steps
        // as sub-tasks: plan files made after that cannot carry an integrated score.
        if split == Split::Test
            && !any_team
            && let Some(first) = store::first_test_policy(self.pool(), team.id).await?
            && first < id
        {
            return Err(ServiceError::BadRequest(format!(
                "plans submission {id} was created after your first test-split policy run \
                 (submission {first}); an integrated test run must link a plan file created \
                 before it"
            )));
        }
        Ok(())
    }

    async fn check_policy_quota(&self, team: &Team, split: Split) -> Result<(), ServiceError> {
        self.check_quota(team, split, now_ms()).await?;
        let limit = self.config().quota.concurrent_runs;
        if limit > 0 && run_store::active_runs(self.pool(), team.id).await? >= i64::from(limit) {
            return Err(ServiceError::ConcurrentRuns { limit });
        }
        Ok(())
    }
}

/// The v1.1 choices of GetSpec within this organiser's ranges (policy.proto): a history of
/// 1..=8 frames (0 = 1), an execution count between `control.min_actions_executed_per_chunk`
/// and 16 (0 = `control.actions_executed_per_chunk`). The reason names the field and range.
fn check_contract_v1_1(probed: &ProbedSpec, c: &ControlConfig) -> Result<(), ServiceError> {
    if probed.observation_history > MAX_OBSERVATION_HISTORY {
        return Err(ServiceError::ProbeFailed(format!(
            "GetSpec asks for observation_history {}, which must be between 1 and \
             {MAX_OBSERVATION_HISTORY} (0 means 1)",
            probed.observation_history
        )));
    }
    let k = probed.actions_executed_per_chunk;
    if k != 0 && !(c.min_actions_executed_per_chunk..=HORIZON).contains(&k) {
        return Err(ServiceError::ProbeFailed(format!(
            "GetSpec asks for actions_executed_per_chunk {k}, which must be between {} (this \
             server's control.min_actions_executed_per_chunk) and {HORIZON}, or 0 for the default {}",
            c.min_actions_executed_per_chunk, c.actions_executed_per_chunk
        )));
    }
    Ok(())
}

/// Most frames a policy may ask for (policy.proto, `PolicySpec.observation_history`).
const MAX_OBSERVATION_HISTORY: u32 = 8;
/// Actions per chunk (policy.proto); the largest execution count.
const HORIZON: u32 = 16;

/// The schemes an endpoint may have: gRPC, then openpi WebSocket.
const SCHEMES: [&str; 4] = ["http://", "https://", "ws://", "wss://"];
const OPENPI_SCHEMES: [&str; 2] = ["ws://", "wss://"];

/// `http[s]://HOST:PORT` or `ws[s]://HOST:PORT`, trimmed; the probe does the real address check.
fn validate_endpoint(url: &str) -> Result<String, ServiceError> {
    let url = url.trim();
    let refuse = |why: &str| Err(ServiceError::EndpointRefused(format!("{url:?} {why}")));
    if url.is_empty() {
        return Err(ServiceError::BadRequest(
            "`endpoint` is required: http://HOST:PORT (gRPC) or ws://HOST:PORT (openpi)".into(),
        ));
    }
    if url.chars().count() > MAX_URL_CHARS {
        return refuse(&format!("is longer than {MAX_URL_CHARS} characters"));
    }
    if url.chars().any(|c| c.is_whitespace() || c.is_control()) {
        return refuse("contains whitespace or control characters");
    }
    let Some(rest) = SCHEMES.iter().find_map(|p| url.strip_prefix(p)) else {
        return refuse("must start with http:// or https:// (gRPC), or ws:// or wss:// (openpi)");
    };
    if rest.is_empty() || rest.starts_with('/') {
        return refuse("has no host");
    }
    Ok(url.to_string())
}

/// The key map's compact JSON for the probe: an object, openpi endpoints only, size-capped.
/// Its fields are the probe's to check (it knows the simulator's cameras).
fn validate_key_map(
    endpoint: &str,
    key_map: Option<&serde_json::Value>,
) -> Result<Option<String>, ServiceError> {
    let Some(k) = key_map.filter(|k| !k.is_null()) else {
        return Ok(None);
    };
    if !OPENPI_SCHEMES.iter().any(|p| endpoint.starts_with(p)) {
        return Err(ServiceError::BadRequest(
            "`key_map` applies to ws:// and wss:// (openpi) endpoints only".into(),
        ));
    }
    if !k.is_object() {
        return Err(ServiceError::BadRequest("`key_map` must be a JSON object".into()));
    }
    let text = k.to_string();
    if text.chars().count() > MAX_KEY_MAP_CHARS {
        return Err(ServiceError::BadRequest(format!(
            "`key_map` must be at most {MAX_KEY_MAP_CHARS} characters of JSON"
        )));
    }
    Ok(Some(text))
}

/// A key map as the gRPC request carries it (JSON text; empty for none).
pub(crate) fn key_map_from_text(text: &str) -> Result<Option<serde_json::Value>, ServiceError> {
    if text.trim().is_empty() {
        return Ok(None);
    }
    serde_json::from_str(text)
        .map(Some)
        .map_err(|e| ServiceError::BadRequest(format!("`key_map` is not JSON: {e}")))
}

/// The endpoint's bearer token travels in an HTTP/2 header: visible ASCII only.
fn validate_bearer(token: Option<&str>) -> Result<Option<String>, ServiceError> {
    let Some(t) = token.map(str::trim).filter(|t| !t.is_empty()) else {
        return Ok(None);
    };
    if t.len() > MAX_TOKEN_CHARS || !t.bytes().all(|b| b.is_ascii_graphic()) {
        return Err(ServiceError::BadRequest(format!(
            "`token` must be at most {MAX_TOKEN_CHARS} visible ASCII characters"
        )));
    }
    Ok(Some(t.to_string()))
}

#[cfg(test)]
mod privileged_tests;
#[cfg(test)]
mod tests;
