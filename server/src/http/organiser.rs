//! The organiser's API beside the console (tag `organiser`): teams and their tokens, rescoring
//! every submission, simulating a policy submission again, and what the server refused. The
//! console's own routes (queue, workers, runs, backup, the `/admin` page) are [`super::admin`]'s.

use axum::Router;
use axum::extract::State;
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};

use super::extract::{BodyBytes, PathArg};
use super::schemas;
use crate::error::ServiceError;
use crate::service::{AppState, Caller};

/// Routes answered within the request budget.
pub(super) fn routes() -> Router<AppState> {
    Router::new()
        .route("/api/v1/teams", post(create_team))
        .route("/api/v1/teams/{id}/token", post(rotate_team_token))
        .route("/api/v1/admin/resimulate", post(resimulate))
        .route("/api/v1/admin/stats", get(admin_stats))
}

/// The rescore walks every stored submission, so its length grows with the contest; abandoning
/// it would leave it half done. It is organiser-only, so no budget.
pub(super) fn unbounded_routes() -> Router<AppState> {
    Router::new().route("/api/v1/admin/rescore", post(rescore))
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
    request_body = schemas::TeamRequest,
    security(("organiser_token" = [])),
    responses(
        (status = 201, description = "The team and its token (shown once)", body = crate::service::NewTeam),
        (status = 400, description = "The body is not `{\"name\": \"...\"}` or the name is not allowed", body = schemas::ErrorBody),
        (status = 409, description = "A team of that name exists", body = schemas::ErrorBody),
        (status = 413, description = "The body is over `max_body_bytes`", body = schemas::ErrorBody),
    )
)]
pub(super) async fn create_team(
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
        (status = 401, description = "No token, or one that is no team's nor the organiser's", body = schemas::ErrorBody),
        (status = 404, description = "No such team (or another team's id, or the baseline team)", body = schemas::ErrorBody),
    )
)]
pub(super) async fn rotate_team_token(
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
    post,
    path = "/api/v1/admin/rescore",
    tag = "organiser",
    summary = "Rescore every submission against the current ground truth",
    security(("organiser_token" = [])),
    responses((status = 200, description = "What was rescored, and what could not be", body = crate::service::RescoreReport))
)]
pub(super) async fn rescore(State(s): State<AppState>, caller: Caller) -> Result<Response, ServiceError> {
    Ok(axum::Json(s.rescore_all(caller.organiser()?).await?).into_response())
}

/// Organiser: `{"submission": ID}` → a new run simulating that policy submission again.
#[utoipa::path(
    post,
    path = "/api/v1/admin/resimulate",
    tag = "organiser",
    summary = "Simulate a policy submission again",
    request_body = schemas::ResimulateRequest,
    security(("organiser_token" = [])),
    responses(
        (status = 201, description = "A new run, queued", body = crate::service::policies::Registered),
        (status = 400, description = "The body is not `{\"submission\": ID}`", body = schemas::ErrorBody),
        (status = 404, description = "No such policy submission", body = schemas::ErrorBody),
        (status = 409, description = "It is still evaluating", body = schemas::ErrorBody),
        (status = 413, description = "The body is over `max_body_bytes`", body = schemas::ErrorBody),
    )
)]
pub(super) async fn resimulate(
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
pub(super) async fn admin_stats(State(s): State<AppState>, caller: Caller) -> Result<Response, ServiceError> {
    Ok(axum::Json(s.admin_stats(caller.organiser()?)).into_response())
}
