//! The leaderboard over HTTP (tag `leaderboard`): the public page at `/` (every board of a
//! split) and `GET /api/v1/leaderboard` (one board, as JSON, CSV or HTML). The service ranks and
//! caches; the HTML is [`page`]'s, handed to the service as the renderer of its cached bodies.

pub(in crate::http) mod page;
#[cfg(test)]
mod tests;

use axum::Router;
use axum::extract::State;
use axum::response::{Html, IntoResponse, Response};
use axum::routing::get;
use kitchen_r_core::GraspMode;
use kitchen_r_core::dataset::Split;
use kitchen_r_core::observations::ObservationTrack;

pub(super) use page::integrity_rules;
// The service's leaderboard tests render the page the server serves.
#[cfg(test)]
pub(crate) use page::render;

use super::extract::QueryArgs;
use super::queries::{LeaderboardQuery, SplitQuery, split_param};
use super::reply::typed;
use super::schemas;
use crate::error::ServiceError;
use crate::leaderboard::{Format, Track};
use crate::service::AppState;

/// The leaderboard's routes, answered within the request budget.
pub(super) fn routes() -> Router<AppState> {
    Router::new()
        .route("/", get(index))
        .route("/api/v1/leaderboard", get(leaderboard))
}

pub(super) async fn index(
    State(s): State<AppState>,
    QueryArgs(q): QueryArgs<SplitQuery>,
) -> Result<Response, ServiceError> {
    let split = split_param(q.split.as_ref(), Some(Split::Test))?;
    let body = s.leaderboard_page(split, page::render).await?;
    Ok(Html(body).into_response())
}

#[utoipa::path(
    get,
    path = "/api/v1/leaderboard",
    tag = "leaderboard",
    summary = "One track's leaderboard",
    params(
        ("track" = Option<schemas::TrackParam>, Query, description = "`planning` (default), `control` or `integrated`"),
        ("split" = Option<schemas::SplitParam>, Query, description = "`test` (default) or `dev`"),
        ("observations" = Option<String>, Query, description = "Control and integrated: `standard` (default) or `privileged`, the board of runs whose policy received privileged observations (ranked apart)"),
        ("grasp_mode" = Option<crate::schema::GraspModeName>, Query, description = "Control and integrated: `abstract` or `physical`, the board of runs evaluated in that grasp mode (ranked apart); default the contest's mode (`[control] grasp`). The answer names it in `grasp_mode`"),
        ("format" = Option<schemas::FormatParam>, Query, description = "`json` (default), `csv` or `html`"),
    ),
    responses(
        (status = 200, description = "The ranked rows", content(
            (crate::leaderboard::Leaderboard = "application/json"),
            (String = "text/csv; charset=utf-8"),
            (String = "text/html; charset=utf-8"),
        )),
        (status = 400, description = "An unknown track, split, observations, grasp mode or format, or a grasp mode for the planning track", body = schemas::ErrorBody),
    )
)]
pub(super) async fn leaderboard(
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
        .leaderboard_rendered(track, observations, grasp, split, format, page::render)
        .await?;
    Ok(typed(content_type, body))
}
