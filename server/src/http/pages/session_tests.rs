//! Sessions are sessions (docs/reference/pages.md): the cookie is no credential, logout and token
//! rotation end a session on the server, sessions expire, and failed logins are throttled.

use axum::body::Body;
use axum::http::{Request, header};

use super::tests::{call, get, login, pair, post_form};
use super::*;
use crate::http::router;
use crate::testutil::{ADMIN, FakeProbe, fixture};

/// The team session cookie's `name=value` in a browser's cookie string.
fn session_pair(cookies: &str) -> String {
    (cookies.split("; "))
        .find(|c| c.starts_with(&format!("{TEAM_COOKIE}=")))
        .unwrap()
        .to_string()
}

#[tokio::test]
async fn the_session_cookie_holds_no_credential_and_logout_ends_the_session_on_the_server() {
    let f = fixture(FakeProbe::ok(2), |_| {}).await;
    let token = f.team("alpha").await;
    let app = router(f.state.clone());
    let cookies = login(&app, &token).await;
    let session = session_pair(&cookies);
    assert!(
        !session.contains(&token) && !session.contains(&hex::encode(&token)),
        "the cookie carries the token: {session}"
    );
    // Two logins are two sessions.
    assert_ne!(session, session_pair(&login(&app, &token).await));

    let page = call(&app, get("/team", &cookies)).await;
    assert_eq!(page.status, StatusCode::OK);
    let out = call(
        &app,
        post_form("/team/logout", &cookies, &format!("csrf={}", page.csrf())),
    )
    .await;
    assert_eq!(out.status, StatusCode::SEE_OTHER);
    // A copy of the cookie taken before the logout (another browser, a stolen one) opens nothing.
    let after = call(&app, get("/team", &cookies)).await;
    assert_eq!(
        after.status,
        StatusCode::SEE_OTHER,
        "a logged-out cookie still opens the team page"
    );
    assert_eq!(after.headers[header::LOCATION], "/team/login?next=/team");
    // A cookie holding the token itself (as the first sessions did) is no session.
    let old_style = format!("{TEAM_COOKIE}={}", hex::encode(&token));
    assert_eq!(
        call(&app, get("/team", &old_style)).await.status,
        StatusCode::SEE_OTHER
    );
}

#[tokio::test]
async fn rotating_a_team_token_ends_its_sessions_and_the_old_token() {
    let f = fixture(FakeProbe::ok(2), |_| {}).await;
    let alpha = f.team("alpha").await;
    let beta = f.team("beta").await;
    let alpha_id = f.team_of(&alpha).await.id;
    let app = router(f.state.clone());
    let alpha_cookies = login(&app, &alpha).await;
    let beta_cookies = login(&app, &beta).await;
    let rotate = |id: i64, bearer: &str| {
        Request::post(format!("/api/v1/teams/{id}/token"))
            .header(header::AUTHORIZATION, format!("Bearer {bearer}"))
            .body(Body::empty())
            .unwrap()
    };
    // Another team cannot rotate alpha's token; it is as if alpha did not exist.
    assert_eq!(
        call(&app, rotate(alpha_id, &beta)).await.status,
        StatusCode::NOT_FOUND
    );
    assert_eq!(
        call(&app, rotate(alpha_id, "")).await.status,
        StatusCode::UNAUTHORIZED
    );

    let a = call(&app, rotate(alpha_id, &alpha)).await;
    assert_eq!(a.status, StatusCode::OK, "{}", a.body);
    let v: serde_json::Value = serde_json::from_str(&a.body).unwrap();
    let new = v["token"].as_str().unwrap().to_string();
    assert_ne!(new, alpha);
    assert_eq!(v["name"], "alpha");
    // The old token and every session opened with it stop working; beta's session does not.
    assert!(matches!(f.caller(&alpha).await, Caller::Unrecognised));
    assert!(matches!(f.caller(&new).await, Caller::Team(_)));
    assert_eq!(
        call(&app, get("/team", &alpha_cookies)).await.status,
        StatusCode::SEE_OTHER,
        "a session opened with the rotated token still works"
    );
    assert_eq!(
        call(&app, get("/team", &beta_cookies)).await.status,
        StatusCode::OK
    );
    // The organiser may rotate any team's; a new login works with the new token.
    let a = call(&app, rotate(alpha_id, ADMIN)).await;
    assert_eq!(a.status, StatusCode::OK);
    let newest: serde_json::Value = serde_json::from_str(&a.body).unwrap();
    let cookies = login(&app, newest["token"].as_str().unwrap()).await;
    assert_eq!(call(&app, get("/team", &cookies)).await.status, StatusCode::OK);
    assert_eq!(
        call(&app, rotate(9999, ADMIN)).await.status,
        StatusCode::NOT_FOUND
    );
}

#[tokio::test]
async fn sessions_expire() {
    let f = fixture(FakeProbe::ok(2), |_| {}).await;
    let token = f.team("alpha").await;
    let app = router(f.state.clone());
    let cookies = login(&app, &token).await;
    let id = session_pair(&cookies).split_once('=').unwrap().1.to_string();
    assert!(matches!(f.state.session(&id).await.unwrap(), Caller::Team(_)));
    sqlx::query("UPDATE sessions SET expires_at = 0")
        .execute(f.state.pool())
        .await
        .unwrap();
    assert!(matches!(f.state.session(&id).await.unwrap(), Caller::Anonymous));
    assert_eq!(
        call(&app, get("/team", &cookies)).await.status,
        StatusCode::SEE_OTHER
    );
}

#[tokio::test]
async fn failed_logins_are_throttled_with_retry_after_even_for_a_right_token() {
    let f = fixture(FakeProbe::ok(2), |c| {
        c.sessions.failures_per_minute_per_address = 3;
    })
    .await;
    let token = f.team("alpha").await;
    let app = router(f.state.clone());
    let form = call(&app, get("/team/login", "")).await;
    let nonce = pair(&form.cookie(crate::http::session::CSRF_COOKIE).unwrap());
    let attempt = |t: &str| post_form("/team/login", &nonce, &format!("token={t}&csrf={}", form.csrf()));
    for _ in 0..3 {
        assert_eq!(
            call(&app, attempt("kr_guess")).await.status,
            StatusCode::UNAUTHORIZED
        );
    }
    for t in ["kr_guess", token.as_str()] {
        let a = call(&app, attempt(t)).await;
        assert_eq!(a.status, StatusCode::TOO_MANY_REQUESTS, "{t}: {}", a.body);
        let wait: u64 = a.headers[header::RETRY_AFTER].to_str().unwrap().parse().unwrap();
        assert!((1..=20).contains(&wait), "{wait}");
        assert!(a.body.contains("Too many failed logins"), "{}", a.body);
        assert!(a.cookie(TEAM_COOKIE).is_none());
    }
}
