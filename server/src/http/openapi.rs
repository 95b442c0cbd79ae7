//! The HTTP API described: an OpenAPI 3.1 document generated from the handlers' `#[utoipa::path]`
//! annotations and the response types' `ToSchema` derives, served at `GET /api/v1/openapi.json`
//! and rendered as the page `/api/docs` ([`super::pages`]).
//!
//! Policy: every `/api/v1` route, `/healthz` and `/metrics` is in the document (a unit test
//! compares it with the router's route lines, so a new route without an annotation fails), and
//! every status a route can answer is listed, so a client (and the schemathesis fuzz in
//! `tests/e2e/openapi.rs`) can rely on it. The statuses every route shares are added here once
//! by [`Shared`] instead of on each handler: 500 and 503 everywhere, 401 where a token is
//! needed, 403 where the organiser's is.

use std::sync::OnceLock;

use axum::http::{HeaderValue, header};
use axum::response::{IntoResponse, Response};
use utoipa::openapi::path::Operation;
use utoipa::openapi::security::{HttpAuthScheme, HttpBuilder, SecurityScheme};
use utoipa::openapi::{ContentBuilder, OpenApi as Document, RefOr, ResponseBuilder};
use utoipa::{Modify, OpenApi};

use super::schemas::{ErrorBody, FlagParam, FormatParam, SplitParam, TrackParam};
use crate::schema::SplitName;

/// The security scheme of routes that take a team's token.
pub(crate) const TEAM: &str = "team_token";
/// The security scheme of routes that take the organiser's token.
pub(crate) const ORGANISER: &str = "organiser_token";

#[derive(OpenApi)]
#[openapi(
    info(
        title = "Kitchen-R evaluation server",
        description = "The HTTP API of a Kitchen-R contest server: the dataset and scenes, plan and \
policy submissions, their results, the leaderboard, and the organiser's console. Errors are always \
JSON: `{\"error\": message, \"code\": stable identifier, \"request_id\": ...}` (quote the request id \
when reporting a problem). Send tokens as `Authorization: Bearer <token>`.",
    ),
    paths(
        super::health::healthz,
        super::health::metrics,
        openapi_json,
        super::organiser::create_team,
        super::organiser::rotate_team_token,
        super::dataset::dataset_manifest,
        super::dataset::dataset,
        super::dataset::scenes,
        super::dataset::scene,
        super::dataset::topdown,
        super::dataset::brief,
        super::submissions::submit_plans,
        super::submissions::register_policy,
        super::submissions::submission,
        super::submissions::episode_plot,
        super::leaderboard::leaderboard,
        super::organiser::rescore,
        super::organiser::resimulate,
        super::organiser::admin_stats,
        super::admin::queue,
        super::admin::workers,
        super::admin::runs,
        super::admin::cancel,
        super::admin::requeue,
        super::admin::backup,
        super::verification::verdicts,
        super::verification::plan,
        super::verification::record,
        super::verification::trace,
        super::verification::reevaluation,
        super::verification::export,
        super::verification::import,
    ),
    // The schemas only parameters name (utoipa registers those of bodies and answers itself).
    components(schemas(ErrorBody, SplitName, SplitParam, TrackParam, FormatParam, FlagParam)),
    modifiers(&Shared),
    tags(
        (name = "service", description = "Health, metrics and this description."),
        (name = "dataset", description = "The instructions and the scenes they happen in."),
        (name = "submissions", description = "Plan files and policy endpoints, and their results."),
        (name = "leaderboard", description = "The ranked tracks."),
        (name = "organiser", description = "Teams, rescoring and the console: the organiser token only."),
    )
)]
pub(crate) struct ApiDoc;

/// The document, built once: it only depends on the code.
pub(crate) fn document() -> &'static Document {
    static DOC: OnceLock<Document> = OnceLock::new();
    DOC.get_or_init(ApiDoc::openapi)
}

/// The document as JSON text, serialised once.
pub(crate) fn document_json() -> &'static str {
    static JSON: OnceLock<String> = OnceLock::new();
    JSON.get_or_init(|| {
        document()
            .to_pretty_json()
            .expect("the OpenAPI document serialises")
    })
}

/// `GET /api/v1/openapi.json`.
#[utoipa::path(
    get,
    path = "/api/v1/openapi.json",
    tag = "service",
    summary = "This API's OpenAPI 3.1 document",
    responses((status = 200, description = "The OpenAPI document", content_type = "application/json", body = Object))
)]
pub(super) async fn openapi_json() -> Response {
    (
        [(header::CONTENT_TYPE, HeaderValue::from_static("application/json"))],
        document_json(),
    )
        .into_response()
}

/// Adds the security schemes and the error answers every route shares.
struct Shared;

impl Modify for Shared {
    fn modify(&self, doc: &mut Document) {
        let components = doc.components.get_or_insert_with(Default::default);
        components.add_security_scheme(
            TEAM,
            SecurityScheme::Http(
                HttpBuilder::new()
                    .scheme(HttpAuthScheme::Bearer)
                    .description(Some(
                        "A team's token, from the organiser (`kitchen-r team create`).",
                    ))
                    .build(),
            ),
        );
        components.add_security_scheme(
            ORGANISER,
            SecurityScheme::Http(
                HttpBuilder::new()
                    .scheme(HttpAuthScheme::Bearer)
                    .description(Some(
                        "The organiser token (`admin_token` in the server's config).",
                    ))
                    .build(),
            ),
        );
        doc.paths
            .paths
            .insert(media::VIDEO_PATH.to_string(), media::video_item());
        doc.paths
            .paths
            .insert(media::TRACE_PATH.to_string(), media::trace_item());
        for item in doc.paths.paths.values_mut() {
            for op in [
                &mut item.get,
                &mut item.post,
                &mut item.put,
                &mut item.delete,
                &mut item.patch,
                &mut item.head,
            ]
            .into_iter()
            .flatten()
            {
                add_shared_errors(op);
            }
        }
    }
}

/// 500 and 503 on every operation; 401 where a token is required; 403 where the organiser's is.
fn add_shared_errors(op: &mut Operation) {
    let schemes: Vec<String> = (op.security.iter().flatten())
        .flat_map(|req| {
            serde_json::to_value(req)
                .ok()
                .and_then(|v| v.as_object().map(|o| o.keys().cloned().collect::<Vec<_>>()))
                .unwrap_or_default()
        })
        .collect();
    let mut add = |status: &str, description: &str| {
        if !op.responses.responses.contains_key(status) {
            op.responses
                .responses
                .insert(status.to_string(), RefOr::T(error_response(description)));
        }
    };
    if !schemes.is_empty() {
        add(
            "401",
            "No token (`missing_token`) or a token the server does not know (`bad_token`).",
        );
    }
    if schemes.iter().any(|s| s == ORGANISER) {
        add("403", "A valid token that is not the organiser's (`not_admin`).");
    }
    add(
        "500",
        "An internal error (`internal`): logged with the request id.",
    );
    add(
        "503",
        "The request ran past its time budget (`timeout`) or the server is saturated (`busy`, \
         with `retry_after_s`).",
    );
}

/// A response with the JSON error body.
pub(crate) fn error_response(description: &str) -> utoipa::openapi::Response {
    ResponseBuilder::new()
        .description(description)
        .content(
            "application/json",
            ContentBuilder::new()
                .schema(Some(RefOr::Ref(utoipa::openapi::Ref::from_schema_name(
                    "ErrorBody",
                ))))
                .build(),
        )
        .build()
}

#[path = "openapi_media.rs"]
mod media;
#[cfg(test)]
#[path = "openapi_tests.rs"]
mod tests;
