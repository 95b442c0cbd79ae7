//! The HTTP adapter (axum): routes of DESIGN.md "The public interface".
//!
//! Handlers only extract, call one service function and shape the answer; every rule is in
//! [`crate::service`]. Errors are always JSON (`{"error", "code", "request_id", ...}`): unknown
//! routes and methods answer through fallbacks (405 keeps its `Allow` header), bodies are capped
//! at `max_body_bytes` with a JSON 413, and path, query and body rejections go through
//! [`extract`]'s wrappers; [`stack`] is the tower stack (request id, JSON errors, trace,
//! catch-panic, timeout) every route runs in. HTML pages are [`admin`]'s console and
//! [`pages`] (sessions and CSRF in [`session`]); their errors are pages, not JSON.

use std::collections::HashMap;

use axum::Router;
use axum::body::Body;
use axum::extract::{DefaultBodyLimit, FromRequestParts, State};
use axum::http::request::Parts;
use axum::http::{HeaderValue, Method, StatusCode, header};
use axum::response::{Html, IntoResponse, Response};
use axum::routing::{get, post};
use bytes::Bytes;
use kitchen_r_core::dataset::Split;
use serde_json::json;
use tokio_stream::StreamExt;

use crate::content::TestSetKind;
use crate::error::ServiceError;
use crate::leaderboard::{Format, Track};
use crate::service::auth::bearer_token;
use crate::service::{AppState, Caller, RegisterPolicy};

use extract::{BodyBytes, PathArg, QueryArgs};

type Params = QueryArgs<HashMap<String, String>>;

mod admin;
mod extract;
mod pages;
mod session;
pub(crate) mod stack;

pub(crate) fn router(state: AppState) -> Router {
    let cfg = state.config();
    let quick = Router::new()
        .route("/", get(index))
        .route("/healthz", get(healthz))
        .route("/api/v1/teams", post(create_team))
        .route("/api/v1/dataset/manifest", get(dataset_manifest))
        .route("/api/v1/dataset/{split}", get(dataset))
        .route("/api/v1/scenes", get(scenes))
        .route("/api/v1/scenes/{id}", get(scene))
        .route("/api/v1/scenes/{id}/topdown.png", get(topdown))
        .route("/api/v1/scenes/{id}/brief", get(brief))
        .route("/api/v1/submissions/plans", post(submit_plans))
        .route("/api/v1/submissions/{id}", get(submission))
        .route(
            "/api/v1/submissions/{id}/episodes/{episode_key}/path.png",
            get(episode_plot),
        )
        .route("/api/v1/leaderboard", get(leaderboard))
        .route("/api/v1/admin/resimulate", post(resimulate))
        .route("/api/v1/admin/stats", get(admin_stats))
        // The organiser's console: admin API and the `/admin` page (see `admin`).
        .merge(admin::quick_routes())
        // The participant pages: contest home, team login, team and submission pages.
        .merge(pages::routes());
    // Prometheus text format, no token (see `service::metrics` for why that is safe).
    let quick = match cfg.metrics {
        true => quick.route("/metrics", get(metrics)),
        false => quick,
    };
    // Registration probes the endpoint first, which may take up to `policy.startup_deadline_ms`.
    let probing = Router::new().route("/api/v1/submissions/policies", post(register_policy));
    // The organiser's rescore walks every stored submission, so its length grows with the
    // contest; abandoning it would leave it half done. It is organiser-only, so no budget.
    let unbounded = Router::new()
        .route("/api/v1/admin/rescore", post(rescore))
        .merge(admin::unbounded_routes());
    let routes = stack::with_timeout(quick, cfg.request_timeout())
        .merge(stack::with_timeout(probing, cfg.registration_timeout()))
        .merge(unbounded)
        // After the merge: it is set on the routes present when called.
        .method_not_allowed_fallback(method_not_allowed)
        .fallback(|| async { ServiceError::not_found("route") })
        // Read by `BodyBytes`; plan files are streamed under the same limit by `read_limited`.
        .layer(DefaultBodyLimit::max(cfg.max_body_bytes));
    stack::layered(routes).with_state(state)
}

/// A known route called with a method it does not have; axum adds the `Allow` header.
async fn method_not_allowed(method: Method) -> ServiceError {
    ServiceError::MethodNotAllowed {
        method: method.to_string(),
    }
}

/// The caller of every route that declares one, resolved once from the `authorization` header
/// before the body is read (so a bad token is refused without reading a large upload).
impl FromRequestParts<AppState> for Caller {
    type Rejection = ServiceError;

    async fn from_request_parts(parts: &mut Parts, state: &AppState) -> Result<Self, ServiceError> {
        let header = parts.headers.get(header::AUTHORIZATION);
        let token = header.and_then(|v| v.to_str().ok()).and_then(bearer_token);
        state.caller(token).await
    }
}

fn split_param(value: Option<&String>, default: Option<Split>) -> Result<Split, ServiceError> {
    match (value.map(String::as_str), default) {
        (None | Some(""), Some(d)) => Ok(d),
        (None | Some(""), None) => Err(ServiceError::BadRequest(
            "the `split` query parameter is required: `dev` or `test`".into(),
        )),
        (Some(s), _) => s.parse().map_err(ServiceError::BadRequest),
    }
}

fn typed(content_type: &'static str, body: Bytes) -> Response {
    (
        [(header::CONTENT_TYPE, HeaderValue::from_static(content_type))],
        body,
    )
        .into_response()
}

async fn healthz() -> impl IntoResponse {
    axum::Json(json!({ "status": "ok" }))
}

async fn metrics(State(s): State<AppState>) -> Result<Response, ServiceError> {
    let text = s.metrics_text().await?;
    Ok(typed(crate::metrics::CONTENT_TYPE, Bytes::from(text)))
}

async fn index(State(s): State<AppState>, QueryArgs(q): Params) -> Result<Response, ServiceError> {
    let split = split_param(q.get("split"), Some(Split::Test))?;
    let body = s.leaderboard_page(split).await?;
    Ok(Html(body).into_response())
}

/// The field `key` of a small JSON body shaped like `shape`. Organiser routes check the token
/// before reading the body, so a caller without one learns nothing from body errors.
fn body_field<T: serde::de::DeserializeOwned>(
    body: &[u8],
    key: &str,
    shape: &str,
) -> Result<T, ServiceError> {
    let req: serde_json::Value = serde_json::from_slice(body)
        .map_err(|e| ServiceError::BadRequest(format!("expected {shape}: {e}")))?;
    req.get(key)
        .and_then(|v| T::deserialize(v).ok())
        .ok_or_else(|| ServiceError::BadRequest(format!("expected {shape}")))
}

async fn create_team(
    State(s): State<AppState>,
    caller: Caller,
    BodyBytes(body): BodyBytes,
) -> Result<Response, ServiceError> {
    let admin = caller.organiser()?;
    let name: String = body_field(&body, "name", r#"{"name": "..."}"#)?;
    let team = s.create_team(admin, &name).await?;
    Ok((StatusCode::CREATED, axum::Json(team)).into_response())
}

async fn dataset(
    State(s): State<AppState>,
    PathArg(split): PathArg<String>,
) -> Result<Response, ServiceError> {
    let split: Split = split.parse().map_err(ServiceError::BadRequest)?;
    let mut response = typed("application/x-ndjson", s.content().public_jsonl(split));
    // Says on every test download whether its answers are public (see /api/v1/dataset/manifest).
    let kind = match (split, &s.content().test_set.kind) {
        (Split::Dev, _) => "dev",
        (Split::Test, TestSetKind::PublicSample) => "public-sample",
        (Split::Test, TestSetKind::Private) => "private",
    };
    response
        .headers_mut()
        .insert("x-kitchen-r-split-kind", HeaderValue::from_static(kind));
    Ok(response)
}

/// What the dataset splits are: the dev split (public, with plans) and the test split's
/// provenance (public sample or private set), with a notice to show participants.
async fn dataset_manifest(State(s): State<AppState>) -> impl IntoResponse {
    let c = s.content();
    axum::Json(json!({
        "dev": { "instructions": c.dataset.dev.len(), "plans": "public" },
        "test": c.test_set,
    }))
}

/// The English scene description planners read (zones, the furniture that holds them and the
/// names instructions may use for them, and where each key object starts).
async fn brief(State(s): State<AppState>, PathArg(id): PathArg<String>) -> Result<Response, ServiceError> {
    let scene = s
        .content()
        .scene(&id)
        .ok_or_else(|| ServiceError::not_found(format!("scene {id:?}")))?;
    Ok(typed(
        "text/plain; charset=utf-8",
        Bytes::from(scene.planner_brief()),
    ))
}

async fn scenes(State(s): State<AppState>) -> impl IntoResponse {
    axum::Json(s.content().scene_summaries())
}

async fn scene(State(s): State<AppState>, PathArg(id): PathArg<String>) -> Result<Response, ServiceError> {
    let scene = s
        .content()
        .scene(&id)
        .ok_or_else(|| ServiceError::not_found(format!("scene {id:?}")))?;
    Ok(axum::Json(scene).into_response())
}

async fn topdown(State(s): State<AppState>, PathArg(id): PathArg<String>) -> Result<Response, ServiceError> {
    let scene = id.clone();
    let png = tokio::task::spawn_blocking(move || s.content().topdown_png(&scene))
        .await
        .map_err(anyhow::Error::from)?
        .ok_or_else(|| ServiceError::not_found(format!("scene {id:?}")))?;
    Ok(typed("image/png", png))
}

/// Reads at most `max_body_bytes + 1` bytes, so an oversized upload is refused without being
/// held in memory whole, and the service can still say on which line the limit was crossed.
async fn read_limited(body: Body, limit: usize) -> Result<Vec<u8>, ServiceError> {
    let mut stream = body.into_data_stream();
    let mut buf = Vec::new();
    while let Some(chunk) = stream.next().await {
        let chunk = chunk.map_err(|e| ServiceError::BadRequest(format!("cannot read the body: {e}")))?;
        let room = limit + 1 - buf.len();
        buf.extend_from_slice(&chunk[..chunk.len().min(room)]);
        if buf.len() > limit {
            break;
        }
    }
    Ok(buf)
}

async fn submit_plans(
    State(s): State<AppState>,
    QueryArgs(q): Params,
    caller: Caller,
    body: Body,
) -> Result<Response, ServiceError> {
    // Refuse bad credentials and parameters before reading a possibly large body.
    let team = caller.team()?;
    let split = split_param(q.get("split"), None)?;
    let body = read_limited(body, s.config().max_body_bytes).await?;
    let done = s.submit_plans(team, split, &body).await?;
    Ok((StatusCode::CREATED, axum::Json(done)).into_response())
}

async fn register_policy(
    State(s): State<AppState>,
    caller: Caller,
    BodyBytes(body): BodyBytes,
) -> Result<Response, ServiceError> {
    let req: RegisterPolicy = serde_json::from_slice(&body).map_err(|e| {
        ServiceError::BadRequest(format!(
            "expected {{\"endpoint\": \"http://HOST:PORT\", \"split\": \"dev\"|\"test\", \"token\"?, \"plans\"?, \"episodes\"?, \"reference\"?}}: {e}"
        ))
    })?;
    let done = s.register_policy(&caller, req).await?;
    Ok((StatusCode::CREATED, axum::Json(done)).into_response())
}

async fn submission(
    State(s): State<AppState>,
    PathArg(id): PathArg<String>,
    caller: Caller,
) -> Result<Response, ServiceError> {
    let id: i64 = id
        .parse()
        .map_err(|_| ServiceError::not_found(format!("submission {id:?}")))?;
    Ok(axum::Json(s.get_submission(&caller, id).await?).into_response())
}

async fn episode_plot(
    State(s): State<AppState>,
    PathArg((id, key)): PathArg<(String, String)>,
    caller: Caller,
) -> Result<Response, ServiceError> {
    let id: i64 = id
        .parse()
        .map_err(|_| ServiceError::not_found(format!("submission {id:?}")))?;
    let png = s.episode_plot(&caller, id, &key).await?;
    Ok(typed("image/png", Bytes::from(png)))
}

async fn leaderboard(State(s): State<AppState>, QueryArgs(q): Params) -> Result<Response, ServiceError> {
    let track: Track = q.get("track").map_or("", String::as_str).parse()?;
    let split = split_param(q.get("split"), Some(Split::Test))?;
    let (format, content_type) = match q.get("format").map(String::as_str) {
        None | Some("" | "json") => (Format::Json, "application/json"),
        Some("csv") => (Format::Csv, "text/csv; charset=utf-8"),
        Some("html") => (Format::Html, "text/html; charset=utf-8"),
        Some(other) => {
            return Err(ServiceError::BadRequest(format!(
                "unknown format {other:?} (expected json, csv or html)"
            )));
        }
    };
    let body = s.leaderboard_rendered(track, split, format).await?;
    Ok(typed(content_type, body))
}

async fn rescore(State(s): State<AppState>, caller: Caller) -> Result<Response, ServiceError> {
    Ok(axum::Json(s.rescore_all(caller.organiser()?).await?).into_response())
}

/// Organiser: `{"submission": ID}` → a new run simulating that policy submission again.
async fn resimulate(
    State(s): State<AppState>,
    caller: Caller,
    BodyBytes(body): BodyBytes,
) -> Result<Response, ServiceError> {
    let admin = caller.organiser()?;
    let id: i64 = body_field(&body, "submission", r#"{"submission": ID}"#)?;
    let done = s.resimulate(admin, id).await?;
    Ok((StatusCode::CREATED, axum::Json(done)).into_response())
}

/// Organiser: what the server refused since it started (rate limits and daily quotas, per
/// split) and the limits in force.
async fn admin_stats(State(s): State<AppState>, caller: Caller) -> Result<Response, ServiceError> {
    Ok(axum::Json(s.admin_stats(caller.organiser()?)).into_response())
}

#[cfg(test)]
mod stack_tests;
#[cfg(test)]
mod tests;
