//! Who a page, or a page's media request (an episode's video, its plot), acts as: a bearer
//! header first (scripts), then the team's session cookie, then the organiser's console cookie.
//!
//! A file of its own because both the pages ([`super::pages`]) and the video route
//! ([`super::video`]) need it, and the pages route to the video: held in `pages`, it made the
//! two import each other (docs/contributing.md, import circles).

use axum::http::HeaderMap;

use super::{admin, session};
use crate::error::ServiceError;
use crate::service::{AppState, Caller, Organiser};
use crate::store::Team;

/// The team session cookie; its value is a session id (`crate::service::sessions`).
pub(super) const TEAM_COOKIE: &str = "kitchen_r_team";

/// Who opened a page: a bearer header first (scripts), then the team cookie, then the
/// organiser's console cookie.
pub(super) enum Who {
    Nobody,
    Team(Team),
    Organiser(Organiser),
}

pub(super) async fn who(s: &AppState, caller: Caller, headers: &HeaderMap) -> Result<Who, ServiceError> {
    match caller {
        Caller::Team(t) => return Ok(Who::Team(t)),
        Caller::Organiser(o) => return Ok(Who::Organiser(o)),
        _ => {}
    }
    if let Some(id) = session::session_id(headers, TEAM_COOKIE)
        && let Caller::Team(t) = s.session(id).await?
    {
        return Ok(Who::Team(t));
    }
    Ok(match admin::organiser_session(s, headers).await? {
        Some(o) => Who::Organiser(o),
        None => Who::Nobody,
    })
}

/// The caller a page's media request acts as: the team or organiser of its session cookie (or
/// bearer header); `None` for nobody, whom media routes answer as not found.
pub(super) async fn session_caller(
    s: &AppState,
    caller: Caller,
    headers: &HeaderMap,
) -> Result<Option<Caller>, ServiceError> {
    Ok(match who(s, caller, headers).await? {
        Who::Team(t) => Some(Caller::Team(t)),
        Who::Organiser(o) => Some(Caller::Organiser(o)),
        Who::Nobody => None,
    })
}
