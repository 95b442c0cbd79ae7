//! The episode video's upload (`UploadVideo`): after the result is reported, the MP4 goes to
//! the server as a stream of chunks. Best-effort by design: the score is what matters, so a
//! failed upload is retried a few times, logged, and given up; it never delays or changes the
//! result, which is already in.

use std::time::Duration;

use kitchen_r_proto::worker::v1 as pb;
use tonic::Request;
use tracing::{info, warn};

use super::client::Client;

/// Bytes per chunk (the server decodes messages of up to 1 MiB).
pub(crate) const CHUNK: usize = 256 << 10;
/// Tries before the video is given up.
const TRIES: u32 = 3;

/// The chunks of `mp4` for `job`: the first names the job and the size, the rest carry bytes.
pub(crate) fn chunks(worker_id: &str, job: &pb::Job, mp4: &[u8]) -> Vec<pb::VideoChunk> {
    let mut out: Vec<pb::VideoChunk> = mp4
        .chunks(CHUNK)
        .map(|data| pb::VideoChunk {
            data: data.to_vec(),
            ..Default::default()
        })
        .collect();
    if out.is_empty() {
        out.push(pb::VideoChunk::default());
    }
    let first = &mut out[0];
    first.worker_id = worker_id.to_string();
    first.job_id = job.job_id;
    first.attempt = job.attempt;
    first.run_id = job.run_id;
    first.episode_key = job.episode_key.clone();
    first.total_bytes = mp4.len() as u64;
    out
}

/// Upload `mp4`, retrying transport failures; logs the outcome and never fails.
pub(crate) async fn upload_video(client: &Client, worker_id: &str, job: &pb::Job, mp4: Vec<u8>) {
    let size = mp4.len();
    let timeout = Duration::from_secs(30) + Duration::from_millis((size / 1024) as u64);
    for attempt in 1..=TRIES {
        let stream = tokio_stream::iter(chunks(worker_id, job, &mp4));
        let mut req = Request::new(stream);
        req.set_timeout(timeout);
        match client.clone().upload_video(req).await {
            Ok(r) => {
                let r = r.into_inner();
                info!(bytes = r.bytes, sha256 = %r.sha256, "episode video uploaded");
                return;
            }
            Err(s) if attempt < TRIES && super::client::retryable(&s) => {
                warn!(
                    "uploading the episode video failed ({:?}: {}); retrying",
                    s.code(),
                    s.message()
                );
                tokio::time::sleep(Duration::from_secs(u64::from(attempt))).await;
            }
            Err(s) => {
                warn!(
                    bytes = size,
                    "the episode video was not stored ({:?}: {}); the result is not affected",
                    s.code(),
                    s.message()
                );
                return;
            }
        }
    }
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
        assert!(c[1].episode_key.is_empty() && c[1].job_id == 0);
        let joined: Vec<u8> = c.iter().flat_map(|x| x.data.iter().copied()).collect();
        assert_eq!(joined, mp4);
    }
}
