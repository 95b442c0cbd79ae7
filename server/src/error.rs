//! The service layer's one error type, mapped once to an HTTP response and once to a
//! `tonic::Status`, so both transports say the same thing for the same failure.
//!
//! Participants must always learn *why* something was refused: every variant's message is meant
//! to be shown to them as is; internal failures are logged in full and answered with a generic
//! message instead of leaking paths or SQL.

use axum::http::StatusCode;
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
    #[error("internal error")]
    Internal(#[from] anyhow::Error),
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
            ServiceError::Internal(_) => StatusCode::INTERNAL_SERVER_ERROR,
        }
    }

    /// The JSON body: `{"error": message, "code": ..., ...details}`.
    pub fn body(&self) -> Value {
        let mut body = json!({ "error": self.to_string(), "code": self.code() });
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
        if let ServiceError::Internal(e) = self {
            tracing::error!(error = format!("{e:#}"), "internal error");
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
        let msg = e.to_string();
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
            ServiceError::Internal(_) => tonic::Status::internal(msg),
        }
    }
}
