//! What `GET /metrics` reads when scraped (see [`crate::metrics`] for what is recorded as it
//! happens): the jobs by state and the oldest queued job's age from the database, the workers
//! seen lately, the upload refusals, and the recorder's series.
//!
//! Bounded by design, since the route needs no token: the database gauges are one statement on
//! the read pool, run at most once a second however often the route is called (concurrent
//! scrapes wait for that one and share it), and every label value comes from a fixed set.

use std::collections::HashMap;
use std::sync::{Mutex, PoisonError};
use std::time::{Duration, Instant};

use super::{AppState, now_ms};
use crate::error::ServiceError;
use crate::metrics::{self as m, family};
use crate::store::queue::{self, QueueGauges};

/// The states `kitchen_r_jobs` always lists (0 when none).
const JOB_STATES: [&str; 5] = ["queued", "leased", "done", "failed", "cancelled"];
/// Database gauges are reused for this long.
const GAUGE_TTL: Duration = Duration::from_secs(1);
/// Workers remembered at most; past it the ones not seen lately are forgotten first.
const MAX_WORKERS: usize = 4096;

/// Scrape-time state of one server.
pub(super) struct Telemetry {
    /// Worker id → when it last leased or heartbeat.
    workers: Mutex<HashMap<String, Instant>>,
    gauges: tokio::sync::Mutex<Option<(Instant, QueueGauges)>>,
}

impl Telemetry {
    pub(super) fn new() -> Telemetry {
        Telemetry {
            workers: Mutex::new(HashMap::new()),
            gauges: tokio::sync::Mutex::new(None),
        }
    }
}

impl AppState {
    /// A worker leased or heartbeat now.
    pub(super) fn worker_seen(&self, worker: &str) {
        let now = Instant::now();
        let window = self.worker_window();
        let mut seen = self.seen_workers();
        if let Some(t) = seen.get_mut(worker) {
            *t = now;
            return;
        }
        if seen.len() >= MAX_WORKERS {
            seen.retain(|_, t| now.duration_since(*t) < window);
        }
        if seen.len() < MAX_WORKERS {
            seen.insert(worker.to_string(), now);
        }
    }

    /// The workers seen, by id (a panic elsewhere never poisons a count).
    fn seen_workers(&self) -> std::sync::MutexGuard<'_, HashMap<String, Instant>> {
        (self.inner.telemetry.workers.lock()).unwrap_or_else(PoisonError::into_inner)
    }

    /// How recently a worker must have leased or heartbeat to count as connected: a lease
    /// period, and at least a long-polling Lease call's longest wait.
    fn worker_window(&self) -> Duration {
        let lease = Duration::from_secs(self.config().control.lease_s);
        lease.max(Duration::from_millis(u64::from(super::lease::MAX_LEASE_WAIT_MS)) + Duration::from_secs(5))
    }

    fn workers_connected(&self) -> usize {
        let now = Instant::now();
        let window = self.worker_window();
        let mut seen = self.seen_workers();
        seen.retain(|_, t| now.duration_since(*t) < window);
        seen.len()
    }

    /// The queue gauges, from the database at most once per [`GAUGE_TTL`].
    async fn queue_gauges(&self) -> Result<QueueGauges, ServiceError> {
        let mut cached = self.inner.telemetry.gauges.lock().await;
        if let Some((at, g)) = cached.as_ref()
            && at.elapsed() < GAUGE_TTL
        {
            return Ok(g.clone());
        }
        let g = queue::gauges(self.read_pool()).await?;
        *cached = Some((Instant::now(), g.clone()));
        Ok(g)
    }

    /// Record how long the jobs just leased for the first time waited in the queue (one read
    /// of their creation times; skipped without a recorder). A requeued job's second wait is
    /// not recorded: its creation time would count the attempts before.
    pub(super) async fn record_queue_waits(&self, claimed: &[queue::Claimed], now: i64) {
        let first: Vec<i64> = claimed.iter().filter(|c| c.attempt == 1).map(|c| c.id).collect();
        if first.is_empty() || !m::installed() {
            return;
        }
        match queue::created_at(self.read_pool(), &first).await {
            Ok(times) => times.into_iter().for_each(|t| record::queue_wait(now - t)),
            Err(e) => tracing::debug!(error = %e, "queue wait not recorded"),
        }
    }

    /// `GET /metrics`: the Prometheus text format.
    pub(crate) async fn metrics_text(&self) -> Result<String, ServiceError> {
        let g = self.queue_gauges().await?;
        let mut out = m::render_process();
        let jobs: Vec<(String, f64)> = JOB_STATES
            .iter()
            .map(|s| {
                let n = g.by_state.iter().find(|(k, _)| k == s).map_or(0, |(_, n)| *n);
                (format!("state=\"{s}\""), n as f64)
            })
            .collect();
        family(
            &mut out,
            "kitchen_r_jobs",
            "gauge",
            "Episode jobs by state, from the database when scraped",
            &jobs,
        );
        let oldest = g
            .oldest_queued_at
            .map_or(0.0, |t| (now_ms().saturating_sub(t)).max(0) as f64 / 1000.0);
        family(
            &mut out,
            "kitchen_r_queue_oldest_queued_seconds",
            "gauge",
            "How long the longest-waiting queued job has waited since it was queued or requeued (0 when none)",
            &[(String::new(), oldest)],
        );
        family(
            &mut out,
            "kitchen_r_workers_connected",
            "gauge",
            "Distinct worker ids that leased or heartbeat within the last lease period (this process)",
            &[(String::new(), self.workers_connected() as f64)],
        );
        let r = self.refusals();
        let refusals = [
            ("rate_limited", "dev", r.rate_limited.dev),
            ("rate_limited", "test", r.rate_limited.test),
            ("daily_quota", "dev", r.daily_quota.dev),
            ("daily_quota", "test", r.daily_quota.test),
        ]
        .map(|(kind, split, n)| (format!("kind=\"{kind}\",split=\"{split}\""), n as f64));
        family(
            &mut out,
            "kitchen_r_upload_refusals_total",
            "counter",
            "Uploads refused since this process started, by kind and split",
            &refusals,
        );
        Ok(out)
    }
}

/// Recording helpers for the queue paths ([`super::jobs`]); every call is cheap and does nothing
/// without a recorder.
pub(super) mod record {
    use crate::metrics as m;

    /// Jobs leased for the first time after waiting `waited_ms` in the queue.
    pub(crate) fn queue_wait(waited_ms: i64) {
        metrics::histogram!(m::QUEUE_WAIT).record(waited_ms.max(0) as f64 / 1000.0);
    }

    /// An accepted result: the episode's reported wall time.
    pub(crate) fn episode_done(mode: &'static str, wall_ms: u64) {
        metrics::histogram!(m::EPISODE_DURATION, "mode" => mode).record(wall_ms as f64 / 1000.0);
        metrics::counter!(m::JOBS_FINISHED, "outcome" => "done").increment(1);
    }

    /// A failed attempt: requeued for another (`failed == false`) or out of attempts.
    pub(crate) fn attempt_failed(reason: &'static str, failed: bool) {
        if failed {
            metrics::counter!(m::JOBS_FINISHED, "outcome" => "failed").increment(1);
        } else {
            metrics::counter!(m::JOB_RETRIES, "reason" => reason).increment(1);
        }
    }

    /// Leases the reaper took back: `requeued` for another attempt, `failed` out of attempts.
    pub(crate) fn reaped(requeued: usize, failed: usize) {
        metrics::counter!(m::LEASES_RECLAIMED).increment((requeued + failed) as u64);
        metrics::counter!(m::JOB_RETRIES, "reason" => "lease_expired").increment(requeued as u64);
        metrics::counter!(m::JOBS_FINISHED, "outcome" => "failed").increment(failed as u64);
    }
}

#[cfg(test)]
mod tests {
    use crate::testutil::{FakeProbe, fixture};

    #[tokio::test]
    async fn an_empty_queue_renders_every_state_at_zero_and_workers_seen_are_counted() {
        let f = fixture(FakeProbe::ok(1), |_| {}).await;
        f.state.worker_seen("host-1");
        f.state.worker_seen("host-1");
        f.state.worker_seen("host-2");
        let text = f.state.metrics_text().await.unwrap();
        for s in super::JOB_STATES {
            assert!(
                text.contains(&format!("kitchen_r_jobs{{state=\"{s}\"}} 0\n")),
                "{text}"
            );
        }
        assert!(
            text.contains("kitchen_r_queue_oldest_queued_seconds 0\n"),
            "{text}"
        );
        assert!(text.contains("kitchen_r_workers_connected 2\n"), "{text}");
        assert!(
            text.contains("kitchen_r_upload_refusals_total{kind=\"daily_quota\",split=\"test\"} 0\n"),
            "{text}"
        );
        assert!(!text.contains("host-1"), "no worker ids as labels: {text}");
    }

    async fn get_metrics(app: axum::Router) -> (axum::http::StatusCode, String) {
        use tower::ServiceExt;
        let req = axum::http::Request::get("/metrics")
            .body(axum::body::Body::empty())
            .unwrap();
        let resp = app.oneshot(req).await.unwrap();
        let status = resp.status();
        let body = axum::body::to_bytes(resp.into_body(), 1 << 20).await.unwrap();
        (status, String::from_utf8(body.to_vec()).unwrap())
    }

    #[tokio::test]
    async fn the_route_needs_no_token_counts_itself_and_can_be_turned_off() {
        crate::metrics::install();
        let f = fixture(FakeProbe::ok(1), |_| {}).await;
        let app = crate::http::router(f.state.clone());
        let (status, _) = get_metrics(app.clone()).await;
        assert_eq!(status, 200);
        let (_, text) = get_metrics(app).await;
        assert!(
            text.contains(r#"kitchen_r_http_requests_total{method="GET",route="/metrics",status="200"}"#),
            "{text}"
        );
        assert!(text.contains("# TYPE kitchen_r_jobs gauge"), "{text}");
        let off = fixture(FakeProbe::ok(1), |c| c.metrics = false).await;
        let (status, _) = get_metrics(crate::http::router(off.state.clone())).await;
        assert_eq!(status, 404);
    }
}
