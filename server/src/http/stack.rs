//! The tower stack around every HTTP route (the fallback included), outermost first:
//!
//! 1. request id: the caller's `x-request-id` when sane, else a fresh one; put in the request's
//!    extensions, echoed in the response header, and made current
//!    ([`crate::error::with_request_id`]) so every JSON error body carries it;
//! 2. trace: one span per request with the method, the *matched route* (`/api/v1/scenes/{id}`,
//!    not the raw path, so spans group by route and carry no ids) and the request id;
//! 3. catch-panic: a handler that panics answers 500 `{"code": "internal", "request_id"}`; the
//!    panic message is logged, never sent;
//! 4. timeout (per route group, see [`crate::http::router`]): a request past its budget answers
//!    503 `{"code": "timeout", "request_id"}` instead of hanging.
//!
//! The stack is applied with `Router::layer`, i.e. after routing, because the matched route is
//! only known there; the timeout is applied to each route group before they are merged.

use std::any::Any;
use std::sync::Arc;
use std::time::Duration;

use axum::Router;
use axum::extract::{MatchedPath, Request, State};
use axum::http::HeaderValue;
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use tower::ServiceBuilder;
use tower_http::catch_panic::CatchPanicLayer;
use tower_http::trace::TraceLayer;

use crate::error::{REQUEST_ID_HEADER, ServiceError, request_id_from, with_request_id};

/// The id of the request, in its extensions (handlers may extract it with
/// `Extension<RequestId>`).
#[derive(Debug, Clone)]
pub(crate) struct RequestId(pub Arc<str>);

/// `routes` with the request id, trace and catch-panic layers (see the module documentation).
pub(crate) fn layered<S: Clone + Send + Sync + 'static>(routes: Router<S>) -> Router<S> {
    routes.layer(
        ServiceBuilder::new()
            .layer(middleware::from_fn(request_id))
            .layer(TraceLayer::new_for_http().make_span_with(span))
            .layer(CatchPanicLayer::custom(panic_response)),
    )
}

/// `routes` with a request budget: past it, 503 with code `timeout`.
pub(crate) fn with_timeout<S: Clone + Send + Sync + 'static>(
    routes: Router<S>,
    budget: Duration,
) -> Router<S> {
    routes.layer(middleware::from_fn_with_state(budget, timeout))
}

async fn request_id(mut req: Request, next: Next) -> Response {
    let id = request_id_from(req.headers());
    req.extensions_mut().insert(RequestId(id.clone()));
    let mut resp = with_request_id(id.clone(), next.run(req)).await;
    // `request_id_from` only keeps header-safe ids, so this cannot fail; stay quiet if it does.
    if let Ok(v) = HeaderValue::from_str(&id) {
        resp.headers_mut().insert(REQUEST_ID_HEADER, v);
    }
    resp
}

fn span<B>(req: &axum::http::Request<B>) -> tracing::Span {
    let route = req
        .extensions()
        .get::<MatchedPath>()
        .map_or("<unmatched>", MatchedPath::as_str);
    let id = req.extensions().get::<RequestId>().map_or("", |r| &*r.0);
    tracing::info_span!("http", method = %req.method(), route, request_id = id)
}

/// Runs inside the request id's scope (the id layer is outside this one), so the body has it.
fn panic_response(panic: Box<dyn Any + Send + 'static>) -> Response {
    let what = panic
        .downcast_ref::<&str>()
        .map(|s| (*s).to_string())
        .or_else(|| panic.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "a non-string payload".into());
    ServiceError::Internal(anyhow::anyhow!("handler panicked: {what}")).into_response()
}

async fn timeout(State(budget): State<Duration>, req: Request, next: Next) -> Response {
    match tokio::time::timeout(budget, next.run(req)).await {
        Ok(resp) => resp,
        Err(_) => ServiceError::Timeout {
            after_ms: u64::try_from(budget.as_millis()).unwrap_or(u64::MAX),
        }
        .into_response(),
    }
}
