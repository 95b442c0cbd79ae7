//! What every worker lease shares, whether it holds an evaluation job ([`super::jobs`]) or a
//! video render ([`super::renders`]): the bounds of one `Lease` call and a heartbeat's answer.
//! A file of its own because the queue enforces the bounds while the metrics
//! ([`super::metrics`]) and the gRPC stack's time budget read them, and both lease kinds answer
//! heartbeats alike: held in `jobs`, these made `jobs` import each of `metrics` and `renders`
//! and be imported back (docs/contributing.md, import circles).

/// Most jobs one Lease call hands out, and the longest it is held open.
pub(crate) const MAX_JOBS_PER_LEASE: u32 = 64;
pub(crate) const MAX_LEASE_WAIT_MS: u32 = 30_000;

/// `None` expiry means the lease is gone: stop working.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct HeartbeatOutcome {
    pub lease_expires_at_ms: Option<i64>,
}
