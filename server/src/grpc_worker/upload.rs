//! `UploadVideo` and `UploadTrace`: an episode video or trace streamed in chunks after the
//! episode's result; and `FetchTrace`, a render job's trace streamed back the same way. The first chunk names the job; the upload is accepted only for a job whose
//! result that attempt reported (or, for a render's video, the render lease it names), so a
//! worker token cannot attach a file to any other episode. A video's announced size is booked
//! against the storage budgets before a byte is written (`service::video_budget`), and so is a
//! trace's (videos and traces share the budgets).

use std::pin::Pin;

use kitchen_r_proto::worker::v1 as pb;
use tokio_stream::{Stream, StreamExt};
use tokio_util::io::ReaderStream;
use tonic::{Status, Streaming};

use crate::service::AppState;
use crate::service::renders::RenderTrace;
use crate::service::videos::{Complete, Incoming, UploadError};
use crate::store;

/// Read the stream to its end, store the file and link it; returns its sha256 and size.
pub(super) async fn receive(
    state: &AppState,
    mut stream: Streaming<pb::VideoChunk>,
) -> Result<(String, u64), Status> {
    let Some(dir) = state.video_dir() else {
        return Err(Status::failed_precondition(
            "this server does not store episode videos (`[video] enabled` is false or it has no video directory)",
        ));
    };
    let first = first_chunk(&mut stream).await?;
    let (id, attempt) = (first.job_id, i64::from(first.attempt));
    let known = match first.render {
        true => store::renders::held(state.read_pool(), id, attempt, first.run_id, &first.episode_key).await,
        false => {
            store::videos::reported_job(
                state.read_pool(),
                id,
                first.attempt,
                first.run_id,
                &first.episode_key,
            )
            .await
        }
    }
    .map_err(|e| Status::internal(e.to_string()))?;
    if !known {
        return Err(unknown_job(
            first.job_id,
            first.attempt,
            first.run_id,
            &first.episode_key,
        ));
    }
    let (run, key) = (first.run_id, first.episode_key.as_str());
    let limit = state.config().video.max_bytes;
    let file = Incoming::start(&dir, first.total_bytes, limit)
        .await
        .map_err(refused)?;
    let booking = match state.book_video(&dir, run, key, first.total_bytes).await {
        Ok(b) => b,
        // A render's video with no room: the render waits, queued with the reason.
        Err(UploadError::NoRoom(why)) if first.render => {
            state.render_waits(id, attempt, &why).await?;
            return Err(Status::resource_exhausted(why));
        }
        Err(e) => return Err(refused(e)),
    };
    let file = write_all(file, &first.data, &mut stream, |c: &pb::VideoChunk| &c.data).await?;
    let (sha, bytes) = state
        .store_video(&dir, booking, run, key, file)
        .await
        .map_err(refused)?;
    if first.render {
        state.render_done(id, attempt, &sha).await?;
    }
    tracing::info!(run, episode = %key, bytes, sha256 = %sha, render = first.render, "episode video stored");
    Ok((sha, bytes))
}

/// Read a trace stream to its end, store the file and link it; returns its sha256 and size.
pub(super) async fn receive_trace(
    state: &AppState,
    mut stream: Streaming<pb::TraceChunk>,
) -> Result<(String, u64), Status> {
    let Some(dir) = state.video_dir() else {
        return Err(Status::failed_precondition(
            "this server does not store episode traces (`[video] enabled` is false or it has no video directory)",
        ));
    };
    let first = first_chunk(&mut stream).await?;
    let (run, key) = (first.run_id, first.episode_key.as_str());
    let known = store::videos::reported_job(state.read_pool(), first.job_id, first.attempt, run, key)
        .await
        .map_err(|e| Status::internal(e.to_string()))?;
    if !known {
        return Err(unknown_job(first.job_id, first.attempt, run, key));
    }
    let limit = state.config().video.max_bytes;
    let file = Incoming::start(&dir, first.total_bytes, limit)
        .await
        .map_err(refused)?;
    let booking = state
        .book_trace(&dir, run, key, first.total_bytes)
        .await
        .map_err(refused)?;
    let file = write_all(file, &first.data, &mut stream, |c: &pb::TraceChunk| &c.data).await?;
    let (sha, bytes) = state
        .trace_uploaded(&dir, booking, run, key, file)
        .await
        .map_err(refused)?;
    tracing::info!(run, episode = %key, bytes, sha256 = %sha, "episode trace stored");
    Ok((sha, bytes))
}

/// The first chunk, which names the job.
async fn first_chunk<T>(stream: &mut Streaming<T>) -> Result<T, Status> {
    stream
        .message()
        .await?
        .ok_or_else(|| Status::invalid_argument("an empty upload: the first chunk must name the job"))
}

fn unknown_job(job_id: i64, attempt: u32, run: i64, key: &str) -> Status {
    Status::failed_precondition(format!(
        "job {job_id} attempt {attempt} has no reported result for run {run} episode {key:?}"
    ))
}

/// The first chunk's bytes, then every later chunk's, into `file`; the finished file.
async fn write_all<T>(
    mut file: Incoming,
    first: &[u8],
    stream: &mut Streaming<T>,
    data: impl Fn(&T) -> &[u8],
) -> Result<Complete, Status> {
    file.write(first).await.map_err(refused)?;
    while let Some(chunk) = stream.message().await? {
        file.write(data(&chunk)).await.map_err(refused)?;
    }
    file.finish().await.map_err(refused)
}

fn refused(e: UploadError) -> Status {
    match e {
        UploadError::Io(e) => Status::internal(format!("storing the video: {e}")),
        UploadError::Service(e) => e.into(),
        UploadError::NoRoom(why) => Status::resource_exhausted(why),
        e => Status::invalid_argument(e.to_string()),
    }
}

/// Bytes per `FetchTrace` chunk: well under the 4 MiB a gRPC client takes by default.
const FETCH_CHUNK: usize = 1 << 20;

/// The chunks of a trace as `FetchTrace` answers them.
pub(super) type TraceStream = Pin<Box<dyn Stream<Item = Result<pb::TraceChunk, Status>> + Send>>;

/// Stream `trace`'s file in chunks of at most [`FETCH_CHUNK`]: the first names the episode and
/// the size, each later one carries only bytes. The file is opened before the answer starts, so
/// a trace deleted meanwhile is a NOT_FOUND, not a stream that breaks.
pub(super) async fn send_trace(trace: RenderTrace) -> Result<TraceStream, Status> {
    let file = tokio::fs::File::open(&trace.path)
        .await
        .map_err(|e| match e.kind() {
            std::io::ErrorKind::NotFound => Status::not_found("the trace file is gone"),
            _ => Status::internal(format!("opening the trace: {e}")),
        })?;
    let mut first = Some(pb::TraceChunk {
        run_id: trace.run_id,
        episode_key: trace.episode_key,
        total_bytes: trace.bytes,
        ..Default::default()
    });
    let chunks = ReaderStream::with_capacity(file, FETCH_CHUNK).map(move |read| {
        let data = read
            .map_err(|e| Status::internal(format!("reading the trace: {e}")))?
            .to_vec();
        let header = first.take().unwrap_or_default();
        Ok(pb::TraceChunk { data, ..header })
    });
    Ok(Box::pin(chunks))
}
