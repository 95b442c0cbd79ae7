//! The HTTP adapter (axum): routes of docs/reference/http-api.md, one file per API tag
//! ([`health`], [`dataset`], [`submissions`] with [`video`], [`leaderboard`], [`organiser`] with
//! the console [`admin`] and [`verification`]: verify, re-evaluate, the contest archive) and the
//! participant [`pages`]; this file assembles the router.
//!
//! Handlers only extract, call one service function and shape the answer; every rule is in
//! [`crate::service`]. Errors are always JSON (`{"error", "code", "request_id", ...}`): unknown
//! routes and methods answer through fallbacks (405 keeps its `Allow` header), bodies are capped
//! at `max_body_bytes` with a JSON 413, and path, query and body rejections go through
//! [`extract`]'s wrappers; [`stack`] is the tower stack (request id, JSON errors, trace,
//! catch-panic, timeout) every route runs in. HTML is built with maud, here only: the console
//! ([`admin`]), the leaderboard page ([`leaderboard`]) and [`pages`] (sessions and CSRF in
//! [`session`]); their errors are pages, not JSON.

use axum::Router;
use axum::extract::{DefaultBodyLimit, FromRequestParts};
use axum::http::request::Parts;
use axum::http::{Method, header};
use axum::routing::get;

use crate::error::ServiceError;
use crate::service::auth::bearer_token;
use crate::service::{AppState, Caller};

mod admin;
mod conditional;
mod dataset;
mod extract;
mod health;
mod leaderboard;
pub(crate) mod openapi;
mod organiser;
mod pages;
mod queries;
mod reply;
mod schemas;
mod session;
pub(crate) mod stack;
mod submissions;
mod verification;
mod video;
mod viewer;

// The service's leaderboard tests render the page the server serves.
#[cfg(test)]
pub(crate) use leaderboard::render as leaderboard_page;

pub(crate) fn router(state: AppState) -> Router {
    let cfg = state.config();
    let quick = Router::new()
        .route("/healthz", get(health::healthz))
        .route("/api/v1/openapi.json", get(openapi::openapi_json))
        .merge(dataset::routes())
        .merge(submissions::routes())
        .merge(leaderboard::routes())
        .merge(organiser::routes())
        // Verification, re-evaluation (see `verification`).
        .merge(verification::routes())
        // The organiser's console: admin API and the `/admin` page (see `admin`).
        .merge(admin::quick_routes())
        // The participant pages: contest home, team login, team and submission pages.
        .merge(pages::routes());
    // Prometheus text format, no token (see `service::metrics` for why that is safe).
    let quick = match cfg.metrics {
        true => quick.route("/metrics", get(health::metrics)),
        false => quick,
    };
    // Registration probes the endpoint first, within its own budget.
    let probing = submissions::probing_routes();
    // Organiser-only work whose length grows with the contest (rescore, backup): no budget.
    let unbounded = organiser::unbounded_routes()
        .merge(admin::unbounded_routes())
        // The contest archive, exported and imported.
        .merge(verification::unbounded_routes());
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

#[cfg(test)]
mod hardening_tests;
#[cfg(test)]
mod stack_tests;
#[cfg(test)]
mod tests;
