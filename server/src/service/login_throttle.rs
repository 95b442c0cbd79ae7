//! The throttle on failed logins to the pages (`[sessions] failures_per_minute*`): a token
//! bucket per client address and one for all addresses together, both counting failures only.
//! A login is refused before its token is even looked at while either bucket is empty, so a
//! guesser gains nothing by sending more; a correct token costs nothing.
//!
//! In memory, like the upload rate limits (`super::limits`): one server process per contest.

use std::collections::HashMap;
use std::net::IpAddr;
use std::sync::{Mutex, PoisonError};
use std::time::{Duration, Instant};

/// Addresses remembered before full buckets are forgotten (a full bucket is the same as none).
const MAX_ADDRESSES: usize = 10_000;

#[derive(Debug, Clone, Copy)]
struct Bucket {
    tokens: f64,
    at: Instant,
}

impl Bucket {
    /// Refill at `per_minute / 60` per second up to `per_minute`, as of `now`.
    fn refilled(self, per_minute: u32, now: Instant) -> Bucket {
        let cap = f64::from(per_minute);
        let elapsed = now.saturating_duration_since(self.at).as_secs_f64();
        Bucket {
            tokens: (self.tokens + elapsed * cap / 60.0).min(cap),
            at: now,
        }
    }

    /// How long until one token is there (zero when one is).
    fn wait(self, per_minute: u32) -> Duration {
        if self.tokens >= 1.0 {
            return Duration::ZERO;
        }
        Duration::from_secs_f64((1.0 - self.tokens) * 60.0 / f64::from(per_minute))
    }
}

struct State {
    all: Bucket,
    /// `None` key: the client's address is unknown (requests not served over a socket).
    by_address: HashMap<Option<IpAddr>, Bucket>,
}

pub(super) struct LoginThrottle {
    per_address: u32,
    all: u32,
    state: Mutex<State>,
}

impl LoginThrottle {
    pub(super) fn new(per_address: u32, all: u32) -> LoginThrottle {
        LoginThrottle {
            per_address,
            all,
            state: Mutex::new(State {
                all: Bucket {
                    tokens: f64::from(all),
                    at: Instant::now(),
                },
                by_address: HashMap::new(),
            }),
        }
    }

    /// `Err(wait)` while `client` (or everyone) has no failure left to spend.
    pub(super) fn check(&self, client: Option<IpAddr>, now: Instant) -> Result<(), Duration> {
        let mut s = self.state.lock().unwrap_or_else(PoisonError::into_inner);
        s.all = s.all.refilled(self.all, now);
        let mine = (s.by_address.get(&client).copied()).map_or(Duration::ZERO, |b| {
            b.refilled(self.per_address, now).wait(self.per_address)
        });
        match mine.max(s.all.wait(self.all)) {
            Duration::ZERO => Ok(()),
            wait => Err(wait),
        }
    }

    /// Spend one failure of `client`'s and of everyone's.
    pub(super) fn failed(&self, client: Option<IpAddr>, now: Instant) {
        let (per_address, all) = (self.per_address, self.all);
        let mut s = self.state.lock().unwrap_or_else(PoisonError::into_inner);
        s.all = s.all.refilled(all, now);
        s.all.tokens = (s.all.tokens - 1.0).max(0.0);
        if s.by_address.len() >= MAX_ADDRESSES {
            let cap = f64::from(per_address);
            s.by_address
                .retain(|_, b| b.refilled(per_address, now).tokens < cap);
        }
        let full = Bucket {
            tokens: f64::from(per_address),
            at: now,
        };
        let b = s.by_address.entry(client).or_insert(full);
        *b = b.refilled(per_address, now);
        b.tokens = (b.tokens - 1.0).max(0.0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn failures_are_throttled_per_address_and_in_all() {
        let t = LoginThrottle::new(3, 5);
        let now = Instant::now();
        let a = Some(IpAddr::from([10, 0, 0, 1]));
        let b = Some(IpAddr::from([10, 0, 0, 2]));
        for _ in 0..3 {
            assert!(t.check(a, now).is_ok());
            t.failed(a, now);
        }
        // a spent its 3; it may fail again after a third of a minute (3 per minute).
        let wait = t.check(a, now).unwrap_err();
        assert!((19..=21).contains(&wait.as_secs()), "{wait:?}");
        assert!(t.check(b, now).is_ok());
        t.failed(b, now);
        t.failed(b, now);
        // 5 failures in all: everyone waits, a fresh address too.
        assert!(t.check(Some(IpAddr::from([10, 0, 0, 3])), now).is_err());
        // A minute later both buckets have refilled.
        assert!(t.check(a, now + Duration::from_secs(60)).is_ok());
    }
}
