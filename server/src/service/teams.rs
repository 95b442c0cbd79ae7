//! Teams: the organiser creates them; a team's token is shown once and only its hash is kept.
//!
//! Policy: a name that looks like an existing team's is refused (409 naming that team), so no
//! team can pass for another on the leaderboard: names are compared by their Unicode confusable
//! skeletons (UTS #39), with and without case ([`name_keys`]). Teams already stored keep working.

use serde::Serialize;

use super::{AppState, Organiser, hash_token, new_token, now_ms};
use crate::error::ServiceError;
use crate::store::{self, NameKeys};

/// A new team and its token (shown once: only its hash is stored).
#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub(crate) struct NewTeam {
    pub id: i64,
    pub name: String,
    pub token: String,
}

impl AppState {
    /// Organiser: make a team and its token.
    pub(crate) async fn create_team(&self, _: Organiser, name: &str) -> Result<NewTeam, ServiceError> {
        let name = validate_team_name(name)?;
        let keys = name_keys(&name);
        store::fill_team_name_keys(self.pool(), name_keys).await?;
        let token = new_token();
        let Some(id) = store::insert_team(self.pool(), &name, &keys, &hash_token(&token), now_ms()).await?
        else {
            let existing = store::team_like(self.pool(), &name, &keys).await?;
            return Err(name_taken(&name, existing.as_deref()));
        };
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

/// The keys two names collide on when they look alike. `skeleton` is UTS #39's, which maps each
/// character to a representative of the characters it can be mistaken for (Cyrillic а → a,
/// capital I → l, 0 → O). `skeleton_folded` is that of the lower-cased name, lower-cased again
/// (the skeleton of a small letter can be a capital): it makes case differences collide. Runs of
/// spaces count as one, as HTML shows them.
fn name_keys(name: &str) -> NameKeys {
    let spaced = name.split_whitespace().collect::<Vec<_>>().join(" ");
    let skeleton: String = unicode_security::skeleton(&spaced).collect();
    let lower = spaced.to_lowercase();
    let skeleton_folded = unicode_security::skeleton(&lower)
        .collect::<String>()
        .to_lowercase();
    NameKeys {
        skeleton,
        skeleton_folded,
    }
}

/// The 409 for a name that is taken or looks like `existing`.
fn name_taken(name: &str, existing: Option<&str>) -> ServiceError {
    match existing {
        Some(e) if e != name => {
            // The look-alike characters are invisible in the message itself: name them.
            let unusual: Vec<String> = name
                .chars()
                .filter(|c| !c.is_ascii())
                .map(|c| format!("U+{:04X} {c:?}", u32::from(c)))
                .collect();
            let which = if unusual.is_empty() {
                String::new()
            } else {
                format!(" (its non-ASCII characters: {})", unusual.join(", "))
            };
            ServiceError::Conflict(format!(
                "team name {name:?} looks like the existing team {e:?}{which}: names that differ \
                 only in letter case or in look-alike characters are refused, so that no team \
                 can pass for another; choose a name that reads differently"
            ))
        }
        // Taken as is (or, in a race, by a name that is now gone from view: say the same).
        _ => ServiceError::Conflict(format!("a team named {name:?} already exists")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::{FakeProbe, fixture};

    #[test]
    fn team_names_are_checked() {
        assert_eq!(validate_team_name("  Team Rocket-2 ").unwrap(), "Team Rocket-2");
        for bad in ["", "   ", "a<b>", "x\ny", &"n".repeat(65)] {
            assert!(validate_team_name(bad).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn look_alike_names_share_a_key_and_different_names_do_not() {
        let collide = |a: &str, b: &str| {
            let (x, y) = (name_keys(a), name_keys(b));
            x.skeleton == y.skeleton || x.skeleton_folded == y.skeleton_folded
        };
        for (a, b) in [
            ("rt-alpha", "rt-\u{430}lpha"), // Cyrillic а
            ("rt-alpha", "RT-Alpha"),
            ("rt-alpha", "RT-\u{410}LPHA"), // Cyrillic А
            ("PayPal", "PayPaI"),           // capital I for small l
            ("team0", "teamO"),
            ("Team Rocket", "Team  Rocket"),
        ] {
            assert!(collide(a, b), "{a:?} vs {b:?}");
        }
        for (a, b) in [
            ("rt-alpha", "rt-beta"),
            ("rt-alpha", "rt-alpha2"),
            ("lion", "iion"),
        ] {
            assert!(!collide(a, b), "{a:?} vs {b:?}");
        }
    }

    #[tokio::test]
    async fn a_look_alike_of_an_existing_team_is_refused_naming_it() {
        let f = fixture(FakeProbe::ok(1), |_| {}).await;
        f.team("rt-alpha").await;
        let admin = f.admin().await;
        for name in ["rt-\u{430}lpha", "RT-ALPHA", "rt-alpha"] {
            let e = f.state.create_team(admin, name).await.unwrap_err();
            let msg = e.to_string();
            assert_eq!(e.code(), "conflict", "{name}");
            assert!(msg.contains("\"rt-alpha\""), "names the existing team: {msg}");
        }
        let e = f.state.create_team(admin, "rt-\u{430}lpha").await.unwrap_err();
        assert!(e.to_string().contains("U+0430"), "{e}");
        f.state.create_team(admin, "rt-beta").await.unwrap();
    }

    #[tokio::test]
    async fn teams_stored_before_the_keys_existed_are_compared_too() {
        let f = fixture(FakeProbe::ok(1), |_| {}).await;
        // A team as an older server stored it: no keys.
        sqlx::query("INSERT INTO teams (name, token_hash, created_at) VALUES ('Old Team', 'h', 0)")
            .execute(f.state.pool())
            .await
            .unwrap();
        let e = f
            .state
            .create_team(f.admin().await, "old team")
            .await
            .unwrap_err();
        assert!(e.to_string().contains("\"Old Team\""), "{e}");
    }
}
