//! The HTTP adapter (axum): routes of docs/reference/http-api.md.
//!
//! Handlers only extract, call one service function and shape the answer; every rule is in
//! [`crate::service`]. Errors are always JSON (`{"error", "code", "request_id", ...}`): unknown
//! routes and methods answer through fallbacks (405 keeps its `Allow` header), bodies are capped
//! at `max_body_bytes` with a JSON 413, and path, query and body rejections go through
//! [`extract`]'s wrappers; [`stack`] is the tower stack (request id, JSON errors, trace,
//! catch-panic, timeout) every route runs in. HTML pages are [`admin`]'s console and
//! [`pages`] (sessions and CSRF in [`session`]); their errors are pages, not JSON.

use axum::Router;
use axum::body::Body;
use axum::extract::{DefaultBodyLimit, FromRequestParts, State};
use axum::http::request::Parts;
use axum::http::{HeaderValue, Method, StatusCode, header};
use axum::response::{Html, IntoResponse, Response};
use axum::routing::{get, post};
use bytes::Bytes;
use kitchen_r_core::GraspMode;
use kitchen_r_core::dataset::Split;
use kitchen_r_core::observations::ObservationTrack;
use tokio_stream::StreamExt;

use crate::content::TestSetKind;
use crate::error::ServiceError;
use crate::leaderboard::{Format, Track};
use crate::service::auth::bearer_token;
use crate::service::{AppState, Caller, RegisterPolicy};

use extract::{BodyBytes, PathArg, QueryArgs};
use queries::{LeaderboardQuery, PlansQuery, SplitQuery};
// The route tests (`tests.rs`, `use super::*`) build expected bodies with it.
#[cfg(test)]
use serde_json::json;

mod admin;
mod conditional;
mod error_body;
mod extract;
pub(crate) mod openapi;
mod pages;
mod queries;
mod session;
pub(crate) mod stack;
mod video;
mod viewer;

pub(crate) fn router(state: AppState) -> Router {
    let cfg = state.config();
    let quick = Router::new()
        .route("/", get(index))
        .route("/healthz", get(healthz))
        .route("/api/v1/openapi.json", get(openapi::openapi_json))
        .route("/api/v1/teams", post(create_team))
        .route("/api/v1/teams/{id}/token", post(rotate_team_token))
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
        .route(
            "/api/v1/submissions/{id}/episodes/{episode_key}/video.mp4",
            get(video::api_video),
        )
        .route(
            "/api/v1/submissions/{id}/episodes/{episode_key}/trace",
            get(video::api_trace),
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

#[utoipa::path(
    get,
    path = "/healthz",
    tag = "service",
    summary = "Liveness: the server answers",
    responses((status = 200, description = "The server is up", body = openapi::Health))
)]
async fn healthz() -> impl IntoResponse {
    axum::Json(openapi::Health { status: "ok" })
}

#[utoipa::path(
    get,
    path = "/metrics",
    tag = "service",
    summary = "Prometheus metrics (text exposition format)",
    description = "No token: see `service::metrics` for why nothing in it is secret. Absent (404) when `metrics = false`.",
    responses(
        (status = 200, description = "The metrics", content_type = "text/plain; version=0.0.4", body = String),
        (status = 404, description = "Metrics are turned off (`metrics = false`)", body = openapi::ErrorBody),
    )
)]
async fn metrics(State(s): State<AppState>) -> Result<Response, ServiceError> {
    let text = s.metrics_text().await?;
    Ok(typed(crate::metrics::CONTENT_TYPE, Bytes::from(text)))
}

async fn index(
    State(s): State<AppState>,
    QueryArgs(q): QueryArgs<SplitQuery>,
) -> Result<Response, ServiceError> {
    let split = split_param(q.split.as_ref(), Some(Split::Test))?;
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

#[utoipa::path(
    post,
    path = "/api/v1/teams",
    tag = "organiser",
    summary = "Create a team and its token",
    request_body = openapi::TeamRequest,
    security(("organiser_token" = [])),
    responses(
        (status = 201, description = "The team and its token (shown once)", body = crate::service::NewTeam),
        (status = 400, description = "The body is not `{\"name\": \"...\"}` or the name is not allowed", body = openapi::ErrorBody),
        (status = 409, description = "A team of that name exists", body = openapi::ErrorBody),
        (status = 413, description = "The body is over `max_body_bytes`", body = openapi::ErrorBody),
    )
)]
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

#[utoipa::path(
    post,
    path = "/api/v1/teams/{id}/token",
    tag = "organiser",
    summary = "Give a team a new token",
    description = "The organiser, or the team itself with its current token. The old token stops working at once and every page session of the team ends.",
    params(("id" = i64, Path, description = "The team's id")),
    security(("organiser_token" = []), ("team_token" = [])),
    responses(
        (status = 200, description = "The team and its new token (shown once)", body = crate::service::NewTeam),
        (status = 401, description = "No token, or one that is no team's nor the organiser's", body = openapi::ErrorBody),
        (status = 404, description = "No such team (or another team's id, or the baseline team)", body = openapi::ErrorBody),
    )
)]
async fn rotate_team_token(
    State(s): State<AppState>,
    caller: Caller,
    PathArg(id): PathArg<String>,
) -> Result<Response, ServiceError> {
    let id: i64 = id
        .parse()
        .map_err(|_| ServiceError::not_found(format!("team {id:?}")))?;
    Ok(axum::Json(s.rotate_team_token(&caller, id).await?).into_response())
}

#[utoipa::path(
    get,
    path = "/api/v1/dataset/{split}",
    tag = "dataset",
    summary = "A split's instructions (JSON Lines)",
    description = "One JSON object a line: the instruction's id, scene and text; on the dev split also its plan. The `x-kitchen-r-split-kind` header says `dev`, `public-sample` or `private`.",
    params(("split" = crate::schema::SplitName, Path, description = "`dev` or `test`", example = "dev")),
    responses(
        (status = 200, description = "The instructions, one JSON object a line", content_type = "application/x-ndjson", body = String,
            headers(("x-kitchen-r-split-kind" = String, description = "`dev`, `public-sample` or `private`"))),
        (status = 400, description = "Not a split name", body = openapi::ErrorBody),
    )
)]
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
#[utoipa::path(
    get,
    path = "/api/v1/dataset/manifest",
    tag = "dataset",
    summary = "What the dataset splits are",
    responses((status = 200, description = "The splits' sizes and the test split's provenance", body = openapi::DatasetManifest))
)]
async fn dataset_manifest(State(s): State<AppState>) -> impl IntoResponse {
    let c = s.content();
    axum::Json(openapi::DatasetManifest {
        dev: openapi::DevSplitInfo {
            instructions: c.dataset.dev.len(),
            plans: "public",
        },
        test: c.test_set.clone(),
    })
}

/// The English scene description planners read (zones, the furniture that holds them and the
/// names instructions may use for them, and where each key object starts).
#[utoipa::path(
    get,
    path = "/api/v1/scenes/{id}/brief",
    tag = "dataset",
    summary = "A scene described in English for planners",
    params(("id" = String, Path, description = "A scene id from `GET /api/v1/scenes`", example = "kitchen_a")),
    responses(
        (status = 200, description = "The planner brief", content_type = "text/plain; charset=utf-8", body = String),
        (status = 404, description = "No such scene", body = openapi::ErrorBody),
    )
)]
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

#[utoipa::path(
    get,
    path = "/api/v1/scenes",
    tag = "dataset",
    summary = "The scenes",
    responses((status = 200, description = "Every scene, in short", body = Vec<crate::content::SceneSummary>))
)]
async fn scenes(State(s): State<AppState>) -> impl IntoResponse {
    axum::Json(s.content().scene_summaries())
}

#[utoipa::path(
    get,
    path = "/api/v1/scenes/{id}",
    tag = "dataset",
    summary = "One scene in full",
    description = "Its zones, furniture and key objects with their poses, as the simulator loads them.",
    params(("id" = String, Path, description = "A scene id from `GET /api/v1/scenes`", example = "kitchen_a")),
    responses(
        (status = 200, description = "The scene", body = Object),
        (status = 404, description = "No such scene", body = openapi::ErrorBody),
    )
)]
async fn scene(State(s): State<AppState>, PathArg(id): PathArg<String>) -> Result<Response, ServiceError> {
    let scene = s
        .content()
        .scene(&id)
        .ok_or_else(|| ServiceError::not_found(format!("scene {id:?}")))?;
    Ok(axum::Json(scene).into_response())
}

#[utoipa::path(
    get,
    path = "/api/v1/scenes/{id}/topdown.png",
    tag = "dataset",
    summary = "A scene's top-down map",
    params(("id" = String, Path, description = "A scene id from `GET /api/v1/scenes`", example = "kitchen_a")),
    responses(
        (status = 200, description = "The map", content_type = "image/png", body = Vec<u8>),
        (status = 404, description = "No such scene", body = openapi::ErrorBody),
    )
)]
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

#[utoipa::path(
    post,
    path = "/api/v1/submissions/plans",
    tag = "submissions",
    summary = "Submit a plan file (planning track)",
    description = "The body is JSON Lines: one object a line, `{\"id\": instruction id, \"plan\": [sub-task sentences]}`. Other fields of a line are ignored and dropped before storage: the stored file holds only `id` and `plan`. It is scored at once; on the dev split per-instruction results follow on the submission.",
    params(("split" = crate::schema::SplitName, Query, description = "`dev` or `test`", example = "dev"),
        ("reference" = Option<openapi::FlagParam>, Query, description = "Organiser only: file it as the planning board's baseline row (reserved `(baseline)` team, no quota)")),
    request_body(content = String, content_type = "application/x-ndjson", description = "The plan file: one JSON object a line",
        example = json!("{\"id\": \"dev-0001\", \"plan\": [\"move to the blue zone\", \"pick the bowl\", \"move to the red zone\", \"place the bowl\"]}\n")),
    security(("team_token" = []), ("organiser_token" = [])),
    responses(
        (status = 201, description = "Scored and stored", body = crate::service::Submitted),
        (status = 400, description = "A missing or unknown split, or a plan file that does not parse (`line` says where)", body = openapi::ErrorBody),
        (status = 403, description = "Not a team's token (or, with `reference`, not the organiser's)", body = openapi::ErrorBody),
        (status = 413, description = "The file is over `max_body_bytes` or a plan limit", body = openapi::ErrorBody),
        (status = 429, description = "The daily quota or the per-minute rate limit", body = openapi::ErrorBody,
            headers(("retry-after" = u64, description = "Seconds until a retry can succeed"))),
    )
)]
async fn submit_plans(
    State(s): State<AppState>,
    QueryArgs(q): QueryArgs<PlansQuery>,
    caller: Caller,
    body: Body,
) -> Result<Response, ServiceError> {
    // Refuse bad credentials and parameters before reading a possibly large body.
    let reference = match q.reference.as_deref() {
        None | Some("" | "false" | "0") => false,
        Some("true" | "1") => true,
        Some(other) => {
            return Err(ServiceError::BadRequest(format!(
                "`reference` must be `true` or `false`, not {other:?}"
            )));
        }
    };
    if reference {
        caller.organiser()?;
    } else {
        caller.team()?;
    }
    let split = split_param(q.split.as_ref(), None)?;
    let body = read_limited(body, s.config().max_body_bytes).await?;
    let done = match reference {
        true => s.submit_reference_plans(&caller, split, &body).await?,
        false => s.submit_plans(caller.team()?, split, &body).await?,
    };
    Ok((StatusCode::CREATED, axum::Json(done)).into_response())
}

#[utoipa::path(
    post,
    path = "/api/v1/submissions/policies",
    tag = "submissions",
    summary = "Register a policy endpoint for evaluation (control and integrated tracks)",
    description = "The server probes the endpoint (health, GetSpec) before it answers, then queues one episode job per instruction. `reference` is for the organiser's baseline runs.",
    request_body = crate::service::RegisterPolicy,
    security(("team_token" = []), ("organiser_token" = [])),
    responses(
        (status = 201, description = "Registered and queued", body = crate::service::policies::Registered),
        (status = 400, description = "A body that is not a registration, or an endpoint that is not allowed", body = openapi::ErrorBody),
        (status = 403, description = "A reference run without the organiser token", body = openapi::ErrorBody),
        (status = 404, description = "The `plans` submission is not the team's", body = openapi::ErrorBody),
        (status = 413, description = "The body is over `max_body_bytes`", body = openapi::ErrorBody),
        (status = 422, description = "The endpoint did not pass the probe", body = openapi::ErrorBody),
        (status = 429, description = "The daily quota, the rate limit or the concurrent-runs limit", body = openapi::ErrorBody),
    )
)]
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

#[utoipa::path(
    get,
    path = "/api/v1/submissions/{id}",
    tag = "submissions",
    summary = "A submission and its latest run",
    description = "For its team or the organiser. Dev runs list per-instruction (plans) or per-episode (policies) results; test runs are aggregate only.",
    params(("id" = i64, Path, description = "The submission id", example = 1)),
    security(("team_token" = []), ("organiser_token" = [])),
    responses(
        (status = 200, description = "The submission", body = crate::service::SubmissionView),
        (status = 404, description = "No such submission, or another team's", body = openapi::ErrorBody),
    )
)]
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

#[utoipa::path(
    get,
    path = "/api/v1/submissions/{id}/episodes/{episode_key}/path.png",
    tag = "submissions",
    summary = "Where the robot went in one dev episode",
    description = "A top-down plot on the scene map: the base path coloured by task, the object's path, each task's goal and where failed tasks ended. Dev split only.",
    params(("id" = i64, Path, description = "The submission id", example = 1), ("episode_key" = String, Path, description = "The episode's key, e.g. `dev-0007`", example = "dev-0001")),
    security(("team_token" = []), ("organiser_token" = [])),
    responses(
        (status = 200, description = "The plot", content_type = "image/png", body = Vec<u8>),
        (status = 404, description = "No such submission or episode, not the caller's, on the test split, or no path recorded", body = openapi::ErrorBody),
    )
)]
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

#[utoipa::path(
    get,
    path = "/api/v1/leaderboard",
    tag = "leaderboard",
    summary = "One track's leaderboard",
    params(
        ("track" = Option<openapi::TrackParam>, Query, description = "`planning` (default), `control` or `integrated`"),
        ("split" = Option<openapi::SplitParam>, Query, description = "`test` (default) or `dev`"),
        ("observations" = Option<String>, Query, description = "Control and integrated: `standard` (default) or `privileged`, the board of runs whose policy received privileged observations (ranked apart)"),
        ("grasp_mode" = Option<crate::schema::GraspModeName>, Query, description = "Control and integrated: `abstract` or `physical`, the board of runs evaluated in that grasp mode (ranked apart); default the contest's mode (`[control] grasp`). The answer names it in `grasp_mode`"),
        ("format" = Option<openapi::FormatParam>, Query, description = "`json` (default), `csv` or `html`"),
    ),
    responses(
        (status = 200, description = "The ranked rows", content(
            (crate::leaderboard::Leaderboard = "application/json"),
            (String = "text/csv; charset=utf-8"),
            (String = "text/html; charset=utf-8"),
        )),
        (status = 400, description = "An unknown track, split, observations, grasp mode or format, or a grasp mode for the planning track", body = openapi::ErrorBody),
    )
)]
async fn leaderboard(
    State(s): State<AppState>,
    QueryArgs(q): QueryArgs<LeaderboardQuery>,
) -> Result<Response, ServiceError> {
    let track: Track = q.track.as_deref().unwrap_or("").parse()?;
    let split = split_param(q.split.as_ref(), Some(Split::Test))?;
    let observations: ObservationTrack = (q.observations.as_deref().unwrap_or(""))
        .parse()
        .map_err(ServiceError::BadRequest)?;
    let grasp = match q.grasp_mode.as_deref() {
        None | Some("") => None,
        Some(m) => Some(m.parse::<GraspMode>().map_err(ServiceError::BadRequest)?),
    };
    let (format, content_type) = match q.format.as_deref() {
        None | Some("" | "json") => (Format::Json, "application/json"),
        Some("csv") => (Format::Csv, "text/csv; charset=utf-8"),
        Some("html") => (Format::Html, "text/html; charset=utf-8"),
        Some(other) => {
            return Err(ServiceError::BadRequest(format!(
                "unknown format {other:?} (expected json, csv or html)"
            )));
        }
    };
    let body = s
        .leaderboard_rendered(track, observations, grasp, split, format)
        .await?;
    Ok(typed(content_type, body))
}

#[utoipa::path(
    post,
    path = "/api/v1/admin/rescore",
    tag = "organiser",
    summary = "Rescore every submission against the current ground truth",
    security(("organiser_token" = [])),
    responses((status = 200, description = "What was rescored, and what could not be", body = crate::service::RescoreReport))
)]
async fn rescore(State(s): State<AppState>, caller: Caller) -> Result<Response, ServiceError> {
    Ok(axum::Json(s.rescore_all(caller.organiser()?).await?).into_response())
}

/// Organiser: `{"submission": ID}` → a new run simulating that policy submission again.
#[utoipa::path(
    post,
    path = "/api/v1/admin/resimulate",
    tag = "organiser",
    summary = "Simulate a policy submission again",
    request_body = openapi::ResimulateRequest,
    security(("organiser_token" = [])),
    responses(
        (status = 201, description = "A new run, queued", body = crate::service::policies::Registered),
        (status = 400, description = "The body is not `{\"submission\": ID}`", body = openapi::ErrorBody),
        (status = 404, description = "No such policy submission", body = openapi::ErrorBody),
        (status = 409, description = "It is still evaluating", body = openapi::ErrorBody),
        (status = 413, description = "The body is over `max_body_bytes`", body = openapi::ErrorBody),
    )
)]
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
#[utoipa::path(
    get,
    path = "/api/v1/admin/stats",
    tag = "organiser",
    summary = "Refused uploads since start, and the limits in force",
    security(("organiser_token" = [])),
    responses((status = 200, description = "The counts", body = crate::service::AdminStats))
)]
async fn admin_stats(State(s): State<AppState>, caller: Caller) -> Result<Response, ServiceError> {
    Ok(axum::Json(s.admin_stats(caller.organiser()?)).into_response())
}

#[cfg(test)]
mod hardening_tests;
#[cfg(test)]
mod stack_tests;
#[cfg(test)]
mod tests;
