//! `[secrets]`: where the server's secret key lives (it seals policy endpoints' bearer tokens at
//! rest, see `crate::secrets`).

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SecretsConfig {
    /// The secret key file (64 hex digits), created with mode 0600 at first start when missing.
    /// Empty means `secret.key` beside the database file (an in-memory database gets a new key
    /// per process). Keep it with the database but out of its backups: the two together
    /// reveal the stored tokens.
    pub key_file: PathBuf,
}

impl SecretsConfig {
    /// The key file of a server whose database is `db`; `None` for an in-memory database with
    /// no `key_file`.
    pub fn key_path(&self, db: &str) -> Option<PathBuf> {
        if !self.key_file.as_os_str().is_empty() {
            return Some(self.key_file.clone());
        }
        Some(super::beside_database(db)?.join("secret.key"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_key_lives_beside_the_database_unless_a_file_is_named() {
        let s = SecretsConfig::default();
        assert_eq!(
            s.key_path("sqlite://data/kitchen-r.db"),
            Some(PathBuf::from("data/secret.key"))
        );
        assert_eq!(
            s.key_path("sqlite:/srv/k.db?mode=rwc"),
            Some(PathBuf::from("/srv/secret.key"))
        );
        assert_eq!(s.key_path("sqlite::memory:"), None);
        let s = SecretsConfig {
            key_file: "/etc/kitchen-r/key".into(),
        };
        assert_eq!(
            s.key_path("sqlite::memory:"),
            Some(PathBuf::from("/etc/kitchen-r/key"))
        );
    }
}
