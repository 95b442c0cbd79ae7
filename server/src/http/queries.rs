//! The query strings of the HTTP routes, one typed struct each, read through
//! [`super::extract::QueryArgs`] (axum's `Query<T>` with the API's error body). A malformed query
//! string, or a parameter given twice, is a 400 naming it; the values are checked where they are
//! used, with the errors the API documents. Parameters a route does not know are ignored.

use kitchen_r_core::dataset::Split;
use serde::Deserialize;

use crate::error::ServiceError;

/// `GET /`: which split's boards the page shows.
#[derive(Debug, Default, Deserialize)]
pub(crate) struct SplitQuery {
    pub split: Option<String>,
}

/// `POST /api/v1/submissions/plans`: the split, and whether it is the organiser's reference run.
#[derive(Debug, Default, Deserialize)]
pub(crate) struct PlansQuery {
    pub split: Option<String>,
    pub reference: Option<String>,
}

/// `GET /api/v1/leaderboard`: which board, and in which format.
#[derive(Debug, Default, Deserialize)]
pub(crate) struct LeaderboardQuery {
    pub track: Option<String>,
    pub split: Option<String>,
    pub observations: Option<String>,
    pub grasp_mode: Option<String>,
    pub format: Option<String>,
}

/// `GET /login`: where to go after signing in.
#[derive(Debug, Default, Deserialize)]
pub(crate) struct LoginQuery {
    pub next: Option<String>,
}

/// A `split` parameter: `dev` or `test`; absent or empty is `default`, or a 400 without one.
pub(super) fn split_param(value: Option<&String>, default: Option<Split>) -> Result<Split, ServiceError> {
    match (value.map(String::as_str), default) {
        (None | Some(""), Some(d)) => Ok(d),
        (None | Some(""), None) => Err(ServiceError::BadRequest(
            "the `split` query parameter is required: `dev` or `test`".into(),
        )),
        (Some(s), _) => s.parse().map_err(ServiceError::BadRequest),
    }
}

/// A run id from a path (`/api/v1/admin/runs/{id}/…`): a positive integer, else 400
/// `bad_request` (an unknown one is 404 where it is looked up).
pub(crate) fn run_id(id: &str) -> Result<i64, ServiceError> {
    id.parse::<i64>()
        .ok()
        .filter(|n| *n > 0)
        .ok_or_else(|| ServiceError::BadRequest(format!("a run id is a positive integer, not {id:?}")))
}
