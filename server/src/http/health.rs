//! The server's own routes (tag `service`): liveness and the Prometheus metrics. The OpenAPI
//! document, the third, is [`super::openapi`]'s.

use axum::extract::State;
use axum::response::{IntoResponse, Response};
use bytes::Bytes;

use super::reply::typed;
use super::schemas;
use crate::error::ServiceError;
use crate::service::AppState;

#[utoipa::path(
    get,
    path = "/healthz",
    tag = "service",
    summary = "Liveness: the server answers",
    responses((status = 200, description = "The server is up", body = schemas::Health))
)]
pub(super) async fn healthz() -> impl IntoResponse {
    axum::Json(schemas::Health { status: "ok" })
}

#[utoipa::path(
    get,
    path = "/metrics",
    tag = "service",
    summary = "Prometheus metrics (text exposition format)",
    description = "No token: see `service::metrics` for why nothing in it is secret. Absent (404) when `metrics = false`.",
    responses(
        (status = 200, description = "The metrics", content_type = "text/plain; version=0.0.4", body = String),
        (status = 404, description = "Metrics are turned off (`metrics = false`)", body = schemas::ErrorBody),
    )
)]
pub(super) async fn metrics(State(s): State<AppState>) -> Result<Response, ServiceError> {
    let text = s.metrics_text().await?;
    Ok(typed(crate::metrics::CONTENT_TYPE, Bytes::from(text)))
}
