//! `[sessions]`: browser sessions of the pages and the throttle on failed logins (issues #23,
//! #37). A login makes a server-side session (`crate::service::sessions`); these keys bound how
//! long it lives, how fast one client address may guess at the login forms, and how that
//! address is found behind reverse proxies.
//!
//! Failed logins are limited per client address only: an overall cap (the removed
//! `failures_per_minute`) let anyone with many addresses lock every valid login out, and added
//! no protection to 256-bit tokens. A file that still sets it is refused with a message saying
//! so, rather than serde's list of known keys.

use serde::{Deserialize, Serialize};

use super::ConfigError;

/// The most proxies the client address may be looked for behind.
const MAX_TRUSTED_PROXY_HOPS: u8 = 8;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "SessionKeys")]
pub struct SessionConfig {
    /// How long a team's page session lasts after its login, hours.
    pub team_hours: u32,
    /// How long the organiser console's session lasts after its login, hours.
    pub organiser_hours: u32,
    /// Failed logins (team and organiser forms together) one client address may make per
    /// minute; past it that address's logins answer 429 with `Retry-After` without checking
    /// the token. Other addresses are not affected.
    pub failures_per_minute_per_address: u32,
    /// How many reverse proxies in front of the server append the address they received a
    /// request from to `client_address_header`. 0 (the default): none is trusted, the TCP
    /// peer's address is the client's. N: the TCP peer is the nearest of N trusted proxies and
    /// the client is the N-th entry from the right of the header, the rightmost address no
    /// trusted proxy vouches for (`crate::http`'s `client_address`). At most 8.
    pub trusted_proxy_hops: u8,
    /// The header the trusted proxies append to, e.g. `x-forwarded-for`; required when
    /// `trusted_proxy_hops` is above 0 and must be empty when it is 0 (it is read only then).
    pub client_address_header: String,
}

impl Default for SessionConfig {
    fn default() -> Self {
        SessionConfig {
            team_hours: 7 * 24,
            organiser_hours: 8,
            failures_per_minute_per_address: 10,
            trusted_proxy_hops: 0,
            client_address_header: String::new(),
        }
    }
}

/// What a `[sessions]` table may hold: [`SessionConfig`]'s keys and the removed ones, which
/// are refused by name.
#[derive(Deserialize)]
#[serde(deny_unknown_fields, default)]
struct SessionKeys {
    team_hours: u32,
    organiser_hours: u32,
    failures_per_minute_per_address: u32,
    trusted_proxy_hops: u8,
    client_address_header: String,
    failures_per_minute: Option<serde::de::IgnoredAny>,
}

impl Default for SessionKeys {
    fn default() -> Self {
        let d = SessionConfig::default();
        SessionKeys {
            team_hours: d.team_hours,
            organiser_hours: d.organiser_hours,
            failures_per_minute_per_address: d.failures_per_minute_per_address,
            trusted_proxy_hops: d.trusted_proxy_hops,
            client_address_header: d.client_address_header,
            failures_per_minute: None,
        }
    }
}

/// The refusal of a file that still sets `failures_per_minute`.
const REMOVED_OVERALL_CAP: &str = "`sessions.failures_per_minute` was removed: failed \
    logins are limited per client address only (`failures_per_minute_per_address`); delete the \
    key";

impl TryFrom<SessionKeys> for SessionConfig {
    type Error = &'static str;

    fn try_from(k: SessionKeys) -> Result<Self, Self::Error> {
        if k.failures_per_minute.is_some() {
            return Err(REMOVED_OVERALL_CAP);
        }
        Ok(SessionConfig {
            team_hours: k.team_hours,
            organiser_hours: k.organiser_hours,
            failures_per_minute_per_address: k.failures_per_minute_per_address,
            trusted_proxy_hops: k.trusted_proxy_hops,
            client_address_header: k.client_address_header,
        })
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
        if self.failures_per_minute_per_address == 0 {
            return invalid("sessions.failures_per_minute_per_address", "must be at least 1");
        }
        if self.trusted_proxy_hops > MAX_TRUSTED_PROXY_HOPS {
            return invalid("sessions.trusted_proxy_hops", "must be between 0 and 8");
        }
        let header = self.client_address_header.as_str();
        match (self.trusted_proxy_hops, header) {
            (0, "") => Ok(()),
            // Before `trusted_proxies` the header alone was trusted (its first, client-written
            // entry): refuse that setting rather than silently count every client as the proxy.
            (0, _) => invalid(
                "sessions.client_address_header",
                "is read only behind trusted proxies: set `trusted_proxy_hops` to the number \
                 of proxies that append to it (1 behind one ingress), or leave it empty",
            ),
            (_, "") => invalid(
                "sessions.client_address_header",
                "must name the header the trusted proxies append to (e.g. \"x-forwarded-for\") \
                 when `trusted_proxy_hops` is above 0",
            ),
            _ if axum::http::HeaderName::try_from(header).is_err() => invalid(
                "sessions.client_address_header",
                "must be a header name such as x-forwarded-for",
            ),
            _ => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use figment::Figment;
    use figment::providers::{Format, Toml};

    use super::*;

    fn parse(toml: &str) -> Result<SessionConfig, String> {
        Figment::from(Toml::string(toml))
            .extract_inner("sessions")
            .map_err(|e| e.to_string())
    }

    #[test]
    fn session_limits_are_checked() {
        assert!(SessionConfig::default().validate().is_ok());
        let behind_one_proxy = SessionConfig {
            trusted_proxy_hops: 1,
            client_address_header: "X-Forwarded-For".into(),
            ..SessionConfig::default()
        };
        assert!(behind_one_proxy.validate().is_ok());
        for (bad, key) in [
            (
                SessionConfig {
                    team_hours: 0,
                    ..SessionConfig::default()
                },
                "sessions.team_hours",
            ),
            (
                SessionConfig {
                    failures_per_minute_per_address: 0,
                    ..SessionConfig::default()
                },
                "sessions.failures_per_minute_per_address",
            ),
            (
                SessionConfig {
                    trusted_proxy_hops: 9,
                    ..behind_one_proxy.clone()
                },
                "sessions.trusted_proxy_hops",
            ),
            (
                SessionConfig {
                    client_address_header: "x forwarded".into(),
                    ..behind_one_proxy.clone()
                },
                "sessions.client_address_header",
            ),
            (
                SessionConfig {
                    client_address_header: String::new(),
                    ..behind_one_proxy.clone()
                },
                "sessions.client_address_header",
            ),
            // The pre-#37 setting (the header trusted without proxies) is refused, not ignored.
            (
                SessionConfig {
                    trusted_proxy_hops: 0,
                    ..behind_one_proxy.clone()
                },
                "sessions.client_address_header",
            ),
        ] {
            match bad.validate() {
                Err(ConfigError::Invalid { key: k, .. }) => assert_eq!(k, key, "{bad:?}"),
                other => panic!("{bad:?}: {other:?}"),
            }
        }
    }

    #[test]
    fn the_removed_overall_cap_is_refused_by_name_saying_what_to_do() {
        // The [sessions] table of the config file shipped before `trusted_proxies` and the login
        // limits.
        let old = "[sessions]\nfailures_per_minute_per_address = 10\nfailures_per_minute = 120\n\
                   client_address_header = \"\"\n";
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("server.toml");
        std::fs::write(&file, old).unwrap();
        let err = crate::Config::load(Some(&file)).unwrap_err().to_string();
        for needed in [
            "`sessions.failures_per_minute` was removed",
            "per client address only",
            "failures_per_minute_per_address",
        ] {
            assert!(err.contains(needed), "{needed:?} missing from: {err}");
        }
        let c = parse("[sessions]\ntrusted_proxy_hops = 2\nclient_address_header = \"x-real\"\n");
        let c = c.unwrap();
        assert_eq!((c.trusted_proxy_hops, c.team_hours), (2, 168));
        assert!(parse("[sessions]\nfailures_per_hour = 1\n").is_err());
    }
}
