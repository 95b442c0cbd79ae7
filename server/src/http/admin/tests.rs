use axum::body::to_bytes;
use axum::http::Request;
use serde_json::Value;
use tower::ServiceExt;

use super::super::router;
use super::*;
use crate::testutil::{ADMIN, FakeProbe, fixture};

async fn call(app: &Router, req: Request<Body>) -> (StatusCode, HeaderMap, Vec<u8>) {
    let resp = app.clone().oneshot(req).await.unwrap();
    let (parts, body) = resp.into_parts();
    let bytes = to_bytes(body, 64 << 20).await.unwrap().to_vec();
    (parts.status, parts.headers, bytes)
}

fn bearer(req: axum::http::request::Builder, token: &str) -> axum::http::request::Builder {
    req.header(header::AUTHORIZATION, format!("Bearer {token}"))
}

#[tokio::test]
async fn admin_routes_need_the_organiser_and_bad_run_ids_answer_json_errors() {
    let f = fixture(FakeProbe::ok(2), |_| {}).await;
    let team = f.team("alpha").await;
    let app = router(f.state.clone());
    for path in [
        "/api/v1/admin/queue",
        "/api/v1/admin/workers",
        "/api/v1/admin/runs",
    ] {
        let (status, _, body) = call(&app, Request::get(path).body(Body::empty()).unwrap()).await;
        assert_eq!(status, StatusCode::UNAUTHORIZED, "{path}");
        let v: Value = serde_json::from_slice(&body).unwrap();
        assert_eq!(v["code"], "missing_token");
        let (status, _, _) = call(
            &app,
            bearer(Request::get(path), &team).body(Body::empty()).unwrap(),
        )
        .await;
        assert_eq!(status, StatusCode::FORBIDDEN, "{path}");
        let (status, _, body) = call(
            &app,
            bearer(Request::get(path), ADMIN).body(Body::empty()).unwrap(),
        )
        .await;
        assert_eq!(status, StatusCode::OK, "{path}");
        let _: Value = serde_json::from_slice(&body).unwrap();
    }
    for (id, status, code) in [
        ("abc", StatusCode::BAD_REQUEST, "bad_request"),
        ("-1", StatusCode::BAD_REQUEST, "bad_request"),
        ("99999999999999999999", StatusCode::BAD_REQUEST, "bad_request"),
        ("42", StatusCode::NOT_FOUND, "not_found"),
    ] {
        for op in ["cancel", "requeue"] {
            let path = format!("/api/v1/admin/runs/{id}/{op}");
            let (got, headers, body) = call(
                &app,
                bearer(Request::post(&path), ADMIN).body(Body::empty()).unwrap(),
            )
            .await;
            assert_eq!(got, status, "{path}");
            assert_eq!(headers[header::CONTENT_TYPE], "application/json");
            let v: Value = serde_json::from_slice(&body).unwrap();
            assert_eq!(v["code"], code, "{v}");
            assert!(v["error"].is_string() && v["request_id"].is_string(), "{v}");
        }
    }
    // Organiser-only, checked before anything else.
    let (status, _, _) = call(
        &app,
        bearer(Request::post("/api/v1/admin/runs/abc/cancel"), &team)
            .body(Body::empty())
            .unwrap(),
    )
    .await;
    assert_eq!(status, StatusCode::FORBIDDEN);
    let (status, _, _) = call(
        &app,
        Request::post("/api/v1/admin/backup").body(Body::empty()).unwrap(),
    )
    .await;
    assert_eq!(status, StatusCode::UNAUTHORIZED);
}

#[tokio::test]
async fn backup_streams_a_sqlite_copy() {
    let f = fixture(FakeProbe::ok(2), |_| {}).await;
    f.team("alpha").await;
    let app = router(f.state.clone());
    let (status, headers, body) = call(
        &app,
        bearer(Request::post("/api/v1/admin/backup"), ADMIN)
            .body(Body::empty())
            .unwrap(),
    )
    .await;
    assert_eq!(status, StatusCode::OK);
    assert_eq!(headers[header::CONTENT_TYPE], "application/vnd.sqlite3");
    assert_eq!(headers[header::CONTENT_LENGTH], body.len().to_string().as_str());
    assert!(body.starts_with(b"SQLite format 3\0"));
}

#[tokio::test]
async fn the_page_logs_in_with_a_strict_http_only_cookie() {
    let f = fixture(FakeProbe::ok(2), |_| {}).await;
    let team = f.team("alpha").await;
    let app = router(f.state.clone());
    let (status, headers, body) = call(&app, Request::get("/admin").body(Body::empty()).unwrap()).await;
    assert_eq!(status, StatusCode::UNAUTHORIZED);
    assert_eq!(headers[header::CONTENT_TYPE], "text/html; charset=utf-8");
    assert!(
        String::from_utf8(body.clone())
            .unwrap()
            .contains("name=\"token\"")
    );
    assert_eq!(headers[header::CACHE_CONTROL], "no-store");
    assert!(headers.contains_key(header::CONTENT_SECURITY_POLICY));

    // The form's CSRF field and the nonce cookie it is bound to.
    let nonce = headers[header::SET_COOKIE].to_str().unwrap();
    let nonce = nonce.split(';').next().unwrap().to_string();
    let page = String::from_utf8(body).unwrap();
    let csrf = page.split("name=csrf value=\"").nth(1).unwrap();
    let csrf = csrf.split('"').next().unwrap().to_string();
    let login = |token: &str| {
        Request::post("/admin/login")
            .header(header::CONTENT_TYPE, "application/x-www-form-urlencoded")
            .header(header::COOKIE, &nonce)
            .body(Body::from(format!("token={token}&csrf={csrf}")))
            .unwrap()
    };
    // Without the CSRF field, or with another one, the right token is refused.
    for form in [format!("token={ADMIN}"), format!("token={ADMIN}&csrf=00")] {
        let req = Request::post("/admin/login")
            .header(header::CONTENT_TYPE, "application/x-www-form-urlencoded")
            .header(header::COOKIE, &nonce)
            .body(Body::from(form))
            .unwrap();
        let (status, headers, _) = call(&app, req).await;
        assert_eq!(status, StatusCode::FORBIDDEN);
        assert!(
            !headers.contains_key(header::SET_COOKIE)
                || !headers[header::SET_COOKIE].to_str().unwrap().starts_with(COOKIE)
        );
    }
    let (status, headers, _) = call(&app, login(&team)).await;
    assert_eq!(
        status,
        StatusCode::UNAUTHORIZED,
        "a team token is not the organiser's"
    );
    assert!(!headers.contains_key(header::SET_COOKIE));

    let (status, headers, _) = call(&app, login(ADMIN)).await;
    assert_eq!(status, StatusCode::SEE_OTHER);
    let cookie = headers[header::SET_COOKIE].to_str().unwrap().to_string();
    for attr in ["HttpOnly", "SameSite=Strict", "Path=/;"] {
        assert!(cookie.contains(attr), "{cookie}");
    }
    // The cookie holds a session id, not the organiser token in any form.
    assert!(
        !cookie.contains(ADMIN) && !cookie.contains(&hex::encode(ADMIN)),
        "{cookie}"
    );
    let pair = cookie.split(';').next().unwrap().to_string();
    let (status, _, body) = call(
        &app,
        Request::get("/admin")
            .header(header::COOKIE, format!("other=1; {pair}"))
            .body(Body::empty())
            .unwrap(),
    )
    .await;
    assert_eq!(status, StatusCode::OK);
    let console = String::from_utf8(body).unwrap();
    assert!(console.contains("organiser console"));

    // Logging out takes the console's CSRF field (bound to this session), not the login form's.
    let logout = |csrf: &str| {
        Request::post("/admin/logout")
            .header(header::CONTENT_TYPE, "application/x-www-form-urlencoded")
            .header(header::COOKIE, format!("{nonce}; {pair}"))
            .body(Body::from(format!("csrf={csrf}")))
            .unwrap()
    };
    let (status, _, _) = call(&app, logout(&csrf)).await;
    assert_eq!(status, StatusCode::FORBIDDEN);
    let (_, _, page) = call(
        &app,
        Request::get("/admin")
            .header(header::COOKIE, format!("{nonce}; {pair}"))
            .body(Body::empty())
            .unwrap(),
    )
    .await;
    let page = String::from_utf8(page).unwrap();
    let field = page
        .split("name=csrf value=\"")
        .nth(1)
        .unwrap()
        .split('"')
        .next()
        .unwrap();
    let (status, headers, _) = call(&app, logout(field)).await;
    assert_eq!(status, StatusCode::SEE_OTHER);
    let cleared: Vec<&str> = headers
        .get_all(header::SET_COOKIE)
        .iter()
        .map(|v| v.to_str().unwrap())
        .collect();
    assert!(
        cleared
            .iter()
            .any(|c| c.starts_with("kitchen_r_admin=;") && c.contains("Path=/;") && c.contains("Max-Age=0")),
        "{cleared:?}"
    );
    // The session ended on the server: a copy of the cookie taken before the logout opens
    // nothing.
    let (status, _, _) = call(
        &app,
        Request::get("/admin")
            .header(header::COOKIE, format!("{nonce}; {pair}"))
            .body(Body::empty())
            .unwrap(),
    )
    .await;
    assert_eq!(
        status,
        StatusCode::UNAUTHORIZED,
        "a logged-out session still works"
    );

    // A forged or team cookie is not a session.
    let forged = format!("{COOKIE}={}", hex::encode(&team));
    let (status, _, _) = call(
        &app,
        Request::get("/admin")
            .header(header::COOKIE, forged)
            .body(Body::empty())
            .unwrap(),
    )
    .await;
    assert_eq!(status, StatusCode::UNAUTHORIZED);
    // The cookie reaches no API route: actions need the bearer token.
    let (status, _, _) = call(
        &app,
        Request::get("/api/v1/admin/queue")
            .header(header::COOKIE, pair)
            .body(Body::empty())
            .unwrap(),
    )
    .await;
    assert_eq!(status, StatusCode::UNAUTHORIZED);
}

/// The `<tr>` of the console's runs table that shows `run`.
fn run_row(page: &str, run: i64) -> &str {
    let runs = &page[page.find("<h2>Runs</h2>").expect("a runs section")..];
    let start = runs
        .find(&format!("<tr><td class=\"n\">{run}</td>"))
        .unwrap_or_else(|| panic!("no row of run {run} in {page}"));
    let row = &runs[start..];
    &row[..row.find("</tr>").unwrap()]
}

#[tokio::test]
async fn the_console_names_each_runs_observation_track_in_json_and_on_the_page() {
    use kitchen_r_core::dataset::Split;

    // One database, two policies: the first server's probe asks for privileged observations,
    // the second's (a restart on the same file) does not.
    let f = fixture(FakeProbe::privileged(2), |c| c.control.privileged_track = true).await;
    let (alpha, bravo) = (f.team("alpha").await, f.team("bravo").await);
    let privileged = (f.state)
        .register_policy(&f.caller(&alpha).await, f.request(Split::Dev))
        .await
        .unwrap();
    let other = f.reopen(FakeProbe::ok(2)).await;
    let standard = other
        .register_policy(&other.caller(Some(&bravo)).await.unwrap(), f.request(Split::Dev))
        .await
        .unwrap();

    let app = router(f.state.clone());
    let (status, _, body) = call(
        &app,
        bearer(Request::get("/api/v1/admin/runs"), ADMIN)
            .body(Body::empty())
            .unwrap(),
    )
    .await;
    assert_eq!(status, StatusCode::OK);
    let v: Value = serde_json::from_slice(&body).unwrap();
    let track = |run: i64| {
        let runs = v["runs"].as_array().unwrap();
        let r = runs.iter().find(|r| r["run"] == run).unwrap();
        (r["team"].as_str().unwrap(), r["observations"].as_str().unwrap())
    };
    assert_eq!(track(privileged.run_id), ("alpha", "privileged"), "{v:#}");
    assert_eq!(track(standard.run_id), ("bravo", "standard"), "{v:#}");

    let page = page::console(&f.state.admin_console(f.admin().await).await.unwrap(), "");
    assert!(page.contains("<th>Observations</th>"), "{page}");
    let row = run_row(&page, privileged.run_id);
    assert!(
        row.contains("<td>alpha</td>") && row.contains("<td>privileged</td>"),
        "{row}"
    );
    let row = run_row(&page, standard.run_id);
    assert!(
        row.contains("<td>bravo</td>") && row.contains("<td>standard</td>"),
        "{row}"
    );
}

#[tokio::test]
async fn the_console_page_escapes_what_others_wrote() {
    let f = fixture(FakeProbe::ok(8), |c| c.quota.per_minute = 0).await;
    for team in ["alpha", "bravo"] {
        let token = f.team(team).await;
        f.state
            .register_policy(
                &f.caller(&token).await,
                f.request(kitchen_r_core::dataset::Split::Dev),
            )
            .await
            .unwrap();
    }
    // Worker ids are the workers' own text: the page escapes them like every other value.
    let w1 = "<i>w1</i>";
    let held = f.lease(w1, 2).await;
    let r = f.report(w1, &held[0], |_| true, 0.0);
    f.state.report_result(f.worker().await, r).await.unwrap();
    let page = page::console(
        &f.state.admin_console(f.admin().await).await.unwrap(),
        "<!--csrf-->",
    );
    assert!(page.contains("&lt;i&gt;w1&lt;/i&gt;"), "{page}");
    assert!(!page.contains(w1), "worker ids are escaped");
    assert!(page.contains("bravo") && page.contains(&held[1].episode_key));
    assert!(
        page.contains("<!--csrf--><button>Log out</button>"),
        "the CSRF field goes in as markup"
    );
    let login = page::login(Some("<b>bad</b> token"), "");
    assert!(login.contains("&lt;b&gt;bad&lt;/b&gt; token") && !login.contains("<b>bad</b>"));
}
