//! The service layer's one error type, mapped once to an HTTP response and once to a
//! `tonic::Status`, so both transports say the same thing for the same failure.
//!
//! Participants must always learn *why* something was refused: every variant's message is meant
//! to be shown to them as is; internal failures are logged in full and answered with a generic
//! message instead of leaking paths or SQL.
//!
//! Every error also carries the id of the request that caused it (docs/reference/cli.md, "request ids in
//! every error"): the transport stacks ([`crate::http::stack`], [`crate::grpc::GrpcStackLayer`])
//! run each request inside [`with_request_id`], and the conversions below read it back with
//! [`current_request_id`], so a participant can quote the id and an organiser find the log line.

use std::future::Future;
use std::sync::Arc;

use axum::http::{HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use serde_json::{Value, json};

use crate::plans::PlanFileError;

#[derive(Debug, thiserror::Error)]
pub enum ServiceError {
    #[error("missing bearer token: send `Authorization: Bearer <token>`")]
    MissingToken,
    #[error("the token is not valid")]
    BadToken,
    #[error("this needs the organiser token")]
    NotAdmin,
    #[error("{0}")]
    PlanFile(#[from] PlanFileError),
    #[error("{0}")]
    BadRequest(String),
    #[error("{what} not found")]
    NotFound { what: String },
    #[error("{0}")]
    Conflict(String),
    #[error("quota exceeded: {limit} {split} submissions per UTC day; the quota resets at {resets_at}")]
    Quota {
        split: &'static str,
        limit: u32,
        /// RFC 3339 time of the next UTC midnight.
        resets_at: String,
        retry_after_s: i64,
    },
    /// Too many uploads from one team in a short time (`quota.per_minute`).
    #[error(
        "rate limited: at most {per_minute} {split} submissions per minute per team; retry after {retry_after_s} s"
    )]
    RateLimited {
        split: &'static str,
        per_minute: u32,
        retry_after_s: u64,
    },
    #[error("{0}")]
    Unavailable(String),
    /// The server is saturated (a bounded queue is full): refused at once rather than left to
    /// wait for seconds, so the client retries later instead of piling up.
    #[error("the server is saturated ({what}); retry after {retry_after_s} s")]
    Busy { retry_after_s: u64, what: String },
    /// The policy endpoint's address is not allowed (private network, malformed URL, ...).
    #[error("policy endpoint refused: {0}")]
    EndpointRefused(String),
    /// The endpoint did not pass the registration probe (health, GetSpec).
    #[error("policy probe failed: {0}")]
    ProbeFailed(String),
    /// This server was built without a policy probe, so it cannot accept policies.
    #[error("{0}")]
    PolicyDisabled(String),
    /// The policy asks for privileged observations on a server whose organiser has not enabled
    /// the privileged track.
    #[error(
        "the policy asks for privileged observations in GetSpec (PolicySpec.privileged_observations), \
         but this server does not run the privileged track; the organiser enables it with \
         `privileged_track = true` in the [control] section of the server config \
         (control.privileged_track). To run on the standard track, answer GetSpec with \
         privileged_observations = false"
    )]
    PrivilegedTrackOff,
    #[error(
        "quota exceeded: at most {limit} policy runs of a team evaluate at the same time; wait for one to finish"
    )]
    ConcurrentRuns { limit: u32 },
    /// The request ran past its budget (`request_timeout_ms`) and was abandoned.
    #[error("the request took longer than {after_ms} ms and was abandoned; try again")]
    Timeout { after_ms: u64 },
    /// The route exists, but not with this method; the `Allow` header lists the ones it has.
    #[error("method {method} is not allowed on this route; the Allow header lists the methods it accepts")]
    MethodNotAllowed { method: String },
    /// A request body over `max_body_bytes` (a plan file says on which line instead:
    /// [`PlanFileError::TooLarge`]).
    #[error("the body is larger than {limit} bytes")]
    BodyTooLarge { limit: usize },
    #[error("internal error")]
    Internal(#[from] anyhow::Error),
}

/// The header that carries the request id, both ways, on HTTP and gRPC.
pub(crate) const REQUEST_ID_HEADER: &str = "x-request-id";

tokio::task_local! {
    static REQUEST_ID: Arc<str>;
}

/// Run `fut` as the handling of the request `id`: errors built inside it carry that id.
pub(crate) async fn with_request_id<F: Future>(id: Arc<str>, fut: F) -> F::Output {
    REQUEST_ID.scope(id, fut).await
}

/// The id of the request being handled, if any (none outside the transport stacks, e.g. in
/// service-level tests or background tasks).
pub(crate) fn current_request_id() -> Option<Arc<str>> {
    REQUEST_ID.try_with(Arc::clone).ok()
}

/// The caller's `x-request-id` when it is sane (1 to 64 characters of `[A-Za-z0-9._:-]`, so it
/// can be logged and echoed without escaping), else a fresh random one.
pub(crate) fn request_id_from(headers: &HeaderMap) -> Arc<str> {
    let given = headers
        .get(REQUEST_ID_HEADER)
        .and_then(|v| v.to_str().ok())
        .filter(|v| {
            (1..=64).contains(&v.len())
                && v.bytes()
                    .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'-' | b'_' | b'.' | b':'))
        });
    match given {
        Some(v) => Arc::from(v),
        None => {
            let bytes: [u8; 8] = rand::random();
            Arc::from(hex::encode(bytes))
        }
    }
}

impl From<sqlx::Error> for ServiceError {
    fn from(e: sqlx::Error) -> Self {
        match e {
            // Every connection of the pool stayed busy for the configured wait
            // (`db_pool.*_wait_ms`): the server is saturated, not broken; say when to retry.
            sqlx::Error::PoolTimedOut => ServiceError::Busy {
                retry_after_s: 1,
                what: "the database".into(),
            },
            e => ServiceError::Internal(e.into()),
        }
    }
}

impl ServiceError {
    pub fn not_found(what: impl Into<String>) -> Self {
        ServiceError::NotFound { what: what.into() }
    }

    /// A short stable identifier clients can match on.
    pub fn code(&self) -> &'static str {
        match self {
            ServiceError::MissingToken => "missing_token",
            ServiceError::BadToken => "bad_token",
            ServiceError::NotAdmin => "not_admin",
            ServiceError::PlanFile(e) => e.code(),
            ServiceError::BadRequest(_) => "bad_request",
            ServiceError::NotFound { .. } => "not_found",
            ServiceError::Conflict(_) => "conflict",
            ServiceError::Quota { .. } => "quota_exceeded",
            ServiceError::RateLimited { .. } => "rate_limited",
            ServiceError::Unavailable(_) => "unavailable",
            ServiceError::Busy { .. } => "busy",
            ServiceError::EndpointRefused(_) => "endpoint_refused",
            ServiceError::ProbeFailed(_) => "policy_probe_failed",
            ServiceError::PolicyDisabled(_) => "policy_evaluation_disabled",
            ServiceError::PrivilegedTrackOff => "privileged_track_disabled",
            ServiceError::ConcurrentRuns { .. } => "concurrent_runs_exceeded",
            ServiceError::Timeout { .. } => "timeout",
            ServiceError::MethodNotAllowed { .. } => "method_not_allowed",
            ServiceError::BodyTooLarge { .. } => "body_too_large",
            ServiceError::Internal(_) => "internal",
        }
    }

    fn status(&self) -> StatusCode {
        match self {
            ServiceError::MissingToken | ServiceError::BadToken => StatusCode::UNAUTHORIZED,
            ServiceError::NotAdmin => StatusCode::FORBIDDEN,
            ServiceError::PlanFile(PlanFileError::TooLarge { .. }) => StatusCode::PAYLOAD_TOO_LARGE,
            ServiceError::PlanFile(_) => StatusCode::BAD_REQUEST,
            ServiceError::BadRequest(_) => StatusCode::BAD_REQUEST,
            ServiceError::NotFound { .. } => StatusCode::NOT_FOUND,
            ServiceError::Conflict(_) => StatusCode::CONFLICT,
            ServiceError::Quota { .. } | ServiceError::RateLimited { .. } => StatusCode::TOO_MANY_REQUESTS,
            ServiceError::Unavailable(_) | ServiceError::PolicyDisabled(_) | ServiceError::Busy { .. } => {
                StatusCode::SERVICE_UNAVAILABLE
            }
            ServiceError::EndpointRefused(_) => StatusCode::BAD_REQUEST,
            ServiceError::ProbeFailed(_) => StatusCode::UNPROCESSABLE_ENTITY,
            ServiceError::PrivilegedTrackOff => StatusCode::FORBIDDEN,
            ServiceError::ConcurrentRuns { .. } => StatusCode::TOO_MANY_REQUESTS,
            ServiceError::Timeout { .. } => StatusCode::SERVICE_UNAVAILABLE,
            ServiceError::MethodNotAllowed { .. } => StatusCode::METHOD_NOT_ALLOWED,
            ServiceError::BodyTooLarge { .. } => StatusCode::PAYLOAD_TOO_LARGE,
            ServiceError::Internal(_) => StatusCode::INTERNAL_SERVER_ERROR,
        }
    }

    /// The JSON body: `{"error": message, "code": ..., "request_id": ...?, ...details}`
    /// (`request_id` whenever the error is built while a request is being handled).
    pub fn body(&self) -> Value {
        let mut body = error_body(&self.to_string(), self.code());
        match self {
            ServiceError::PlanFile(e) => {
                if let Some(line) = e.line() {
                    body["line"] = json!(line);
                }
            }
            ServiceError::Quota { resets_at, .. } => {
                body["resets_at"] = json!(resets_at);
            }
            ServiceError::BodyTooLarge { limit } => {
                body["limit_bytes"] = json!(limit);
            }
            _ => {}
        }
        if let Some(s) = self.retry_after_s() {
            body["retry_after_s"] = json!(s);
        }
        body
    }

    /// Seconds after which retrying can succeed, for the refusals that know it (sent as the
    /// `Retry-After` header, `retry_after_s` in the body and `retry-after` gRPC metadata).
    pub fn retry_after_s(&self) -> Option<u64> {
        match self {
            ServiceError::Quota { retry_after_s, .. } => Some(u64::try_from(*retry_after_s).unwrap_or(0)),
            ServiceError::RateLimited { retry_after_s, .. } | ServiceError::Busy { retry_after_s, .. } => {
                Some(*retry_after_s)
            }
            _ => None,
        }
    }

    fn log(&self) {
        match self {
            ServiceError::Internal(e) => tracing::error!(error = format!("{e:#}"), "internal error"),
            ServiceError::Timeout { after_ms } => tracing::warn!(after_ms, "request timed out"),
            _ => {}
        }
    }
}

impl IntoResponse for ServiceError {
    fn into_response(self) -> Response {
        self.log();
        let mut resp = (self.status(), axum::Json(self.body())).into_response();
        if let Some(s) = self.retry_after_s() {
            resp.headers_mut()
                .insert(axum::http::header::RETRY_AFTER, axum::http::HeaderValue::from(s));
        }
        resp
    }
}

impl From<ServiceError> for tonic::Status {
    fn from(e: ServiceError) -> Self {
        e.log();
        let mut msg = e.to_string();
        // gRPC has no JSON body: the id is in the `x-request-id` metadata (set by the stack), and
        // in the message of the errors a participant would have to report.
        if let (ServiceError::Internal(_) | ServiceError::Timeout { .. }, Some(id)) =
            (&e, current_request_id())
        {
            msg = format!("{msg} (request id {id})");
        }
        let retry_after = e.retry_after_s();
        let mut status = match e {
            ServiceError::MissingToken | ServiceError::BadToken => tonic::Status::unauthenticated(msg),
            ServiceError::NotAdmin => tonic::Status::permission_denied(msg),
            ServiceError::PlanFile(_) | ServiceError::BadRequest(_) | ServiceError::BodyTooLarge { .. } => {
                tonic::Status::invalid_argument(msg)
            }
            ServiceError::NotFound { .. } => tonic::Status::not_found(msg),
            ServiceError::Conflict(_) => tonic::Status::already_exists(msg),
            ServiceError::Quota { .. }
            | ServiceError::ConcurrentRuns { .. }
            | ServiceError::RateLimited { .. } => tonic::Status::resource_exhausted(msg),
            ServiceError::Unavailable(_) | ServiceError::PolicyDisabled(_) | ServiceError::Busy { .. } => {
                tonic::Status::unavailable(msg)
            }
            ServiceError::EndpointRefused(_) => tonic::Status::invalid_argument(msg),
            ServiceError::ProbeFailed(_) | ServiceError::PrivilegedTrackOff => {
                tonic::Status::failed_precondition(msg)
            }
            ServiceError::Timeout { .. } => tonic::Status::unavailable(msg),
            ServiceError::MethodNotAllowed { .. } => tonic::Status::unimplemented(msg),
            ServiceError::Internal(_) => tonic::Status::internal(msg),
        };
        // gRPC has no Retry-After header: the same seconds travel as metadata.
        if let Some(s) = retry_after {
            status.metadata_mut().insert("retry-after", s.into());
        }
        status
    }
}

/// The documented shape of every HTTP error body, `{"error", "code", "request_id"?}`: used by
/// [`ServiceError::body`] and by the HTTP stack for answers no handler made (see
/// `crate::http::stack`).
pub(crate) fn error_body(message: &str, code: &str) -> Value {
    let mut body = json!({ "error": message, "code": code });
    if let Some(id) = current_request_id() {
        body["request_id"] = json!(&*id);
    }
    body
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn busy_says_when_to_retry_on_both_transports() {
        let busy = || ServiceError::Busy {
            retry_after_s: 2,
            what: "the write queue is full".into(),
        };
        let resp = with_request_id(Arc::from("req-busy"), async { busy().into_response() }).await;
        assert_eq!(resp.status(), StatusCode::SERVICE_UNAVAILABLE);
        assert_eq!(resp.headers()[axum::http::header::RETRY_AFTER], "2");
        let body: Value =
            serde_json::from_slice(&axum::body::to_bytes(resp.into_body(), 1 << 16).await.unwrap()).unwrap();
        assert_eq!(
            body,
            json!({
                "error": "the server is saturated (the write queue is full); retry after 2 s",
                "code": "busy",
                "request_id": "req-busy",
                "retry_after_s": 2,
            })
        );
        let status = tonic::Status::from(busy());
        assert_eq!(status.code(), tonic::Code::Unavailable);
        assert_eq!(status.metadata().get("retry-after").unwrap(), "2");
    }

    #[test]
    fn rate_limits_are_resource_exhausted_over_grpc() {
        let e = ServiceError::RateLimited {
            split: "dev",
            per_minute: 20,
            retry_after_s: 3,
        };
        assert_eq!(
            (e.code(), e.status()),
            ("rate_limited", StatusCode::TOO_MANY_REQUESTS)
        );
        let status = tonic::Status::from(e);
        assert_eq!(status.code(), tonic::Code::ResourceExhausted);
        assert_eq!(status.metadata().get("retry-after").unwrap(), "3");
    }
}
