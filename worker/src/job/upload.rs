//! Uploads after the result: the episode video (`UploadVideo`) or the episode trace
//! (`UploadTrace`, videos on demand) go to the server as a stream of chunks. Best-effort by
//! design: the score is what matters, so a failed upload is retried a few times, logged, and
//! given up; it never delays or changes the result, which is already in. A render job's video
//! (`VideoChunk.render`) goes the same way, and its failure is the render's.

use std::future::Future;
use std::time::Duration;

use kitchen_r_proto::worker::v1 as pb;
use tonic::{Request, Status};
use tracing::{info, warn};

use super::rpc::Client;

/// Bytes per chunk (the server decodes messages of up to 1 MiB).
pub(crate) const CHUNK: usize = 256 << 10;
/// Tries before an upload is given up.
const TRIES: u32 = 3;

/// The chunks of `mp4` for `job`: the first names the job and the size, the rest carry bytes.
/// A render job's first chunk says so (`render`).
pub(crate) fn chunks(worker_id: &str, job: &pb::Job, mp4: &[u8]) -> Vec<pb::VideoChunk> {
    let mut out = cut::<pb::VideoChunk>(worker_id, job, mp4);
    out[0].render = job.render.is_some();
    out
}

/// The chunks of a gzipped trace, as [`chunks`] cuts a video.
pub(crate) fn trace_chunks(worker_id: &str, job: &pb::Job, gz: &[u8]) -> Vec<pb::TraceChunk> {
    cut::<pb::TraceChunk>(worker_id, job, gz)
}

/// An upload's chunk message: bytes, and the job-naming header its first chunk carries.
trait Chunk: Default {
    fn with_data(data: Vec<u8>) -> Self;
    fn name_job(&mut self, worker_id: &str, job: &pb::Job, total_bytes: u64);
}

// The two messages have the same fields (proto/kitchen_r/worker/v1/worker.proto).
macro_rules! chunk_message {
    ($t:ty) => {
        impl Chunk for $t {
            fn with_data(data: Vec<u8>) -> Self {
                Self {
                    data,
                    ..Default::default()
                }
            }
            fn name_job(&mut self, worker_id: &str, job: &pb::Job, total_bytes: u64) {
                self.worker_id = worker_id.to_string();
                self.job_id = job.job_id;
                self.attempt = job.attempt;
                self.run_id = job.run_id;
                self.episode_key = job.episode_key.clone();
                self.total_bytes = total_bytes;
            }
        }
    };
}
chunk_message!(pb::VideoChunk);
chunk_message!(pb::TraceChunk);

/// `bytes` as chunks, the first naming the job and the size.
fn cut<C: Chunk>(worker_id: &str, job: &pb::Job, bytes: &[u8]) -> Vec<C> {
    let mut out: Vec<C> = pieces(bytes).map(|d| C::with_data(d.to_vec())).collect();
    out[0].name_job(worker_id, job, bytes.len() as u64);
    out
}

/// `bytes` in [`CHUNK`]s; one empty piece for an empty file (the first chunk names the job).
fn pieces(bytes: &[u8]) -> impl Iterator<Item = &[u8]> {
    let empty: &[u8] = &[];
    bytes.chunks(CHUNK).chain(bytes.is_empty().then_some(empty))
}

/// Upload `mp4`, retrying transport failures; logs the outcome. `Err` is the server's last
/// answer when the video was not stored (a render job decides from it whether it failed).
pub(crate) async fn upload_video(
    client: &Client,
    worker_id: &str,
    job: &pb::Job,
    mp4: Vec<u8>,
) -> Result<(), Status> {
    let timeout = timeout_for(mp4.len());
    let sent = with_retries("episode video", mp4.len(), || {
        let mut req = Request::new(tokio_stream::iter(chunks(worker_id, job, &mp4)));
        req.set_timeout(timeout);
        let mut client = client.clone();
        async move {
            let r = client.upload_video(req).await?.into_inner();
            Ok((r.sha256, r.bytes))
        }
    });
    sent.await
}

/// Upload a gzipped trace, as [`upload_video`] does a video.
pub(crate) async fn upload_trace(client: &Client, worker_id: &str, job: &pb::Job, gz: Vec<u8>) {
    let timeout = timeout_for(gz.len());
    let sent = with_retries("episode trace", gz.len(), || {
        let mut req = Request::new(tokio_stream::iter(trace_chunks(worker_id, job, &gz)));
        req.set_timeout(timeout);
        let mut client = client.clone();
        async move {
            let r = client.upload_trace(req).await?.into_inner();
            Ok((r.sha256, r.bytes))
        }
    });
    // Logged by `with_retries`; the result is in either way.
    let _ = sent.await;
}

/// 30 s and a millisecond per KiB.
fn timeout_for(size: usize) -> Duration {
    Duration::from_secs(30) + Duration::from_millis((size / 1024) as u64)
}

/// Call `send` up to [`TRIES`] times while it fails with a retryable status.
async fn with_retries<F, Fut>(what: &str, size: usize, mut send: F) -> Result<(), Status>
where
    F: FnMut() -> Fut,
    Fut: Future<Output = Result<(String, u64), Status>>,
{
    for attempt in 1..=TRIES {
        match send().await {
            Ok((sha256, bytes)) => {
                info!(bytes, %sha256, "{what} uploaded");
                return Ok(());
            }
            Err(s) if attempt < TRIES && super::rpc::retryable(&s) => {
                warn!(
                    "uploading the {what} failed ({:?}: {}); retrying",
                    s.code(),
                    s.message()
                );
                tokio::time::sleep(Duration::from_secs(u64::from(attempt))).await;
            }
            Err(s) => {
                warn!(
                    bytes = size,
                    "the {what} was not stored ({:?}: {}); the result is not affected",
                    s.code(),
                    s.message()
                );
                return Err(s);
            }
        }
    }
    Err(Status::unknown(format!("the {what} upload was not accepted")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_chunks_rebuild_the_file_and_only_the_first_names_the_job() {
        let job = pb::Job {
            job_id: 7,
            attempt: 2,
            run_id: 3,
            episode_key: "dev-0001".into(),
            ..Default::default()
        };
        let mp4: Vec<u8> = (0..CHUNK * 2 + 5).map(|i| i as u8).collect();
        let c = chunks("w1", &job, &mp4);
        assert_eq!(c.len(), 3);
        assert_eq!((c[0].job_id, c[0].attempt, c[0].run_id), (7, 2, 3));
        assert_eq!(
            (c[0].episode_key.as_str(), c[0].total_bytes),
            ("dev-0001", mp4.len() as u64)
        );
        assert!(c[1].episode_key.is_empty() && c[1].job_id == 0 && !c[0].render);
        let joined: Vec<u8> = c.iter().flat_map(|x| x.data.iter().copied()).collect();
        assert_eq!(joined, mp4);
        let t = trace_chunks("w1", &job, &mp4[..10]);
        assert_eq!((t.len(), t[0].total_bytes, t[0].job_id), (1, 10, 7));
        assert_eq!(trace_chunks("w1", &job, &[]).len(), 1);
        // A render job's video says it is one.
        let render = pb::Job {
            render: Some(pb::RenderJob::default()),
            ..job
        };
        assert!(chunks("w1", &render, b"mp4")[0].render);
    }
}
