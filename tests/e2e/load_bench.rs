//! `kitchen-r bench load` end to end with tiny parameters: it starts its own server, seeds,
//! loads and checks it. A behaviour test (nothing fails, nothing is lost, something was
//! measured), never a timing assertion: the figures belong to docs/measured/load-benchmark.md, not to CI.

use std::process::Command;

use serde_json::Value;

use crate::support::bin;

#[test]
fn bench_load_runs_end_to_end_without_failures_or_lost_uploads() {
    let out = Command::new(bin())
        .args([
            "bench",
            "load",
            "--submissions",
            "20",
            "--teams",
            "2",
            "--readers",
            "2",
        ])
        .args(["--uploads-per-s", "5", "--seconds", "2", "--json"])
        // A bound for a debug build on a shared machine; the run itself takes seconds.
        .args(["--deadline-s", "300"])
        .env_remove("KITCHEN_R_ADMIN_TOKEN")
        .output()
        .expect("run kitchen-r bench load");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "bench load failed:\n{stderr}");
    let r: Value = serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "not one JSON object ({e}):\n{}",
            String::from_utf8_lossy(&out.stdout)
        )
    });

    assert_eq!(r["server"], "spawned");
    assert_eq!(r["seed"]["ok"], 20, "{r:#}");
    assert_eq!(r["failed_requests"], 0, "{r:#}");
    assert_eq!(r["reads"]["failed"], 0, "{r:#}");
    assert_eq!(r["uploads"]["failed"], 0, "{r:#}");
    assert_eq!(r["uploads_due"], 10, "{r:#}");
    assert!(r["reads"]["throughput_per_s"].as_f64().unwrap() > 0.0, "{r:#}");
    assert!(r["uploads"]["throughput_per_s"].as_f64().unwrap() > 0.0, "{r:#}");
    assert!(r["reads"]["latency_ms"]["p99"].as_f64().is_some(), "{r:#}");

    // Every acknowledged upload is there with its EM, and the board shows each team's best.
    let v = &r["verify"];
    assert_eq!(v["checked"], r["uploads"]["ok"], "{r:#}");
    assert_eq!(v["verified"], v["checked"], "{r:#}");
    assert_eq!(r["all_verified"], true);
    assert_eq!(v["leaderboard_teams"], 2, "{r:#}");
    assert_eq!(v["leaderboard_mismatches"], 0, "{r:#}");

    let db = &r["db"];
    assert_eq!(db["acknowledged"], 30, "{r:#}");
    assert_eq!(db["stored"], 30, "{r:#}");
    assert_eq!(db["stopped_gracefully"], true, "{r:#}");
    assert!(db["kib_per_submission"].as_f64().unwrap() > 0.0, "{r:#}");
}
