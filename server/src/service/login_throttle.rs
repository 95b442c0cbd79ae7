//! The throttle on failed logins to the pages (`[sessions] failures_per_minute_per_address`):
//! a token bucket per client address, counting failures only. A login is refused before its
//! token is even looked at while its address's bucket is empty, so a guesser gains nothing by
//! sending more; a correct token costs nothing.
//!
//! Policy (docs/reference/pages.md): there is no bucket for all addresses together. Team tokens are
//! 256-bit, so an overall cap protects no token; it only let anyone with many addresses make every
//! valid login answer 429. One address's failures never delay another address's logins, with one
//! exception bounded by memory: past [`MAX_ADDRESSES`] remembered addresses, the least spent
//! buckets are forgotten (a forgotten bucket is a full one again).
//!
//! Who "the client address" is (the TCP peer or an address vouched for by trusted proxies) is
//! the HTTP adapter's to say; `None` is one shared bucket for clients whose address is unknown.
//!
//! In memory, like the upload rate limits (`super::limits`): one server process per contest.

use std::collections::HashMap;
use std::net::IpAddr;
use std::sync::{Mutex, PoisonError};
use std::time::{Duration, Instant};

/// Addresses remembered at most. Reaching it forgets the full buckets (the same as none) and,
/// while a flood from more addresses keeps most buckets spent, the least spent ones down to
/// half of it, so the work of forgetting is spread over the next `MAX_ADDRESSES / 2` failures.
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

/// `None` key: the client's address is unknown (no socket, or no address a trusted proxy
/// vouched for).
type Buckets = HashMap<Option<IpAddr>, Bucket>;

pub(super) struct LoginThrottle {
    per_address: u32,
    by_address: Mutex<Buckets>,
}

impl LoginThrottle {
    pub(super) fn new(per_address: u32) -> LoginThrottle {
        LoginThrottle {
            per_address,
            by_address: Mutex::new(HashMap::new()),
        }
    }

    /// `Err(wait)` while `client` has no failure left to spend.
    pub(super) fn check(&self, client: Option<IpAddr>, now: Instant) -> Result<(), Duration> {
        let buckets = self.by_address.lock().unwrap_or_else(PoisonError::into_inner);
        let wait = (buckets.get(&client).copied()).map_or(Duration::ZERO, |b| {
            b.refilled(self.per_address, now).wait(self.per_address)
        });
        match wait {
            Duration::ZERO => Ok(()),
            wait => Err(wait),
        }
    }

    /// Spend one of `client`'s failures.
    pub(super) fn failed(&self, client: Option<IpAddr>, now: Instant) {
        let per_address = self.per_address;
        let mut buckets = self.by_address.lock().unwrap_or_else(PoisonError::into_inner);
        if buckets.len() >= MAX_ADDRESSES && !buckets.contains_key(&client) {
            make_room(&mut buckets, per_address, now);
        }
        let full = Bucket {
            tokens: f64::from(per_address),
            at: now,
        };
        let b = buckets.entry(client).or_insert(full);
        *b = b.refilled(per_address, now);
        b.tokens = (b.tokens - 1.0).max(0.0);
    }

    #[cfg(test)]
    fn remembered(&self) -> usize {
        self.by_address.lock().unwrap().len()
    }
}

/// Forget the full buckets, then, if more than half of [`MAX_ADDRESSES`] are left, the ones
/// with the most tokens down to half: the addresses that failed least lately lose nothing they
/// would not soon have back, and a spent address keeps its wait unless thousands more spent
/// addresses crowd it out (whoever holds those has their failures anyway).
fn make_room(buckets: &mut Buckets, per_address: u32, now: Instant) {
    let cap = f64::from(per_address);
    buckets.retain(|_, b| b.refilled(per_address, now).tokens < cap);
    let keep = MAX_ADDRESSES / 2;
    if buckets.len() <= keep {
        return;
    }
    let mut by_tokens: Vec<(f64, Option<IpAddr>)> = (buckets.iter())
        .map(|(a, b)| (b.refilled(per_address, now).tokens, *a))
        .collect();
    by_tokens.sort_unstable_by(|x, y| y.0.total_cmp(&x.0));
    let forget = by_tokens.len() - keep;
    for (_, a) in &by_tokens[..forget] {
        buckets.remove(a);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v4(last: u32) -> Option<IpAddr> {
        Some(IpAddr::from(((10u32 << 24) | last).to_be_bytes()))
    }

    #[test]
    fn failures_are_throttled_per_address_only() {
        let t = LoginThrottle::new(3);
        let now = Instant::now();
        let (a, b) = (v4(1), v4(2));
        for _ in 0..3 {
            assert!(t.check(a, now).is_ok());
            t.failed(a, now);
        }
        // a spent its 3; it may fail again after a third of a minute (3 per minute).
        let wait = t.check(a, now).unwrap_err();
        assert!((19..=21).contains(&wait.as_secs()), "{wait:?}");
        // b is not affected by a, nor by spending its own.
        assert!(t.check(b, now).is_ok());
        t.failed(b, now);
        t.failed(b, now);
        assert!(t.check(b, now).is_ok());
        // The unknown address is a bucket of its own like any other.
        assert!(t.check(None, now).is_ok());
        // A minute later a's bucket has refilled.
        assert!(t.check(a, now + Duration::from_secs(60)).is_ok());
    }

    #[test]
    fn a_flood_from_many_addresses_throttles_none_but_each_flooder() {
        let t = LoginThrottle::new(10);
        let now = Instant::now();
        // 200 addresses fail 10 times each in the same instant: 2,000 failures, 16 times the
        // overall cap this throttle used to have.
        for i in 0..200 {
            for _ in 0..10 {
                t.failed(v4(i), now);
            }
        }
        for i in 0..200 {
            assert!(t.check(v4(i), now).is_err(), "flooder {i}");
        }
        assert!(t.check(v4(999), now).is_ok());
        assert!(t.check(None, now).is_ok());
    }

    #[test]
    fn memory_stays_bounded_and_spent_addresses_are_forgotten_last() {
        let t = LoginThrottle::new(10);
        let now = Instant::now();
        let spent = v4(0xff_ff_ff);
        for _ in 0..10 {
            t.failed(spent, now);
        }
        // A flood from 5 * MAX_ADDRESSES fresh addresses, one failure each.
        for i in 0..(5 * MAX_ADDRESSES as u32) {
            t.failed(v4(i), now);
            assert!(t.remembered() <= MAX_ADDRESSES, "{i}");
        }
        assert!(t.check(spent, now).is_err(), "the spent address was forgotten");
    }
}
