//! The JSON error body's schema. A file of its own because the handlers name it in their
//! `#[utoipa::path]` answers while [`super::openapi`] lists the handlers: held in `openapi`, it
//! made `openapi` and the organiser's routes ([`super::admin`]) import each other (issue #29).
//! `openapi` re-exports it, so other handlers' `openapi::ErrorBody` still reads.

use serde::Serialize;
use utoipa::ToSchema;

/// Every error answer: the message to show, a stable code, the request id, and details some
/// errors add.
#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct ErrorBody {
    /// What went wrong and what to do, meant to be shown as is.
    pub error: String,
    /// A stable identifier to match on: `missing_token`, `bad_token`, `not_admin`,
    /// `bad_request`, `not_found`, `conflict`, `quota_exceeded`, `rate_limited`, `unavailable`,
    /// `busy`, `endpoint_refused`, `policy_probe_failed`, `policy_evaluation_disabled`,
    /// `concurrent_runs_exceeded`, `timeout`, `method_not_allowed`, `body_too_large`,
    /// `internal`, or a plan-file code.
    pub code: String,
    /// The id of the request (also the `x-request-id` header): quote it when reporting.
    pub request_id: Option<String>,
    /// Plan files: the 1-based line the error is on.
    pub line: Option<u64>,
    /// Daily quota: when it resets (RFC 3339).
    pub resets_at: Option<String>,
    /// 413: the largest body accepted.
    pub limit_bytes: Option<u64>,
    /// 429 and 503 refusals that know it: seconds after which a retry can succeed (also the
    /// `Retry-After` header).
    pub retry_after_s: Option<u64>,
}
