use axum::body::Body;
use axum::body::to_bytes;
use axum::http::Request;
use axum::http::StatusCode;
use bytes::Bytes;
use kitchen_r_core::dataset::Split;
use serde_json::Value;
use serde_json::json;
use tower::ServiceExt;

use super::*;
use crate::probe::ProbeError;
use crate::testutil::{ADMIN, FakeProbe, fixture};

async fn post(app: Router, token: Option<&str>, body: &str) -> (StatusCode, Value) {
    let mut req =
        Request::post("/api/v1/submissions/policies").header(header::CONTENT_TYPE, "application/json");
    if let Some(t) = token {
        req = req.header(header::AUTHORIZATION, format!("Bearer {t}"));
    }
    let resp = app
        .oneshot(req.body(Body::from(body.to_string())).unwrap())
        .await
        .unwrap();
    let status = resp.status();
    let bytes = to_bytes(resp.into_body(), 1 << 20).await.unwrap();
    (status, serde_json::from_slice(&bytes).unwrap())
}

async fn get(app: Router, path: &str, token: &str) -> Value {
    let req = Request::get(path)
        .header(header::AUTHORIZATION, format!("Bearer {token}"))
        .body(Body::empty())
        .unwrap();
    let resp = app.oneshot(req).await.unwrap();
    assert_eq!(resp.status(), StatusCode::OK);
    serde_json::from_slice(&to_bytes(resp.into_body(), 1 << 20).await.unwrap()).unwrap()
}

#[tokio::test]
async fn register_a_policy_and_follow_its_progress() {
    let f = fixture(FakeProbe::ok(2), |_| {}).await;
    let token = f.team("alpha").await;
    let app = router(f.state.clone());
    let (status, body) = post(
        app.clone(),
        Some(&token),
        r#"{"endpoint": "http://127.0.0.1:7000", "split": "dev", "token": "s3cret", "episodes": 2}"#,
    )
    .await;
    assert_eq!(status, StatusCode::CREATED, "{body}");
    assert_eq!(
        (body["episodes"].as_u64(), body["instructions"].as_u64()),
        (Some(4), Some(2))
    );
    assert_eq!(body["state"], "queued");
    let id = body["id"].as_i64().unwrap();
    let view = get(app, &format!("/api/v1/submissions/{id}"), &token).await;
    assert_eq!(view["kind"], "policy");
    assert_eq!(view["policy"]["has_token"], true);
    assert!(
        !view.to_string().contains("s3cret"),
        "the endpoint token is never shown: {view}"
    );
    let eval = &view["latest_run"]["evaluation"];
    assert_eq!(
        (eval["state"].as_str(), eval["episodes_total"].as_i64()),
        (Some("queued"), Some(4))
    );
}

#[tokio::test]
async fn refusals_are_json_with_a_code() {
    let f = fixture(
        FakeProbe::err(ProbeError::Failed("health: NOT_SERVING".into())),
        |_| {},
    )
    .await;
    let token = f.team("alpha").await;
    let app = router(f.state.clone());
    let ok = r#"{"endpoint": "http://127.0.0.1:7000", "split": "dev"}"#;
    let (status, body) = post(app.clone(), Some(&token), ok).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    assert_eq!(body["code"], "policy_probe_failed");
    assert_eq!(body["error"], "policy probe failed: health: NOT_SERVING");
    let (status, body) = post(app.clone(), None, ok).await;
    assert_eq!(
        (status, body["code"].as_str()),
        (StatusCode::UNAUTHORIZED, Some("missing_token"))
    );
    let (status, body) = post(app.clone(), Some(&token), r#"{"split": "dev"}"#).await;
    assert_eq!(
        (status, body["code"].as_str()),
        (StatusCode::BAD_REQUEST, Some("bad_request"))
    );
    let (status, body) = post(
        app.clone(),
        Some(&token),
        r#"{"endpoint": "http://x:1", "split": "dev", "typo": 1}"#,
    )
    .await;
    assert_eq!(status, StatusCode::BAD_REQUEST, "{body}");
    let (status, body) = post(
        app,
        Some(ADMIN),
        r#"{"endpoint": "ftp://x", "split": "dev", "reference": true}"#,
    )
    .await;
    assert_eq!(
        (status, body["code"].as_str()),
        (StatusCode::BAD_REQUEST, Some("endpoint_refused"))
    );
}

#[tokio::test]
async fn leaderboard_accepts_the_policy_tracks() {
    let f = fixture(FakeProbe::ok(1), |_| {}).await;
    let app = router(f.state.clone());
    for track in ["control", "integrated"] {
        let v = get(
            app.clone(),
            &format!("/api/v1/leaderboard?track={track}&split=dev"),
            "x",
        )
        .await;
        assert_eq!(v["track"], track);
    }
}

#[tokio::test]
async fn downloads_say_the_test_split_is_a_public_sample_and_briefs_are_served() {
    let f = fixture(FakeProbe::ok(1), |_| {}).await;
    let app = router(f.state.clone());
    let manifest = get(app.clone(), "/api/v1/dataset/manifest", "-").await;
    assert_eq!(manifest["test"]["kind"], "public_sample", "{manifest}");
    assert!(
        manifest["test"]["notice"]
            .as_str()
            .unwrap()
            .contains("public sample")
    );
    let resp = app
        .clone()
        .oneshot(Request::get("/api/v1/dataset/test").body(Body::empty()).unwrap())
        .await
        .unwrap();
    assert_eq!(resp.headers()["x-kitchen-r-split-kind"], "public-sample");
    let resp = app
        .clone()
        .oneshot(
            Request::get("/api/v1/scenes/kitchen_a/brief")
                .body(Body::empty())
                .unwrap(),
        )
        .await
        .unwrap();
    assert_eq!(resp.status(), StatusCode::OK);
    let brief = String::from_utf8(to_bytes(resp.into_body(), 1 << 20).await.unwrap().to_vec()).unwrap();
    assert!(
        brief.contains("also called"),
        "the brief grounds furniture names: {brief}"
    );
    let resp = app
        .oneshot(
            Request::get("/api/v1/scenes/nowhere/brief")
                .body(Body::empty())
                .unwrap(),
        )
        .await
        .unwrap();
    assert_eq!(resp.status(), StatusCode::NOT_FOUND);
}

/// One request with a request id; the answer's status, headers and body.
async fn send(
    app: &Router,
    method: Method,
    path: &str,
    token: Option<&str>,
    body: impl Into<Body>,
) -> (StatusCode, axum::http::HeaderMap, Bytes) {
    let mut req = Request::builder()
        .method(method)
        .uri(path)
        .header(crate::error::REQUEST_ID_HEADER, "walk-1");
    if let Some(t) = token {
        req = req.header(header::AUTHORIZATION, format!("Bearer {t}"));
    }
    let resp = app.clone().oneshot(req.body(body.into()).unwrap()).await.unwrap();
    let (status, headers) = (resp.status(), resp.headers().clone());
    (
        status,
        headers,
        to_bytes(resp.into_body(), 1 << 20).await.unwrap(),
    )
}

/// The answer is the documented JSON error with `code` and the request id sent by [`send`].
fn json_error(status: StatusCode, headers: &axum::http::HeaderMap, body: &[u8], code: &str) -> Value {
    let what = String::from_utf8_lossy(body);
    assert_eq!(
        headers[header::CONTENT_TYPE],
        "application/json",
        "{status}: {what}"
    );
    let v: Value = serde_json::from_slice(body).unwrap_or_else(|e| panic!("{status}: {e}: {what}"));
    assert_eq!(v["code"], code, "{status}: {v}");
    assert_eq!(v["request_id"], "walk-1", "{status}: {v}");
    assert!(v["error"].as_str().is_some_and(|e| !e.is_empty()), "{v}");
    v
}

#[tokio::test]
async fn every_error_the_router_can_send_is_json_with_a_code_and_the_request_id() {
    let f = fixture(FakeProbe::ok(1), |c| c.max_body_bytes = 2048).await;
    let token = f.team("alpha").await;
    let app = router(f.state.clone());
    // Known routes, wrong methods: 405 with `Allow`.
    for (method, path, allowed) in [
        (Method::GET, "/api/v1/submissions/plans", "POST"),
        (Method::DELETE, "/api/v1/teams", "POST"),
        (Method::PUT, "/healthz", "GET"),
        (Method::POST, "/api/v1/leaderboard", "GET"),
    ] {
        let (status, headers, body) = send(&app, method.clone(), path, None, Body::empty()).await;
        assert_eq!(status, StatusCode::METHOD_NOT_ALLOWED, "{method} {path}");
        // The route's own answer (not the stack's net), saying what to do.
        let v = json_error(status, &headers, &body, "method_not_allowed");
        assert!(v["error"].as_str().unwrap().contains("Allow header"), "{v}");
        let allow = headers[header::ALLOW].to_str().unwrap();
        assert!(allow.contains(allowed), "{method} {path}: Allow {allow}");
    }
    // Bodies over `max_body_bytes` (2 KiB here, not axum's 2 MB default): 413 with the limit.
    let big = format!(r#"{{"name": "{}"}}"#, "x".repeat(3000));
    for (path, token) in [
        ("/api/v1/teams", ADMIN),
        ("/api/v1/submissions/policies", token.as_str()),
        ("/api/v1/admin/resimulate", ADMIN),
    ] {
        let (status, headers, body) = send(&app, Method::POST, path, Some(token), big.clone()).await;
        assert_eq!(status, StatusCode::PAYLOAD_TOO_LARGE, "{path}");
        let v = json_error(status, &headers, &body, "body_too_large");
        assert_eq!(v["limit_bytes"], 2048, "{path}: {v}");
    }
    // A plan file says on which line the limit was crossed.
    let plans = "{}\n".repeat(1000);
    let path = "/api/v1/submissions/plans?split=dev";
    let (status, headers, body) = send(&app, Method::POST, path, Some(&token), plans).await;
    assert_eq!(status, StatusCode::PAYLOAD_TOO_LARGE);
    assert!(json_error(status, &headers, &body, "body_too_large")["line"].is_number());
    // Path segments that are not UTF-8: 400.
    for path in [
        "/api/v1/dataset/%ff",
        "/api/v1/scenes/%ff",
        "/api/v1/scenes/%ff/brief",
        "/api/v1/scenes/%ff/topdown.png",
        "/api/v1/submissions/%ff",
    ] {
        let (status, headers, body) = send(&app, Method::GET, path, Some(&token), Body::empty()).await;
        assert_eq!(status, StatusCode::BAD_REQUEST, "{path}");
        let v = json_error(status, &headers, &body, "bad_request");
        assert!(v["error"].as_str().unwrap().starts_with("bad URL path"), "{v}");
    }
    // Unknown routes: 404.
    let (status, headers, body) = send(&app, Method::GET, "/api/v2/nothing", None, Body::empty()).await;
    assert_eq!(status, StatusCode::NOT_FOUND);
    json_error(status, &headers, &body, "not_found");
}

/// A valid one-line dev plan file.
fn dev_file(f: &crate::testutil::Fixture) -> String {
    let id = &f.state.content().ground_truth(Split::Dev)[0].id;
    format!(r#"{{"id": "{id}", "plan": []}}"#)
}

async fn stats(app: &Router) -> Value {
    let (status, _, body) = send(
        app,
        Method::GET,
        "/api/v1/admin/stats",
        Some(ADMIN),
        Body::empty(),
    )
    .await;
    assert_eq!(status, StatusCode::OK);
    serde_json::from_slice(&body).unwrap()
}

#[tokio::test]
async fn a_burst_over_the_rate_limit_gets_429_with_retry_after_and_is_counted() {
    let f = fixture(FakeProbe::ok(1), |c| c.quota.per_minute = 3).await;
    let token = f.team("alpha").await;
    let other = f.team("beta").await;
    let app = router(f.state.clone());
    let plans = "/api/v1/submissions/plans?split=dev";
    for _ in 0..3 {
        let (status, _, body) = send(&app, Method::POST, plans, Some(&token), dev_file(&f)).await;
        assert_eq!(status, StatusCode::CREATED, "{body:?}");
    }
    let (status, headers, body) = send(&app, Method::POST, plans, Some(&token), dev_file(&f)).await;
    assert_eq!(status, StatusCode::TOO_MANY_REQUESTS);
    let v = json_error(status, &headers, &body, "rate_limited");
    let retry: u64 = headers[header::RETRY_AFTER].to_str().unwrap().parse().unwrap();
    assert!((1..=20).contains(&retry), "one slot every 20 s: {retry}");
    assert_eq!(v["retry_after_s"], retry);
    // Policy registrations on the same split share the team's slots.
    let reg = r#"{"endpoint": "http://127.0.0.1:7000", "split": "dev"}"#;
    let path = "/api/v1/submissions/policies";
    let (status, _, _) = send(&app, Method::POST, path, Some(&token), reg).await;
    assert_eq!(status, StatusCode::TOO_MANY_REQUESTS);
    // Another team, and the other split, have their own.
    let (status, _, _) = send(&app, Method::POST, plans, Some(&other), dev_file(&f)).await;
    assert_eq!(status, StatusCode::CREATED);
    let test_id = &f.state.content().ground_truth(Split::Test)[0].id;
    let test_file = format!(r#"{{"id": "{test_id}", "plan": []}}"#);
    let path = "/api/v1/submissions/plans?split=test";
    let (status, _, _) = send(&app, Method::POST, path, Some(&token), test_file).await;
    assert_eq!(status, StatusCode::CREATED);
    let v = stats(&app).await;
    assert_eq!(v["refusals"]["rate_limited"], json!({"dev": 2, "test": 0}), "{v}");
    assert_eq!(v["limits"]["per_minute"], 3, "{v}");
    assert_eq!(f.state.refusals().rate_limited.dev, 2);
    // Organiser only.
    let (status, headers, body) = send(
        &app,
        Method::GET,
        "/api/v1/admin/stats",
        Some(&token),
        Body::empty(),
    )
    .await;
    assert_eq!(status, StatusCode::FORBIDDEN);
    json_error(status, &headers, &body, "not_admin");
}

#[tokio::test]
async fn daily_quota_refusals_are_counted_per_split() {
    let f = fixture(FakeProbe::ok(1), |c| c.quota.dev_per_day = 1).await;
    let token = f.team("alpha").await;
    let app = router(f.state.clone());
    let plans = "/api/v1/submissions/plans?split=dev";
    let (status, _, _) = send(&app, Method::POST, plans, Some(&token), dev_file(&f)).await;
    assert_eq!(status, StatusCode::CREATED);
    let (status, headers, body) = send(&app, Method::POST, plans, Some(&token), dev_file(&f)).await;
    assert_eq!(status, StatusCode::TOO_MANY_REQUESTS);
    json_error(status, &headers, &body, "quota_exceeded");
    assert!(headers.contains_key(header::RETRY_AFTER));
    let v = stats(&app).await;
    assert_eq!(v["refusals"]["daily_quota"], json!({"dev": 1, "test": 0}), "{v}");
    assert_eq!(v["refusals"]["rate_limited"], json!({"dev": 0, "test": 0}), "{v}");
}

#[tokio::test]
async fn a_look_alike_team_name_is_refused_with_409_naming_the_team() {
    let f = fixture(FakeProbe::ok(1), |_| {}).await;
    f.team("rt-alpha").await;
    let app = router(f.state.clone());
    let body = r#"{"name": "rt-аlpha"}"#; // Cyrillic а
    let (status, headers, body) = send(&app, Method::POST, "/api/v1/teams", Some(ADMIN), body).await;
    assert_eq!(status, StatusCode::CONFLICT);
    let v = json_error(status, &headers, &body, "conflict");
    assert!(v["error"].as_str().unwrap().contains("\"rt-alpha\""), "{v}");
}

/// A path as a worker reports it: two tasks across the room, the second failed.
fn reported_path(tasks: &[crate::episodes::TaskOutcome]) -> kitchen_r_core::topdown::PathPlot {
    use kitchen_r_proto::worker::v1 as pb;
    let mut p = pb::EpisodePath::default();
    for k in 0..40u32 {
        let t = k as f32 / 40.0;
        p.base_xy.extend([0.8 + 2.5 * t, 0.8 + 1.5 * t]);
        p.object_xy.extend([f32::NAN, f32::NAN]);
        p.task.push(u32::from(k >= 20));
    }
    p.goals = vec![
        pb::PathGoal {
            index: 0,
            kind: "nav".into(),
            x: 2.05,
            y: 1.55,
            radius: 0.1,
            end_x: 2.05,
            end_y: 1.55,
        },
        pb::PathGoal {
            index: 1,
            kind: "place".into(),
            x: 4.0,
            y: 3.0,
            radius: 0.05,
            end_x: 3.3,
            end_y: 2.3,
        },
    ];
    crate::plots::from_report(Some(&p), tasks).expect("a well-formed path")
}

async fn fetch(app: &Router, path: &str, token: &str) -> (StatusCode, Option<String>, Vec<u8>) {
    let req = Request::get(path)
        .header(header::AUTHORIZATION, format!("Bearer {token}"))
        .body(Body::empty())
        .unwrap();
    let resp = app.clone().oneshot(req).await.unwrap();
    let status = resp.status();
    let ct = (resp.headers().get(header::CONTENT_TYPE)).map(|v| v.to_str().unwrap().to_string());
    (
        status,
        ct,
        to_bytes(resp.into_body(), 8 << 20).await.unwrap().to_vec(),
    )
}

#[tokio::test]
async fn an_episode_path_is_a_png_on_dev_and_not_found_on_test_or_for_another_team() {
    let f = fixture(FakeProbe::ok(8), |c| c.control.offline_mse = false).await;
    let (alpha, bravo, dev, test) = f.runs_with_paths(|r| reported_path(&r.tasks)).await;
    let app = router(f.state.clone());

    let view = get(app.clone(), &format!("/api/v1/submissions/{dev}"), &alpha).await;
    let episodes = view["latest_run"]["evaluation"]["episodes"].as_array().unwrap();
    assert!(!episodes.is_empty(), "{view}");
    let ep = &episodes[0];
    let url = ep["plot_url"].as_str().expect("a dev episode links its plot");
    let key = ep["key"].as_str().unwrap();
    assert_eq!(url, format!("/api/v1/submissions/{dev}/episodes/{key}/path.png"));

    let (status, ct, png) = fetch(&app, url, &alpha).await;
    assert_eq!(status, StatusCode::OK);
    assert_eq!(ct.as_deref(), Some("image/png"));
    assert!(
        png.starts_with(b"\x89PNG\r\n\x1a\n") && png.len() > 1000,
        "{} bytes",
        png.len()
    );
    if let Ok(dir) = std::env::var("KITCHEN_R_PLOT_PREVIEW") {
        std::fs::write(std::path::Path::new(&dir).join("served-plot.png"), &png).unwrap();
    }
    // The organiser sees it; another team and nobody do not.
    assert_eq!(fetch(&app, url, ADMIN).await.0, StatusCode::OK);
    assert_eq!(fetch(&app, url, &bravo).await.0, StatusCode::NOT_FOUND);
    assert!(!fetch(&app, url, "").await.0.is_success());
    let missing = format!("/api/v1/submissions/{dev}/episodes/dev-9999/path.png");
    assert_eq!(fetch(&app, &missing, &alpha).await.0, StatusCode::NOT_FOUND);

    // On test a path is stored but never served, nor linked, to anyone.
    let view = get(app.clone(), &format!("/api/v1/submissions/{test}"), &alpha).await;
    assert!(!view.to_string().contains("plot_url"), "{view}");
    let test_key: String = sqlx::query_scalar(
        "SELECT e.episode_key FROM episode_results e JOIN scoring_runs r ON r.id = e.run_id
         WHERE r.submission_id = ? AND e.path_z IS NOT NULL LIMIT 1",
    )
    .bind(test)
    .fetch_one(f.state.pool())
    .await
    .unwrap();
    let url = format!("/api/v1/submissions/{test}/episodes/{test_key}/path.png");
    for token in [alpha.as_str(), ADMIN, bravo.as_str()] {
        assert_eq!(fetch(&app, &url, token).await.0, StatusCode::NOT_FOUND);
    }
}
