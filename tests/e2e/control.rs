//! Control track end to end, every part a real process on loopback: `kitchen-r serve` with its
//! SQLite queue, in-process or standalone `kitchen-r worker` processes, and policies served over
//! gRPC (`kitchen-r policy oracle` and the Python starter kit).
//!
//! Each test protects one promise of the issue: the oracle scores SR ≥ 0.95 through the server;
//! a worker killed with SIGKILL mid-episode loses nothing and counts nothing twice; a server
//! restarted mid-run resumes it; a participant's starter kit completes a run with a score; a
//! private address is refused at registration.

use crate::remote_support;
use crate::support;

use std::collections::BTreeSet;
use std::sync::Arc;

use kitchen_r_contract::server::ServeOptions;

use serde_json::{Value, json};
use support::*;

/// Small runs: four dev instructions, shorter leases so a dead worker's job comes back quickly.
const CONFIG: &str = "[control]\nlease_s = 4\nreaper_interval_s = 1\n";

fn episodes(view: &Value) -> Vec<Value> {
    view["latest_run"]["evaluation"]["episodes"]
        .as_array()
        .cloned()
        .unwrap_or_default()
}

/// Every episode key appears once and every one of them finished.
fn assert_counted_once(view: &Value, expected: usize) {
    let eps = episodes(view);
    let keys: BTreeSet<&str> = eps.iter().filter_map(|e| e["key"].as_str()).collect();
    assert_eq!(keys.len(), eps.len(), "an episode was counted twice: {view:#}");
    assert_eq!(eps.len(), expected, "{view:#}");
    let e = &view["latest_run"]["evaluation"];
    assert_eq!(e["episodes_done"], expected, "{view:#}");
    assert_eq!(e["episodes_total"], expected, "{view:#}");
}

/// Register an organiser reference run of `url` on the first `episodes` dev instructions.
async fn register_reference(server: &Server, url: &str, episodes: u32) -> i64 {
    let body = json!({"endpoint": url, "split": "dev", "episodes": episodes, "reference": true});
    let (status, reg) = register_policy(server, ADMIN, body).await;
    assert_eq!(status, 201, "{reg}");
    reg["id"].as_i64().unwrap()
}

fn sr(view: &Value) -> f64 {
    view["latest_run"]["scores"]["sr"]
        .as_f64()
        .unwrap_or_else(|| panic!("no SR in {view:#}"))
}

#[tokio::test(flavor = "multi_thread")]
async fn the_oracle_reference_run_scores_at_least_095_through_serve() {
    let fx = ControlFixture::new(CONFIG);
    let server = fx.serve(2);
    let (_oracle, url) = oracle_policy();
    let id = register_reference(&server, &url, 4).await;
    let view = wait_for(&server, id, ADMIN, "the reference run", finished).await;
    assert_eq!(view["latest_run"]["evaluation"]["state"], "finished", "{view:#}");
    // Four online episodes and their four offline (MSE) twins.
    assert_counted_once(&view, 8);
    assert!(sr(&view) >= 0.95, "{view:#}");
    let mse = view["latest_run"]["scores"]["mse"].as_f64().unwrap();
    assert!(
        mse.is_finite() && mse < 0.05,
        "the oracle predicts the expert: {view:#}"
    );

    let (_, board) = get_json(&server, "/api/v1/leaderboard?track=control&split=dev", None).await;
    let rows = board["rows"].as_array().unwrap();
    assert!(
        rows.iter()
            .any(|r| r["baseline"] == true && r["submission_id"] == id),
        "{board:#}"
    );
    // Its intervals and results card (docs/reference/leaderboard.md): SR over the 4 online
    // episodes and per task kind, MSE over the offline tasks; the rules every job carried.
    let row = rows.iter().find(|r| r["submission_id"] == id).unwrap();
    let iv = &row["intervals"];
    let (low, high) = (iv["sr"][0].as_f64().unwrap(), iv["sr"][1].as_f64().unwrap());
    assert!(
        low <= sr(&view) && sr(&view) <= high && high - low > 0.1,
        "{row:#}"
    );
    assert!(iv["mse"][0].as_f64().unwrap() <= mse, "{row:#}");
    for kind in ["navigation", "manipulation", "pick", "place"] {
        assert!(iv["sr_by_kind"][kind]["tasks"].as_u64().unwrap() > 0, "{row:#}");
    }
    let card = &row["card"];
    assert_eq!(card["episodes"], 8, "{card:#}");
    assert_eq!(card["seeds"], json!([0]), "{card:#}");
    assert_eq!(card["grasp_mode"], "abstract", "{card:#}");
    assert_eq!(card["observations"], "standard", "{card:#}");
    assert_eq!(card["config_hash"].as_str().unwrap().len(), 16, "{card:#}");
    let config = card["config"][0].as_str().unwrap();
    assert!(
        config.starts_with("seed=0 task_time_limit=120 execute=")
            && config.ends_with("grasp=abstract privileged_observations=none"),
        "{card:#}"
    );
    let csv = client()
        .get(server.url("/api/v1/leaderboard?track=control&split=dev&format=csv"))
        .send()
        .await
        .unwrap()
        .text()
        .await
        .unwrap();
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    let at = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let line: Vec<&str> = (csv.lines())
        .find(|l| l.contains(&format!(",{id},")))
        .unwrap()
        .split(',')
        .collect();
    assert!(
        !line[at("sr_low")].is_empty() && !line[at("sr_pick_high")].is_empty(),
        "{csv}"
    );
}

#[tokio::test(flavor = "multi_thread")]
async fn a_sigkilled_worker_loses_no_episode_and_counts_none_twice() {
    let fx = ControlFixture::new(&format!("{CONFIG}offline_mse = false\n"));
    let server = fx.serve(0);
    let (_oracle, url) = oracle_policy();
    let id = register_reference(&server, &url, 3).await;

    let mut first = worker(&server, 1, "doomed");
    wait_for(&server, id, ADMIN, "an episode to start", |e| {
        e["episodes_running"].as_u64().unwrap_or(0) >= 1
    })
    .await;
    first.kill();

    let _second = worker(&server, 2, "survivor");
    let view = wait_for(&server, id, ADMIN, "the run after the kill", finished).await;
    assert_eq!(view["latest_run"]["evaluation"]["state"], "finished", "{view:#}");
    assert_counted_once(&view, 3);
    assert!(sr(&view) >= 0.95, "{view:#}");
    let retried = episodes(&view)
        .iter()
        .filter(|e| e["attempt"].as_u64().unwrap_or(1) >= 2)
        .count();
    assert!(
        retried >= 1,
        "the killed worker's episode was leased again: {view:#}"
    );
}

#[tokio::test(flavor = "multi_thread")]
async fn a_server_restarted_mid_run_resumes_the_run() {
    let fx = ControlFixture::new(&format!("{CONFIG}offline_mse = false\n"));
    let (_oracle, url) = oracle_policy();
    let id = {
        let server = fx.serve(1);
        let id = register_reference(&server, &url, 3).await;
        wait_for(&server, id, ADMIN, "the first episode", |e| {
            e["episodes_done"].as_u64().unwrap_or(0) >= 1
        })
        .await;
        id
        // Dropping the server kills it (SIGKILL) mid-run.
    };
    let server = fx.serve(1);
    let view = wait_for(&server, id, ADMIN, "the resumed run", finished).await;
    assert_eq!(view["latest_run"]["evaluation"]["state"], "finished", "{view:#}");
    assert_counted_once(&view, 3);
    assert!(sr(&view) >= 0.95, "{view:#}");
}

#[tokio::test(flavor = "multi_thread")]
async fn the_python_starter_kit_completes_a_run_with_a_score() {
    let Some((_kit, url)) = starter_kit(&[]) else {
        return;
    };
    // One task per episode with a short limit: the kit's placeholder policy never succeeds, so
    // every task runs to its limit.
    let fx = ControlFixture::new(&format!("{CONFIG}max_plan_steps = 1\ntask_time_limit_s = 10.0\n"));
    let server = fx.serve(2);
    let token = team(&server, "starters").await;
    let (status, reg) = register_policy(
        &server,
        &token,
        json!({"endpoint": url, "split": "dev", "episodes": 2}),
    )
    .await;
    assert_eq!(status, 201, "{reg}");
    let id = reg["id"].as_i64().unwrap();
    let view = wait_for(&server, id, &token, "the starter kit's run", finished).await;
    assert_eq!(view["latest_run"]["evaluation"]["state"], "finished", "{view:#}");
    assert_counted_once(&view, 4);
    let scores = &view["latest_run"]["scores"];
    assert!(scores["sr"].as_f64().is_some(), "{view:#}");
    assert!(scores["mse"].as_f64().is_some_and(f64::is_finite), "{view:#}");
    for e in episodes(&view).iter().filter(|e| e["mode"] == "online") {
        for t in e["tasks"].as_array().unwrap() {
            if t["success"] == false {
                assert!(!t["failure_reason"].as_str().unwrap().is_empty(), "{e:#}");
            }
        }
    }
    let (_, board) = get_json(&server, "/api/v1/leaderboard?track=control&split=dev", None).await;
    assert!(
        board["rows"]
            .as_array()
            .unwrap()
            .iter()
            .any(|r| r["team"] == "starters" && r["rank"] == 1),
        "{board:#}"
    );
}

#[tokio::test(flavor = "multi_thread")]
async fn a_private_address_endpoint_is_refused_at_registration() {
    let fx = ControlFixture::new(CONFIG);
    let server = fx.serve(0);
    let token = team(&server, "sneaky").await;
    let (status, v) = register_policy(
        &server,
        &token,
        json!({"endpoint": "http://10.1.2.3:50051", "split": "dev"}),
    )
    .await;
    assert_eq!(status, 400, "{v}");
    assert_eq!(v["code"], "endpoint_refused", "{v}");
    let msg = v["error"].as_str().unwrap();
    assert!(msg.contains("10.1.2.3"), "the refusal names the address: {msg}");
    // Nothing of the refused registration was stored.
    let (_, board) = get_json(&server, "/api/v1/leaderboard?track=control&split=dev", None).await;
    assert!(board["rows"].as_array().unwrap().is_empty(), "{board:#}");
}

#[test]
fn misbehaving_policies_fail_their_tasks_with_the_reason_while_the_runs_complete() {
    use kitchen_r_episode::policy::HORIZON as H;
    use remote_support::{STILL, TestServer, factory};
    let scripted = |answer: fn() -> Vec<[f64; 10]>| {
        TestServer::start(
            factory(H, Arc::new(move |_| Ok(answer()))),
            ServeOptions::default(),
        )
    };
    let policies = [
        ("is not finite", scripted(|| vec![[f64::NAN; 10]; H])),
        ("expected 160 values", scripted(|| vec![STILL; 3])),
        (
            "did not answer within",
            scripted(|| {
                std::thread::sleep(std::time::Duration::from_millis(1500));
                vec![STILL; H]
            }),
        ),
    ];
    let fx = ControlFixture::new(&format!(
        "{CONFIG}offline_mse = false\nmax_plan_steps = 1\ntask_time_limit_s = 5.0\n\
         [policy]\ncall_deadline_ms = 300\nmax_successive_timeouts = 1\n[quota]\nconcurrent_runs = 0\n"
    ));
    let server = fx.serve(2);
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let token = team(&server, "chaos").await;
        let mut runs = Vec::new();
        for (needle, policy) in &policies {
            let (status, reg) = register_policy(
                &server,
                &token,
                json!({"endpoint": policy.url(), "split": "dev", "episodes": 1}),
            )
            .await;
            assert_eq!(status, 201, "{reg}");
            runs.push((*needle, reg["id"].as_i64().unwrap()));
        }
        for (needle, id) in runs {
            let view = wait_for(&server, id, &token, needle, finished).await;
            assert_eq!(view["latest_run"]["evaluation"]["state"], "finished", "{view:#}");
            assert_counted_once(&view, 1);
            assert_eq!(sr(&view), 0.0, "{view:#}");
            let task = &episodes(&view)[0]["tasks"][0];
            let reason = task["failure_reason"].as_str().unwrap_or_default();
            assert!(reason.contains(needle), "expected {needle:?} in {reason:?}");
        }
    });
}

/// Contract v1.1 through `serve`: a policy whose chunks slip within tolerance (gripper 1.0001,
/// quaternion norm 1.02) is not failed for it; the episode's log shows the counted corrections.
#[test]
fn slips_within_tolerance_are_reported_as_warnings_not_failures() {
    use kitchen_r_episode::policy::HORIZON as H;
    use remote_support::{STILL, TestServer, factory};
    let sloppy = TestServer::start(
        factory(
            H,
            Arc::new(|_| {
                let mut c = vec![STILL; H];
                c[0][9] = 1.0001;
                c[1][6] = 1.02;
                Ok(c)
            }),
        ),
        ServeOptions::default(),
    );
    let fx = ControlFixture::new(&format!(
        "{CONFIG}offline_mse = false\nmax_plan_steps = 1\ntask_time_limit_s = 2.0\n"
    ));
    let server = fx.serve(1);
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let token = team(&server, "sloppy").await;
        let (status, reg) = register_policy(
            &server,
            &token,
            json!({"endpoint": sloppy.url(), "split": "dev", "episodes": 1}),
        )
        .await;
        assert_eq!(status, 201, "{reg}");
        let id = reg["id"].as_i64().unwrap();
        let view = wait_for(&server, id, &token, "time limit", finished).await;
        let episode = &episodes(&view)[0];
        let reason = episode["tasks"][0]["failure_reason"].as_str().unwrap_or_default();
        assert!(
            reason.contains("time limit of 2 s reached"),
            "not a chunk failure: {reason:?}"
        );
        let log = episode["log_tail"].as_str().unwrap_or_default();
        // 20 steps at 8 per chunk: 3 chunks, each with one clamp and one normalisation.
        assert!(
            log.contains("task 0 warning: 6 corrections: 3 quaternions normalised")
                && log.contains("3 gripper values clamped"),
            "{log}"
        );
    });
}
