use axum::body::{Body, to_bytes};
use axum::http::{HeaderValue, Request, header};
use tower::ServiceExt;

use super::*;
use crate::http::{admin, router};
use crate::testutil::{ADMIN, FakeProbe, Fixture, fixture};

pub(super) struct Answer {
    pub status: StatusCode,
    pub headers: HeaderMap,
    pub body: String,
}

impl Answer {
    pub(super) fn cookies(&self) -> Vec<String> {
        self.headers
            .get_all(header::SET_COOKIE)
            .iter()
            .map(|v| v.to_str().unwrap().to_string())
            .collect()
    }

    pub(super) fn cookie(&self, name: &str) -> Option<String> {
        self.cookies()
            .into_iter()
            .find(|c| c.starts_with(&format!("{name}=")))
    }

    /// The CSRF field's value of the page's (first) form.
    pub(super) fn csrf(&self) -> String {
        let after = self
            .body
            .split("name=csrf value=\"")
            .nth(1)
            .expect("a CSRF field");
        after.split('"').next().unwrap().to_string()
    }
}

pub(super) async fn call(app: &Router, req: Request<Body>) -> Answer {
    let resp = app.clone().oneshot(req).await.unwrap();
    let (parts, body) = resp.into_parts();
    let bytes = to_bytes(body, 16 << 20).await.unwrap();
    Answer {
        status: parts.status,
        headers: parts.headers,
        body: String::from_utf8(bytes.to_vec()).unwrap(),
    }
}

pub(super) fn get(path: &str, cookies: &str) -> Request<Body> {
    let mut r = Request::get(path);
    if !cookies.is_empty() {
        r = r.header(header::COOKIE, cookies);
    }
    r.body(Body::empty()).unwrap()
}

pub(super) fn post_form(path: &str, cookies: &str, form: &str) -> Request<Body> {
    Request::post(path)
        .header(header::CONTENT_TYPE, "application/x-www-form-urlencoded")
        .header(header::COOKIE, cookies)
        .body(Body::from(form.to_string()))
        .unwrap()
}

/// The `name=value` part of a `Set-Cookie`.
pub(super) fn pair(set_cookie: &str) -> String {
    set_cookie.split(';').next().unwrap().to_string()
}

/// Log in through the form; the browser's cookies afterwards (CSRF nonce and team session).
pub(super) async fn login(app: &Router, token: &str) -> String {
    let form = call(app, get("/team/login", "")).await;
    let nonce = pair(&form.cookie(session::CSRF_COOKIE).unwrap());
    let done = call(
        app,
        post_form(
            "/team/login",
            &nonce,
            &format!("token={token}&csrf={}&next=/team", form.csrf()),
        ),
    )
    .await;
    assert_eq!(done.status, StatusCode::SEE_OTHER, "{}", done.body);
    format!("{nonce}; {}", pair(&done.cookie(TEAM_COOKIE).unwrap()))
}

/// A plan file for `split` with the dev ground truth's plans (EM = 1 on dev).
fn plan_file(f: &Fixture, split: Split, n: usize) -> String {
    let gt = f.state.content().ground_truth(Split::Dev);
    let ids: Vec<String> = f
        .state
        .content()
        .ground_truth(split)
        .iter()
        .map(|i| i.id.clone())
        .collect();
    ids.iter()
        .zip(gt.iter().cycle())
        .take(n)
        .map(|(id, i)| serde_json::json!({"id": id, "plan": i.plan}).to_string() + "\n")
        .collect()
}

async fn submit(f: &Fixture, token: &str, split: Split) -> i64 {
    let team = f.team_of(token).await;
    let body = plan_file(f, split, usize::MAX);
    f.state
        .submit_plans(&team, split, body.as_bytes())
        .await
        .unwrap()
        .id
}

#[tokio::test]
async fn login_sets_a_strict_http_only_cookie_and_forms_need_their_csrf_token() {
    let f = fixture(FakeProbe::ok(2), |_| {}).await;
    let token = f.team("alpha").await;
    let app = router(f.state.clone());

    let form = call(&app, get("/team/login?next=/submissions/1", "")).await;
    assert_eq!(form.status, StatusCode::OK);
    assert!(
        form.body.contains("name=\"next\" value=\"/submissions/1\""),
        "{}",
        form.body
    );
    let nonce_cookie = form.cookie(session::CSRF_COOKIE).unwrap();
    for attr in ["HttpOnly", "SameSite=Strict", "Path=/"] {
        assert!(nonce_cookie.contains(attr), "{nonce_cookie}");
    }
    let nonce = pair(&nonce_cookie);
    let csrf = form.csrf();

    // Without the CSRF field, with a wrong one, or without the nonce cookie: refused.
    for (cookies, body) in [
        (nonce.as_str(), format!("token={token}")),
        (
            nonce.as_str(),
            format!("token={token}&csrf=0123456789abcdef0123456789abcdef"),
        ),
        ("", format!("token={token}&csrf={csrf}")),
        ("kitchen_r_csrf=00ff", format!("token={token}&csrf={csrf}")),
    ] {
        let a = call(&app, post_form("/team/login", cookies, &body)).await;
        assert_eq!(a.status, StatusCode::FORBIDDEN, "{cookies} {body}");
        assert!(a.cookie(TEAM_COOKIE).is_none());
        assert!(a.body.contains("reload the page"), "{}", a.body);
    }
    // A cross-site POST is refused even with the right field.
    let mut cross = post_form("/team/login", &nonce, &format!("token={token}&csrf={csrf}"));
    cross
        .headers_mut()
        .insert("sec-fetch-site", HeaderValue::from_static("cross-site"));
    assert_eq!(call(&app, cross).await.status, StatusCode::FORBIDDEN);

    // A wrong token, or the organiser's, is no team login.
    for (bad, says) in [("kr_nope", "not a team token"), (ADMIN, "organiser token")] {
        let a = call(
            &app,
            post_form("/team/login", &nonce, &format!("token={bad}&csrf={csrf}")),
        )
        .await;
        assert_eq!(a.status, StatusCode::UNAUTHORIZED);
        assert!(a.body.contains(says), "{}", a.body);
        assert!(a.cookie(TEAM_COOKIE).is_none());
    }

    // The right one: a session cookie, then back to `next` (only a local path).
    let form_body = format!("token={token}&csrf={csrf}&next=/submissions/1");
    let a = call(&app, post_form("/team/login", &nonce, &form_body)).await;
    assert_eq!(a.status, StatusCode::SEE_OTHER);
    assert_eq!(a.headers[header::LOCATION], "/submissions/1");
    let session_cookie = a.cookie(TEAM_COOKIE).unwrap();
    for attr in ["HttpOnly", "SameSite=Strict", "Path=/;", "Max-Age="] {
        assert!(session_cookie.contains(attr), "{session_cookie}");
    }
    assert!(!session_cookie.contains("Secure"), "plain http: {session_cookie}");
    let evil = format!("token={token}&csrf={csrf}&next=//evil.example/");
    let a = call(&app, post_form("/team/login", &nonce, &evil)).await;
    assert_eq!(a.headers[header::LOCATION], "/team");

    // Behind an https proxy the cookies are Secure.
    let mut https = post_form("/team/login", &nonce, &form_body);
    https
        .headers_mut()
        .insert("x-forwarded-proto", HeaderValue::from_static("https"));
    let a = call(&app, https).await;
    assert!(a.cookie(TEAM_COOKIE).unwrap().contains("; Secure"));

    // Logout needs the field of a page rendered under this session.
    let cookies = format!("{nonce}; {}", pair(&session_cookie));
    let a = call(&app, post_form("/team/logout", &cookies, &format!("csrf={csrf}"))).await;
    assert_eq!(
        a.status,
        StatusCode::FORBIDDEN,
        "the pre-login field is not this session's"
    );
    let team_page = call(&app, get("/team", &cookies)).await;
    assert_eq!(team_page.status, StatusCode::OK);
    let a = call(
        &app,
        post_form("/team/logout", &cookies, &format!("csrf={}", team_page.csrf())),
    )
    .await;
    assert_eq!(a.status, StatusCode::SEE_OTHER);
    assert!(a.cookie(TEAM_COOKIE).unwrap().contains("Max-Age=0"));
}

#[tokio::test]
async fn the_team_page_lists_its_own_submissions_and_quota_only() {
    let f = fixture(FakeProbe::ok(2), |c| c.quota.dev_per_day = 5).await;
    let alpha = f.team("alpha").await;
    let beta = f.team("beta").await;
    let mine = submit(&f, &alpha, Split::Dev).await;
    let theirs = submit(&f, &beta, Split::Dev).await;
    let app = router(f.state.clone());

    let a = call(&app, get("/team", "")).await;
    assert_eq!(a.status, StatusCode::SEE_OTHER);
    assert_eq!(a.headers[header::LOCATION], "/team/login?next=/team");

    let cookies = login(&app, &alpha).await;
    let page = call(&app, get("/team", &cookies)).await;
    assert_eq!(page.status, StatusCode::OK);
    assert!(
        page.body.contains(&format!("href=\"/submissions/{mine}\"")),
        "{}",
        page.body
    );
    assert!(
        !page.body.contains(&format!("/submissions/{theirs}\"")),
        "{}",
        page.body
    );
    assert!(page.body.contains("1.000000"), "EM shown: {}", page.body);
    // Quota: 5 a day on dev, one used, and when it resets.
    assert!(
        page.body
            .contains("<td class=\"n\">5</td><td class=\"n\">1</td><td class=\"n\">4</td>"),
        "{}",
        page.body
    );
    assert!(page.body.contains("T00:00:00Z"), "{}", page.body);
    let cookies = login(&app, &beta).await;
    let page = call(&app, get("/team", &cookies)).await;
    assert!(page.body.contains(&format!("/submissions/{theirs}\"")));
    assert!(!page.body.contains(&format!("/submissions/{mine}\"")));
}

#[tokio::test]
async fn another_teams_submission_is_not_found_and_the_organiser_sees_it() {
    let f = fixture(FakeProbe::ok(2), |_| {}).await;
    let alpha = f.team("alpha").await;
    let beta = f.team("beta").await;
    let id = submit(&f, &alpha, Split::Dev).await;
    let app = router(f.state.clone());
    let path = format!("/submissions/{id}");

    let a = call(&app, get(&path, "")).await;
    assert_eq!(a.status, StatusCode::SEE_OTHER);
    assert_eq!(
        a.headers[header::LOCATION],
        format!("/team/login?next={path}").as_str()
    );

    let theirs = login(&app, &beta).await;
    let other = call(&app, get(&path, &theirs)).await;
    let missing = call(&app, get("/submissions/999999", &theirs)).await;
    let junk = call(&app, get("/submissions/abc", &theirs)).await;
    for a in [&other, &missing, &junk] {
        assert_eq!(a.status, StatusCode::NOT_FOUND);
        assert_eq!(a.headers[header::CONTENT_TYPE], "text/html; charset=utf-8");
    }
    assert_eq!(other.body, missing.body, "a taken id reads like a free one");

    let mine = login(&app, &alpha).await;
    let page = call(&app, get(&path, &mine)).await;
    assert_eq!(page.status, StatusCode::OK);
    assert!(
        page.body.contains("Per instruction") && page.body.contains("1.000000"),
        "{}",
        page.body
    );

    // The organiser: the console's session cookie, or the bearer header.
    let console = call(&app, get("/admin", "")).await;
    let nonce = pair(&console.cookie(session::CSRF_COOKIE).unwrap());
    let logged = call(
        &app,
        post_form(
            "/admin/login",
            &nonce,
            &format!("token={ADMIN}&csrf={}", console.csrf()),
        ),
    )
    .await;
    let admin_cookie = pair(&logged.cookie(admin::COOKIE).unwrap());
    let page = call(&app, get(&path, &admin_cookie)).await;
    assert_eq!(page.status, StatusCode::OK);
    assert!(page.body.contains("Organiser"), "{}", page.body);
    let bearer = Request::get(&path)
        .header(header::AUTHORIZATION, format!("Bearer {ADMIN}"))
        .body(Body::empty())
        .unwrap();
    assert_eq!(call(&app, bearer).await.status, StatusCode::OK);
}

/// Lease `n` jobs of the queue and report them: task 0 succeeds, the others time out.
async fn run_jobs(f: &Fixture, n: u32) {
    let worker = f.worker().await;
    for job in f.lease("w1", n).await {
        let report = f.report("w1", &job, |j| j == 0, 0.25);
        f.state.report_result(worker, report).await.unwrap();
    }
}

#[tokio::test]
async fn dev_runs_show_each_episode_and_test_runs_only_aggregates() {
    let f = fixture(FakeProbe::ok(8), |c| c.control.offline_mse = false).await;
    let token = f.team("alpha").await;
    let caller = f.caller(&token).await;
    let dev = f
        .state
        .register_policy(&caller, f.request(Split::Dev))
        .await
        .unwrap()
        .id;
    let app = router(f.state.clone());
    let cookies = login(&app, &token).await;

    let page = call(&app, get(&format!("/submissions/{dev}"), &cookies)).await;
    assert!(
        page.body.contains("<meta http-equiv=\"refresh\""),
        "queued: reloads"
    );
    assert!(page.body.contains("queued"), "{}", page.body);
    run_jobs(&f, 1).await;
    let page = call(&app, get(&format!("/submissions/{dev}"), &cookies)).await;
    assert!(page.body.contains("Estimated to finish in"), "{}", page.body);
    run_jobs(&f, 8).await;
    let page = call(&app, get(&format!("/submissions/{dev}"), &cookies)).await;
    assert!(
        !page.body.contains("http-equiv=\"refresh\""),
        "finished: {}",
        page.body
    );
    assert!(page.body.contains("<h2>Episodes</h2>"), "{}", page.body);
    assert!(page.body.contains("dev-0"), "episode keys on dev: {}", page.body);
    assert!(page.body.contains("failed</span>: timeout"), "{}", page.body);

    let test = f
        .state
        .register_policy(&caller, f.request(Split::Test))
        .await
        .unwrap()
        .id;
    run_jobs(&f, 3).await;
    let page = call(&app, get(&format!("/submissions/{test}"), &cookies)).await;
    assert_eq!(page.status, StatusCode::OK);
    // In progress: progress only (docs/integrity.md), and the page says when the aggregate comes.
    assert!(!page.body.contains("Failures by kind"), "{}", page.body);
    assert!(page.body.contains("appear once, when it ends"), "{}", page.body);
    let run = f
        .state
        .get_submission(&caller, test)
        .await
        .unwrap()
        .latest_run
        .unwrap();
    f.state.cancel_run(f.admin().await, run.id).await.unwrap();
    let page = call(&app, get(&format!("/submissions/{test}"), &cookies)).await;
    assert!(
        page.body.contains("Failures by kind") && page.body.contains("timeout"),
        "{}",
        page.body
    );
    for leak in ["<h2>Episodes</h2>", "test-0", "Per instruction", "<ol"] {
        assert!(!page.body.contains(leak), "{leak} on a test page: {}", page.body);
    }
    // A test plan file: EM, no per-instruction rows.
    let plans = submit(&f, &token, Split::Test).await;
    let page = call(&app, get(&format!("/submissions/{plans}"), &cookies)).await;
    assert!(
        page.body.contains("EM") && !page.body.contains("Per instruction"),
        "{}",
        page.body
    );
    assert!(!page.body.contains("test-0"), "{}", page.body);
}

#[tokio::test]
async fn pages_render_without_script_and_the_leaderboard_links_public_summaries() {
    let f = fixture(FakeProbe::ok(2), |_| {}).await;
    let alpha = f.team("alpha").await;
    let id = submit(&f, &alpha, Split::Test).await;
    let app = router(f.state.clone());
    let cookies = login(&app, &alpha).await;

    let board = call(&app, get("/", "")).await;
    let entry = format!("/leaderboard/planning/test/{id}");
    assert!(
        board.body.contains(&format!("href=\"{entry}\"")),
        "{}",
        board.body
    );
    assert!(board.body.contains("href=\"/contest\""));

    let home = call(&app, get("/contest", "")).await;
    for needle in [
        "<math",
        "EM = (1/N) · Σ_i PS_i / N_i",
        "M = (1/N)",
        "P = 1/EM",
        "10 cm",
        "/api/v1/scenes/kitchen_a/topdown.png",
        "/api/v1/dataset/dev",
        &crate::http::leaderboard::integrity_rules().into_string(),
    ] {
        assert!(home.body.contains(needle), "{needle}");
    }

    let summary = call(&app, get(&entry, "")).await;
    assert_eq!(summary.status, StatusCode::OK);
    assert!(summary.body.contains("<td>alpha</td>") && summary.body.contains("<th>EM</th>"));
    // The entry's results card and its score's interval (docs/reference/leaderboard.md).
    assert!(
        summary.body.contains("<h2>Results card</h2>")
            && summary.body.contains(&format!(
                "<dt>Binary version</dt><dd>{}</dd>",
                env!("CARGO_PKG_VERSION")
            ))
            && summary.body.contains(" [0."),
        "{}",
        summary.body
    );
    assert!(!summary.body.contains("Per instruction"));
    for bad in [
        format!("/leaderboard/planning/dev/{id}"),
        format!("/leaderboard/control/test/{id}"),
        "/leaderboard/nope/test/1".to_string(),
        "/leaderboard/planning/test/x".to_string(),
    ] {
        assert_eq!(
            call(&app, get(&bad, "")).await.status,
            StatusCode::NOT_FOUND,
            "{bad}"
        );
    }

    for (path, who) in [
        ("/contest", ""),
        ("/team/login", ""),
        ("/team", cookies.as_str()),
        (&format!("/submissions/{id}") as &str, cookies.as_str()),
        (entry.as_str(), ""),
        ("/", ""),
    ] {
        let a = call(&app, get(path, who)).await;
        assert_eq!(a.status, StatusCode::OK, "{path}");
        assert!(
            a.headers[header::CONTENT_TYPE]
                .to_str()
                .unwrap()
                .starts_with("text/html")
        );
        assert!(!a.body.to_ascii_lowercase().contains("<script"), "{path}");
        let csp = a.headers[header::CONTENT_SECURITY_POLICY].to_str().unwrap();
        assert!(
            csp.contains("default-src 'none'") && !csp.contains("script-src"),
            "{csp}"
        );
    }
}

#[tokio::test]
async fn a_dev_episode_row_shows_its_path_plot_to_the_session_and_a_test_page_none() {
    let f = fixture(FakeProbe::ok(8), |c| c.control.offline_mse = false).await;
    let plot = kitchen_r_core::topdown::PathPlot {
        base: vec![([1.0, 1.0], 0), ([2.0, 1.5], 0), ([3.0, 2.0], 1)],
        object: vec![None, None, Some([3.0, 2.1])],
        goals: Vec::new(),
    };
    let (alpha, bravo, dev, test) = f.runs_with_paths(|_| plot.clone()).await;
    let app = router(f.state.clone());
    let cookies = login(&app, &alpha).await;
    let page = call(&app, get(&format!("/submissions/{dev}"), &cookies)).await;
    let prefix = format!("<img class=\"plot\" src=\"/submissions/{dev}/episodes/");
    let at = page.body.find(&prefix).unwrap_or_else(|| panic!("{}", page.body));
    let src_start = at + "<img class=\"plot\" src=\"".len();
    let src: String = page.body[src_start..].chars().take_while(|c| *c != '"').collect();
    assert!(src.ends_with("/path.png"), "{src}");
    assert!(
        page.body.contains("title=\"path colour\""),
        "tasks wear their path colour"
    );

    let image = |cookies: String| {
        let (app, src) = (app.clone(), src.clone());
        async move {
            let resp = app.oneshot(get(&src, &cookies)).await.unwrap();
            let status = resp.status();
            let bytes = to_bytes(resp.into_body(), 16 << 20).await.unwrap();
            (status, bytes)
        }
    };
    let (status, png) = image(cookies.clone()).await;
    assert_eq!(status, StatusCode::OK);
    assert!(png.starts_with(b"\x89PNG"));
    assert_eq!(image(login(&app, &bravo).await).await.0, StatusCode::NOT_FOUND);
    assert_eq!(image(String::new()).await.0, StatusCode::NOT_FOUND);

    let page = call(&app, get(&format!("/submissions/{test}"), &cookies)).await;
    assert_eq!(page.status, StatusCode::OK);
    assert!(!page.body.contains("path.png"), "{}", page.body);
}
