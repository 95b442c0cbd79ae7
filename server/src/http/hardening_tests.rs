//! Route tests of an outside review's loose ends, through the real router: page security headers on
//! every HTML answer, CSV cells a spreadsheet would evaluate, plan-line fields dropped before
//! storage and endpoint tokens absent from every answer.

use axum::body::Body;
use axum::body::to_bytes;
use axum::http::Request;
use axum::http::StatusCode;
use tower::ServiceExt;

use super::*;
use crate::testutil::{ADMIN, FakeProbe, fixture};

type Answer = (StatusCode, axum::http::HeaderMap, String);

/// `(status, headers, body)` of a GET with an optional bearer token.
async fn fetch(app: &Router, path: &str, token: Option<&str>) -> Answer {
    fetch_with(app, path, token, &[]).await
}

/// [`fetch`] with more request headers.
async fn fetch_with(
    app: &Router,
    path: &str,
    token: Option<&str>,
    headers: &[(header::HeaderName, &str)],
) -> Answer {
    let mut req = Request::get(path);
    if let Some(t) = token {
        req = req.header(header::AUTHORIZATION, format!("Bearer {t}"));
    }
    for (name, value) in headers {
        req = req.header(name, *value);
    }
    let resp = app
        .clone()
        .oneshot(req.body(Body::empty()).unwrap())
        .await
        .unwrap();
    let (parts, body) = resp.into_parts();
    let body = to_bytes(body, 16 << 20).await.unwrap();
    (
        parts.status,
        parts.headers,
        String::from_utf8_lossy(&body).into_owned(),
    )
}

/// POST `body` to `path` as `token`; `(status, body)`.
async fn send(app: &Router, path: &str, token: &str, body: Vec<u8>) -> (StatusCode, String) {
    let req = Request::post(path)
        .header(header::AUTHORIZATION, format!("Bearer {token}"))
        .header(header::CONTENT_TYPE, "application/json")
        .body(Body::from(body))
        .unwrap();
    let resp = app.clone().oneshot(req).await.unwrap();
    let status = resp.status();
    let body = to_bytes(resp.into_body(), 16 << 20).await.unwrap();
    (status, String::from_utf8_lossy(&body).into_owned())
}

/// Issue 23: the leaderboard pages (`/`, `/?split=dev`, `?format=html`) were sent without the
/// headers every other page has. The rule is the stack's now: every HTML answer gets them.
#[tokio::test]
async fn every_html_answer_carries_the_page_security_headers_leaderboards_included() {
    let f = fixture(FakeProbe::ok(1), |_| {}).await;
    let app = router(f.state.clone());
    let mut paths = vec![
        "/".to_string(),
        "/?split=dev".to_string(),
        "/contest".to_string(),
        "/team/login".to_string(),
        "/admin".to_string(),
        "/api/docs".to_string(),
    ];
    for track in ["planning", "control", "integrated"] {
        for split in ["dev", "test"] {
            paths.push(format!(
                "/api/v1/leaderboard?track={track}&split={split}&format=html"
            ));
        }
    }
    for path in &paths {
        let (status, h, body) = fetch(&app, path, None).await;
        // The console without a session answers its login form as a 401 page.
        let want = if path == "/admin" {
            StatusCode::UNAUTHORIZED
        } else {
            StatusCode::OK
        };
        assert_eq!(status, want, "{path}");
        assert!(
            h[header::CONTENT_TYPE].to_str().unwrap().starts_with("text/html"),
            "{path}"
        );
        for (name, value) in super::stack::PAGE_HEADERS {
            assert_eq!(
                h.get(&name).map(|v| v.to_str().unwrap()),
                Some(value),
                "{path}: {name}"
            );
        }
        // The leaderboard is styled inline and has no script: the policy allows the one and
        // forbids the other.
        let csp = h[header::CONTENT_SECURITY_POLICY].to_str().unwrap();
        assert!(csp.contains("style-src 'unsafe-inline'") && !csp.contains("script-src"));
        assert!(!body.to_ascii_lowercase().contains("<script"), "{path}");
    }
    // JSON and CSV answers are not pages: left alone.
    let (_, h, _) = fetch(&app, "/api/v1/leaderboard?format=csv", None).await;
    assert!(!h.contains_key(header::CONTENT_SECURITY_POLICY));
}

/// Issue 23: a team may be named `-1-1`, which a spreadsheet opening the CSV export evaluated.
#[tokio::test]
async fn the_leaderboard_csv_neutralises_a_formula_team_name() {
    let f = fixture(FakeProbe::ok(1), |_| {}).await;
    let app = router(f.state.clone());
    let (status, team) = send(&app, "/api/v1/teams", ADMIN, br#"{"name": "-1-1"}"#.to_vec()).await;
    assert_eq!(status, StatusCode::CREATED, "{team}");
    let token: serde_json::Value = serde_json::from_str(&team).unwrap();
    let token = token["token"].as_str().unwrap();
    let plan = r#"{"id": "dev-0001", "plan": ["move to the blue zone"]}"#;
    let (status, body) = send(&app, "/api/v1/submissions/plans?split=dev", token, plan.into()).await;
    assert_eq!(status, StatusCode::CREATED, "{body}");
    let (_, _, csv) = fetch(&app, "/api/v1/leaderboard?split=dev&format=csv", None).await;
    let row = csv.lines().nth(1).unwrap();
    assert!(row.starts_with("1,\"'-1-1\","), "{csv}");
}

/// Issue 23: a plan line's unknown fields were stored (a 4 MB random field kept as 3 MB). They
/// are dropped before storage; the body limit still refuses an oversized file.
#[tokio::test]
async fn a_plan_lines_unknown_fields_are_dropped_before_storage() {
    let f = fixture(FakeProbe::ok(1), |_| {}).await;
    let app = router(f.state.clone());
    let token = f.team("alpha").await;
    let junk = "x".repeat(3 << 20);
    let file = format!(
        "{{\"id\": \"dev-0002\", \"plan\": [\"pick the bowl\"], \"junk\": \"{junk}\"}}\n\n\
         {{\"instruction\": \"carry it\", \"id\": \"dev-0001\", \"plan\": [], \"extra\": {{\"a\": [1, 2]}}}}\n"
    );
    let path = "/api/v1/submissions/plans?split=dev";
    let (status, body) = send(&app, path, &token, file.into_bytes()).await;
    assert_eq!(status, StatusCode::CREATED, "{body}");
    let id = serde_json::from_str::<serde_json::Value>(&body).unwrap()["id"]
        .as_i64()
        .unwrap();
    let stored = crate::store::submission_body(f.state.pool(), id)
        .await
        .unwrap()
        .body;
    assert_eq!(
        stored,
        "{\"id\":\"dev-0002\",\"plan\":[\"pick the bowl\"]}\n{\"id\":\"dev-0001\",\"plan\":[]}\n"
    );
    // What was stored still scores the same on a rescore.
    let (split, file) = f.state.stored_plans("dev", &stored).unwrap();
    assert_eq!(
        (split, file.order.clone()),
        (kitchen_r_core::dataset::Split::Dev, vec![1, 0])
    );
    // The body limit applies before anything is parsed or dropped.
    let huge = format!(
        "{{\"id\": \"dev-0001\", \"plan\": [], \"junk\": \"{}\"}}\n",
        "y".repeat(5 << 20)
    );
    let (status, body) = send(&app, path, &token, huge.into_bytes()).await;
    assert_eq!(status, StatusCode::PAYLOAD_TOO_LARGE, "{body}");
}

/// Issue 23: the video's ETag was never honoured (`If-None-Match` got the whole body).
#[tokio::test]
async fn a_video_answers_304_to_a_matching_if_none_match_or_if_modified_since() {
    let f = fixture(FakeProbe::ok(8), |c| c.control.dev_episodes = 1).await;
    let (alpha, _, dev, _) = f.runs_with_paths(|_| Default::default()).await;
    let pool = f.state.pool();
    let (run, key): (i64, String) = sqlx::query_as(
        "SELECT run_id, episode_key FROM jobs WHERE episode_key NOT LIKE '%/offline' ORDER BY id",
    )
    .fetch_one(pool)
    .await
    .unwrap();
    let dir = f.state.video_dir().unwrap();
    let sha = crate::service::videos::tests::store_file(&dir, b"mp4!!").await;
    let team = f.team_of(&alpha).await.id;
    let row = crate::store::videos::Row {
        run,
        key: &key,
        team,
        now: crate::service::now_ms(),
    };
    crate::store::videos::link(pool, row, &sha, 5).await.unwrap();
    let app = router(f.state.clone());
    let path = format!("/api/v1/submissions/{dev}/episodes/{key}/video.mp4");
    let get = |h: Vec<(header::HeaderName, String)>| {
        let (app, path, alpha) = (app.clone(), path.clone(), alpha.clone());
        async move {
            let h: Vec<(header::HeaderName, &str)> = h.iter().map(|(k, v)| (k.clone(), v.as_str())).collect();
            fetch_with(&app, &path, Some(&alpha), &h).await
        }
    };
    let (status, h, body) = get(vec![]).await;
    assert_eq!((status, body.as_str()), (StatusCode::OK, "mp4!!"));
    let etag = h[header::ETAG].to_str().unwrap().to_string();
    let modified = h[header::LAST_MODIFIED].to_str().unwrap().to_string();
    assert_eq!(etag, format!("\"{sha}\""));
    assert!(httpdate::parse_http_date(&modified).is_ok(), "{modified}");
    let not_modified = [
        vec![(header::IF_NONE_MATCH, etag.clone())],
        vec![(header::IF_NONE_MATCH, format!("\"x\", W/{etag}"))],
        vec![(header::IF_NONE_MATCH, "*".to_string())],
        vec![(header::IF_MODIFIED_SINCE, modified.clone())],
        vec![
            (header::IF_NONE_MATCH, etag.clone()),
            (header::RANGE, "bytes=0-1".into()),
        ],
    ];
    for headers in not_modified {
        let (status, h, body) = get(headers.clone()).await;
        assert_eq!(status, StatusCode::NOT_MODIFIED, "{headers:?}");
        assert!(body.is_empty(), "{headers:?}");
        assert_eq!(h[header::ETAG], etag.as_str());
        assert_eq!(h[header::LAST_MODIFIED], modified.as_str());
    }
    let long_ago = httpdate::fmt_http_date(std::time::UNIX_EPOCH);
    let full = [
        vec![(header::IF_NONE_MATCH, "\"other\"".to_string())],
        vec![(header::IF_MODIFIED_SINCE, long_ago)],
        // If-None-Match decides alone when present.
        vec![
            (header::IF_NONE_MATCH, "\"other\"".to_string()),
            (header::IF_MODIFIED_SINCE, modified.clone()),
        ],
    ];
    for headers in full {
        let (status, _, body) = get(headers.clone()).await;
        assert_eq!((status, body.as_str()), (StatusCode::OK, "mp4!!"), "{headers:?}");
    }
}

/// Issue 23: a policy endpoint's token was stored in plain text in `submissions.body`. It is
/// stored sealed (the raw rows hold no token), the worker still gets it with the leased job, and
/// no answer shows it: the submission, the organiser's console and API, the OpenAPI document.
#[tokio::test]
async fn an_endpoint_token_is_stored_sealed_shown_nowhere_and_handed_to_the_worker() {
    const SECRET: &str = "tok-Very-Secret-4242";
    let f = fixture(FakeProbe::ok(2), |c| c.control.dev_episodes = 1).await;
    let app = router(f.state.clone());
    let team = f.team("alpha").await;
    let body = format!(r#"{{"endpoint": "http://127.0.0.1:7000", "split": "dev", "token": "{SECRET}"}}"#);
    let (status, answer) = send(&app, "/api/v1/submissions/policies", &team, body.into_bytes()).await;
    assert_eq!(status, StatusCode::CREATED, "{answer}");
    assert!(!answer.contains(SECRET));
    let id = serde_json::from_str::<serde_json::Value>(&answer).unwrap()["id"]
        .as_i64()
        .unwrap();

    let pool = f.state.pool();
    let bodies: Vec<String> = sqlx::query_scalar("SELECT body FROM submissions")
        .fetch_all(pool)
        .await
        .unwrap();
    let specs: Vec<String> = sqlx::query_scalar("SELECT spec FROM jobs")
        .fetch_all(pool)
        .await
        .unwrap();
    assert_eq!(specs.len(), 2);
    for row in bodies.iter().chain(&specs) {
        assert!(!row.contains(SECRET), "a raw row holds the token: {row}");
    }
    assert!(bodies[0].contains("\"token_sealed\":\"kr1."), "{}", bodies[0]);

    let submission = format!("/api/v1/submissions/{id}");
    for (path, token) in [
        (submission.as_str(), team.as_str()),
        (submission.as_str(), ADMIN),
        ("/api/v1/admin/queue", ADMIN),
        ("/api/v1/admin/runs", ADMIN),
        ("/api/v1/admin/workers", ADMIN),
        ("/admin", ADMIN),
        ("/api/v1/openapi.json", ADMIN),
    ] {
        let (status, _, body) = fetch(&app, path, Some(token)).await;
        assert_eq!(status, StatusCode::OK, "{path}");
        assert!(!body.contains(SECRET), "{path} shows the token");
    }
    let (_, _, view) = fetch(&app, &submission, Some(&team)).await;
    assert!(view.contains("\"has_token\":true"), "{view}");

    let jobs = f.lease("w1", 8).await;
    assert_eq!(jobs.len(), 2);
    for j in &jobs {
        assert_eq!(j.spec.endpoint.bearer_token, SECRET);
        assert_eq!(j.spec.endpoint.bearer_token_sealed, None);
    }
}
