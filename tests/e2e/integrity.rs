//! Benchmark integrity end to end: `kitchen-r serve --test-set DIR` on a private test set, a
//! participant's policy endpoint that logs everything it receives, and the rules that keep a
//! team's own endpoint traffic from raising its planning or integrated score.
//!
//! One test, one story: a team uploads a test plan file, runs its policy on the test split,
//! then uploads the ground truth it could have rebuilt from its endpoint's log. The endpoint
//! never saw an instruction id or run number; the later plan file is scored but not ranked and
//! cannot be linked for an integrated run; and no test-split page carries per-instruction data.

use crate::remote_support;
use crate::support;

use std::sync::{Arc, Mutex};

use kitchen_r_contract::server::ServeOptions;
use kitchen_r_core::dataset::Instruction;
use kitchen_r_episode::policy::HORIZON;
use remote_support::{STILL, TestServer, factory};
use serde_json::{Value, json};
use support::*;

/// The first two instructions of the committed public sample, written as a private test set
/// (manifest of a set generated with private phrasings, no seed recorded).
fn private_test_set(dir: &std::path::Path) -> Vec<Instruction> {
    let public = kitchen_r_core::assets::assets_dir().join("dataset/test_ground_truth.jsonl");
    let all: Vec<Instruction> = kitchen_r_core::dataset::read_jsonl(&public).unwrap();
    let picked: Vec<Instruction> = all.into_iter().take(2).collect();
    std::fs::create_dir_all(dir).unwrap();
    let lines: String = (picked.iter())
        .map(|i| serde_json::to_string(i).unwrap() + "\n")
        .collect();
    std::fs::write(dir.join("test_ground_truth.jsonl"), lines).unwrap();
    std::fs::write(dir.join("dev.jsonl"), "").unwrap();
    let manifest = json!({
        "kind": "private",
        "generator_version": kitchen_r_core::dataset::GENERATOR_VERSION,
        "templates": 58,
        "dev": 0,
        "test": picked.len(),
        "private_phrasings": {"templates": 1, "phrasings": 4, "sha256": "0".repeat(64)},
    });
    std::fs::write(dir.join("manifest.json"), manifest.to_string()).unwrap();
    picked
}

fn plan_file(items: &[Instruction], wrong: bool) -> String {
    (items.iter())
        .map(|i| {
            let plan: Vec<&str> = match wrong {
                true => vec!["move to the nowhere zone"],
                false => i.plan.iter().map(String::as_str).collect(),
            };
            line(&i.id, &plan) + "\n"
        })
        .collect()
}

async fn upload(server: &Server, token: &str, body: String) -> Value {
    let (status, v) = submit(server, Some(token), "test", body).await;
    assert_eq!(status, 201, "{v}");
    v
}

#[test]
fn endpoint_traffic_cannot_raise_a_teams_planning_or_integrated_score() {
    // What the participant's endpoint receives, as it would log it.
    let log: Arc<Mutex<Vec<String>>> = Arc::default();
    let seen = log.clone();
    let policy = TestServer::start(
        factory(
            HORIZON,
            Arc::new(move |input| {
                assert!(input.privileged.is_none());
                seen.lock().unwrap().push(format!(
                    "episode_id={} step={} task={} sub_task={}",
                    input.episode_id, input.step, input.task_index, input.sub_task
                ));
                Ok(vec![STILL; HORIZON])
            }),
        ),
        ServeOptions::default(),
    );

    let fx = ControlFixture::new("[control]\ntask_time_limit_s = 1.0\nmax_plan_steps = 1\n");
    let set_dir = fx.dir.path().join("private-set");
    let truth = private_test_set(&set_dir);
    let config = fx.dir.path().join("server.toml");
    let text = std::fs::read_to_string(&config).unwrap();
    let text = format!("test_set = \"{}\"\ncontest = true\n{text}", set_dir.display());
    std::fs::write(&config, text).unwrap();
    let server = fx.serve(1);
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(the_story(&server, &policy, &truth, &log));
}

async fn the_story(server: &Server, policy: &TestServer, truth: &[Instruction], log: &Mutex<Vec<String>>) {
    let token = team(server, "Loggers").await;

    // A plan file before any policy run: ranked.
    let before = upload(server, &token, plan_file(truth, true)).await;
    let before_id = before["id"].as_i64().unwrap();

    let body = json!({"endpoint": policy.url(), "split": "test"});
    let (status, reg) = register_policy(server, &token, body).await;
    assert_eq!(status, 201, "{reg}");
    let run = reg["id"].as_i64().unwrap();
    let view = wait_for(server, run, &token, "the test policy run", finished).await;

    // 1. Nothing the endpoint received names an instruction or the run.
    let received = log.lock().unwrap().clone();
    assert!(!received.is_empty(), "the endpoint was called");
    for entry in &received {
        let id = entry
            .split_whitespace()
            .next()
            .unwrap()
            .trim_start_matches("episode_id=");
        assert!(
            id.len() == 27 && id.starts_with("ep-") && id[3..].chars().all(|c| c.is_ascii_hexdigit()),
            "episode id is not opaque: {entry}"
        );
        for i in truth {
            assert!(!entry.contains(&i.id), "{entry} names {}", i.id);
        }
        assert!(!entry.contains(&format!("r{run}/")), "{entry} names the run");
    }

    // 2. Test-split pages are aggregate only.
    let text = view.to_string();
    for i in truth {
        assert!(
            !text.contains(&i.id),
            "the policy run page names {}: {view:#}",
            i.id
        );
    }
    let eval = &view["latest_run"]["evaluation"];
    assert_eq!(eval["episodes"], json!([]), "{view:#}");
    assert!(
        eval["failure_counts"].as_array().is_some_and(|c| !c.is_empty()),
        "{view:#}"
    );
    let (_, plan_view) = get_json(server, &format!("/api/v1/submissions/{before_id}"), Some(&token)).await;
    assert_eq!(
        plan_view["latest_run"]["instructions"],
        json!([]),
        "{plan_view:#}"
    );
    assert_eq!(
        plan_view["latest_run"]["instructions_total"],
        truth.len(),
        "{plan_view:#}"
    );
    assert_eq!(plan_view["ranked"], true, "{plan_view:#}");
    for i in truth {
        assert!(!plan_view.to_string().contains(&i.id), "{plan_view:#}");
    }

    // 3. The ground truth the log reveals, uploaded afterwards: scored, shown, not ranked.
    let after = upload(server, &token, plan_file(truth, false)).await;
    assert_eq!(
        after["scores"]["em"], 1.0,
        "a plan file equal to the ground truth scores EM 1: {after}"
    );
    assert!(after["warnings"].to_string().contains("not ranked"), "{after}");
    let after_id = after["id"].as_i64().unwrap();
    let (_, after_view) = get_json(server, &format!("/api/v1/submissions/{after_id}"), Some(&token)).await;
    assert_eq!(after_view["ranked"], false, "{after_view:#}");
    assert!(
        after_view["unranked_reason"]
            .as_str()
            .unwrap()
            .contains("policy run"),
        "{after_view:#}"
    );
    let (_, board) = get_json(server, "/api/v1/leaderboard?track=planning&split=test", None).await;
    let rows = board["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 1, "{board:#}");
    assert_eq!(rows[0]["submission_id"], before_id, "{board:#}");
    assert_eq!(rows[0]["scores"]["em"], 0.0, "{board:#}");

    // 4. An integrated test run cannot link the later plan file; the earlier one it can.
    let body = json!({"endpoint": policy.url(), "split": "test", "plans": after_id});
    let (status, refused) = register_policy(server, &token, body).await;
    assert_eq!(status, 400, "{refused}");
    assert!(
        refused["error"].as_str().unwrap().contains("created after"),
        "{refused}"
    );
    let body = json!({"endpoint": policy.url(), "split": "test", "plans": before_id});
    let (status, linked) = register_policy(server, &token, body).await;
    assert_eq!(status, 201, "{linked}");
    let id = linked["id"].as_i64().unwrap();
    let view = wait_for(server, id, &token, "the integrated run", finished).await;
    assert_eq!(
        view["latest_run"]["scores"]["em"], 0.0,
        "integrated runs show their EM: {view:#}"
    );
}
