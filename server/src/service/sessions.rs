//! Browser sessions of the pages (docs/reference/pages.md): a login checks a token once and opens a
//! server-side session; the browser's cookie holds only the session's random id.
//!
//! Policy:
//! - The cookie never carries a credential: it is 32 random bytes (hex), and the database keeps
//!   only their SHA-256, so neither a copied database nor a logged cookie reveals a token.
//! - A session is bound to the team or organiser *and to the token it was opened with*: logout
//!   deletes it; rotating a team's token ends all of that team's sessions; changing the
//!   organiser token (config) ends the organiser's. Sessions expire after
//!   `[sessions] team_hours` / `organiser_hours`.
//! - Failed logins are throttled per client address only ([`super::login_throttle`]); while
//!   throttled a login is refused before its token is read.

use std::net::IpAddr;
use std::time::Instant;

use super::{AppState, Caller, Organiser, hash_token, new_token, now_ms};
use crate::error::ServiceError;
use crate::service::NewTeam;
use crate::store::sessions as session_store;

/// Which form a login came through.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Role {
    Team,
    Organiser,
}

/// What a login attempt came to.
#[derive(Debug)]
pub(crate) enum Login {
    /// A session was opened: the cookie value to set and how long it lasts, seconds.
    Opened {
        cookie: String,
        max_age_s: u32,
        caller: Caller,
    },
    /// The token is not one for this form; what to say.
    Refused(&'static str),
    /// Too many failed logins from this address: try again after this many seconds.
    Throttled { retry_after_s: u64 },
}

impl AppState {
    /// A login with `token` through the `role` form, from `client` (when known).
    pub(crate) async fn log_in(
        &self,
        role: Role,
        token: &str,
        client: Option<IpAddr>,
    ) -> Result<Login, ServiceError> {
        let throttle = &self.inner.logins;
        if let Err(wait) = throttle.check(client, Instant::now()) {
            tracing::info!(?client, "login throttled after repeated failures");
            return Ok(Login::Throttled {
                retry_after_s: wait.as_secs_f64().ceil().max(1.0) as u64,
            });
        }
        let caller = match token.trim() {
            "" => Caller::Anonymous,
            t => self.caller(Some(t)).await?,
        };
        let cfg = &self.config().sessions;
        let (team_id, hours) = match (role, &caller) {
            (Role::Team, Caller::Team(t)) => (Some(t.id), cfg.team_hours),
            (Role::Organiser, Caller::Organiser(_)) => (None, cfg.organiser_hours),
            (Role::Team, Caller::Organiser(_)) => {
                // The organiser's own token is not a guess: no failure is counted.
                return Ok(Login::Refused(
                    "That is the organiser token: log in on the console (/admin).",
                ));
            }
            (Role::Team, _) => {
                throttle.failed(client, Instant::now());
                tracing::warn!(?client, "team pages: failed login");
                return Ok(Login::Refused("That is not a team token."));
            }
            (Role::Organiser, _) => {
                throttle.failed(client, Instant::now());
                tracing::warn!(?client, "organiser console: failed login");
                return Ok(Login::Refused("That is not the organiser token."));
            }
        };
        let id = hex::encode(rand::random::<[u8; 32]>());
        let now = now_ms();
        let max_age_s = hours * 3600;
        session_store::insert(
            self.pool(),
            &session_store::NewSession {
                id_hash: &hash_token(&id),
                team_id,
                credential_hash: &hash_token(token.trim()),
                now,
                expires_at: now + i64::from(max_age_s) * 1000,
            },
        )
        .await?;
        Ok(Login::Opened {
            cookie: id,
            max_age_s,
            caller,
        })
    }

    /// Who the session `cookie` belongs to: [`Caller::Anonymous`] when it is no live session.
    pub(crate) async fn session(&self, cookie: &str) -> Result<Caller, ServiceError> {
        let holder = session_store::holder(self.read_pool(), &hash_token(cookie), now_ms()).await?;
        Ok(match holder {
            Some(session_store::Holder::Team(t)) => Caller::Team(t),
            Some(session_store::Holder::Organiser { credential_hash })
                if credential_hash == self.inner.admin_hash =>
            {
                Caller::Organiser(Organiser::by_session())
            }
            // An organiser session opened with a token the server no longer has.
            Some(session_store::Holder::Organiser { .. }) | None => Caller::Anonymous,
        })
    }

    /// End the session `cookie` (logout). Ending one that is gone already is not an error.
    pub(crate) async fn log_out(&self, cookie: &str) -> Result<(), ServiceError> {
        session_store::delete(self.pool(), &hash_token(cookie)).await?;
        Ok(())
    }

    /// A new token for team `team`, for the organiser or the team itself; the old token stops
    /// working at once and every page session of the team ends.
    pub(crate) async fn rotate_team_token(
        &self,
        caller: &Caller,
        team: i64,
    ) -> Result<NewTeam, ServiceError> {
        let not_found = || ServiceError::not_found(format!("team {team}"));
        match caller {
            Caller::Organiser(_) => {}
            Caller::Team(t) if t.id == team => {}
            // Another team's id answers as if it did not exist.
            Caller::Team(_) => return Err(not_found()),
            Caller::Anonymous => return Err(ServiceError::MissingToken),
            Caller::Unrecognised | Caller::Worker(_) => return Err(ServiceError::BadToken),
        }
        let token = new_token();
        let name = session_store::rotate_team_token(self.pool(), team, &hash_token(&token))
            .await?
            .ok_or_else(not_found)?;
        tracing::info!(team, name = %name, "team token rotated; the team's sessions ended");
        Ok(NewTeam {
            id: team,
            name,
            token,
        })
    }
}
