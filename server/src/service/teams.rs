//! Teams: the organiser creates them; a team's token is shown once and only its hash is kept.

use serde::Serialize;

use super::{AppState, Organiser, hash_token, new_token, now_ms};
use crate::error::ServiceError;
use crate::store;

/// A new team and its token (shown once: only its hash is stored).
#[derive(Debug, Clone, Serialize)]
pub(crate) struct NewTeam {
    pub id: i64,
    pub name: String,
    pub token: String,
}

impl AppState {
    /// Organiser: make a team and its token.
    pub(crate) async fn create_team(&self, _: Organiser, name: &str) -> Result<NewTeam, ServiceError> {
        let name = validate_team_name(name)?;
        let token = new_token();
        let id = store::insert_team(self.pool(), &name, &hash_token(&token), now_ms())
            .await?
            .ok_or_else(|| ServiceError::Conflict(format!("a team named {name:?} already exists")))?;
        tracing::info!(team = id, name = %name, "team created");
        Ok(NewTeam { id, name, token })
    }
}

/// Team names: 1 to 64 characters of letters, digits, space, `-`, `_`, `.`; trimmed.
fn validate_team_name(name: &str) -> Result<String, ServiceError> {
    let name = name.trim();
    let ok_char = |c: char| c.is_alphanumeric() || matches!(c, ' ' | '-' | '_' | '.');
    if name.is_empty() || name.chars().count() > 64 || !name.chars().all(ok_char) {
        return Err(ServiceError::BadRequest(format!(
            "team name {name:?} must be 1 to 64 letters, digits, spaces, '-', '_' or '.'"
        )));
    }
    Ok(name.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn team_names_are_checked() {
        assert_eq!(validate_team_name("  Team Rocket-2 ").unwrap(), "Team Rocket-2");
        for bad in ["", "   ", "a<b>", "x\ny", &"n".repeat(65)] {
            assert!(validate_team_name(bad).is_err(), "{bad:?}");
        }
    }
}
