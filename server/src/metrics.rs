//! Prometheus metrics: the process-wide recorder (`metrics` facade, `metrics-exporter-prometheus`
//! rendering on demand, no listener of its own) and the names every part records under.
//!
//! Two kinds of series end up in `GET /metrics`:
//! - recorded as things happen, through the `metrics` macros into the recorder installed by
//!   [`install`]: HTTP and gRPC requests, queue waits, episode durations, finished jobs, leases
//!   reclaimed, and whatever the in-process simulation workers record (`kitchen_r_worker_*`,
//!   policy call latency among them);
//! - read when scraped and written here as text (`crate::service` owns them): the jobs by
//!   state and the oldest queued job's age from the database, connected workers, upload
//!   refusals, build info. Those are exact for the serving process whatever else records.
//!
//! No label ever carries a submission, run, team or worker id: label values come from small
//! fixed sets (methods, matched routes, gRPC methods of our services, statuses, outcomes), so
//! no caller can grow the number of series.
//!
//! The recorder is process-wide (one per process, like the `metrics` facade itself); the
//! standalone worker installs it too and serves [`render_process`] through [`serve`].

use std::fmt::Write as _;
use std::future::Future;
use std::sync::OnceLock;
use std::time::Duration;

use axum::http::{HeaderMap, Method};
use metrics_exporter_prometheus::{Matcher, PrometheusBuilder, PrometheusHandle};

pub(crate) const HTTP_REQUESTS: &str = "kitchen_r_http_requests_total";
pub(crate) const HTTP_DURATION: &str = "kitchen_r_http_request_duration_seconds";
pub(crate) const GRPC_REQUESTS: &str = "kitchen_r_grpc_requests_total";
pub(crate) const GRPC_DURATION: &str = "kitchen_r_grpc_request_duration_seconds";
pub(crate) const QUEUE_WAIT: &str = "kitchen_r_queue_wait_seconds";
pub(crate) const EPISODE_DURATION: &str = "kitchen_r_episode_duration_seconds";
pub(crate) const JOBS_FINISHED: &str = "kitchen_r_jobs_finished_total";
pub(crate) const JOB_RETRIES: &str = "kitchen_r_job_retries_total";
pub(crate) const LEASES_RECLAIMED: &str = "kitchen_r_leases_reclaimed_total";
pub(crate) const VIDEO_EVICTIONS: &str = "kitchen_r_video_evictions_total";
pub(crate) const VIDEO_STORED_BYTES: &str = "kitchen_r_video_stored_bytes";
pub(crate) const VIDEO_REFUSED: &str = "kitchen_r_video_uploads_refused_total";
pub(crate) const VIDEO_RENDERS: &str = "kitchen_r_video_renders_total";
/// The `outcome` label values of [`VIDEO_RENDERS`].
pub(crate) const RENDER_OUTCOMES: [&str; 6] = ["queued", "reused", "done", "failed", "requeued", "waiting"];

/// The Prometheus text format's content type.
pub(crate) const CONTENT_TYPE: &str = "text/plain; version=0.0.4; charset=utf-8";

/// Request latencies, seconds.
const REQUEST_BUCKETS: [f64; 14] = [
    0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0,
];
/// Time in the queue, seconds (up to six hours).
const QUEUE_BUCKETS: [f64; 12] = [
    1.0, 5.0, 15.0, 30.0, 60.0, 120.0, 300.0, 600.0, 1800.0, 3600.0, 7200.0, 21600.0,
];
/// One episode, seconds (up to the paper's 50 minutes and beyond).
const EPISODE_BUCKETS: [f64; 12] = [
    1.0, 5.0, 10.0, 30.0, 60.0, 120.0, 300.0, 600.0, 1200.0, 1800.0, 3600.0, 7200.0,
];
/// How often histogram samples are folded into their buckets when nobody scrapes.
const UPKEEP_EVERY: Duration = Duration::from_secs(5);

static HANDLE: OnceLock<Option<PrometheusHandle>> = OnceLock::new();

/// Install the process-wide recorder (once; later calls do nothing). Returns `false` when
/// another recorder was installed first, in which case only the series read at scrape time
/// are served.
pub fn install() -> bool {
    HANDLE.get_or_init(build).is_some()
}

/// Whether this process records (the recorder is installed).
pub(crate) fn installed() -> bool {
    HANDLE.get().is_some_and(Option::is_some)
}

fn build() -> Option<PrometheusHandle> {
    let full = |name: &str| Matcher::Full(name.to_string());
    // Worker series (`kitchen_r_worker_*`) are named in the worker crate; its duration
    // histograms end in `_seconds` and take the episode or request buckets below.
    let builder = PrometheusBuilder::new()
        .set_buckets(&REQUEST_BUCKETS)
        .and_then(|b| b.set_buckets_for_metric(full(QUEUE_WAIT), &QUEUE_BUCKETS))
        .and_then(|b| b.set_buckets_for_metric(full(EPISODE_DURATION), &EPISODE_BUCKETS))
        .and_then(|b| {
            b.set_buckets_for_metric(
                full("kitchen_r_worker_episode_duration_seconds"),
                &EPISODE_BUCKETS,
            )
        });
    let builder = match builder {
        Ok(b) => b,
        Err(e) => {
            tracing::error!("metrics: {e}");
            return None;
        }
    };
    let handle = match builder.install_recorder() {
        Ok(h) => h,
        Err(e) => {
            tracing::warn!(
                "metrics: another recorder is installed ({e}); only scrape-time series are served"
            );
            return None;
        }
    };
    let upkeep = handle.clone();
    let spawned = std::thread::Builder::new()
        .name("metrics-upkeep".into())
        .spawn(move || {
            loop {
                std::thread::sleep(UPKEEP_EVERY);
                upkeep.run_upkeep();
            }
        });
    if let Err(e) = spawned {
        tracing::warn!("metrics: no upkeep thread ({e}); histograms are folded at scrape time only");
    }
    describe();
    Some(handle)
}

/// Help texts, and the counters a dashboard expects to see at 0 before anything happened.
fn describe() {
    use metrics::{describe_counter, describe_histogram};
    describe_counter!(
        HTTP_REQUESTS,
        "HTTP requests answered, by method, matched route and status"
    );
    describe_histogram!(
        HTTP_DURATION,
        metrics::Unit::Seconds,
        "HTTP request latency up to the response headers, by method, matched route and status"
    );
    describe_counter!(
        GRPC_REQUESTS,
        "gRPC calls answered, by method path and grpc-status (code)"
    );
    describe_histogram!(
        GRPC_DURATION,
        metrics::Unit::Seconds,
        "gRPC call latency up to the response headers (whole call for unary methods)"
    );
    describe_histogram!(
        QUEUE_WAIT,
        metrics::Unit::Seconds,
        "Time from an episode job being queued to its first lease"
    );
    describe_histogram!(
        EPISODE_DURATION,
        metrics::Unit::Seconds,
        "Wall time of an episode as reported by its worker (accepted results), by mode"
    );
    describe_counter!(
        JOBS_FINISHED,
        "Episode jobs finished, by outcome (done: result recorded; failed: out of attempts)"
    );
    describe_counter!(
        JOB_RETRIES,
        "Episode jobs requeued for another attempt, by reason (platform_error, lease_expired)"
    );
    describe_counter!(
        LEASES_RECLAIMED,
        "Expired leases taken back by the reaper (requeued or failed)"
    );
    describe_counter!(
        VIDEO_EVICTIONS,
        "Episode videos and traces removed to keep a storage budget, by budget (team: [video] team_max_bytes; total: total_max_bytes, from teams over their fair share)"
    );
    describe_counter!(
        VIDEO_REFUSED,
        "Video and trace uploads refused for want of room, by file (video, trace): nothing could be evicted (uploads in flight, every team within its fair share, protected traces)"
    );
    describe_counter!(
        VIDEO_RENDERS,
        "Episode videos rendered on demand from traces, by outcome (queued: asked for; reused: another episode's render of the same trace; done: rendered and stored; failed: refused, e.g. the replay disagreed with the stored result; requeued: a lost render lease queued again; waiting: its video found no room in the storage budgets, queued again later)"
    );
    metrics::describe_gauge!(
        VIDEO_STORED_BYTES,
        metrics::Unit::Bytes,
        "Bytes of episode videos and traces stored, as the budgets count them (per linked episode), after the last upload or sweep"
    );
    for outcome in ["done", "failed"] {
        metrics::counter!(JOBS_FINISHED, "outcome" => outcome).increment(0);
    }
    for budget in ["team", "total"] {
        metrics::counter!(VIDEO_EVICTIONS, "budget" => budget).increment(0);
    }
    for file in ["video", "trace"] {
        metrics::counter!(VIDEO_REFUSED, "file" => file).increment(0);
    }
    metrics::counter!(LEASES_RECLAIMED).increment(0);
    for outcome in RENDER_OUTCOMES {
        metrics::counter!(VIDEO_RENDERS, "outcome" => outcome).increment(0);
    }
}

/// What the recorder holds (empty when none is installed), and the build info.
pub fn render_process() -> String {
    let mut out = HANDLE
        .get()
        .and_then(Option::as_ref)
        .map(PrometheusHandle::render)
        .unwrap_or_default();
    if !out.is_empty() && !out.ends_with('\n') {
        out.push('\n');
    }
    family(
        &mut out,
        "kitchen_r_build_info",
        "gauge",
        "The running build (always 1)",
        &[(format!("version=\"{}\"", env!("CARGO_PKG_VERSION")), 1.0)],
    );
    out
}

/// Append one metric family in the text format: `samples` are `(labels, value)` where labels
/// is the inside of the braces (empty for none). Label values must already be escaped; callers
/// only pass fixed strings.
pub(crate) fn family(out: &mut String, name: &str, kind: &str, help: &str, samples: &[(String, f64)]) {
    let _ = writeln!(out, "# HELP {name} {help}");
    let _ = writeln!(out, "# TYPE {name} {kind}");
    for (labels, value) in samples {
        if labels.is_empty() {
            let _ = writeln!(out, "{name} {value}");
        } else {
            let _ = writeln!(out, "{name}{{{labels}}} {value}");
        }
    }
}

/// Serve `GET /metrics` ([`render_process`]) on `listener` until `shutdown`: the standalone
/// worker's endpoint (`kitchen-r worker --metrics ADDR`). Anything else answers 404.
pub async fn serve(
    listener: tokio::net::TcpListener,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> std::io::Result<()> {
    use axum::routing::get;
    let app = axum::Router::new().route(
        "/metrics",
        get(|| async {
            (
                [(axum::http::header::CONTENT_TYPE, CONTENT_TYPE)],
                render_process(),
            )
        }),
    );
    axum::serve(listener, app).with_graceful_shutdown(shutdown).await
}

/// The `method` label: standard methods by name, anything else `other` (a client may send any
/// token as a method).
pub(crate) fn method_label(m: &Method) -> &'static str {
    const KNOWN: [(Method, &str); 9] = [
        (Method::GET, "GET"),
        (Method::POST, "POST"),
        (Method::PUT, "PUT"),
        (Method::DELETE, "DELETE"),
        (Method::HEAD, "HEAD"),
        (Method::OPTIONS, "OPTIONS"),
        (Method::PATCH, "PATCH"),
        (Method::CONNECT, "CONNECT"),
        (Method::TRACE, "TRACE"),
    ];
    KNOWN
        .iter()
        .find_map(|(k, name)| (k == m).then_some(*name))
        .unwrap_or("other")
}

/// One answered HTTP request; `route` is the matched route (`/api/v1/submissions/{id}`), never
/// the raw path.
pub(crate) fn record_http(method: &Method, route: &str, status: u16, elapsed: Duration) {
    let labels = [
        ("method", method_label(method).to_string()),
        ("route", route.to_string()),
        ("status", status.to_string()),
    ];
    metrics::counter!(HTTP_REQUESTS, &labels).increment(1);
    metrics::histogram!(HTTP_DURATION, &labels).record(elapsed.as_secs_f64());
}

/// One answered gRPC call at `path` (`/package.Service/Method`). The code is the
/// trailers-only answer's `grpc-status` header, else OK (a unary call that answered with a
/// message; a streaming call's final status is not waited for). A path nothing serves
/// (`Unimplemented`) is labelled `<unknown>`, so made-up paths add no series.
pub(crate) fn record_grpc(path: &str, headers: &HeaderMap, elapsed: Duration) {
    let code = headers
        .get("grpc-status")
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<i32>().ok())
        .map_or(tonic::Code::Ok, tonic::Code::from);
    let path = match code {
        tonic::Code::Unimplemented => "<unknown>".to_string(),
        _ => path.to_string(),
    };
    let labels = [("path", path), ("code", format!("{code:?}"))];
    metrics::counter!(GRPC_REQUESTS, &labels).increment(1);
    metrics::histogram!(GRPC_DURATION, &labels).record(elapsed.as_secs_f64());
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn odd_methods_share_one_label() {
        assert_eq!(method_label(&Method::GET), "GET");
        assert_eq!(method_label(&Method::from_bytes(b"BREW").unwrap()), "other");
    }

    #[test]
    fn recorded_requests_render_with_bounded_labels() {
        assert!(install());
        record_http(
            &Method::from_bytes(b"X-ANYTHING").unwrap(),
            "<unmatched>",
            404,
            Duration::from_millis(3),
        );
        let mut unimplemented = HeaderMap::new();
        unimplemented.insert("grpc-status", "12".parse().unwrap());
        record_grpc("/made.up/Path123", &unimplemented, Duration::from_millis(1));
        record_grpc(
            "/kitchen_r.worker.v1.Worker/Lease",
            &HeaderMap::new(),
            Duration::from_millis(1),
        );
        let text = render_process();
        assert!(
            text.contains(
                r#"kitchen_r_http_requests_total{method="other",route="<unmatched>",status="404"}"#
            ),
            "{text}"
        );
        assert!(
            text.contains(r#"kitchen_r_grpc_requests_total{path="<unknown>",code="Unimplemented"}"#),
            "{text}"
        );
        assert!(!text.contains("made.up"), "{text}");
        assert!(
            text.contains(r#"kitchen_r_grpc_request_duration_seconds_bucket{path="/kitchen_r.worker.v1.Worker/Lease",code="Ok",le="0.005"}"#),
            "histograms have buckets: {text}"
        );
        assert!(
            text.contains(r#"kitchen_r_jobs_finished_total{outcome="failed"} 0"#),
            "{text}"
        );
        assert!(text.contains("# TYPE kitchen_r_build_info gauge"), "{text}");
    }
}
