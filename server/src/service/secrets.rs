//! Policy endpoints' bearer tokens at rest (the cipher and key file are [`crate::secrets`]).
//!
//! Policy: a token is sealed before anything is stored (the submission's body holds
//! `token_sealed`, each job's spec `endpoint.bearer_token_sealed`), opened only when a job is
//! leased, so only the worker that calls the endpoint gets it, and never shown in an answer or
//! a log line. At start-up the server seals any plain token an earlier version stored, then
//! checks that its key opens the newest sealed one: a replaced key file stops the server with
//! the reason instead of handing workers tokens it cannot open.

use anyhow::Context;

use super::AppState;
use crate::secrets::SecretError;
use crate::store;

impl AppState {
    /// `plain` sealed for storage.
    pub(crate) fn seal_token(&self, plain: &str) -> String {
        self.inner.secret_key.seal(plain)
    }

    /// The plain text of a stored sealed token.
    pub(crate) fn open_token(&self, sealed: &str) -> Result<String, SecretError> {
        self.inner.secret_key.open(sealed)
    }

    /// Start-up: seal the plain tokens stored before tokens were sealed, then check that this
    /// server's key opens the stored ones.
    pub(crate) async fn seal_stored_tokens(&self) -> anyhow::Result<()> {
        let key = &self.inner.secret_key;
        let (bodies, jobs) = store::secrets::seal_plain_tokens(self.pool(), key)
            .await
            .context("sealing the endpoint tokens stored in plain text")?;
        if bodies + jobs > 0 {
            tracing::info!(
                submissions = bodies,
                jobs,
                "sealed endpoint tokens stored in plain text before 20261126000200"
            );
        }
        if let Some(sealed) = store::secrets::newest_sealed(self.pool()).await? {
            self.open_token(&sealed)
                .context("checking the secret key against the stored endpoint tokens")?;
        }
        // Names the key (not its bytes), so an organiser can tell which key file a server uses.
        tracing::info!(
            fingerprint = key.fingerprint(),
            "endpoint tokens sealed with this secret key"
        );
        Ok(())
    }
}

#[cfg(test)]
mod tests;
