//! A render job's trace, fetched from the server in chunks (`FetchTrace`). A trace may be far
//! larger than one gRPC message (a failing policy that executes one action of each chunk leaves
//! up to about 14 MB gzipped), so the lease names it by size and sha256 and the worker streams
//! it. The bytes are checked against both before a replay starts: a trace that arrives short or
//! altered is never rendered. The call itself is the caller's (it holds the client): this file
//! only reads the stream, retries and decides what a failure means.

use std::future::Future;
use std::time::Duration;

use kitchen_r_proto::worker::v1 as pb;
use sha2::{Digest, Sha256};
use tonic::{Code, Status, Streaming};

/// Tries of a fetch that failed in transit before the render is left to its lease.
const TRIES: u32 = 3;

/// Why a trace was not fetched.
#[derive(Debug)]
pub(crate) enum FetchError {
    /// The render cannot succeed: the episode shows this reason (the trace is gone, or arrived
    /// other than announced).
    Fails(String),
    /// The lease is not held any more (cancelled, or leased to someone else): stop quietly.
    LeaseGone,
    /// The server could not be reached: the lease expires and the render is queued again.
    Transient(String),
}

/// The trace of the render job `render` (its `trace_gz` when an older server inlined it);
/// `call` opens one `FetchTrace` stream for the job's lease (the caller holds the client).
pub(crate) async fn trace<F, Fut>(render: Option<&pb::RenderJob>, call: F) -> Result<Vec<u8>, FetchError>
where
    F: Fn() -> Fut,
    Fut: Future<Output = Result<Streaming<pb::TraceChunk>, Status>>,
{
    let render = render.ok_or(FetchError::LeaseGone)?;
    if !render.trace_gz.is_empty() {
        return Ok(render.trace_gz.clone());
    }
    let mut last = String::new();
    for attempt in 1..=TRIES {
        match fetch_once(&call, render).await {
            Ok(bytes) => return Ok(bytes),
            Err(Err(s)) if s.code() == Code::NotFound => {
                return Err(FetchError::Fails(format!(
                    "the trace cannot be fetched: {}",
                    s.message()
                )));
            }
            Err(Err(s)) if matches!(s.code(), Code::AlreadyExists | Code::FailedPrecondition) => {
                return Err(FetchError::LeaseGone);
            }
            Err(Err(s)) => last = format!("{:?}: {}", s.code(), s.message()),
            Err(Ok(why)) => return Err(FetchError::Fails(why)),
        }
        tracing::warn!(attempt, "fetching the trace failed ({last}); retrying");
        tokio::time::sleep(Duration::from_millis(500 * u64::from(attempt))).await;
    }
    Err(FetchError::Transient(last))
}

/// One fetch: the bytes, a transport error (`Err(Err)`), or why the bytes are not the trace
/// the lease named (`Err(Ok)`).
async fn fetch_once<F, Fut>(call: &F, render: &pb::RenderJob) -> Result<Vec<u8>, Result<String, Status>>
where
    F: Fn() -> Fut,
    Fut: Future<Output = Result<Streaming<pb::TraceChunk>, Status>>,
{
    let mut stream = call().await.map_err(Err)?;
    let announced = render.trace_bytes;
    let mut bytes = Vec::with_capacity(usize::try_from(announced).unwrap_or(0).min(1 << 30));
    while let Some(chunk) = stream.message().await.map_err(Err)? {
        bytes.extend_from_slice(&chunk.data);
        if bytes.len() as u64 > announced {
            return Err(Ok(format!(
                "the trace arrived longer than the {announced} bytes its render job names"
            )));
        }
    }
    check(&bytes, announced, &render.trace_sha256).map_err(Ok)?;
    Ok(bytes)
}

/// The fetched bytes are the trace the lease named: its size and its sha256.
fn check(bytes: &[u8], announced: u64, sha256: &str) -> Result<(), String> {
    if bytes.len() as u64 != announced {
        return Err(format!(
            "the trace arrived short: {} of the {announced} bytes its render job names",
            bytes.len()
        ));
    }
    let got = hex::encode(Sha256::digest(bytes));
    if !sha256.is_empty() && got != sha256 {
        return Err(format!(
            "the trace arrived altered: sha256 {got}, the render job names {sha256}"
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_fetched_trace_must_match_its_size_and_sha256() {
        let sha = hex::encode(<sha2::Sha256 as sha2::Digest>::digest(b"abc"));
        assert_eq!(super::check(b"abc", 3, &sha), Ok(()));
        let e = super::check(b"ab", 3, &sha).unwrap_err();
        assert!(e.contains("short: 2 of the 3 bytes"), "{e}");
        let e = super::check(b"abd", 3, &sha).unwrap_err();
        assert!(e.contains("altered"), "{e}");
    }
}
