//! `[sessions]`: browser sessions of the pages and the throttle on failed logins (issue #23).
//! A login makes a server-side session (`crate::service::sessions`); these keys bound how long
//! it lives and how fast anyone may guess at the login forms.

use serde::{Deserialize, Serialize};

use super::ConfigError;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SessionConfig {
    /// How long a team's page session lasts after its login, hours.
    pub team_hours: u32,
    /// How long the organiser console's session lasts after its login, hours.
    pub organiser_hours: u32,
    /// Failed logins (team and organiser forms together) one client address may make per
    /// minute; past it the forms answer 429 with `Retry-After` without checking the token.
    pub failures_per_minute_per_address: u32,
    /// Failed logins all addresses together may make per minute, past which every login
    /// answers 429. A failed login names no team (the token alone identifies one), so this is
    /// the bound that protects every team's token at once from a guesser with many addresses.
    pub failures_per_minute: u32,
    /// The request header that carries the client's address when the server is behind a
    /// reverse proxy that sets it (e.g. `x-forwarded-for`; its first address is used). Empty:
    /// the TCP peer's address. Set it only behind such a proxy: a client could forge it.
    pub client_address_header: String,
}

impl Default for SessionConfig {
    fn default() -> Self {
        SessionConfig {
            team_hours: 7 * 24,
            organiser_hours: 8,
            failures_per_minute_per_address: 10,
            failures_per_minute: 120,
            client_address_header: String::new(),
        }
    }
}

impl SessionConfig {
    pub(super) fn validate(&self) -> Result<(), ConfigError> {
        let invalid = |key, message: &str| {
            Err(ConfigError::Invalid {
                key,
                message: message.into(),
            })
        };
        if !(1..=24 * 365).contains(&self.team_hours) {
            return invalid("sessions.team_hours", "must be between 1 and 8760 hours");
        }
        if !(1..=24 * 30).contains(&self.organiser_hours) {
            return invalid("sessions.organiser_hours", "must be between 1 and 720 hours");
        }
        if self.failures_per_minute_per_address == 0 || self.failures_per_minute == 0 {
            return invalid(
                "sessions.failures_per_minute",
                "failures_per_minute and failures_per_minute_per_address must be at least 1",
            );
        }
        if axum::http::HeaderName::try_from(self.client_address_header.as_str()).is_err()
            && !self.client_address_header.is_empty()
        {
            return invalid(
                "sessions.client_address_header",
                "must be a header name such as x-forwarded-for, or empty",
            );
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn session_limits_are_checked() {
        assert!(SessionConfig::default().validate().is_ok());
        for bad in [
            SessionConfig {
                team_hours: 0,
                ..SessionConfig::default()
            },
            SessionConfig {
                failures_per_minute: 0,
                ..SessionConfig::default()
            },
            SessionConfig {
                client_address_header: "x forwarded".into(),
                ..SessionConfig::default()
            },
        ] {
            assert!(bad.validate().is_err(), "{bad:?}");
        }
    }
}
