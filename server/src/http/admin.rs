//! The organiser's console over HTTP: the JSON admin API (`/api/v1/admin/queue`, `workers`,
//! `runs`, `runs/{id}/cancel`, `runs/{id}/requeue`, `backup`) with the bearer token, and the
//! HTML page `GET /admin`.
//!
//! A browser cannot send a bearer header from a plain page, so `/admin` has a login form that
//! takes the organiser token and sets it as a cookie: `HttpOnly` (no script can read it),
//! `SameSite=Strict` (no other site's page or link sends it), `Path=/admin` (no other route
//! sees it), 8 hours. The cookie authorises only *reading* the page: every action (cancel,
//! requeue, backup) stays on the bearer-token API (the CLI), so a forged cross-site request
//! could do nothing even if the browser sent the cookie. The page sends `Cache-Control:
//! no-store`, a strict Content-Security-Policy and `X-Frame-Options: DENY`. Serve it over
//! TLS (a reverse proxy) when the organiser's browser is not on the server's machine.

use axum::Router;
use axum::body::Body;
use axum::extract::{Form, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use bytes::Bytes;
use serde::Deserialize;
use tokio::io::AsyncReadExt;

use super::extract::PathArg;
use crate::error::ServiceError;
use crate::service::admin::login_page;
use crate::service::{AppState, Caller};

/// The session cookie's name; its value is the organiser token, hex-encoded.
const COOKIE: &str = "kitchen_r_admin";
const SESSION_S: u32 = 8 * 3600;

/// Routes answered within the request budget.
pub(super) fn quick_routes() -> Router<AppState> {
    Router::new()
        .route("/api/v1/admin/queue", get(queue))
        .route("/api/v1/admin/workers", get(workers))
        .route("/api/v1/admin/runs", get(runs))
        .route("/api/v1/admin/runs/{id}/cancel", post(cancel))
        .route("/api/v1/admin/runs/{id}/requeue", post(requeue))
        .route("/admin", get(page))
        .route("/admin/login", post(login))
        .route("/admin/logout", post(logout))
}

/// The backup streams a copy of the whole database: its length grows with the contest.
pub(super) fn unbounded_routes() -> Router<AppState> {
    Router::new().route("/api/v1/admin/backup", post(backup))
}

/// A run id from the path: a positive integer, else 400 `bad_request` (an unknown one is 404).
fn run_id(id: &str) -> Result<i64, ServiceError> {
    id.parse::<i64>()
        .ok()
        .filter(|n| *n > 0)
        .ok_or_else(|| ServiceError::BadRequest(format!("a run id is a positive integer, not {id:?}")))
}

async fn queue(State(s): State<AppState>, caller: Caller) -> Result<Response, ServiceError> {
    Ok(axum::Json(s.admin_queue(caller.organiser()?).await?).into_response())
}

async fn workers(State(s): State<AppState>, caller: Caller) -> Result<Response, ServiceError> {
    Ok(axum::Json(s.admin_workers(caller.organiser()?).await?).into_response())
}

async fn runs(State(s): State<AppState>, caller: Caller) -> Result<Response, ServiceError> {
    Ok(axum::Json(s.admin_runs(caller.organiser()?).await?).into_response())
}

async fn cancel(
    State(s): State<AppState>,
    caller: Caller,
    PathArg(id): PathArg<String>,
) -> Result<Response, ServiceError> {
    let admin = caller.organiser()?;
    Ok(axum::Json(s.cancel_run(admin, run_id(&id)?).await?).into_response())
}

async fn requeue(
    State(s): State<AppState>,
    caller: Caller,
    PathArg(id): PathArg<String>,
) -> Result<Response, ServiceError> {
    let admin = caller.organiser()?;
    Ok(axum::Json(s.requeue_run(admin, run_id(&id)?).await?).into_response())
}

/// The database copy as `application/vnd.sqlite3`, streamed in 64 KiB chunks.
async fn backup(State(s): State<AppState>, caller: Caller) -> Result<Response, ServiceError> {
    let b = s.backup(caller.organiser()?).await?;
    let stream = futures_util::stream::unfold(Some(b.file), |file| async move {
        let mut f = file?;
        let mut buf = vec![0u8; 64 << 10];
        match f.read(&mut buf).await {
            Ok(0) => None,
            Ok(n) => {
                buf.truncate(n);
                Some((Ok(Bytes::from(buf)), Some(f)))
            }
            // Cut the body short: the client sees a truncated transfer, never a bad copy.
            Err(e) => Some((Err(e), None)),
        }
    });
    let disposition = format!("attachment; filename=\"{}\"", b.name);
    let mut response = Body::from_stream(stream).into_response();
    let h = response.headers_mut();
    h.insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("application/vnd.sqlite3"),
    );
    h.insert(header::CONTENT_LENGTH, HeaderValue::from(b.len));
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    if let Ok(v) = HeaderValue::from_str(&disposition) {
        h.insert(header::CONTENT_DISPOSITION, v);
    }
    Ok(response)
}

/// The organiser token of the session cookie, if any.
fn cookie_token(headers: &HeaderMap) -> Option<String> {
    headers
        .get_all(header::COOKIE)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(';'))
        .filter_map(|kv| kv.trim().strip_prefix(COOKIE)?.strip_prefix('='))
        .find_map(|hexed| String::from_utf8(hex::decode(hexed).ok()?).ok())
}

fn html(status: StatusCode, body: String) -> Response {
    let mut r = (status, body).into_response();
    let h = r.headers_mut();
    h.insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("text/html; charset=utf-8"),
    );
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    h.insert(
        header::CONTENT_SECURITY_POLICY,
        HeaderValue::from_static(
            "default-src 'none'; style-src 'unsafe-inline'; form-action 'self'; frame-ancestors 'none'",
        ),
    );
    h.insert(header::X_FRAME_OPTIONS, HeaderValue::from_static("DENY"));
    h.insert(header::REFERRER_POLICY, HeaderValue::from_static("no-referrer"));
    r
}

/// `GET /admin`: the console for the organiser (session cookie or bearer header), else the
/// login form.
async fn page(
    State(s): State<AppState>,
    caller: Caller,
    headers: HeaderMap,
) -> Result<Response, ServiceError> {
    let admin = match caller.organiser() {
        Ok(a) => Some(a),
        Err(_) => match cookie_token(&headers) {
            Some(t) => s.caller(Some(&t)).await?.organiser().ok(),
            None => None,
        },
    };
    match admin {
        Some(a) => Ok(html(StatusCode::OK, s.admin_page(a).await?)),
        None => Ok(html(StatusCode::UNAUTHORIZED, login_page(None))),
    }
}

#[derive(Debug, Deserialize)]
struct LoginForm {
    token: String,
}

/// `POST /admin/login` (form `token=...`): the organiser token sets the session cookie.
async fn login(
    State(s): State<AppState>,
    form: Result<Form<LoginForm>, axum::extract::rejection::FormRejection>,
) -> Result<Response, ServiceError> {
    let Ok(Form(form)) = form else {
        return Ok(html(
            StatusCode::BAD_REQUEST,
            login_page(Some("Send the organiser token.")),
        ));
    };
    let token = form.token.trim();
    if token.is_empty() || s.caller(Some(token)).await?.organiser().is_err() {
        tracing::warn!("organiser console: failed login");
        return Ok(html(
            StatusCode::UNAUTHORIZED,
            login_page(Some("That is not the organiser token.")),
        ));
    }
    let cookie = format!(
        "{COOKIE}={}; Path=/admin; HttpOnly; SameSite=Strict; Max-Age={SESSION_S}",
        hex::encode(token)
    );
    let mut r = StatusCode::SEE_OTHER.into_response();
    let h = r.headers_mut();
    h.insert(header::LOCATION, HeaderValue::from_static("/admin"));
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    if let Ok(v) = HeaderValue::from_str(&cookie) {
        h.insert(header::SET_COOKIE, v);
    }
    Ok(r)
}

/// `POST /admin/logout`: drop the session cookie.
async fn logout() -> Response {
    let mut r = StatusCode::SEE_OTHER.into_response();
    let h = r.headers_mut();
    h.insert(header::LOCATION, HeaderValue::from_static("/admin"));
    h.insert(
        header::SET_COOKIE,
        HeaderValue::from_static("kitchen_r_admin=; Path=/admin; HttpOnly; SameSite=Strict; Max-Age=0"),
    );
    r
}

#[cfg(test)]
mod tests;
