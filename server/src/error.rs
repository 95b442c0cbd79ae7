//! The service layer's one error type, mapped once to an HTTP response and once to a
//! `tonic::Status`, so both transports say the same thing for the same failure.
//!
//! Participants must always learn *why* something was refused: every variant's message is meant
//! to be shown to them as is; internal failures are logged in full and answered with a generic
//! message instead of leaking paths or SQL.
//!
//! Every error also carries the id of the request that caused it (DESIGN.md: "request ids in
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
    #[error("{0}")]
    Unavailable(String),
    /// The policy endpoint's address is not allowed (private network, malformed URL, ...).
    #[error("policy endpoint refused: {0}")]
    EndpointRefused(String),
    /// The endpoint did not pass the registration probe (health, GetSpec).
    #[error("policy probe failed: {0}")]
    ProbeFailed(String),
    /// This server was built without a policy probe, so it cannot accept policies.
    #[error("{0}")]
    PolicyDisabled(String),
    #[error(
        "quota exceeded: at most {limit} policy runs of a team evaluate at the same time; wait for one to finish"
    )]
    ConcurrentRuns { limit: u32 },
    /// The request ran past its budget (`request_timeout_ms`) and was abandoned.
    #[error("the request took longer than {after_ms} ms and was abandoned; try again")]
    Timeout { after_ms: u64 },
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
        ServiceError::Internal(e.into())
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
            ServiceError::Unavailable(_) => "unavailable",
            ServiceError::EndpointRefused(_) => "endpoint_refused",
            ServiceError::ProbeFailed(_) => "policy_probe_failed",
            ServiceError::PolicyDisabled(_) => "policy_evaluation_disabled",
            ServiceError::ConcurrentRuns { .. } => "concurrent_runs_exceeded",
            ServiceError::Timeout { .. } => "timeout",
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
            ServiceError::Quota { .. } => StatusCode::TOO_MANY_REQUESTS,
            ServiceError::Unavailable(_) | ServiceError::PolicyDisabled(_) => StatusCode::SERVICE_UNAVAILABLE,
            ServiceError::EndpointRefused(_) => StatusCode::BAD_REQUEST,
            ServiceError::ProbeFailed(_) => StatusCode::UNPROCESSABLE_ENTITY,
            ServiceError::ConcurrentRuns { .. } => StatusCode::TOO_MANY_REQUESTS,
            ServiceError::Timeout { .. } => StatusCode::SERVICE_UNAVAILABLE,
            ServiceError::Internal(_) => StatusCode::INTERNAL_SERVER_ERROR,
        }
    }

    /// The JSON body: `{"error": message, "code": ..., "request_id": ...?, ...details}`
    /// (`request_id` whenever the error is built while a request is being handled).
    pub fn body(&self) -> Value {
        let mut body = json!({ "error": self.to_string(), "code": self.code() });
        if let Some(id) = current_request_id() {
            body["request_id"] = json!(&*id);
        }
        match self {
            ServiceError::PlanFile(e) => {
                if let Some(line) = e.line() {
                    body["line"] = json!(line);
                }
            }
            ServiceError::Quota {
                resets_at,
                retry_after_s,
                ..
            } => {
                body["resets_at"] = json!(resets_at);
                body["retry_after_s"] = json!(retry_after_s);
            }
            _ => {}
        }
        body
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
        if let ServiceError::Quota { retry_after_s, .. } = &self {
            resp.headers_mut().insert(
                axum::http::header::RETRY_AFTER,
                axum::http::HeaderValue::from(*retry_after_s),
            );
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
        match e {
            ServiceError::MissingToken | ServiceError::BadToken => tonic::Status::unauthenticated(msg),
            ServiceError::NotAdmin => tonic::Status::permission_denied(msg),
            ServiceError::PlanFile(_) | ServiceError::BadRequest(_) => tonic::Status::invalid_argument(msg),
            ServiceError::NotFound { .. } => tonic::Status::not_found(msg),
            ServiceError::Conflict(_) => tonic::Status::already_exists(msg),
            ServiceError::Quota { .. } | ServiceError::ConcurrentRuns { .. } => {
                tonic::Status::resource_exhausted(msg)
            }
            ServiceError::Unavailable(_) | ServiceError::PolicyDisabled(_) => tonic::Status::unavailable(msg),
            ServiceError::EndpointRefused(_) => tonic::Status::invalid_argument(msg),
            ServiceError::ProbeFailed(_) => tonic::Status::failed_precondition(msg),
            ServiceError::Timeout { .. } => tonic::Status::unavailable(msg),
            ServiceError::Internal(_) => tonic::Status::internal(msg),
        }
    }
}
