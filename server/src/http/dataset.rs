//! The dataset over HTTP (tag `dataset`): the splits' instructions and what they are, and the
//! scenes (in full, in short, as a top-down map and as the planners' English brief).

use axum::Router;
use axum::extract::State;
use axum::http::HeaderValue;
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use bytes::Bytes;
use kitchen_r_core::dataset::Split;

use super::extract::PathArg;
use super::reply::typed;
use super::schemas;
use crate::content::TestSetKind;
use crate::error::ServiceError;
use crate::service::AppState;

/// The dataset's routes, all answered within the request budget.
pub(super) fn routes() -> Router<AppState> {
    Router::new()
        .route("/api/v1/dataset/manifest", get(dataset_manifest))
        .route("/api/v1/dataset/{split}", get(dataset))
        .route("/api/v1/scenes", get(scenes))
        .route("/api/v1/scenes/{id}", get(scene))
        .route("/api/v1/scenes/{id}/topdown.png", get(topdown))
        .route("/api/v1/scenes/{id}/brief", get(brief))
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
        (status = 400, description = "Not a split name", body = schemas::ErrorBody),
    )
)]
pub(super) async fn dataset(
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
    responses((status = 200, description = "The splits' sizes and the test split's provenance", body = schemas::DatasetManifest))
)]
pub(super) async fn dataset_manifest(State(s): State<AppState>) -> impl IntoResponse {
    let c = s.content();
    axum::Json(schemas::DatasetManifest {
        dev: schemas::DevSplitInfo {
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
        (status = 404, description = "No such scene", body = schemas::ErrorBody),
    )
)]
pub(super) async fn brief(
    State(s): State<AppState>,
    PathArg(id): PathArg<String>,
) -> Result<Response, ServiceError> {
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
pub(super) async fn scenes(State(s): State<AppState>) -> impl IntoResponse {
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
        (status = 404, description = "No such scene", body = schemas::ErrorBody),
    )
)]
pub(super) async fn scene(
    State(s): State<AppState>,
    PathArg(id): PathArg<String>,
) -> Result<Response, ServiceError> {
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
        (status = 404, description = "No such scene", body = schemas::ErrorBody),
    )
)]
pub(super) async fn topdown(
    State(s): State<AppState>,
    PathArg(id): PathArg<String>,
) -> Result<Response, ServiceError> {
    let scene = id.clone();
    let png = tokio::task::spawn_blocking(move || s.content().topdown_png(&scene))
        .await
        .map_err(anyhow::Error::from)?
        .ok_or_else(|| ServiceError::not_found(format!("scene {id:?}")))?;
    Ok(typed("image/png", png))
}
