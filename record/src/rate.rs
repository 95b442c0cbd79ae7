//! The Monitoring Module's recording-rate check: a topic whose rate, over a sliding window of
//! sim time, falls below its configured minimum marks the episode failed.

use std::collections::{BTreeMap, VecDeque};

/// A topic that fell below its minimum rate.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error(
    "topic {topic} recorded at {observed_hz:.2} Hz over the last {window_s} s, below the minimum {min_hz} Hz"
)]
pub struct RateViolation {
    pub topic: String,
    pub observed_hz: f64,
    pub min_hz: f64,
    pub window_s: f64,
}

#[derive(Debug, Clone)]
pub struct RateMonitor {
    min_hz: BTreeMap<String, f64>,
    window_s: f64,
    seen: BTreeMap<String, VecDeque<f64>>,
}

impl RateMonitor {
    /// `min_hz`: topic → minimum rate; topics not listed are not checked.
    pub fn new(min_hz: BTreeMap<String, f64>, window_s: f64) -> Self {
        RateMonitor {
            min_hz,
            window_s,
            seen: BTreeMap::new(),
        }
    }

    pub(crate) fn record(&mut self, topic: &str, t: f64) {
        if self.min_hz.contains_key(topic) {
            self.seen.entry(topic.to_string()).or_default().push_back(t);
        }
    }

    /// Check every monitored topic at sim time `now`; only once a full window has elapsed.
    pub fn check(&mut self, now: f64) -> Result<(), RateViolation> {
        if now + 1e-9 < self.window_s {
            return Ok(());
        }
        for (topic, min_hz) in &self.min_hz {
            let q = self.seen.entry(topic.clone()).or_default();
            while q.front().is_some_and(|t| *t <= now - self.window_s + 1e-9) {
                q.pop_front();
            }
            let observed_hz = q.len() as f64 / self.window_s;
            if observed_hz + 1e-9 < *min_hz {
                return Err(RateViolation {
                    topic: topic.clone(),
                    observed_hz,
                    min_hz: *min_hz,
                    window_s: self.window_s,
                });
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn monitor() -> RateMonitor {
        RateMonitor::new([("/odom".to_string(), 8.0)].into(), 1.0)
    }

    #[test]
    fn steady_ten_hertz_passes() {
        let mut m = monitor();
        for i in 0..50 {
            let t = i as f64 * 0.1;
            m.record("/odom", t);
            m.check(t).unwrap();
        }
    }

    #[test]
    fn a_gap_in_recording_is_reported() {
        let mut m = monitor();
        for i in 0..20 {
            m.record("/odom", i as f64 * 0.1);
        }
        // Nothing recorded between 1.9 s and 2.6 s.
        let err = m.check(2.6).unwrap_err();
        assert_eq!(err.topic, "/odom");
        assert!(err.observed_hz < 8.0);
    }

    #[test]
    fn unmonitored_topics_are_ignored() {
        let mut m = monitor();
        for i in 0..30 {
            m.record("/odom", i as f64 * 0.1);
        }
        m.record("/other", 0.0);
        m.check(2.9).unwrap();
    }
}
