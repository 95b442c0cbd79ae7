//! Episode videos over HTTP (docs/contest/video.md), with byte ranges so a `<video>` element can
//! seek:
//!
//! - `GET /api/v1/submissions/{id}/episodes/{key}/video.mp4`: bearer token (own team on dev;
//!   organiser on dev and test);
//! - `GET /submissions/{id}/episodes/{key}/video.mp4`: the same by the page's cookie session
//!   (a `<video src>` cannot send a bearer header), like the path plot's page route.
//!
//! Videos on demand: an episode with a stored trace and no video yet queues a render
//! when its video is asked for and answers `202 Accepted` with `Retry-After` and
//! `{"status": "queued" | "rendering", "progress": 0..1}` until the video is stored; a render
//! that failed (the replay disagreed with the stored result) answers `409` with
//! `{"status": "failed", "error": why, "code": "video_render_failed"}`. The trace itself is
//! served gzipped at `.../trace` to the same callers ([`api_trace`]).
//!
//! Who may see which video is `AppState::media_run`'s (see `crate::service::videos`). Range support:
//! one `bytes=` range (`a-b`, `a-`, `-n`) is answered 206 with `Content-Range`; a range past the
//! end is 416 with `Content-Range: bytes */<size>`; several ranges, a malformed header, or an
//! `If-Range` that does not match the ETag get the whole file (200), as RFC 9110 allows. Every
//! answer says `Accept-Ranges: bytes` and carries the file's sha256 as its ETag and its
//! modification time as `Last-Modified`; a matching `If-None-Match` (or, without one, an
//! `If-Modified-Since` not older than the file) answers 304 with no body
//! ([`super::conditional`]).

use axum::body::Body;
use axum::extract::State;
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use bytes::Bytes;
use tokio::io::{AsyncReadExt, AsyncSeekExt};

use super::conditional;
use super::extract::PathArg;
use super::viewer::session_caller;
use crate::error::ServiceError;
use crate::service::renders::VideoState;
use crate::service::videos::StoredVideo;
use crate::service::{AppState, Caller};
use serde_json::json;

/// Bytes read from the file per body chunk.
const READ_CHUNK: usize = 64 << 10;

/// The API route: bearer token.
pub(super) async fn api_video(
    State(s): State<AppState>,
    PathArg((id, key)): PathArg<(String, String)>,
    caller: Caller,
    headers: HeaderMap,
) -> Result<Response, ServiceError> {
    let id: i64 = id
        .parse()
        .map_err(|_| ServiceError::not_found(format!("submission {id:?}")))?;
    let video = s.video_or_render(&caller, id, &key).await?;
    respond_state(video, &headers).await
}

/// `GET /api/v1/submissions/{id}/episodes/{key}/trace`: the episode's trace, gzipped JSON (what
/// `kitchen-r replay` reads), for whoever may see its video.
pub(super) async fn api_trace(
    State(s): State<AppState>,
    PathArg((id, key)): PathArg<(String, String)>,
    caller: Caller,
) -> Result<Response, ServiceError> {
    let id: i64 = id
        .parse()
        .map_err(|_| ServiceError::not_found(format!("submission {id}")))?;
    let trace = s.episode_trace(&caller, id, &key).await?;
    let bytes = tokio::fs::read(&trace.path)
        .await
        .map_err(|e| anyhow::anyhow!("reading {}: {e}", trace.path.display()))?;
    let name = format!(
        "attachment; filename=\"{}.trace.json.gz\"",
        key.replace(['"', '/', '\\'], "_")
    );
    Response::builder()
        .header(header::CONTENT_TYPE, "application/gzip")
        .header(header::CONTENT_DISPOSITION, name)
        .header(header::ETAG, format!("\"{}\"", trace.sha256))
        .header(header::CACHE_CONTROL, "private, max-age=3600")
        .body(Body::from(bytes))
        .map_err(|e| anyhow::Error::from(e).into())
}

/// Seconds a client should wait before asking again for a video being rendered.
const RETRY_RENDER_S: u64 = 2;

/// The video, or what its render is doing.
async fn respond_state(state: VideoState, headers: &HeaderMap) -> Result<Response, ServiceError> {
    let (status, body) = match state {
        VideoState::Ready(video) => return respond(&video, headers).await,
        VideoState::Rendering { leased, progress } => (
            StatusCode::ACCEPTED,
            json!({"status": if leased { "rendering" } else { "queued" }, "progress": progress}),
        ),
        VideoState::Failed(why) => {
            let mut body = crate::error::error_body(&why, "video_render_failed");
            body["status"] = json!("failed");
            (StatusCode::CONFLICT, body)
        }
    };
    let mut resp = (status, axum::Json(body)).into_response();
    let h = resp.headers_mut();
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    if status == StatusCode::ACCEPTED {
        h.insert(header::RETRY_AFTER, HeaderValue::from(RETRY_RENDER_S));
    }
    Ok(resp)
}

/// The page route: the team (or organiser console) cookie, or a bearer header.
pub(super) async fn page_video(
    State(s): State<AppState>,
    PathArg((id, key)): PathArg<(String, String)>,
    caller: Caller,
    headers: HeaderMap,
) -> Result<Response, ServiceError> {
    let not_found = || ServiceError::not_found(format!("a video of episode {key:?} of submission {id}"));
    let caller = session_caller(&s, caller, &headers)
        .await?
        .ok_or_else(not_found)?;
    let sub = id.parse::<i64>().map_err(|_| not_found())?;
    let video = s.video_or_render(&caller, sub, &key).await?;
    respond_state(video, &headers).await
}

/// What a `Range` header asks of a file of `len` bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Wanted {
    Whole,
    /// First and last byte, inclusive.
    Part(u64, u64),
    Unsatisfiable,
}

/// Read a `Range` header (RFC 9110 §14.1.2) for a file of `len` bytes.
pub(crate) fn wanted(range: Option<&str>, len: u64) -> Wanted {
    let Some(spec) = range.and_then(|r| r.trim().strip_prefix("bytes=")) else {
        return Wanted::Whole;
    };
    if spec.contains(',') {
        return Wanted::Whole;
    }
    let Some((a, b)) = spec.trim().split_once('-') else {
        return Wanted::Whole;
    };
    let (a, b) = (a.trim(), b.trim());
    let part = match (a.parse::<u64>(), b.parse::<u64>()) {
        (Ok(first), Ok(last)) if first <= last => Some((first, last.min(len.saturating_sub(1)))),
        (Ok(first), Err(_)) if b.is_empty() => Some((first, len.saturating_sub(1))),
        (Err(_), Ok(n)) if a.is_empty() => {
            if n == 0 {
                return Wanted::Unsatisfiable;
            }
            Some((len.saturating_sub(n), len.saturating_sub(1)))
        }
        _ => None,
    };
    match part {
        None => Wanted::Whole,
        Some((first, _)) if first >= len => Wanted::Unsatisfiable,
        Some((first, last)) => Wanted::Part(first, last),
    }
}

/// The file, or the part of it the request asks for.
async fn respond(video: &StoredVideo, headers: &HeaderMap) -> Result<Response, ServiceError> {
    let mut file = tokio::fs::File::open(&video.path)
        .await
        .map_err(|e| anyhow::anyhow!("opening {}: {e}", video.path.display()))?;
    let meta = file.metadata().await.map_err(anyhow::Error::from)?;
    let (len, modified) = (meta.len(), meta.modified().ok());
    let etag = format!("\"{}\"", video.sha256);
    let text = |name| headers.get(name).and_then(|v: &HeaderValue| v.to_str().ok());
    let range = match text(header::IF_RANGE) {
        Some(tag) if tag != etag => None,
        _ => text(header::RANGE),
    };
    let mut b = Response::builder()
        .header(header::CONTENT_TYPE, "video/mp4")
        .header(header::ACCEPT_RANGES, "bytes")
        .header(header::ETAG, &etag)
        .header(header::CACHE_CONTROL, "private, max-age=3600");
    if let Some(m) = modified {
        b = b.header(header::LAST_MODIFIED, conditional::last_modified(m));
    }
    if conditional::not_modified(headers, &etag, modified) {
        let r = b.status(StatusCode::NOT_MODIFIED).body(Body::empty());
        return r.map_err(|e| anyhow::Error::from(e).into());
    }
    let (first, last) = match wanted(range, len) {
        Wanted::Whole => (0, len.saturating_sub(1)),
        Wanted::Part(first, last) => {
            b = b
                .status(StatusCode::PARTIAL_CONTENT)
                .header(header::CONTENT_RANGE, format!("bytes {first}-{last}/{len}"));
            (first, last)
        }
        Wanted::Unsatisfiable => {
            let r = b
                .status(StatusCode::RANGE_NOT_SATISFIABLE)
                .header(header::CONTENT_RANGE, format!("bytes */{len}"))
                .body(Body::empty());
            return r.map_err(|e| anyhow::Error::from(e).into());
        }
    };
    let count = if len == 0 { 0 } else { last - first + 1 };
    file.seek(std::io::SeekFrom::Start(first))
        .await
        .map_err(anyhow::Error::from)?;
    let body = Body::from_stream(futures_util::stream::unfold(
        (file, count),
        |(mut file, left)| async move {
            if left == 0 {
                return None;
            }
            let mut buf = vec![0u8; READ_CHUNK.min(left as usize)];
            match file.read(&mut buf).await {
                Ok(0) => None,
                Ok(n) => {
                    buf.truncate(n);
                    Some((Ok::<_, std::io::Error>(Bytes::from(buf)), (file, left - n as u64)))
                }
                Err(e) => Some((Err(e), (file, 0))),
            }
        },
    ));
    b.header(header::CONTENT_LENGTH, count)
        .body(body)
        .map_err(|e| anyhow::Error::from(e).into())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn byte_ranges_are_read_as_rfc_9110_says() {
        assert_eq!(wanted(None, 100), Wanted::Whole);
        assert_eq!(wanted(Some("bytes=0-"), 100), Wanted::Part(0, 99));
        assert_eq!(wanted(Some("bytes=10-19"), 100), Wanted::Part(10, 19));
        assert_eq!(wanted(Some("bytes=90-500"), 100), Wanted::Part(90, 99));
        assert_eq!(wanted(Some("bytes=-10"), 100), Wanted::Part(90, 99));
        assert_eq!(wanted(Some("bytes=-500"), 100), Wanted::Part(0, 99));
        assert_eq!(wanted(Some("bytes=100-"), 100), Wanted::Unsatisfiable);
        assert_eq!(wanted(Some("bytes=-0"), 100), Wanted::Unsatisfiable);
        // Malformed, reversed, several ranges or another unit: the whole file.
        assert_eq!(wanted(Some("bytes=5-2"), 100), Wanted::Whole);
        assert_eq!(wanted(Some("bytes=0-1,5-6"), 100), Wanted::Whole);
        assert_eq!(wanted(Some("items=0-1"), 100), Wanted::Whole);
        assert_eq!(wanted(Some("bytes=x-"), 100), Wanted::Whole);
    }
}
