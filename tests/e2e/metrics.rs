//! `GET /metrics` through the real binary: a team's policy evaluation run by a standalone
//! `kitchen-r worker --metrics`, with the server's queue gauges, histograms and request counters
//! scraped before, during and after, and the worker's own endpoint.

use crate::support;

use std::process::Command;
use std::time::Duration;

use serde_json::json;
use support::*;

/// The value of one series (`name{labels}` exactly as rendered), if present.
fn sample(text: &str, series: &str) -> Option<f64> {
    text.lines()
        .find_map(|l| l.strip_prefix(series)?.strip_prefix(' '))
        .and_then(|v| v.trim().parse().ok())
}

fn value(text: &str, series: &str) -> f64 {
    sample(text, series).unwrap_or_else(|| panic!("no series {series} in:\n{text}"))
}

async fn scrape(url: &str) -> String {
    let r = client().get(url).send().await.unwrap();
    assert_eq!(r.status(), 200);
    let kind = r.headers()["content-type"].to_str().unwrap().to_string();
    assert!(kind.starts_with("text/plain; version=0.0.4"), "{kind}");
    r.text().await.unwrap()
}

/// The queue gauges are read from the database at most once a second.
async fn fresh_scrape(server: &Server) -> String {
    tokio::time::sleep(Duration::from_millis(1100)).await;
    scrape(&server.url("/metrics")).await
}

#[tokio::test(flavor = "multi_thread")]
async fn metrics_follow_a_policy_evaluation_without_naming_the_team() {
    let fx = ControlFixture::new("[control]\noffline_mse = false\nlease_s = 4\nreaper_interval_s = 1\n");
    let server = fx.serve(0);
    let text = scrape(&server.url("/metrics")).await;
    for state in ["queued", "leased", "done", "failed", "cancelled"] {
        assert_eq!(value(&text, &format!("kitchen_r_jobs{{state=\"{state}\"}}")), 0.0);
    }
    assert_eq!(
        value(
            &text,
            &format!(
                "kitchen_r_build_info{{version=\"{}\"}}",
                env!("CARGO_PKG_VERSION")
            )
        ),
        1.0
    );

    let team_name = "zebra-metrics-team";
    let token = team(&server, team_name).await;
    let (_oracle, url) = oracle_policy();
    let (status, reg) = register_policy(
        &server,
        &token,
        json!({"endpoint": url, "split": "dev", "episodes": 2}),
    )
    .await;
    assert_eq!(status, 201, "{reg}");
    let id = reg["id"].as_i64().unwrap();

    // No worker yet: both episodes wait.
    let text = fresh_scrape(&server).await;
    assert_eq!(value(&text, r#"kitchen_r_jobs{state="queued"}"#), 2.0);
    assert!(
        value(&text, "kitchen_r_queue_oldest_queued_seconds") >= 1.0,
        "{text}"
    );
    assert_eq!(value(&text, "kitchen_r_workers_connected"), 0.0);

    let (child, line) = spawn_ready(
        Command::new(bin())
            .args(["worker", "--server", &server.grpc, "--slots", "1"])
            .args(["--worker-id", "metrics-worker", "--metrics", "127.0.0.1:0"])
            .env("KITCHEN_R_WORKER_TOKEN", WORKER_TOKEN)
            .env("RUST_LOG", "warn"),
        "worker metrics http=",
    );
    let _worker = Proc(child);
    let worker_metrics = format!(
        "http://{}/metrics",
        line.trim_start_matches("worker metrics http=")
    );

    let view = wait_for(&server, id, &token, "the run", finished).await;
    assert_eq!(view["latest_run"]["evaluation"]["state"], "finished", "{view:#}");

    let text = fresh_scrape(&server).await;
    assert_eq!(value(&text, r#"kitchen_r_jobs{state="done"}"#), 2.0, "{text}");
    assert_eq!(value(&text, r#"kitchen_r_jobs{state="queued"}"#), 0.0, "{text}");
    assert_eq!(value(&text, r#"kitchen_r_jobs{state="leased"}"#), 0.0, "{text}");
    assert_eq!(value(&text, "kitchen_r_queue_oldest_queued_seconds"), 0.0);
    assert_eq!(value(&text, "kitchen_r_workers_connected"), 1.0);
    // The histograms count the episodes.
    assert_eq!(value(&text, "kitchen_r_queue_wait_seconds_count"), 2.0, "{text}");
    assert!(value(&text, "kitchen_r_queue_wait_seconds_sum") >= 2.0, "{text}");
    assert_eq!(
        value(
            &text,
            r#"kitchen_r_episode_duration_seconds_count{mode="online"}"#
        ),
        2.0
    );
    assert_eq!(
        value(
            &text,
            r#"kitchen_r_episode_duration_seconds_bucket{mode="online",le="+Inf"}"#
        ),
        2.0
    );
    assert_eq!(
        value(&text, r#"kitchen_r_jobs_finished_total{outcome="done"}"#),
        2.0
    );
    assert_eq!(
        value(&text, r#"kitchen_r_jobs_finished_total{outcome="failed"}"#),
        0.0
    );
    // Videos on demand: nothing asked for a video, so no render yet (the series exist at 0).
    assert_eq!(
        value(&text, r#"kitchen_r_video_renders_total{outcome="queued"}"#),
        0.0
    );
    // Requests, by matched route (no ids) and status.
    let http = |method: &str, route: &str, status: u16| {
        format!(r#"kitchen_r_http_requests_total{{method="{method}",route="{route}",status="{status}"}}"#)
    };
    assert_eq!(value(&text, &http("POST", "/api/v1/teams", 201)), 1.0);
    assert_eq!(
        value(&text, &http("POST", "/api/v1/submissions/policies", 201)),
        1.0
    );
    assert!(value(&text, &http("GET", "/api/v1/submissions/{id}", 200)) >= 1.0);
    // Two scrapes before this one (a scrape is counted once answered).
    assert_eq!(value(&text, &http("GET", "/metrics", 200)), 2.0);
    assert!(
        value(
            &text,
            r#"kitchen_r_http_request_duration_seconds_count{method="POST",route="/api/v1/teams",status="201"}"#
        ) >= 1.0
    );
    assert_eq!(
        value(
            &text,
            r#"kitchen_r_grpc_requests_total{path="/kitchen_r.worker.v1.Worker/ReportResult",code="Ok"}"#
        ),
        2.0
    );
    assert!(
        value(
            &text,
            r#"kitchen_r_grpc_requests_total{path="/kitchen_r.worker.v1.Worker/Lease",code="Ok"}"#
        ) >= 2.0
    );
    assert_eq!(
        value(
            &text,
            r#"kitchen_r_upload_refusals_total{kind="rate_limited",split="dev"}"#
        ),
        0.0
    );
    // Nothing names the team, its token, the submission or the worker.
    for secret in [
        team_name,
        token.as_str(),
        "metrics-worker",
        &format!("/submissions/{id}"),
    ] {
        assert!(!text.contains(secret), "{secret:?} in the metrics:\n{text}");
    }

    // The worker's own endpoint.
    let w = scrape(&worker_metrics).await;
    assert_eq!(
        value(&w, r#"kitchen_r_worker_episodes_total{result="ok"}"#),
        2.0,
        "{w}"
    );
    assert_eq!(value(&w, "kitchen_r_worker_episode_duration_seconds_count"), 2.0);
    assert_eq!(value(&w, "kitchen_r_worker_leases_held"), 0.0);
    assert!(
        value(
            &w,
            r#"kitchen_r_worker_policy_call_duration_seconds_count{call="act"}"#
        ) >= 2.0
    );
    assert!(
        value(
            &w,
            r#"kitchen_r_worker_policy_call_duration_seconds_count{call="reset"}"#
        ) >= 2.0
    );
    assert!(w.contains("kitchen_r_build_info{"), "{w}");
    assert!(!w.contains(&url), "no endpoint as a label: {w}");
    let r = client()
        .get(worker_metrics.replace("/metrics", "/other"))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 404);
}
