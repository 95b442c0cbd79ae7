use axum::body::to_bytes;
use axum::http::Request;
use serde_json::Value;
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
