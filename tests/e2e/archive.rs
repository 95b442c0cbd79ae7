//! Results people can trust and keep (docs/contest/archive.md) through the real binary: `admin
//! export` then `admin import` into a fresh server gives the same boards, byte for byte in the CSV;
//! an altered archive and a non-empty server are refused; `admin verify` replays a policy run's
//! traces and a tampered trace marks the run unverified; `admin reevaluate` runs episodes again
//! against the served oracle policy and reports intervals.

use std::io::Read;
use std::path::Path;
use std::process::{Command, Output};

use serde_json::{Value, json};

use crate::support::*;

const PLANS_CONFIG: &str = "[quota]\ndev_per_day = 0\ntest_per_day = 0\nper_minute = 0\n";
const CONTROL_CONFIG: &str = "[control]\noffline_mse = false\nmax_plan_steps = 1\ntask_time_limit_s = 3.0\n\
                              [quota]\nconcurrent_runs = 0\n[video]\nprerender = \"none\"\n";

fn admin(server: &Server, args: &[&str]) -> Output {
    Command::new(bin())
        .arg("admin")
        .args(args)
        .args(["--server", &server.http])
        .env("KITCHEN_R_ADMIN_TOKEN", ADMIN)
        .output()
        .expect("run kitchen-r admin")
}

async fn csv(server: &Server, track: &str, split: &str) -> Vec<u8> {
    let path = format!("/api/v1/leaderboard?track={track}&split={split}&format=csv");
    let r = client().get(server.url(&path)).send().await.unwrap();
    assert_eq!(r.status(), 200);
    r.bytes().await.unwrap().to_vec()
}

fn plans(items: &[(&str, Vec<&str>)], keep: usize) -> String {
    items
        .iter()
        .take(keep)
        .map(|(id, p)| line(id, p) + "\n")
        .collect()
}

/// The archive's files: (path, bytes), in order.
fn unpack(archive: &Path) -> Vec<(String, Vec<u8>)> {
    let zst = zstd::stream::Decoder::new(std::fs::File::open(archive).unwrap()).unwrap();
    let mut tar = tar::Archive::new(zst);
    let mut out = Vec::new();
    for e in tar.entries().unwrap() {
        let mut e = e.unwrap();
        let path = e.path().unwrap().to_string_lossy().into_owned();
        let mut b = Vec::new();
        e.read_to_end(&mut b).unwrap();
        out.push((path, b));
    }
    out
}

fn pack(files: &[(String, Vec<u8>)], archive: &Path) {
    let out = std::fs::File::create(archive).unwrap();
    let mut tar = tar::Builder::new(zstd::stream::Encoder::new(out, 3).unwrap());
    for (path, b) in files {
        let mut h = tar::Header::new_gnu();
        h.set_size(b.len() as u64);
        h.set_mode(0o644);
        tar.append_data(&mut h, path, b.as_slice()).unwrap();
    }
    tar.into_inner().unwrap().finish().unwrap();
}

#[tokio::test]
async fn an_exported_contest_imports_into_a_fresh_server_with_the_same_boards_and_an_altered_one_is_refused()
{
    let fx = Fixture::new(PLANS_CONFIG);
    let server = fx.serve();
    let alpha = team(&server, "alpha").await;
    let beta = team(&server, "beta").await;
    for (token, split, body) in [
        (&alpha, "dev", plans(&dev_plans(), 3)),
        (&alpha, "dev", plans(&dev_plans(), 1)),
        (&beta, "dev", plans(&dev_plans(), 2)),
        (&alpha, "test", plans(&test_plans(), 2)),
        (&beta, "test", plans(&test_plans(), 1)),
    ] {
        let (status, v) = submit(&server, Some(token), split, body).await;
        assert_eq!(status, 201, "{v}");
    }
    let archive = fx.dir.path().join("contest.tar.zst");
    let a = archive.to_string_lossy().into_owned();
    let exported = ok(admin(&server, &["export", "--out", &a]));
    assert!(err(&exported).contains("hidden answers"), "{}", err(&exported));

    // Readable without our binary: a manifest with every file's sha256, JSON Lines, the dataset
    // with the test answers, and no secret.
    let files = unpack(&archive);
    assert_eq!(files[0].0, "manifest.json");
    let manifest: Value = serde_json::from_slice(&files[0].1).unwrap();
    assert_eq!(manifest["format"], "kitchen-r-contest-archive");
    assert_eq!(manifest["format_version"], 1);
    assert_eq!(manifest["holds_hidden_answers"], true);
    assert_eq!(manifest["files"].as_array().unwrap().len(), files.len() - 1);
    let text = |name: &str| {
        let f = files
            .iter()
            .find(|(p, _)| p == name)
            .unwrap_or_else(|| panic!("no {name}"));
        String::from_utf8(f.1.clone()).unwrap()
    };
    assert!(text("dataset/test_ground_truth.jsonl").contains("test-0001"));
    let teams = text("db/teams.jsonl");
    assert_eq!(teams.lines().count(), 2, "{teams}");
    assert!(!teams.contains("token"), "{teams}");
    assert!(!text("configs/server.json").contains(ADMIN));
    let subs = text("db/submissions.jsonl");
    let first: Value = serde_json::from_str(subs.lines().next().unwrap()).unwrap();
    assert!(first["body_z"].as_str().unwrap().contains("dev-0001"), "{first}");

    // A fresh server: same boards, byte for byte.
    let fresh_fx = Fixture::new(PLANS_CONFIG);
    let fresh = fresh_fx.serve();
    // An altered file is refused whole, before anything is loaded.
    let mut altered = files.clone();
    let i = altered
        .iter()
        .position(|(p, _)| p == "db/scoring_runs.jsonl")
        .unwrap();
    altered[i].1 = String::from_utf8(altered[i].1.clone())
        .unwrap()
        .replacen("\"em\":", "\"em\": ", 1)
        .into_bytes();
    let bad = fx.dir.path().join("altered.tar.zst");
    pack(&altered, &bad);
    let refused = admin(&fresh, &["import", &bad.to_string_lossy()]);
    assert!(!refused.status.success());
    assert!(
        err(&refused).contains("does not match the manifest"),
        "{}",
        err(&refused)
    );

    let imported = ok(admin(&fresh, &["import", &a]));
    assert!(
        out(&imported).contains("teams have no token"),
        "{}",
        out(&imported)
    );
    for split in ["dev", "test"] {
        let (before, after) = (
            csv(&server, "planning", split).await,
            csv(&fresh, "planning", split).await,
        );
        assert!(before.len() > 40, "{}", String::from_utf8_lossy(&before));
        assert_eq!(
            String::from_utf8_lossy(&before),
            String::from_utf8_lossy(&after),
            "{split}"
        );
    }
    // Importing again: the server is not empty any more.
    let twice = admin(&fresh, &["import", &a]);
    assert!(!twice.status.success());
    assert!(err(&twice).contains("not empty"), "{}", err(&twice));
    // Nothing of it reaches a team: the routes are the organiser's.
    let r = client()
        .post(server.url("/api/v1/admin/export"))
        .bearer_auth(&alpha)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 403);
}

fn trace_files(dir: &Path) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    if let Ok(rd) = std::fs::read_dir(dir) {
        for e in rd.flatten() {
            let p = e.path();
            if p.is_dir() {
                out.extend(trace_files(&p));
            } else if p.to_string_lossy().ends_with(".json.gz") {
                out.push(p);
            }
        }
    }
    out
}

#[test]
fn a_policy_run_verifies_a_tampered_trace_makes_it_unverified_and_reevaluate_reports_intervals() {
    let (_policy, url) = oracle_policy();
    let fx = ControlFixture::new(CONTROL_CONFIG);
    let server = fx.serve(1);
    let rt = tokio::runtime::Runtime::new().unwrap();
    let run = rt.block_on(async {
        let alpha = team(&server, "alpha").await;
        let (status, reg) = register_policy(
            &server,
            &alpha,
            json!({"endpoint": url, "split": "dev", "episodes": 2}),
        )
        .await;
        assert_eq!(status, 201, "{reg}");
        let id = reg["id"].as_i64().unwrap();
        let v = wait_for(&server, id, &alpha, "the dev run", finished).await;
        let run = v["latest_run"]["id"].as_i64().unwrap();
        // Traces are uploaded after the results.
        for _ in 0..200 {
            let (_, plan) = get_json(
                &server,
                &format!("/api/v1/admin/runs/{run}/verification"),
                Some(ADMIN),
            )
            .await;
            let eps = plan["episodes"].as_array().cloned().unwrap_or_default();
            if eps.len() == 2 && eps.iter().all(|e| e["trace_sha256"].is_string()) {
                break;
            }
            tokio::time::sleep(std::time::Duration::from_millis(200)).await;
        }
        run
    });
    let run_s = run.to_string();
    let verified = ok(admin(&server, &["verify", &run_s]));
    assert!(out(&verified).contains("VERIFIED"), "{}", out(&verified));

    let again = ok(admin(
        &server,
        &["reevaluate", &run_s, "--episodes", "1", "--json"],
    ));
    let report: Value = serde_json::from_str(out(&again).trim()).unwrap();
    assert_eq!(report["episodes"], 1, "{report}");
    assert_eq!(report["fresh"]["tasks"], report["stored"]["tasks"], "{report}");
    let ci = report["fresh"]["sr_95"].as_array().unwrap();
    assert!(ci[0].as_f64().unwrap() <= ci[1].as_f64().unwrap(), "{report}");
    // The oracle answers the same way when asked again.
    assert_eq!(report["episodes_changed"], json!([]), "{report}");

    // Tamper with one stored trace: the run is unverified, on the server too.
    let traces = trace_files(&fx.dir.path().join("db/videos/traces"));
    assert!(!traces.is_empty());
    let mut b = std::fs::read(&traces[0]).unwrap();
    let n = b.len();
    b[n / 2] ^= 0x55;
    std::fs::write(&traces[0], &b).unwrap();
    let failed = admin(&server, &["verify", &run_s]);
    assert!(!failed.status.success(), "{}", out(&failed));
    assert!(out(&failed).contains("DISAGREES"), "{}", out(&failed));
    assert!(out(&failed).contains("UNVERIFIED"), "{}", out(&failed));
    let (_, v) = rt.block_on(get_json(&server, "/api/v1/admin/verifications", Some(ADMIN)));
    assert_eq!(v["verifications"][0]["verdict"], "unverified", "{v}");
    assert_eq!(v["verifications"][0]["run"], run, "{v}");
}
