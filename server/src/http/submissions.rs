//! Submissions over HTTP (tag `submissions`): a plan file scored at once, a policy endpoint
//! registered (after a probe) for evaluation, a submission's view and an episode's path plot.
//! The episode's video and trace are [`super::video`]'s.

use axum::Router;
use axum::body::Body;
use axum::extract::State;
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use bytes::Bytes;
use tokio_stream::StreamExt;

use super::extract::{BodyBytes, PathArg, QueryArgs};
use super::queries::{PlansQuery, split_param};
use super::reply::typed;
use super::schemas;
use crate::error::ServiceError;
use crate::service::{AppState, Caller, RegisterPolicy};

/// Routes answered within the request budget.
pub(super) fn routes() -> Router<AppState> {
    Router::new()
        .route("/api/v1/submissions/plans", post(submit_plans))
        .route("/api/v1/submissions/{id}", get(submission))
        .route(
            "/api/v1/submissions/{id}/episodes/{episode_key}/path.png",
            get(episode_plot),
        )
        .route(
            "/api/v1/submissions/{id}/episodes/{episode_key}/video.mp4",
            get(super::video::api_video),
        )
        .route(
            "/api/v1/submissions/{id}/episodes/{episode_key}/trace",
            get(super::video::api_trace),
        )
}

/// Registration probes the endpoint first, which may take up to `policy.startup_deadline_ms`:
/// its own budget (`registration_timeout`).
pub(super) fn probing_routes() -> Router<AppState> {
    Router::new().route("/api/v1/submissions/policies", post(register_policy))
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
        ("reference" = Option<schemas::FlagParam>, Query, description = "Organiser only: file it as the planning board's baseline row (reserved `(baseline)` team, no quota)")),
    request_body(content = String, content_type = "application/x-ndjson", description = "The plan file: one JSON object a line",
        example = json!("{\"id\": \"dev-0001\", \"plan\": [\"move to the blue zone\", \"pick the bowl\", \"move to the red zone\", \"place the bowl\"]}\n")),
    security(("team_token" = []), ("organiser_token" = [])),
    responses(
        (status = 201, description = "Scored and stored", body = crate::service::Submitted),
        (status = 400, description = "A missing or unknown split, or a plan file that does not parse (`line` says where)", body = schemas::ErrorBody),
        (status = 403, description = "Not a team's token (or, with `reference`, not the organiser's)", body = schemas::ErrorBody),
        (status = 413, description = "The file is over `max_body_bytes` or a plan limit", body = schemas::ErrorBody),
        (status = 429, description = "The daily quota or the per-minute rate limit", body = schemas::ErrorBody,
            headers(("retry-after" = u64, description = "Seconds until a retry can succeed"))),
    )
)]
pub(super) async fn submit_plans(
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
        (status = 400, description = "A body that is not a registration, or an endpoint that is not allowed", body = schemas::ErrorBody),
        (status = 403, description = "A reference run without the organiser token", body = schemas::ErrorBody),
        (status = 404, description = "The `plans` submission is not the team's", body = schemas::ErrorBody),
        (status = 413, description = "The body is over `max_body_bytes`", body = schemas::ErrorBody),
        (status = 422, description = "The endpoint did not pass the probe", body = schemas::ErrorBody),
        (status = 429, description = "The daily quota, the rate limit or the concurrent-runs limit", body = schemas::ErrorBody),
    )
)]
pub(super) async fn register_policy(
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
        (status = 404, description = "No such submission, or another team's", body = schemas::ErrorBody),
    )
)]
pub(super) async fn submission(
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
        (status = 404, description = "No such submission or episode, not the caller's, on the test split, or no path recorded", body = schemas::ErrorBody),
    )
)]
pub(super) async fn episode_plot(
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
