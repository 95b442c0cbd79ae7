//! The schemas the handlers name in their `#[utoipa::path]` annotations that no service type
//! describes: the JSON error body, the handlers' small answers and requests, and query
//! parameters' allowed values. A file apart from [`super::openapi`], which lists the handlers:
//! held there, a handler naming its schema and the document naming the handler would import
//! each other.

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;
use utoipa::openapi::RefOr;
use utoipa::openapi::schema::{ObjectBuilder, Schema, SchemaType, Type};

/// A query parameter's values, and the empty string (as an HTML form sends an unset field),
/// which means the default. utoipa's derive cannot name an empty enum value, hence by hand.
fn choice_schema(values: &[&str], description: &str) -> RefOr<Schema> {
    ObjectBuilder::new()
        .schema_type(SchemaType::new(Type::String))
        .enum_values(Some(values.iter().copied()))
        .description(Some(description))
        .into()
}

/// `track` of `GET /api/v1/leaderboard`.
pub(crate) struct TrackParam;

impl utoipa::PartialSchema for TrackParam {
    fn schema() -> RefOr<Schema> {
        choice_schema(
            &["", "planning", "control", "integrated"],
            "A ranked track; empty means `planning`.",
        )
    }
}

impl ToSchema for TrackParam {}

/// An optional `split` query parameter.
pub(crate) struct SplitParam;

impl utoipa::PartialSchema for SplitParam {
    fn schema() -> RefOr<Schema> {
        choice_schema(&["", "dev", "test"], "A dataset split; empty means the default.")
    }
}

impl ToSchema for SplitParam {}

/// `format` of `GET /api/v1/leaderboard`.
pub(crate) struct FormatParam;

impl utoipa::PartialSchema for FormatParam {
    fn schema() -> RefOr<Schema> {
        choice_schema(
            &["", "json", "csv", "html"],
            "The answer's format; empty means `json`.",
        )
    }
}

impl ToSchema for FormatParam {}

/// A yes/no query parameter as the handlers read it: `true`/`1`, `false`/`0`, or empty (no).
pub(crate) struct FlagParam;

impl utoipa::PartialSchema for FlagParam {
    fn schema() -> RefOr<Schema> {
        choice_schema(
            &["", "true", "false", "1", "0"],
            "Yes (`true`, `1`) or no (`false`, `0`, empty).",
        )
    }
}

impl ToSchema for FlagParam {}

/// `GET /healthz`.
#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct Health {
    /// Always `ok`: the server answers.
    #[schema(example = "ok")]
    pub status: &'static str,
}

/// `GET /api/v1/dataset/manifest`.
#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct DatasetManifest {
    pub dev: DevSplitInfo,
    pub test: crate::content::TestSetInfo,
}

/// The dev split: public, with its plans.
#[derive(Debug, Serialize, ToSchema)]
pub(crate) struct DevSplitInfo {
    pub instructions: usize,
    /// Always `public`.
    #[schema(example = "public")]
    pub plans: &'static str,
}

/// `POST /api/v1/teams`.
#[derive(Debug, Deserialize, ToSchema)]
#[allow(dead_code)] // read by `body_field`; the struct is the schema
pub(crate) struct TeamRequest {
    /// The team's name as shown on the leaderboard.
    pub name: String,
}

/// `POST /api/v1/admin/resimulate`.
#[derive(Debug, Deserialize, ToSchema)]
#[allow(dead_code)] // read by `body_field`; the struct is the schema
pub(crate) struct ResimulateRequest {
    /// The policy submission to simulate again.
    pub submission: i64,
}

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
