//! The bounds of one worker `Lease` call. A file of their own because the queue
//! ([`super::jobs`]) enforces them while the metrics ([`super::metrics`]) and the gRPC stack's
//! time budget read them: neither of those needs the queue, and the queue records into the
//! metrics, so holding them in `jobs` made `jobs` and `metrics` import each other (issue #29).

/// Most jobs one Lease call hands out, and the longest it is held open.
pub(crate) const MAX_JOBS_PER_LEASE: u32 = 64;
pub(crate) const MAX_LEASE_WAIT_MS: u32 = 30_000;
