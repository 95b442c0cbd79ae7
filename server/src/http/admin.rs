//! The organiser's console over HTTP: the JSON admin API (`/api/v1/admin/queue`, `workers`,
//! `runs`, `runs/{id}/cancel`, `runs/{id}/requeue`, `backup`) with the bearer token, and the
//! HTML page `GET /admin`.
//!
//! A browser cannot send a bearer header from a plain page, so `/admin` has a login form that
//! takes the organiser token and opens a server-side session (`crate::service::sessions`;
//! `[sessions] organiser_hours`, 8 by default) whose id a cookie holds (attributes and CSRF
//! in [`super::session`]). The cookie is `Path=/` so that the participant pages
//! (`/submissions/{id}`) also open for the organiser; no API route reads it. It authorises
//! only *reading* pages: every action (cancel, requeue, backup) stays on the bearer-token API
//! (the CLI), and the login and logout forms carry a CSRF token. Serve it over TLS (a reverse
//! proxy) when the organiser's browser is not on the server's machine.

use axum::Router;
use axum::body::Body;
use axum::extract::{Form, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use bytes::Bytes;
use serde::Deserialize;
use tokio::io::AsyncReadExt;

use super::extract::{ClientAddr, PathArg};
use super::queries::run_id;
use super::session;
use crate::error::ServiceError;
use crate::service::sessions::{Login, Role};
use crate::service::{AppState, Caller};

/// The session cookie's name; its value is a session id (`crate::service::sessions`).
pub(super) const COOKIE: &str = "kitchen_r_admin";

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

#[utoipa::path(
    get,
    path = "/api/v1/admin/queue",
    tag = "organiser",
    summary = "The job queue: counts by state, each team's share, stuck, retrying and failed jobs",
    security(("organiser_token" = [])),
    responses((status = 200, description = "The queue", body = crate::service::admin::QueueView))
)]
pub(super) async fn queue(State(s): State<AppState>, caller: Caller) -> Result<Response, ServiceError> {
    Ok(axum::Json(s.admin_queue(caller.organiser()?).await?).into_response())
}

#[utoipa::path(
    get,
    path = "/api/v1/admin/workers",
    tag = "organiser",
    summary = "The workers seen, when last, and what they hold now",
    security(("organiser_token" = [])),
    responses((status = 200, description = "The workers", body = crate::service::admin::WorkersView))
)]
pub(super) async fn workers(State(s): State<AppState>, caller: Caller) -> Result<Response, ServiceError> {
    Ok(axum::Json(s.admin_workers(caller.organiser()?).await?).into_response())
}

#[utoipa::path(
    get,
    path = "/api/v1/admin/runs",
    tag = "organiser",
    summary = "Policy runs: progress, timing and ETA",
    security(("organiser_token" = [])),
    responses((status = 200, description = "The runs, newest first", body = crate::service::admin::RunsView))
)]
pub(super) async fn runs(State(s): State<AppState>, caller: Caller) -> Result<Response, ServiceError> {
    Ok(axum::Json(s.admin_runs(caller.organiser()?).await?).into_response())
}

#[utoipa::path(
    post,
    path = "/api/v1/admin/runs/{id}/cancel",
    tag = "organiser",
    summary = "Cancel a policy run: its open jobs stop and it uses no quota",
    params(("id" = i64, Path, minimum = 1, description = "The run id (`GET /api/v1/admin/runs`)", example = 1)),
    security(("organiser_token" = [])),
    responses(
        (status = 200, description = "Cancelled", body = crate::service::admin::Cancelled),
        (status = 400, description = "The id is not a positive integer", body = super::schemas::ErrorBody),
        (status = 404, description = "No such run", body = super::schemas::ErrorBody),
        (status = 409, description = "The run is not active", body = super::schemas::ErrorBody),
    )
)]
pub(super) async fn cancel(
    State(s): State<AppState>,
    caller: Caller,
    PathArg(id): PathArg<String>,
) -> Result<Response, ServiceError> {
    let admin = caller.organiser()?;
    Ok(axum::Json(s.cancel_run(admin, run_id(&id)?).await?).into_response())
}

#[utoipa::path(
    post,
    path = "/api/v1/admin/runs/{id}/requeue",
    tag = "organiser",
    summary = "Put a run's failed and stuck jobs back in the queue",
    params(("id" = i64, Path, minimum = 1, description = "The run id (`GET /api/v1/admin/runs`)", example = 1)),
    security(("organiser_token" = [])),
    responses(
        (status = 200, description = "Requeued", body = crate::service::admin::Requeued),
        (status = 400, description = "The id is not a positive integer", body = super::schemas::ErrorBody),
        (status = 404, description = "No such run", body = super::schemas::ErrorBody),
        (status = 409, description = "Nothing to requeue", body = super::schemas::ErrorBody),
    )
)]
pub(super) async fn requeue(
    State(s): State<AppState>,
    caller: Caller,
    PathArg(id): PathArg<String>,
) -> Result<Response, ServiceError> {
    let admin = caller.organiser()?;
    Ok(axum::Json(s.requeue_run(admin, run_id(&id)?).await?).into_response())
}

/// The database copy as `application/vnd.sqlite3`, streamed in 64 KiB chunks.
#[utoipa::path(
    post,
    path = "/api/v1/admin/backup",
    tag = "organiser",
    summary = "A consistent copy of the database (SQLite file), streamed",
    security(("organiser_token" = [])),
    responses((status = 200, description = "The database copy", content_type = "application/vnd.sqlite3", body = Vec<u8>,
        headers(("content-disposition" = String, description = "`attachment; filename=\"kitchen-r-<UTC time>.db\"`"))))
)]
pub(super) async fn backup(State(s): State<AppState>, caller: Caller) -> Result<Response, ServiceError> {
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

/// `GET /admin`: the console for the organiser (session cookie or bearer header), else the
/// login form.
async fn page(
    State(s): State<AppState>,
    caller: Caller,
    headers: HeaderMap,
) -> Result<Response, ServiceError> {
    let admin = match caller.organiser() {
        Ok(a) => Some(a),
        Err(_) => organiser_session(&s, &headers).await?,
    };
    let csrf = session::csrf(&headers, COOKIE);
    match admin {
        Some(a) => {
            let body = page::console(&s.admin_console(a).await?, &csrf.field);
            Ok(session::html_with(StatusCode::OK, body, &csrf))
        }
        None => Ok(session::html_with(
            StatusCode::UNAUTHORIZED,
            page::login(None, &csrf.field),
            &csrf,
        )),
    }
}

/// The organiser, when the request carries the console's session cookie (also read by the
/// participant pages, which the organiser may open too).
pub(super) async fn organiser_session(
    s: &AppState,
    headers: &HeaderMap,
) -> Result<Option<crate::service::Organiser>, ServiceError> {
    Ok(match session::session_id(headers, COOKIE) {
        Some(id) => s.session(id).await?.organiser().ok(),
        None => None,
    })
}

#[derive(Debug, Deserialize)]
struct LoginForm {
    token: String,
    csrf: Option<String>,
}

#[derive(Debug, Deserialize)]
struct CsrfForm {
    csrf: Option<String>,
}

/// The login form again, with `message`, answered with `status`.
fn login_again(headers: &HeaderMap, status: StatusCode, message: &str) -> Response {
    let csrf = session::csrf(headers, COOKIE);
    session::html_with(status, page::login(Some(message), &csrf.field), &csrf)
}

/// `POST /admin/login` (form `token=...&csrf=...`): the organiser token opens a session.
async fn login(
    State(s): State<AppState>,
    ClientAddr(client): ClientAddr,
    headers: HeaderMap,
    form: Result<Form<LoginForm>, axum::extract::rejection::FormRejection>,
) -> Result<Response, ServiceError> {
    let Ok(Form(form)) = form else {
        return Ok(login_again(
            &headers,
            StatusCode::BAD_REQUEST,
            "Send the organiser token.",
        ));
    };
    if !session::csrf_ok(&headers, COOKIE, form.csrf.as_deref()) {
        return Ok(login_again(
            &headers,
            StatusCode::FORBIDDEN,
            session::CSRF_REFUSED,
        ));
    }
    Ok(match s.log_in(Role::Organiser, &form.token, client).await? {
        Login::Opened {
            cookie, max_age_s, ..
        } => {
            let c = session::session_cookie(COOKIE, &cookie, max_age_s, session::https(&headers));
            session::see_other("/admin", &[c])
        }
        Login::Refused(message) => login_again(&headers, StatusCode::UNAUTHORIZED, message),
        Login::Throttled { retry_after_s } => session::with_retry_after(
            login_again(
                &headers,
                StatusCode::TOO_MANY_REQUESTS,
                &session::throttled_message(retry_after_s),
            ),
            retry_after_s,
        ),
    })
}

/// `POST /admin/logout` (form `csrf=...`): end the session and drop its cookie (and the one
/// older servers set on `Path=/admin`).
async fn logout(
    State(s): State<AppState>,
    headers: HeaderMap,
    form: Result<Form<CsrfForm>, axum::extract::rejection::FormRejection>,
) -> Result<Response, ServiceError> {
    let sent = form.ok().and_then(|Form(f)| f.csrf);
    if !session::csrf_ok(&headers, COOKIE, sent.as_deref()) {
        return Ok(login_again(
            &headers,
            StatusCode::FORBIDDEN,
            session::CSRF_REFUSED,
        ));
    }
    if let Some(id) = session::session_id(&headers, COOKIE) {
        s.log_out(id).await?;
    }
    let secure = session::https(&headers);
    let old = HeaderValue::from_static("kitchen_r_admin=; Path=/admin; HttpOnly; SameSite=Strict; Max-Age=0");
    Ok(session::see_other(
        "/admin",
        &[session::set_cookie(COOKIE, "", Some(0), secure), old],
    ))
}

mod page;
#[cfg(test)]
mod tests;
