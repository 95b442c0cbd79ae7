//! `kitchen-r admin reevaluate RUN --episodes N`: run N of a policy run's episodes again, here,
//! against the same endpoint, each as the job the workers leased (same scene, seed, rules and
//! endpoint settings; the workers' own code path, `kitchen_r_worker::job::execute_job`), and
//! report the difference from the stored results with 95 % Wilson intervals.
//!
//! Episodes are bit-reproducible, so a policy that answers the same way again reproduces its
//! stored outcome exactly; a difference means the policy (or what serves it) behaves differently
//! when asked again.

use anyhow::Context;
use kitchen_r_contract::{AllowedNetworks, RemoteConfig};
use kitchen_r_core::GraspMode;
use kitchen_r_core::interval::{overlap, wilson95};
use kitchen_r_core::observations::PrivilegedScope;
use kitchen_r_core::scoring::{Mode, TaskOutcome};
use kitchen_r_proto::convert::EpisodeRules;
use kitchen_r_proto::worker::v1 as pb;
use kitchen_r_worker::job::{JobContext, JobControl, execute_job};
use serde::Deserialize;
use serde_json::{Value, json};

use crate::server_client::{ServerArgs, json, runtime, url};

/// `jobs.spec` as the server hands it out (`episodes::JobSpec`), the token opened.
#[derive(Debug, Deserialize)]
struct Spec {
    mode: Mode,
    scene_id: String,
    instruction_id: String,
    plan: Vec<String>,
    seed: u64,
    task_time_limit_s: f64,
    actions_executed_per_chunk: u32,
    teleport_on_failure: bool,
    max_plan_steps: u32,
    privileged: bool,
    #[serde(default)]
    privileged_observations: Option<PrivilegedScope>,
    endpoint: Endpoint,
    #[serde(default)]
    place_targets: Vec<[f64; 3]>,
    #[serde(default)]
    grasp: GraspMode,
}

#[derive(Debug, Deserialize)]
struct Endpoint {
    url: String,
    #[serde(default)]
    bearer_token: String,
    call_deadline_ms: u32,
    startup_deadline_ms: u32,
    episode_budget_ms: u32,
    max_successive_timeouts: u32,
    #[serde(default)]
    min_actions_executed_per_chunk: u32,
    #[serde(default)]
    quat_norm_tolerance: Option<f64>,
    #[serde(default)]
    gripper_margin: Option<f64>,
    #[serde(default)]
    key_map: Option<String>,
}

impl Spec {
    /// The job a worker would lease (`JobSpec::episode_proto` and the lease's endpoint).
    fn job(self, key: &str) -> pb::Job {
        let rules = EpisodeRules {
            seed: self.seed,
            mode: self.mode,
            task_time_limit_s: self.task_time_limit_s,
            actions_executed_per_chunk: self.actions_executed_per_chunk,
            teleport_on_failure: self.teleport_on_failure,
            max_plan_steps: self.max_plan_steps,
            privileged: self.privileged,
            privileged_observations: self.privileged_observations,
            grasp: self.grasp,
        };
        let e = self.endpoint;
        pb::Job {
            job_id: 0,
            attempt: 1,
            lease_expires_at_ms: 0,
            run_id: 0,
            episode_key: key.to_string(),
            episode: Some(pb::EpisodeSpec::build(
                &self.scene_id,
                &self.instruction_id,
                &self.plan,
                &self.place_targets,
                &rules,
            )),
            policy: Some(pb::PolicyEndpoint {
                url: e.url,
                bearer_token: e.bearer_token,
                call_deadline_ms: e.call_deadline_ms,
                startup_deadline_ms: e.startup_deadline_ms,
                episode_budget_ms: e.episode_budget_ms,
                max_successive_timeouts: e.max_successive_timeouts,
                min_actions_executed_per_chunk: e.min_actions_executed_per_chunk,
                quat_norm_tolerance: e.quat_norm_tolerance,
                gripper_margin: e.gripper_margin,
                key_map: e.key_map.unwrap_or_default(),
            }),
            render: None,
        }
    }
}

/// Successes and tasks.
#[derive(Debug, Default, Clone, Copy)]
struct Tally {
    ok: u64,
    n: u64,
}

impl Tally {
    fn add(&mut self, success: bool) {
        self.ok += u64::from(success);
        self.n += 1;
    }
    fn json(self) -> Value {
        let (lo, hi) = wilson95(self.ok, self.n);
        let sr = if self.n > 0 {
            self.ok as f64 / self.n as f64
        } else {
            0.0
        };
        json!({"successes": self.ok, "tasks": self.n, "sr": sr, "sr_95": [lo, hi]})
    }
    fn text(self) -> String {
        let (lo, hi) = wilson95(self.ok, self.n);
        let sr = if self.n > 0 {
            self.ok as f64 / self.n as f64
        } else {
            0.0
        };
        format!("{sr:.3} [{lo:.3}, {hi:.3}] ({} of {} tasks)", self.ok, self.n)
    }
}

pub(crate) fn reevaluate(
    server: &ServerArgs,
    token: &str,
    run: i64,
    episodes: usize,
    raw: bool,
) -> anyhow::Result<()> {
    let path = format!("/api/v1/admin/runs/{run}/reevaluation?episodes={episodes}");
    let plan = runtime()?.block_on(json(
        reqwest::Client::new().get(url(server, &path)).bearer_auth(token),
    ))?;
    let jobs = plan["jobs"].as_array().cloned().unwrap_or_default();
    if !raw {
        println!(
            "run {run} (submission {}, team {}, {} split): {} of its {} episode(s) again, against the same endpoint",
            plan["submission"],
            plan["team"].as_str().unwrap_or("-"),
            plan["split"].as_str().unwrap_or("-"),
            jobs.len(),
            plan["episodes_total"]
        );
    }
    let ctx = JobContext::load(RemoteConfig::default(), AllowedNetworks::ALL, 1)
        .context("loading the simulator")?;
    let (mut stored, mut fresh) = (Tally::default(), Tally::default());
    let mut changed = Vec::new();
    for j in &jobs {
        let key = j["key"].as_str().unwrap_or_default().to_string();
        let spec: Spec = serde_json::from_value(j["spec"].clone()).context("a job spec")?;
        let was: Vec<TaskOutcome> = serde_json::from_value(j["stored"].clone()).context("a stored result")?;
        let result = execute_job(&spec.job(&key), &ctx, &JobControl::default());
        if !result.platform_error.is_empty() {
            anyhow::bail!("episode {key} could not run here: {}", result.platform_error);
        }
        was.iter().for_each(|t| stored.add(t.success));
        result.tasks.iter().for_each(|t| fresh.add(t.success));
        let before: Vec<bool> = was.iter().map(|t| t.success).collect();
        let now: Vec<bool> = result.tasks.iter().map(|t| t.success).collect();
        if before != now {
            changed.push(json!({"episode": key, "stored": before, "now": now}));
        }
        if !raw {
            let word = |v: &[bool]| v.iter().map(|s| if *s { '+' } else { '-' }).collect::<String>();
            let mark = if before == now { "same" } else { "DIFFERENT" };
            println!("  {key}: stored {} now {} ({mark})", word(&before), word(&now));
        }
    }
    let consistent = overlap(wilson95(stored.ok, stored.n), wilson95(fresh.ok, fresh.n));
    let diff = fresh.json()["sr"].as_f64().unwrap_or(0.0) - stored.json()["sr"].as_f64().unwrap_or(0.0);
    if raw {
        let report = json!({
            "run": run,
            "episodes": jobs.len(),
            "stored_run_sr": plan["stored_sr"],
            "stored": stored.json(),
            "fresh": fresh.json(),
            "difference": diff,
            "intervals_overlap": consistent,
            "episodes_changed": changed,
        });
        println!("{report}");
        return Ok(());
    }
    println!("stored task SR on these episodes: {}", stored.text());
    println!("fresh task SR on these episodes:  {}", fresh.text());
    println!(
        "difference: {diff:+.3}; the run's stored SR over all its episodes: {}",
        plan["stored_sr"]
    );
    println!(
        "{} of {} episode(s) changed outcome; {}",
        changed.len(),
        jobs.len(),
        if changed.is_empty() {
            "the endpoint reproduced its stored results exactly"
        } else if consistent {
            "the 95 % intervals overlap: within what chance explains"
        } else {
            "the 95 % intervals do not overlap: the endpoint behaves differently when asked again"
        }
    );
    Ok(())
}
