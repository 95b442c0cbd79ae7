//! The HTTP tower stack: request ids, catch-panic and timeouts ([`super::stack`]). The panicking
//! and slow routes are test-only routers under the same layers as the production ones.

use std::time::Duration;

use axum::body::Body;
use axum::body::to_bytes;
use axum::http::Request;
use axum::http::StatusCode;
use bytes::Bytes;
use serde_json::Value;
use tower::ServiceExt;

use super::*;
use crate::error::REQUEST_ID_HEADER;
use crate::testutil::{FakeProbe, fixture};

async fn call(app: Router, path: &str, id: Option<&str>) -> (StatusCode, Option<String>, Bytes) {
    let mut req = Request::get(path);
    if let Some(id) = id {
        req = req.header(REQUEST_ID_HEADER, id);
    }
    let resp = app.oneshot(req.body(Body::empty()).unwrap()).await.unwrap();
    let status = resp.status();
    let id = resp
        .headers()
        .get(REQUEST_ID_HEADER)
        .map(|v| v.to_str().unwrap().to_string());
    (status, id, to_bytes(resp.into_body(), 1 << 20).await.unwrap())
}

fn json(body: &Bytes) -> Value {
    serde_json::from_slice(body).unwrap_or_else(|e| panic!("not JSON ({e}): {body:?}"))
}

#[tokio::test]
async fn every_response_carries_a_request_id_and_a_given_one_is_echoed() {
    let f = fixture(FakeProbe::ok(1), |_| {}).await;
    let app = router(f.state.clone());
    let (status, id, _) = call(app.clone(), "/healthz", None).await;
    assert_eq!(status, StatusCode::OK);
    let id = id.expect("a generated request id");
    assert!(
        id.len() == 16 && id.bytes().all(|b| b.is_ascii_hexdigit()),
        "{id}"
    );
    let (_, other, _) = call(app.clone(), "/healthz", None).await;
    assert_ne!(other.as_deref(), Some(&*id), "ids are fresh per request");
    let (_, echoed, _) = call(app.clone(), "/healthz", Some("client-42.a:b_c")).await;
    assert_eq!(echoed.as_deref(), Some("client-42.a:b_c"));
    // An id that is too long or has odd characters is replaced, not echoed.
    for insane in ["x".repeat(65), "a b".into(), String::new()] {
        let (_, got, _) = call(app.clone(), "/healthz", Some(&insane)).await;
        let got = got.unwrap();
        assert!(got != insane && got.len() == 16, "{insane:?} -> {got:?}");
    }
}

#[tokio::test]
async fn error_bodies_carry_the_request_id() {
    let f = fixture(FakeProbe::ok(1), |_| {}).await;
    let app = router(f.state.clone());
    let (status, id, body) = call(app.clone(), "/api/v1/scenes/nowhere", Some("req-1")).await;
    assert_eq!(status, StatusCode::NOT_FOUND);
    assert_eq!(id.as_deref(), Some("req-1"));
    let body = json(&body);
    assert_eq!(
        (body["code"].as_str(), body["request_id"].as_str()),
        (Some("not_found"), Some("req-1"))
    );
    // The fallback (unknown route) too, with a generated id that matches the header.
    let (status, id, body) = call(app, "/api/v1/no/such/route", None).await;
    assert_eq!(status, StatusCode::NOT_FOUND);
    assert_eq!(json(&body)["request_id"].as_str(), id.as_deref());
    assert!(id.is_some());
}

#[tokio::test]
async fn a_panicking_handler_answers_500_json_with_the_request_id_and_no_internals() {
    async fn boom() -> &'static str {
        panic!("secret internals at /srv/db.sqlite");
    }
    let app: Router = stack::layered(Router::new().route("/boom", get(boom)));
    let (status, id, body) = call(app, "/boom", Some("req-boom")).await;
    assert_eq!(status, StatusCode::INTERNAL_SERVER_ERROR);
    assert_eq!(id.as_deref(), Some("req-boom"));
    let text = String::from_utf8_lossy(&body).to_string();
    assert!(!text.contains("secret") && !text.contains("panicked"), "{text}");
    let body = json(&body);
    assert_eq!(
        (
            body["code"].as_str(),
            body["error"].as_str(),
            body["request_id"].as_str()
        ),
        (Some("internal"), Some("internal error"), Some("req-boom"))
    );
}

// On the paused clock: the 30 s handler and the 250 ms budget are tokio timers, so the budget
// fires first without the test waiting for either.
#[tokio::test(start_paused = true)]
async fn a_slow_handler_past_its_budget_answers_503_json() {
    let slow = Router::new().route(
        "/slow",
        get(|| async {
            tokio::time::sleep(Duration::from_secs(30)).await;
            "done"
        }),
    );
    let quick = Router::new().route("/quick", get(|| async { "done" }));
    let app: Router = stack::layered(stack::with_timeout(slow.merge(quick), Duration::from_millis(250)));
    let (status, id, body) = call(app.clone(), "/slow", Some("req-slow")).await;
    assert_eq!(status, StatusCode::SERVICE_UNAVAILABLE);
    assert_eq!(id.as_deref(), Some("req-slow"));
    let body = json(&body);
    assert_eq!(
        (body["code"].as_str(), body["request_id"].as_str()),
        (Some("timeout"), Some("req-slow"))
    );
    assert!(body["error"].as_str().unwrap().contains("250 ms"), "{body}");
    let (status, _, body) = call(app, "/quick", None).await;
    assert_eq!((status, &body[..]), (StatusCode::OK, &b"done"[..]));
}

#[tokio::test]
async fn registration_gets_the_probe_deadline_on_top_of_the_request_budget() {
    let f = fixture(FakeProbe::ok(1), |c| {
        c.request_timeout_ms = 1_000;
        c.policy.startup_deadline_ms = 5_000;
    })
    .await;
    let cfg = f.state.config();
    assert_eq!(cfg.request_timeout(), Duration::from_secs(1));
    assert_eq!(cfg.registration_timeout(), Duration::from_secs(6));
}

#[tokio::test]
async fn an_error_answer_no_handler_made_json_is_rewritten_as_json_keeping_its_headers() {
    let app: Router = stack::layered(
        Router::new()
            .route(
                "/plain",
                get(|| async { (StatusCode::BAD_REQUEST, "plain words") }),
            )
            .route(
                "/empty",
                get(|| async { (StatusCode::METHOD_NOT_ALLOWED, [(header::ALLOW, "POST")]) }),
            )
            .route("/ok", get(|| async { "fine" })),
    );
    let (status, id, body) = call(app.clone(), "/plain", Some("req-plain")).await;
    assert_eq!(status, StatusCode::BAD_REQUEST);
    let v = json(&body);
    assert_eq!(
        (v["code"].as_str(), v["error"].as_str(), v["request_id"].as_str()),
        (Some("bad_request"), Some("plain words"), id.as_deref())
    );
    let resp = app
        .clone()
        .oneshot(Request::get("/empty").body(Body::empty()).unwrap())
        .await
        .unwrap();
    assert_eq!(resp.headers()[header::ALLOW], "POST");
    assert_eq!(resp.headers()[header::CONTENT_TYPE], "application/json");
    let v = json(&to_bytes(resp.into_body(), 1 << 20).await.unwrap());
    assert_eq!(
        (v["code"].as_str(), v["error"].as_str()),
        (Some("method_not_allowed"), Some("Method Not Allowed"))
    );
    let (status, _, body) = call(app, "/ok", None).await;
    assert_eq!((status, &body[..]), (StatusCode::OK, &b"fine"[..]));
}
