//! Who is calling: a request's bearer token resolved once, by the adapter, into a [`Caller`]
//! (the HTTP extractor in `crate::http`, the gRPC layer in `crate::grpc`). Service methods take
//! the proof they need ([`Organiser`], [`WorkerCred`], a [`Team`]) instead of a raw token, so no
//! rule re-reads the token and no method can forget to check it.
//!
//! Only this module compares tokens; it never logs one.

use sha2::{Digest, Sha256};

use super::AppState;
use crate::error::ServiceError;
use crate::store::{self, Team};

/// The caller of one request, resolved from its `authorization: Bearer ...` header.
#[derive(Debug, Clone)]
pub(crate) enum Caller {
    /// No token was sent.
    Anonymous,
    /// A token that is none of the ones below.
    Unrecognised,
    Team(Team),
    Organiser(Organiser),
    Worker(WorkerCred),
}

/// Proof that the caller presented the organiser token (only [`AppState::caller`] makes one,
/// and [`Organiser::by_session`] for a page session opened with that token).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Organiser(());

impl Organiser {
    /// For `super::sessions` alone: a live session whose login presented the current organiser
    /// token.
    pub(super) fn by_session() -> Organiser {
        Organiser(())
    }
}

/// Proof that the caller presented the simulation workers' token.
#[derive(Debug, Clone, Copy)]
pub(crate) struct WorkerCred(());

impl Caller {
    /// The caller's team; the organiser and workers are not teams.
    pub(crate) fn team(&self) -> Result<&Team, ServiceError> {
        match self {
            Caller::Team(t) => Ok(t),
            Caller::Anonymous => Err(ServiceError::MissingToken),
            Caller::Unrecognised | Caller::Organiser(_) | Caller::Worker(_) => Err(ServiceError::BadToken),
        }
    }

    pub(crate) fn organiser(&self) -> Result<Organiser, ServiceError> {
        match self {
            Caller::Organiser(o) => Ok(*o),
            Caller::Anonymous => Err(ServiceError::MissingToken),
            Caller::Unrecognised | Caller::Team(_) | Caller::Worker(_) => Err(ServiceError::NotAdmin),
        }
    }

    pub(crate) fn worker(&self) -> Result<WorkerCred, ServiceError> {
        match self {
            Caller::Worker(w) => Ok(*w),
            Caller::Anonymous => Err(ServiceError::MissingToken),
            Caller::Unrecognised | Caller::Team(_) | Caller::Organiser(_) => Err(ServiceError::BadToken),
        }
    }
}

impl AppState {
    /// Resolve a bearer token. The organiser and worker tokens are compared by hash without a
    /// database read (workers call several times a second); a team token costs one indexed
    /// lookup. An unknown token is not an error here: routes that need no caller ignore it.
    pub(crate) async fn caller(&self, token: Option<&str>) -> Result<Caller, ServiceError> {
        let Some(token) = token else {
            return Ok(Caller::Anonymous);
        };
        let hash = hash_token(token);
        if hash == self.inner.admin_hash {
            return Ok(Caller::Organiser(Organiser(())));
        }
        if hash == self.inner.worker_hash {
            return Ok(Caller::Worker(WorkerCred(())));
        }
        Ok(store::team_by_token_hash(self.read_pool(), &hash)
            .await?
            .map_or(Caller::Unrecognised, Caller::Team))
    }
}

/// The token of an `authorization` header value: `Bearer <token>` (either case of the scheme),
/// trimmed; `None` for any other shape or an empty token. Both adapters use this one reading.
pub(crate) fn bearer_token(header: &str) -> Option<&str> {
    let token = header
        .strip_prefix("Bearer ")
        .or_else(|| header.strip_prefix("bearer "))?
        .trim();
    (!token.is_empty()).then_some(token)
}

/// A fresh bearer token: 32 random bytes, hex, with a prefix that makes leaks greppable.
pub(crate) fn new_token() -> String {
    let bytes: [u8; 32] = rand::random();
    format!("kr_{}", hex::encode(bytes))
}

pub(crate) fn hash_token(token: &str) -> String {
    hex::encode(Sha256::digest(token.as_bytes()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::{ADMIN, FakeProbe, WORKER, fixture};

    #[test]
    fn tokens_are_random_and_hashes_stable() {
        let (a, b) = (new_token(), new_token());
        assert_ne!(a, b);
        assert_eq!(a.len(), 3 + 64);
        assert_eq!(hash_token("x"), hash_token("x"));
        assert_ne!(hash_token(&a), hash_token(&b));
    }

    #[test]
    fn bearer_headers_are_read_one_way() {
        assert_eq!(bearer_token("Bearer abc "), Some("abc"));
        assert_eq!(bearer_token("bearer abc"), Some("abc"));
        for bad in ["abc", "Bearer ", "Basic abc", ""] {
            assert_eq!(bearer_token(bad), None, "{bad:?}");
        }
    }

    #[tokio::test]
    async fn each_role_gets_only_its_own_proof() {
        let f = fixture(FakeProbe::ok(1), |_| {}).await;
        let token = f.team("alpha").await;
        let code = |r: Result<(), ServiceError>| r.map_err(|e| e.code()).err();
        let anonymous = f.state.caller(None).await.unwrap();
        let unknown = f.state.caller(Some("nope")).await.unwrap();
        let team = f.state.caller(Some(&token)).await.unwrap();
        let admin = f.state.caller(Some(ADMIN)).await.unwrap();
        let worker = f.state.caller(Some(WORKER)).await.unwrap();
        assert_eq!(team.team().unwrap().name, "alpha");
        assert!(admin.organiser().is_ok() && worker.worker().is_ok());
        for (caller, team, organiser, worker) in [
            (&anonymous, "missing_token", "missing_token", "missing_token"),
            (&unknown, "bad_token", "not_admin", "bad_token"),
            (&team, "", "not_admin", "bad_token"),
            (&admin, "bad_token", "", "bad_token"),
            (&worker, "bad_token", "not_admin", ""),
        ] {
            let want = |s: &'static str| (!s.is_empty()).then_some(s);
            assert_eq!(code(caller.team().map(|_| ())), want(team), "{caller:?}");
            assert_eq!(
                code(caller.organiser().map(|_| ())),
                want(organiser),
                "{caller:?}"
            );
            assert_eq!(code(caller.worker().map(|_| ())), want(worker), "{caller:?}");
        }
    }
}
