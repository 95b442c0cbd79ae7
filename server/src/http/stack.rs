//! The tower stack around every HTTP route (the fallback included), outermost first:
//!
//! 0. metrics: every answer counted, and its latency to the response headers, by method,
//!    *matched route* (`<unmatched>` for the fallback) and status ([`crate::metrics`]);
//! 1. request id: the caller's `x-request-id` when sane, else a fresh one; put in the request's
//!    extensions, echoed in the response header, and made current
//!    ([`crate::error::with_request_id`]) so every JSON error body carries it;
//! 2. JSON errors: a 4xx/5xx answer that is not JSON (a default answer or extractor rejection
//!    that no route mapped to a [`ServiceError`]) is rewritten into the documented shape
//!    `{"error", "code", "request_id"}`, its text kept as the message and its headers (`Allow`)
//!    kept. Routes map the ones they can foresee themselves (method not allowed, body limits,
//!    path and query rejections: see [`crate::http`]) with better messages; this is the net
//!    under them, so "every error is JSON" holds for whatever a future route or layer sends.
//!    HTML pages (`text/html`: the organiser console, the participant pages) keep their own
//!    error pages: a browser shows them.
//!    (Malformed HTTP that hyper refuses before routing never reaches the stack.)
//! 3. trace: one span per request with the method, the *matched route* (`/api/v1/scenes/{id}`,
//!    not the raw path, so spans group by route and carry no ids) and the request id;
//! 4. catch-panic: a handler that panics answers 500 `{"code": "internal", "request_id"}`; the
//!    panic message is logged, never sent;
//! 5. timeout (per route group, see [`crate::http::router`]): a request past its budget answers
//!    503 `{"code": "timeout", "request_id"}` instead of hanging;
//! 6. page headers: every `text/html` answer (every page, error pages and the leaderboard
//!    included) gets the pages' security headers ([`PAGE_HEADERS`]) unless its handler set
//!    its own, so no page can forget them.
//!
//! The stack is applied with `Router::layer`, i.e. after routing, because the matched route is
//! only known there; the timeout is applied to each route group before they are merged.

use std::any::Any;
use std::sync::Arc;
use std::time::Duration;

use axum::Router;
use axum::extract::{MatchedPath, Request, State};
use axum::http::{HeaderValue, StatusCode, header};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use tower::ServiceBuilder;
use tower_http::catch_panic::CatchPanicLayer;
use tower_http::trace::TraceLayer;

use crate::error::{REQUEST_ID_HEADER, ServiceError, error_body, request_id_from, with_request_id};

/// The id of the request, in its extensions (handlers may extract it with
/// `Extension<RequestId>`).
#[derive(Debug, Clone)]
pub(crate) struct RequestId(pub Arc<str>);

/// `routes` with the request id, trace and catch-panic layers (see the module documentation).
pub(crate) fn layered<S: Clone + Send + Sync + 'static>(routes: Router<S>) -> Router<S> {
    routes.layer(
        ServiceBuilder::new()
            .layer(middleware::from_fn(record_metrics))
            .layer(middleware::from_fn(request_id))
            .layer(middleware::from_fn(json_errors))
            .layer(middleware::from_fn(page_headers))
            .layer(TraceLayer::new_for_http().make_span_with(span))
            .layer(CatchPanicLayer::custom(panic_response)),
    )
}

/// What every HTML answer is sent with: not stored by caches (pages show a session's data), a
/// Content-Security-Policy that allows no script at all, images and media (the episode videos)
/// from the server itself only, inline styles (the pages' one `<style>`), forms posting to the
/// server only, and no framing (also said the old way, `X-Frame-Options`), and no referrer (a
/// submission page's URL names its id).
pub(crate) const PAGE_HEADERS: [(header::HeaderName, &str); 4] = [
    (header::CACHE_CONTROL, "no-store"),
    (
        header::CONTENT_SECURITY_POLICY,
        "default-src 'none'; img-src 'self'; media-src 'self'; style-src 'unsafe-inline'; form-action 'self'; frame-ancestors 'none'",
    ),
    (header::X_FRAME_OPTIONS, "DENY"),
    (header::REFERRER_POLICY, "no-referrer"),
];

async fn page_headers(req: Request, next: Next) -> Response {
    let mut resp = next.run(req).await;
    let is_page = (resp.headers().get(header::CONTENT_TYPE))
        .and_then(|v| v.to_str().ok())
        .is_some_and(|t| t.starts_with("text/html"));
    if is_page {
        let h = resp.headers_mut();
        for (name, value) in PAGE_HEADERS {
            if !h.contains_key(&name) {
                h.insert(name, HeaderValue::from_static(value));
            }
        }
    }
    resp
}

/// `routes` with a request budget: past it, 503 with code `timeout`.
pub(crate) fn with_timeout<S: Clone + Send + Sync + 'static>(
    routes: Router<S>,
    budget: Duration,
) -> Router<S> {
    routes.layer(middleware::from_fn_with_state(budget, timeout))
}

async fn record_metrics(req: Request, next: Next) -> Response {
    let started = std::time::Instant::now();
    let method = req.method().clone();
    let route = req
        .extensions()
        .get::<MatchedPath>()
        .map_or("<unmatched>", MatchedPath::as_str)
        .to_owned();
    let resp = next.run(req).await;
    crate::metrics::record_http(&method, &route, resp.status().as_u16(), started.elapsed());
    resp
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

/// Most of a non-JSON error body kept as the message; such bodies are one-line rejections.
const PLAIN_ERROR_CHARS: usize = 1024;

/// Runs inside the request id's scope, so the rewritten body carries the id.
async fn json_errors(req: Request, next: Next) -> Response {
    let resp = next.run(req).await;
    let status = resp.status();
    let content_type = resp
        .headers()
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .unwrap_or("");
    // An HTML page's error answer (a login form, a 404 page) is meant for a browser: kept.
    let is_json = content_type.starts_with("application/json");
    let is_page = content_type.starts_with("text/html");
    if !(status.is_client_error() || status.is_server_error()) || is_json || is_page {
        return resp;
    }
    let (mut parts, body) = resp.into_parts();
    let text: String = axum::body::to_bytes(body, 64 << 10)
        .await
        .map(|b| {
            String::from_utf8_lossy(&b)
                .trim()
                .chars()
                .take(PLAIN_ERROR_CHARS)
                .collect()
        })
        .unwrap_or_default();
    let message = match text {
        t if t.is_empty() => status.canonical_reason().unwrap_or("error").to_string(),
        t => t,
    };
    tracing::debug!(%status, %message, "non-JSON error answer rewritten as JSON");
    // The old length and type describe the old body.
    parts.headers.remove(header::CONTENT_LENGTH);
    parts.headers.remove(header::CONTENT_TYPE);
    (parts, axum::Json(error_body(&message, status_code(status)))).into_response()
}

/// The `code` of an error answer no handler made, from its status alone (the same codes the
/// service uses for the same situations).
fn status_code(status: StatusCode) -> &'static str {
    match status {
        StatusCode::BAD_REQUEST => "bad_request",
        StatusCode::UNAUTHORIZED => "missing_token",
        StatusCode::FORBIDDEN => "forbidden",
        StatusCode::NOT_FOUND => "not_found",
        StatusCode::METHOD_NOT_ALLOWED => "method_not_allowed",
        StatusCode::REQUEST_TIMEOUT => "timeout",
        StatusCode::PAYLOAD_TOO_LARGE => "body_too_large",
        StatusCode::UNSUPPORTED_MEDIA_TYPE => "unsupported_media_type",
        StatusCode::UNPROCESSABLE_ENTITY => "unprocessable",
        StatusCode::TOO_MANY_REQUESTS => "rate_limited",
        StatusCode::SERVICE_UNAVAILABLE => "unavailable",
        s if s.is_server_error() => "internal",
        _ => "error",
    }
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
