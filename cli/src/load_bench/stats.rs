//! Latency samples and failure counts of one side of the load (reads or uploads).
//!
//! Every sample is kept (a minute at a few thousand requests per second is a few hundred
//! thousand `u64`s) and sorted once at the end, so percentiles are exact, not bucketed.
//! Latencies are those of successful (2xx) answers; every other outcome is counted by what it
//! was (`"503"`, `"timeout"`, `"connect"`, ...) and never mixed into the latencies, so a fast
//! refusal cannot flatter the percentiles.

use std::collections::BTreeMap;
use std::time::Duration;

use serde::Serialize;

/// How a request that did not succeed ended.
pub(super) fn classify(e: &reqwest::Error) -> String {
    if e.is_timeout() {
        "timeout".into()
    } else if e.is_connect() {
        "connect".into()
    } else if e.is_body() || e.is_decode() {
        "body".into()
    } else {
        "transport".into()
    }
}

/// Samples of one side, merged from its tasks.
#[derive(Debug, Default)]
pub(super) struct Recorder {
    latencies_us: Vec<u64>,
    failures: BTreeMap<String, u64>,
}

impl Recorder {
    pub(super) fn ok(&mut self, latency: Duration) {
        self.latencies_us
            .push(u64::try_from(latency.as_micros()).unwrap_or(u64::MAX));
    }

    pub(super) fn fail(&mut self, what: impl Into<String>) {
        *self.failures.entry(what.into()).or_default() += 1;
    }

    /// Count `n` failures of one kind at once.
    pub(super) fn fail_n(&mut self, what: impl Into<String>, n: u64) {
        if n > 0 {
            *self.failures.entry(what.into()).or_default() += n;
        }
    }

    pub(super) fn merge(&mut self, other: Recorder) {
        self.latencies_us.extend(other.latencies_us);
        for (k, n) in other.failures {
            *self.failures.entry(k).or_default() += n;
        }
    }

    /// The side's figures; throughput is successful requests per second of `elapsed`.
    pub(super) fn summary(mut self, elapsed: Duration) -> Side {
        self.latencies_us.sort_unstable();
        let ok = self.latencies_us.len() as u64;
        let failed: u64 = self.failures.values().sum();
        let secs = elapsed.as_secs_f64();
        Side {
            requests: ok + failed,
            ok,
            failed,
            failures: self.failures,
            throughput_per_s: if secs > 0.0 { ok as f64 / secs } else { 0.0 },
            latency_ms: Latency::of_sorted(&self.latencies_us),
        }
    }
}

/// One side's figures as the report shows them.
#[derive(Debug, Clone, Serialize)]
pub(super) struct Side {
    /// Requests that ended (successful or not) plus those counted as failures without being
    /// sent (uploads the in-flight bound held back past the end of the measurement).
    pub requests: u64,
    pub ok: u64,
    pub failed: u64,
    /// Failures by status code or transport outcome.
    pub failures: BTreeMap<String, u64>,
    pub throughput_per_s: f64,
    /// Latency of successful requests; `None` when there were none.
    pub latency_ms: Option<Latency>,
}

#[derive(Debug, Clone, Copy, Serialize)]
pub(super) struct Latency {
    pub p50: f64,
    pub p90: f64,
    pub p99: f64,
    pub max: f64,
    pub mean: f64,
}

impl Latency {
    fn of_sorted(us: &[u64]) -> Option<Latency> {
        let (&max, n) = (us.last()?, us.len());
        let ms = |v: u64| v as f64 / 1000.0;
        let sum: u128 = us.iter().map(|&v| u128::from(v)).sum();
        Some(Latency {
            p50: ms(percentile(us, 0.50)),
            p90: ms(percentile(us, 0.90)),
            p99: ms(percentile(us, 0.99)),
            max: ms(max),
            mean: sum as f64 / n as f64 / 1000.0,
        })
    }
}

/// Nearest-rank percentile of sorted, non-empty samples.
fn percentile(sorted: &[u64], p: f64) -> u64 {
    let rank = (p * sorted.len() as f64).ceil() as usize;
    sorted[rank.clamp(1, sorted.len()) - 1]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_rank_percentiles() {
        let v: Vec<u64> = (1..=100).collect();
        assert_eq!(percentile(&v, 0.50), 50);
        assert_eq!(percentile(&v, 0.99), 99);
        assert_eq!(percentile(&[7], 0.99), 7);
        assert_eq!(percentile(&[1, 2], 0.0), 1);
    }

    #[test]
    fn failures_are_counted_apart_from_latencies() {
        let mut a = Recorder::default();
        a.ok(Duration::from_millis(2));
        a.fail("503");
        let mut b = Recorder::default();
        b.ok(Duration::from_millis(4));
        b.fail("503");
        b.fail_n("not sent", 3);
        a.merge(b);
        let s = a.summary(Duration::from_secs(2));
        assert_eq!((s.requests, s.ok, s.failed), (7, 2, 5));
        assert_eq!(s.failures["503"], 2);
        assert_eq!(s.throughput_per_s, 1.0);
        let l = s.latency_ms.unwrap();
        assert_eq!((l.p50, l.max, l.mean), (2.0, 4.0, 3.0));
        assert!(Recorder::default().summary(Duration::ZERO).latency_ms.is_none());
    }
}
