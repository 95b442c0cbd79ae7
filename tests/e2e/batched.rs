//! Batched decisions (ActBatch, a policy's GetSpec `max_batch`) end to end, every part a real
//! process on loopback: the oracle served over the batch call gives the same results as over
//! Act, in local `kitchen-r eval` and through `serve` and its workers; the Python starter kit's
//! server (`--max-batch`) answers the workers' ActBatch calls through `serve`; a policy whose
//! batch reply has the wrong count fails its tasks with that reason and loses no episode.

use crate::support;

use std::collections::BTreeMap;
use std::process::Command;

use kitchen_r_proto::policy::v1 as pb;
use pb::policy_server::{Policy as PolicyRpc, PolicyServer};
use serde_json::{Value, json};
use support::*;
use tonic::{Request, Response, Status};

/// `kitchen-r policy oracle` for four episodes at once, declaring `max_batch`.
fn batch_oracle(max_batch: u32) -> (Proc, String) {
    oracle_policy_with(&["--max-concurrency", "4", "--max-batch", &max_batch.to_string()])
}

/// `kitchen-r eval --json` of the oracle at `url` with `extra` flags.
fn eval(url: &str, mode: &str, extra: &[&str]) -> Value {
    let out = Command::new(bin())
        .args(["eval", "--policy", url, "--privileged", "--mode", mode])
        .args(["--episodes", "4", "--jobs", "4", "--json"])
        .args(extra)
        .env("RUST_LOG", "warn")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    serde_json::from_slice(&out.stdout).unwrap_or_else(|e| panic!("{e}: {stderr}"))
}

/// A report less what differs between two runs of the same episodes: wall times and how the
/// decisions went out.
fn scored(mut r: Value) -> Value {
    let o = r.as_object_mut().unwrap();
    o.remove("total_wall_s");
    o.remove("batching");
    for e in o["episodes"].as_array_mut().unwrap() {
        e.as_object_mut().unwrap().remove("wall_s");
    }
    r
}

#[test]
fn the_oracle_over_actbatch_gives_local_reports_identical_to_act() {
    let (_oracle, url) = batch_oracle(4);
    for mode in ["online", "offline"] {
        // A long gather window: a batch goes when all four episodes wait, so batches of more
        // than one decision are sure to happen.
        let batched = eval(&url, mode, &["--batch-gather-ms", "200"]);
        let single = eval(&url, mode, &["--max-batch", "1"]);
        let b = &batched["batching"];
        let (calls, decisions) = (b["calls"].as_u64().unwrap(), b["decisions"].as_u64().unwrap());
        assert!(calls > 0 && decisions > calls, "{mode}: {b}");
        assert_eq!(single["batching"]["calls"], 0, "{mode}: {single:#}");
        assert_eq!(batched["episodes"].as_array().unwrap().len(), 4);
        if mode == "online" {
            assert_eq!(batched["sr"], 1.0, "{batched:#}");
        } else {
            assert!(batched["mse_samples"].as_u64().unwrap() > 0, "{batched:#}");
        }
        let (a, s) = (scored(batched), scored(single));
        assert_eq!(
            serde_json::to_string(&a).unwrap(),
            serde_json::to_string(&s).unwrap(),
            "{mode}: batched and single reports differ"
        );
    }
}

/// Each episode's tasks by key, as the run's view shows them.
fn tasks_by_episode(view: &Value) -> BTreeMap<String, Value> {
    (view["latest_run"]["evaluation"]["episodes"]
        .as_array()
        .unwrap()
        .iter())
    .map(|e| (e["key"].as_str().unwrap().to_string(), e["tasks"].clone()))
    .collect()
}

fn metric(text: &str, name: &str) -> f64 {
    (text.lines())
        .find_map(|l| l.strip_prefix(name)?.strip_prefix(' '))
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or(0.0)
}

#[tokio::test(flavor = "multi_thread")]
async fn the_oracle_over_actbatch_scores_as_over_act_through_serve_and_workers() {
    let fx = ControlFixture::new("[control]\nlease_s = 10\nreaper_interval_s = 1\n");
    let server = fx.serve(4);
    let mut views = Vec::new();
    for max_batch in [4, 0] {
        let (_oracle, url) = batch_oracle(max_batch);
        let body = json!({"endpoint": url, "split": "dev", "episodes": 4, "reference": true});
        let (status, reg) = register_policy(&server, ADMIN, body).await;
        assert_eq!(status, 201, "{reg}");
        let id = reg["id"].as_i64().unwrap();
        let view = wait_for(&server, id, ADMIN, "the reference run", finished).await;
        assert_eq!(view["latest_run"]["evaluation"]["state"], "finished", "{view:#}");
        views.push(view);
    }
    let text = get_text(&server, "/metrics").await;
    let calls = metric(&text, "kitchen_r_worker_policy_batch_calls_total");
    let decisions = metric(&text, "kitchen_r_worker_policy_batched_decisions_total");
    assert!(calls > 0.0 && decisions > calls, "{text}");
    let (batched, single) = (tasks_by_episode(&views[0]), tasks_by_episode(&views[1]));
    // Four online episodes and their four offline twins, each task as over Act.
    assert_eq!(batched.len(), 8, "{:#}", views[0]);
    assert_eq!(batched, single);
    assert_eq!(views[0]["latest_run"]["scores"], views[1]["latest_run"]["scores"]);
}

/// The starter kit's Python server declaring `--max-batch 4`, registered by a team and run by
/// `serve`'s two slots: the workers reach it through ActBatch, every task ends with a reason
/// and the run is scored.
#[tokio::test(flavor = "multi_thread")]
async fn the_python_starter_kit_answers_actbatch_through_serve() {
    let Some((_kit, url)) = starter_kit(&["--max-batch", "4"]) else {
        return;
    };
    // One short task per episode: the kit's placeholder policy never succeeds.
    let fx = ControlFixture::new(
        "[control]\nlease_s = 10\nreaper_interval_s = 1\nmax_plan_steps = 1\ntask_time_limit_s = 5.0\n",
    );
    let server = fx.serve(2);
    let token = team(&server, "batchers").await;
    let body = json!({"endpoint": url, "split": "dev", "episodes": 2});
    let (status, reg) = register_policy(&server, &token, body).await;
    assert_eq!(status, 201, "{reg}");
    let id = reg["id"].as_i64().unwrap();
    let view = wait_for(&server, id, &token, "the starter kit's batched run", finished).await;
    assert_eq!(view["latest_run"]["evaluation"]["state"], "finished", "{view:#}");
    assert!(view["latest_run"]["scores"]["sr"].as_f64().is_some(), "{view:#}");
    let tasks = tasks_by_episode(&view);
    assert_eq!(
        tasks.len(),
        4,
        "two online episodes and their offline twins: {view:#}"
    );
    let text = get_text(&server, "/metrics").await;
    let calls = metric(&text, "kitchen_r_worker_policy_batch_calls_total");
    let decisions = metric(&text, "kitchen_r_worker_policy_batched_decisions_total");
    assert!(calls > 0.0 && decisions >= calls, "{text}");
}

/// A policy that declares `max_batch` 4 and answers every ActBatch with one chunk too few.
struct ShortBatches;

const STILL: [f32; 10] = [0.0, 0.0, 0.35, 0.0, 0.95, 0.0, 1.0, 0.0, 0.0, 1.0];

fn still() -> pb::ActionChunk {
    pb::ActionChunk {
        values: STILL.repeat(16),
        values_f64: Vec::new(),
    }
}

#[tonic::async_trait]
impl PolicyRpc for ShortBatches {
    async fn get_spec(&self, _: Request<pb::GetSpecRequest>) -> Result<Response<pb::PolicySpec>, Status> {
        Ok(Response::new(pb::PolicySpec {
            protocol_version: 1,
            horizon: 16,
            action_dim: 10,
            max_concurrency: 4,
            name: "short batches".into(),
            max_batch: 4,
            cameras: ["base", "gripper"]
                .map(|c| pb::CameraRequest {
                    name: c.into(),
                    width: 8,
                    height: 8,
                    encoding: pb::ImageEncoding::RawRgb8 as i32,
                    depth: false,
                })
                .to_vec(),
            ..Default::default()
        }))
    }
    async fn reset(&self, _: Request<pb::ResetRequest>) -> Result<Response<pb::ResetResponse>, Status> {
        Ok(Response::new(pb::ResetResponse {}))
    }
    async fn act(&self, _: Request<pb::Observation>) -> Result<Response<pb::ActionChunk>, Status> {
        Ok(Response::new(still()))
    }
    async fn act_batch(
        &self,
        req: Request<pb::ObservationBatch>,
    ) -> Result<Response<pb::ActionChunkBatch>, Status> {
        let n = req.into_inner().observations.len();
        Ok(Response::new(pb::ActionChunkBatch {
            chunks: vec![still(); n.saturating_sub(1)],
        }))
    }
}

#[tokio::test(flavor = "multi_thread")]
async fn a_batch_reply_with_the_wrong_count_fails_its_tasks_with_the_reason_and_loses_nothing() {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let url = format!("http://{}", listener.local_addr().unwrap());
    let (reporter, health) = tonic_health::server::health_reporter();
    reporter.set_serving::<PolicyServer<ShortBatches>>().await;
    tokio::spawn(
        tonic::transport::Server::builder()
            .add_service(health)
            .add_service(PolicyServer::new(ShortBatches))
            .serve_with_incoming(tokio_stream::wrappers::TcpListenerStream::new(listener)),
    );
    let fx = ControlFixture::new(
        "[control]\noffline_mse = false\nmax_plan_steps = 1\ntask_time_limit_s = 5.0\n\
         [quota]\nconcurrent_runs = 0\n",
    );
    let server = fx.serve(2);
    let token = team(&server, "short-batches").await;
    let body = json!({"endpoint": url, "split": "dev", "episodes": 3});
    let (status, reg) = register_policy(&server, &token, body).await;
    assert_eq!(status, 201, "{reg}");
    let id = reg["id"].as_i64().unwrap();
    let view = wait_for(&server, id, &token, "the run", finished).await;
    assert_eq!(view["latest_run"]["evaluation"]["state"], "finished", "{view:#}");
    let episodes = tasks_by_episode(&view);
    assert_eq!(episodes.len(), 3, "every episode is counted: {view:#}");
    for tasks in episodes.values() {
        let reason = tasks[0]["failure_reason"].as_str().unwrap_or_default();
        assert!(
            reason.contains("ActBatch: the policy answered") && reason.contains("chunks for"),
            "{reason:?}"
        );
    }
    assert_eq!(view["latest_run"]["scores"]["sr"], 0.0, "{view:#}");
}
