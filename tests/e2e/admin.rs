//! The organiser's console end to end (docs/organiser-console.md): `kitchen-r admin backup` against
//! a live server that keeps taking uploads, and a second server started on the copy serving the
//! same leaderboards and submissions; the admin CLI's tables, JSON and errors.

use std::process::Command;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use serde_json::Value;

use crate::support::*;

const CONFIG: &str = "[quota]\ndev_per_day = 0\ntest_per_day = 0\nper_minute = 0\n";

fn file(plans: &[(&str, Vec<&str>)], keep: usize) -> String {
    plans
        .iter()
        .take(keep)
        .map(|(id, p)| line(id, p) + "\n")
        .collect()
}

fn admin_cli(server: &Server, args: &[&str]) -> std::process::Output {
    Command::new(bin())
        .arg("admin")
        .args(args)
        .args(["--server", &server.http])
        .env("KITCHEN_R_ADMIN_TOKEN", ADMIN)
        .output()
        .expect("run kitchen-r admin")
}

/// The rows of a board that belong to `teams`.
async fn rows(server: &Server, track: &str, split: &str, teams: &[&str]) -> Vec<Value> {
    let (status, board) = get_json(
        server,
        &format!("/api/v1/leaderboard?track={track}&split={split}"),
        None,
    )
    .await;
    assert_eq!(status, 200, "{board}");
    board["rows"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|r| teams.contains(&r["team"].as_str().unwrap_or("")))
        .cloned()
        .collect()
}

#[tokio::test]
async fn backup_of_a_live_server_restores_the_same_leaderboard_and_submissions() {
    let fx = Fixture::new(CONFIG);
    let server = fx.serve();
    let alpha = team(&server, "alpha").await;
    let beta = team(&server, "beta").await;
    let gamma = team(&server, "gamma").await;
    let mut ours = Vec::new();
    for (token, split, body) in [
        (&alpha, "dev", file(&dev_plans(), 3)),
        (&alpha, "dev", file(&dev_plans(), 1)),
        (&beta, "dev", file(&dev_plans(), 2)),
        (&alpha, "test", file(&test_plans(), 2)),
        (&beta, "test", file(&test_plans(), 1)),
    ] {
        let (status, v) = submit(&server, Some(token), split, body).await;
        assert_eq!(status, 201, "{v}");
        ours.push((token.clone(), v["id"].as_i64().unwrap()));
    }

    // Another team keeps uploading while the backup is taken: the server is not stopped.
    let stop = Arc::new(AtomicBool::new(false));
    let uploader = {
        let (stop, url, gamma) = (stop.clone(), server.http.clone(), gamma.clone());
        tokio::spawn(async move {
            let mut acked = Vec::new();
            while !stop.load(Ordering::SeqCst) {
                let r = client()
                    .post(format!("{url}/api/v1/submissions/plans?split=dev"))
                    .bearer_auth(&gamma)
                    .body(file(&dev_plans(), 2))
                    .send()
                    .await
                    .unwrap();
                assert_eq!(r.status(), 201);
                let v: Value = r.json().await.unwrap();
                acked.push(v["id"].as_i64().unwrap());
            }
            acked
        })
    };
    tokio::time::sleep(std::time::Duration::from_millis(300)).await;
    let copy = fx.dir.path().join("backup.db");
    let out = {
        let (http, copy) = (server.http.clone(), copy.clone());
        tokio::task::spawn_blocking(move || {
            Command::new(bin())
                .args(["admin", "backup"])
                .arg(&copy)
                .args(["--server", &http, "--admin-token", ADMIN])
                .output()
                .unwrap()
        })
        .await
        .unwrap()
    };
    stop.store(true, Ordering::SeqCst);
    let acked = uploader.await.unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(String::from_utf8_lossy(&out.stdout).contains("backup written"));
    assert!(!acked.is_empty());
    // Refuses to overwrite without --force.
    let again = admin_cli(&server, &["backup", copy.to_str().unwrap()]);
    assert!(!again.status.success());

    // Restore: a new server whose database file is the copy.
    let fx2 = Fixture::new(CONFIG);
    let db = fx2.dir.path().join("db/kitchen-r.db");
    std::fs::create_dir_all(db.parent().unwrap()).unwrap();
    std::fs::copy(&copy, &db).unwrap();
    let restored = fx2.serve();

    for (track, split) in [("planning", "dev"), ("planning", "test")] {
        let live = rows(&server, track, split, &["alpha", "beta"]).await;
        let back = rows(&restored, track, split, &["alpha", "beta"]).await;
        assert_eq!(live.len(), 2, "{track} {split}: {live:?}");
        assert_eq!(live, back, "{track} {split}");
    }
    // Every submission, as its team sees it (team tokens are in the copy too).
    for (token, id) in &ours {
        let path = format!("/api/v1/submissions/{id}");
        let live = get_json(&server, &path, Some(token)).await;
        let back = get_json(&restored, &path, Some(token)).await;
        assert_eq!(live.0, 200);
        assert_eq!(live, back, "submission {id}");
    }
    // The copy is one snapshot: the uploads it holds are a prefix of those acknowledged.
    let mut present = Vec::new();
    for id in &acked {
        let (status, _) = get_json(&restored, &format!("/api/v1/submissions/{id}"), Some(&gamma)).await;
        present.push(status == 200);
    }
    let k = present.iter().take_while(|p| **p).count();
    assert!(present[k..].iter().all(|p| !p), "{present:?}");

    // The admin CLI against the restored server.
    let q = admin_cli(&restored, &["queue", "--json"]);
    assert!(q.status.success(), "{}", String::from_utf8_lossy(&q.stderr));
    let v: Value = serde_json::from_slice(&q.stdout).unwrap();
    assert_eq!(v["jobs"]["queued"], 0);
    let runs = admin_cli(&restored, &["runs"]);
    assert!(String::from_utf8_lossy(&runs.stdout).contains("no policy run yet"));
    let missing = admin_cli(&restored, &["cancel", "424242"]);
    assert!(!missing.status.success());
    assert!(
        String::from_utf8_lossy(&missing.stderr).contains("run 424242 not found (HTTP 404)"),
        "{}",
        String::from_utf8_lossy(&missing.stderr)
    );
}

fn json_of(out: &std::process::Output) -> Value {
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap()
}

#[tokio::test(flavor = "multi_thread")]
async fn cancel_through_the_cli_stops_a_run_a_worker_is_simulating() {
    let fx = ControlFixture::new("[control]\nlease_s = 4\nreaper_interval_s = 1\noffline_mse = false\n");
    let server = fx.serve(0);
    let (_oracle, url) = oracle_policy();
    let body = serde_json::json!({"endpoint": url, "split": "dev", "episodes": 4, "reference": true});
    let (status, reg) = register_policy(&server, ADMIN, body).await;
    assert_eq!(status, 201, "{reg}");
    let id = reg["id"].as_i64().unwrap();
    let _worker = worker(&server, 1, "console-worker");
    wait_for(&server, id, ADMIN, "an episode to start", |e| {
        e["episodes_running"].as_u64().unwrap_or(0) >= 1
    })
    .await;

    let runs = json_of(&admin_cli(&server, &["runs", "--json"]));
    let run = runs["runs"]
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["submission"] == id)
        .unwrap_or_else(|| panic!("{runs:#}"))
        .clone();
    assert_eq!(run["state"], "active");
    let workers = json_of(&admin_cli(&server, &["workers", "--json"]));
    let w = &workers["workers"][0];
    assert_eq!(w["worker"], "console-worker", "{workers:#}");
    assert_eq!(w["current"].as_array().unwrap().len(), 1, "{workers:#}");
    let table = admin_cli(&server, &["workers"]);
    assert!(String::from_utf8_lossy(&table.stdout).contains("console-worker"));

    let run_id = run["run"].as_i64().unwrap().to_string();
    let cancel = admin_cli(&server, &["cancel", &run_id]);
    assert!(
        cancel.status.success(),
        "{}",
        String::from_utf8_lossy(&cancel.stderr)
    );
    assert!(String::from_utf8_lossy(&cancel.stdout).contains("cancelled by organiser"));
    let (_, view) = get_json(&server, &format!("/api/v1/submissions/{id}"), Some(ADMIN)).await;
    let done = view["latest_run"]["evaluation"]["episodes_done"].clone();
    assert_eq!(view["latest_run"]["evaluation"]["state"], "cancelled", "{view:#}");

    // The worker's episode ends or is abandoned; nothing more is leased or counted.
    tokio::time::sleep(std::time::Duration::from_secs(5)).await;
    let (_, later) = get_json(&server, &format!("/api/v1/submissions/{id}"), Some(ADMIN)).await;
    assert_eq!(
        later["latest_run"]["evaluation"]["episodes_done"], done,
        "{later:#}"
    );
    let queue = json_of(&admin_cli(&server, &["queue", "--json"]));
    assert_eq!(queue["jobs"]["leased"], 0, "{queue:#}");
    assert_eq!(queue["jobs"]["queued"], 0, "{queue:#}");
    let again = admin_cli(&server, &["cancel", &run_id]);
    assert!(!again.status.success());
    assert!(String::from_utf8_lossy(&again.stderr).contains("is cancelled"));
}
