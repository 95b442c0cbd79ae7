//! Flood limits: how fast one team may upload (`quota.per_minute`, a token bucket per team and
//! split) and the counts of what was refused, for the organiser (`GET /api/v1/admin/stats`)
//! and `/metrics`.
//!
//! Every upload attempt of a team takes a slot (plan files and policy registrations, on
//! either split, accepted or not): parsing and scoring a file, or probing an endpoint, costs
//! the server as much as storing it, and a refused probe is still a connection made on the
//! team's behalf. A refused attempt takes no slot, so retrying early does not push the wait
//! further. Organiser reference runs are exempt. The daily quota ([`super::plan_uploads`]) is
//! what bounds the database; this bounds the rate at which it can be reached.
//!
//! Limitation: buckets and counts live in this process's memory. A contest runs one server
//! process (docs/contest/deploy.md: one replica), so that suffices; a restart refills every bucket and
//! resets the counts, and several processes behind one address would each allow the full
//! rate. The daily quota is counted in the database and holds across both.

use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Mutex, PoisonError};
use std::time::{Duration, Instant};

use kitchen_r_core::dataset::Split;
use serde::Serialize;

use super::{AppState, Organiser, rfc3339};
use crate::config::Quota;
use crate::error::ServiceError;
use crate::store::Team;

/// The in-memory limit state of one server process.
pub(super) struct Limits {
    rate: RateLimiter,
    refusals: Refusals,
    /// When the counts started (process start), Unix ms.
    since_ms: i64,
}

impl Limits {
    pub(super) fn new(per_minute: u32, now_ms: i64) -> Limits {
        Limits {
            rate: RateLimiter::new(per_minute),
            refusals: Refusals::default(),
            since_ms: now_ms,
        }
    }
}

/// Why an upload was refused, as counted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Refusal {
    /// Over `quota.per_minute` (429 `rate_limited`).
    RateLimited = 0,
    /// Over `quota.dev_per_day` / `quota.test_per_day` (429 `quota_exceeded`).
    DailyQuota = 1,
}

/// Refusal counters, by kind and split; lock-free so counting never slows a refusal down.
#[derive(Debug, Default)]
struct Refusals {
    counts: [[AtomicU64; 2]; 2],
}

fn split_index(split: Split) -> usize {
    match split {
        Split::Dev => 0,
        Split::Test => 1,
    }
}

impl Refusals {
    fn count(&self, kind: Refusal, split: Split) {
        self.counts[kind as usize][split_index(split)].fetch_add(1, Ordering::Relaxed);
    }

    fn snapshot(&self) -> RefusalCounts {
        let get = |kind: Refusal| {
            let row = &self.counts[kind as usize];
            PerSplit {
                dev: row[0].load(Ordering::Relaxed),
                test: row[1].load(Ordering::Relaxed),
            }
        };
        RefusalCounts {
            rate_limited: get(Refusal::RateLimited),
            daily_quota: get(Refusal::DailyQuota),
        }
    }
}

/// Uploads refused since the server started, by kind and split.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, utoipa::ToSchema)]
pub(crate) struct RefusalCounts {
    pub rate_limited: PerSplit,
    pub daily_quota: PerSplit,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, utoipa::ToSchema)]
pub(crate) struct PerSplit {
    pub dev: u64,
    pub test: u64,
}

/// `GET /api/v1/admin/stats`.
#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub(crate) struct AdminStats {
    /// When the counts started (this process's start; they are not persisted).
    pub counting_since: String,
    pub refusals: RefusalCounts,
    /// The limits in force (`[quota]`).
    pub limits: Quota,
}

/// A token bucket per `(team, split)`: `per_minute` slots, refilled continuously at
/// `per_minute / 60` per second, so a team may burst up to `per_minute` and then sustain that
/// rate. One entry per team and split that ever uploaded: teams are made by the organiser, so
/// the map stays small.
struct RateLimiter {
    per_minute: u32,
    buckets: Mutex<HashMap<(i64, Split), Bucket>>,
}

#[derive(Debug, Clone, Copy)]
struct Bucket {
    tokens: f64,
    at: Instant,
}

impl RateLimiter {
    fn new(per_minute: u32) -> RateLimiter {
        RateLimiter {
            per_minute,
            buckets: Mutex::new(HashMap::new()),
        }
    }

    /// Take one slot for `key` at `now`; when none is left, how long until one is.
    fn take(&self, key: (i64, Split), now: Instant) -> Result<(), Duration> {
        if self.per_minute == 0 {
            return Ok(());
        }
        let capacity = f64::from(self.per_minute);
        let per_s = capacity / 60.0;
        // Nothing below can panic while the lock is held; a poisoned map is still consistent.
        let mut buckets = self.buckets.lock().unwrap_or_else(PoisonError::into_inner);
        let b = buckets.entry(key).or_insert(Bucket {
            tokens: capacity,
            at: now,
        });
        let elapsed = now.saturating_duration_since(b.at).as_secs_f64();
        b.tokens = (b.tokens + elapsed * per_s).min(capacity);
        b.at = now;
        if b.tokens >= 1.0 {
            b.tokens -= 1.0;
            Ok(())
        } else {
            Err(Duration::from_secs_f64((1.0 - b.tokens) / per_s))
        }
    }
}

impl AppState {
    /// Take one of `team`'s upload slots on `split`, or refuse with 429 and when to retry.
    pub(super) fn check_rate(&self, team: &Team, split: Split) -> Result<(), ServiceError> {
        let per_minute = self.config().quota.per_minute;
        let Err(wait) = self.inner.limits.rate.take((team.id, split), Instant::now()) else {
            return Ok(());
        };
        self.count_refusal(Refusal::RateLimited, split);
        tracing::info!(team = %team.name, %split, per_minute, "upload rate limited");
        Err(ServiceError::RateLimited {
            split: split.as_str(),
            per_minute,
            // Whole seconds, rounded up so a client that waits exactly this long gets a slot.
            retry_after_s: wait.as_secs_f64().ceil().max(1.0) as u64,
        })
    }

    pub(super) fn count_refusal(&self, kind: Refusal, split: Split) {
        self.inner.limits.refusals.count(kind, split);
    }

    /// Uploads refused since the server started (for `/metrics` and the admin view).
    pub(crate) fn refusals(&self) -> RefusalCounts {
        self.inner.limits.refusals.snapshot()
    }

    /// Organiser: the refusal counts and the limits in force.
    pub(crate) fn admin_stats(&self, _: Organiser) -> AdminStats {
        AdminStats {
            counting_since: rfc3339(self.inner.limits.since_ms),
            refusals: self.refusals(),
            limits: self.config().quota,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bucket_allows_a_burst_then_the_steady_rate() {
        let r = RateLimiter::new(6); // one slot every 10 s
        let t0 = Instant::now();
        let key = (1, Split::Dev);
        for _ in 0..6 {
            r.take(key, t0).unwrap();
        }
        let wait = r.take(key, t0).unwrap_err();
        assert!((9.9..=10.0).contains(&wait.as_secs_f64()), "{wait:?}");
        // A refused attempt takes nothing: the wait only shrinks.
        let later = r.take(key, t0 + Duration::from_secs(4)).unwrap_err();
        assert!((5.9..=6.0).contains(&later.as_secs_f64()), "{later:?}");
        r.take(key, t0 + Duration::from_secs(10)).unwrap();
        assert!(r.take(key, t0 + Duration::from_secs(10)).is_err());
        // Other teams and the other split have their own buckets.
        r.take((2, Split::Dev), t0).unwrap();
        r.take((1, Split::Test), t0).unwrap();
        // Refilling stops at the burst size.
        let much_later = t0 + Duration::from_secs(3600);
        for _ in 0..6 {
            r.take(key, much_later).unwrap();
        }
        assert!(r.take(key, much_later).is_err());
    }

    #[test]
    fn zero_means_unlimited() {
        let r = RateLimiter::new(0);
        let t0 = Instant::now();
        for _ in 0..1000 {
            r.take((1, Split::Dev), t0).unwrap();
        }
    }

    #[test]
    fn refusals_are_counted_by_kind_and_split() {
        let r = Refusals::default();
        r.count(Refusal::RateLimited, Split::Dev);
        r.count(Refusal::RateLimited, Split::Dev);
        r.count(Refusal::DailyQuota, Split::Test);
        assert_eq!(
            r.snapshot(),
            RefusalCounts {
                rate_limited: PerSplit { dev: 2, test: 0 },
                daily_quota: PerSplit { dev: 0, test: 1 },
            }
        );
    }
}
