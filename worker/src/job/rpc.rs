//! The worker's side of the `kitchen_r.worker.v1.Worker` service: the authenticated client, and
//! the two rules every call site shares (which failures to retry, when to heartbeat).

use std::time::{Duration, SystemTime, UNIX_EPOCH};

use kitchen_r_proto::worker::v1 as pb;
use pb::worker_client::WorkerClient;
use tonic::metadata::{Ascii, MetadataValue};
use tonic::service::Interceptor;
use tonic::service::interceptor::InterceptedService;
use tonic::transport::{Channel, ClientTlsConfig, Endpoint};
use tonic::{Code, Request, Status};

use super::{WorkerConfig, WorkerError};

/// Adds `authorization: Bearer <worker token>` to every call.
#[derive(Debug, Clone)]
pub(crate) struct Auth(MetadataValue<Ascii>);

impl Interceptor for Auth {
    fn call(&mut self, mut req: Request<()>) -> Result<Request<()>, Status> {
        req.metadata_mut().insert("authorization", self.0.clone());
        Ok(req)
    }
}

pub(crate) type Client = WorkerClient<InterceptedService<Channel, Auth>>;
/// A (lazy) channel to `cfg.server` with the worker's token: nothing is sent yet, so a server
/// that is not up is not an error here.
pub(crate) fn connect(cfg: &WorkerConfig) -> Result<Client, WorkerError> {
    let bad = |e: String| WorkerError::Config(format!("`server` {:?}: {e}", cfg.server));
    let mut ep = Endpoint::from_shared(cfg.server.clone())
        .map_err(|e| bad(e.to_string()))?
        .connect_timeout(Duration::from_secs(5))
        .tcp_nodelay(true);
    if cfg.server.starts_with("https://") {
        ep = ep
            .tls_config(ClientTlsConfig::new().with_webpki_roots())
            .map_err(|e| bad(e.to_string()))?;
    }
    let token = format!("Bearer {}", cfg.token)
        .parse()
        .map_err(|_| WorkerError::Config("`token` must be printable ASCII".into()))?;
    // Results carry at most a 64 KiB log; jobs are small too.
    Ok(WorkerClient::with_interceptor(ep.connect_lazy(), Auth(token)))
}

/// A third of the time left on the lease, within [0.5 s, 60 s].
pub(super) fn heartbeat_in(expires_at_ms: i64) -> Duration {
    let now = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as i64);
    let left = expires_at_ms.saturating_sub(now);
    if left <= 0 {
        return Duration::from_secs(1);
    }
    Duration::from_millis((left / 3) as u64).clamp(Duration::from_millis(500), Duration::from_secs(60))
}

/// Transport trouble and server hiccups are retried; a refusal (stale attempt, bad request) is
/// final.
pub(crate) fn retryable(s: &Status) -> bool {
    matches!(
        s.code(),
        Code::Unavailable
            | Code::Unknown
            | Code::DeadlineExceeded
            | Code::Cancelled
            | Code::ResourceExhausted
            | Code::Aborted
            | Code::Internal
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn heartbeats_come_at_a_third_of_the_lease() {
        let now = SystemTime::now().duration_since(UNIX_EPOCH).unwrap().as_millis() as i64;
        let d = heartbeat_in(now + 30_000);
        assert!(
            d > Duration::from_millis(9_000) && d <= Duration::from_millis(10_000),
            "{d:?}"
        );
        assert_eq!(heartbeat_in(now - 5), Duration::from_secs(1));
        assert_eq!(heartbeat_in(now + 600), Duration::from_millis(500));
    }
}
