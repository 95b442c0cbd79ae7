//! Results people can trust and keep (docs/contest/archive.md), over HTTP, organiser token only: a
//! run's verification (what to replay, each trace, the verdict), its re-evaluation (the jobs to run
//! again), and the contest archive (export streamed out, import streamed in).

use axum::Router;
use axum::body::Body;
use axum::extract::{DefaultBodyLimit, State};
use axum::http::{HeaderValue, header};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use serde::Deserialize;

use super::extract::{BodyBytes, PathArg, QueryArgs};
use super::queries::run_id;
use crate::error::ServiceError;
use crate::service::verification::VerdictReport;
use crate::service::{AppState, Caller};

/// Routes answered within the request budget.
pub(super) fn routes() -> Router<AppState> {
    Router::new()
        .route("/api/v1/admin/verifications", get(verdicts))
        .route("/api/v1/admin/runs/{id}/verification", get(plan).post(record))
        .route("/api/v1/admin/runs/{id}/episodes/{key}/trace", get(trace))
        .route("/api/v1/admin/runs/{id}/reevaluation", get(reevaluation))
}

/// The archive grows with the contest (traces, videos): no budget, and the import's body is not
/// held to `max_body_bytes` (it is streamed to disk and checked whole before anything is loaded).
pub(super) fn unbounded_routes() -> Router<AppState> {
    Router::new().route("/api/v1/admin/export", post(export)).route(
        "/api/v1/admin/import",
        post(import).layer(DefaultBodyLimit::disable()),
    )
}

#[utoipa::path(
    get,
    path = "/api/v1/admin/verifications",
    tag = "organiser",
    summary = "Every stored verification verdict (`kitchen-r admin verify`)",
    security(("organiser_token" = [])),
    responses((status = 200, description = "Verdicts by run", body = Verdicts))
)]
pub(super) async fn verdicts(State(s): State<AppState>, caller: Caller) -> Result<Response, ServiceError> {
    caller.organiser()?;
    Ok(axum::Json(Verdicts {
        verifications: s.verdicts().await?,
    })
    .into_response())
}

/// Every stored verification verdict.
#[derive(Debug, serde::Serialize, utoipa::ToSchema)]
pub(super) struct Verdicts {
    verifications: Vec<crate::service::verification::Verdict>,
}

#[utoipa::path(
    get,
    path = "/api/v1/admin/runs/{id}/verification",
    tag = "organiser",
    summary = "What verifying a run replays: its episodes' stored results and trace files, and the verdict so far",
    params(("id" = i64, Path, minimum = 1, description = "The run id (`GET /api/v1/admin/runs`)", example = 1)),
    security(("organiser_token" = [])),
    responses(
        (status = 200, description = "The episodes", body = crate::service::verification::VerifyPlan),
        (status = 400, description = "The run id is not a positive integer", body = super::schemas::ErrorBody),
        (status = 404, description = "No such run", body = super::schemas::ErrorBody),
        (status = 409, description = "A plan run (no episodes)", body = super::schemas::ErrorBody),
    )
)]
pub(super) async fn plan(
    State(s): State<AppState>,
    PathArg(id): PathArg<String>,
    caller: Caller,
) -> Result<Response, ServiceError> {
    let admin = caller.organiser()?;
    Ok(axum::Json(s.verification_plan(admin, run_id(&id)?).await?).into_response())
}

#[utoipa::path(
    post,
    path = "/api/v1/admin/runs/{id}/verification",
    tag = "organiser",
    summary = "Record the verdict of a replay of the run's traces: any disagreement marks it unverified",
    request_body = VerdictReport,
    params(("id" = i64, Path, minimum = 1, description = "The run id (`GET /api/v1/admin/runs`)", example = 1)),
    security(("organiser_token" = [])),
    responses(
        (status = 200, description = "The stored verdict", body = crate::service::verification::Verdict),
        (status = 400, description = "The run id is not a positive integer, or the body is not a verdict report", body = super::schemas::ErrorBody),
        (status = 404, description = "No such run", body = super::schemas::ErrorBody),
        (status = 409, description = "A plan run (no episodes)", body = super::schemas::ErrorBody),
    )
)]
pub(super) async fn record(
    State(s): State<AppState>,
    PathArg(id): PathArg<String>,
    caller: Caller,
    BodyBytes(body): BodyBytes,
) -> Result<Response, ServiceError> {
    let admin = caller.organiser()?;
    let report: VerdictReport = serde_json::from_slice(&body)
        .map_err(|e| ServiceError::BadRequest(format!("expected a verdict report: {e}")))?;
    Ok(axum::Json(s.record_verdict(admin, run_id(&id)?, report).await?).into_response())
}

#[utoipa::path(
    get,
    path = "/api/v1/admin/runs/{id}/episodes/{key}/trace",
    tag = "organiser",
    summary = "One episode's stored trace (gzipped JSON) of a given run, dev or test",
    params(("id" = i64, Path, minimum = 1, description = "The run id (`GET /api/v1/admin/runs`)", example = 1),
        ("key" = String, Path, description = "The episode's key, e.g. `dev-0007`", example = "dev-0001")),
    security(("organiser_token" = [])),
    responses(
        (status = 200, description = "The trace", content_type = "application/gzip", body = Vec<u8>),
        (status = 400, description = "The run id is not a positive integer", body = super::schemas::ErrorBody),
        (status = 404, description = "No such run or no stored trace", body = super::schemas::ErrorBody),
        (status = 409, description = "A plan run (no episodes)", body = super::schemas::ErrorBody),
    )
)]
pub(super) async fn trace(
    State(s): State<AppState>,
    PathArg((id, key)): PathArg<(String, String)>,
    caller: Caller,
) -> Result<Response, ServiceError> {
    let admin = caller.organiser()?;
    let path = s.run_trace(admin, run_id(&id)?, &key).await?;
    let bytes = tokio::fs::read(&path)
        .await
        .map_err(|_| ServiceError::not_found(format!("the trace file of episode {key}")))?;
    let mut response = Body::from(bytes).into_response();
    let h = response.headers_mut();
    h.insert(header::CONTENT_TYPE, HeaderValue::from_static("application/gzip"));
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    Ok(response)
}

#[derive(Debug, Deserialize, utoipa::IntoParams)]
pub(super) struct EpisodesQuery {
    /// How many of the run's online episodes to hand out (the first N in key order); required.
    /// Optional to the query parser only, so that a caller without the organiser's token is
    /// told so (401) before anything about its query.
    episodes: Option<usize>,
}

#[utoipa::path(
    get,
    path = "/api/v1/admin/runs/{id}/reevaluation",
    tag = "organiser",
    summary = "N of a run's jobs, as workers lease them (endpoint token opened), with their stored results",
    params(("id" = i64, Path, minimum = 1, description = "The run id (`GET /api/v1/admin/runs`)", example = 1), EpisodesQuery),
    security(("organiser_token" = [])),
    responses(
        (status = 200, description = "The jobs", body = crate::service::verification::Reevaluation),
        (status = 400, description = "The run id is not a positive integer, or `episodes` is missing or not a count", body = super::schemas::ErrorBody),
        (status = 404, description = "No such run", body = super::schemas::ErrorBody),
        (status = 409, description = "A plan run (no episodes)", body = super::schemas::ErrorBody),
    )
)]
pub(super) async fn reevaluation(
    State(s): State<AppState>,
    PathArg(id): PathArg<String>,
    QueryArgs(q): QueryArgs<EpisodesQuery>,
    caller: Caller,
) -> Result<Response, ServiceError> {
    let admin = caller.organiser()?;
    let episodes = q.episodes.ok_or_else(|| {
        ServiceError::BadRequest("`episodes` is required: how many of the run's episodes to run again".into())
    })?;
    Ok(axum::Json(s.reevaluation(admin, run_id(&id)?, episodes).await?).into_response())
}

#[derive(Debug, Deserialize, utoipa::IntoParams)]
pub(super) struct ExportQuery {
    /// Include the stored episode videos (they can be rendered again from the traces).
    #[serde(default)]
    videos: bool,
}

#[utoipa::path(
    post,
    path = "/api/v1/admin/export",
    tag = "organiser",
    summary = "The contest archive (.tar.zst): dataset with the hidden test answers, configs, teams without secrets, submissions, runs, scores, traces",
    params(ExportQuery),
    security(("organiser_token" = [])),
    responses((status = 200, description = "The archive", content_type = "application/zstd", body = Vec<u8>,
        headers(("content-disposition" = String, description = "`attachment; filename=\"kitchen-r-contest-<UTC time>.tar.zst\"`"))))
)]
pub(super) async fn export(
    State(s): State<AppState>,
    QueryArgs(q): QueryArgs<ExportQuery>,
    caller: Caller,
) -> Result<Response, ServiceError> {
    let e = s.export_archive(caller.organiser()?, q.videos).await?;
    let stream = tokio_util::io::ReaderStream::with_capacity(e.file, 64 << 10);
    let mut response = Body::from_stream(stream).into_response();
    let h = response.headers_mut();
    h.insert(header::CONTENT_TYPE, HeaderValue::from_static("application/zstd"));
    h.insert(header::CONTENT_LENGTH, HeaderValue::from(e.len));
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    if let Ok(v) = HeaderValue::from_str(&format!("attachment; filename=\"{}\"", e.name)) {
        h.insert(header::CONTENT_DISPOSITION, v);
    }
    Ok(response)
}

#[utoipa::path(
    post,
    path = "/api/v1/admin/import",
    tag = "organiser",
    summary = "Load a contest archive into this empty server (checked whole against its sha256 manifest first)",
    request_body(content = Vec<u8>, content_type = "application/zstd"),
    security(("organiser_token" = [])),
    responses(
        (status = 200, description = "What was loaded", body = crate::service::archive::Imported),
        (status = 400, description = "Not an archive, or one altered or damaged (a file does not match the manifest)", body = super::schemas::ErrorBody),
        (status = 409, description = "The server is not empty, or runs another dataset, or the archive is of a newer format", body = super::schemas::ErrorBody),
    )
)]
pub(super) async fn import(
    State(s): State<AppState>,
    caller: Caller,
    body: Body,
) -> Result<Response, ServiceError> {
    let admin = caller.organiser()?;
    let report = s.import_archive(admin, body.into_data_stream()).await?;
    Ok(axum::Json(report).into_response())
}
