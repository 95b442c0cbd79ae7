//! The episode media routes of the OpenAPI document, written out by hand: the video
//! (`crate::http::video`: byte ranges, 202 while it renders) and the trace download. Their
//! answers are plain HTTP rather than the service's types.

use super::{ORGANISER, TEAM};

pub(super) const VIDEO_PATH: &str = "/api/v1/submissions/{id}/episodes/{episode_key}/video.mp4";

/// `GET /api/v1/submissions/{id}/episodes/{episode_key}/video.mp4` (`crate::http::video`).
pub(super) fn video_item() -> utoipa::openapi::PathItem {
    let error = |d: &str| serde_json::json!({"description": d, "content": {"application/json": {"schema": {"$ref": "#/components/schemas/ErrorBody"}}}});
    let video = |d: &str| {
        serde_json::json!({
            "description": d,
            "headers": {
                "accept-ranges": {"schema": {"type": "string"}, "description": "Always `bytes`"},
                "etag": {"schema": {"type": "string"}, "description": "The file's sha256, quoted"},
                "content-range": {"schema": {"type": "string"}, "description": "206: `bytes FIRST-LAST/SIZE`"},
            },
            "content": {"video/mp4": {"schema": {"type": "string", "format": "binary"}}},
        })
    };
    let item = serde_json::json!({
        "get": {
            "tags": ["submissions"],
            "summary": "One episode's video (H.264 in MP4), with byte ranges; rendered on first request",
            "description": "Both cameras side by side with a caption bar. The team sees its dev episodes; the organiser dev and test. One `bytes=` range is answered 206; several ranges, a malformed `Range` or an `If-Range` that does not match the ETag get the whole file. Videos are rendered on demand from the episode's trace: the first request queues a render and is answered 202 (with `Retry-After`) until the video is stored; a render whose replay disagrees with the stored result is refused (409, `video_render_failed`).",
            "operationId": "api_video",
            "parameters": [
                {"name": "id", "in": "path", "required": true, "description": "The submission id", "schema": {"type": "integer", "format": "int64"}, "example": 1},
                {"name": "episode_key", "in": "path", "required": true, "description": "The episode's key, e.g. `dev-0007`", "schema": {"type": "string"}, "example": "dev-0001"},
                {"name": "range", "in": "header", "required": false, "description": "`bytes=FIRST-LAST`, `bytes=FIRST-` or `bytes=-SUFFIX`", "schema": {"type": "string"}},
                {"name": "if-range", "in": "header", "required": false, "description": "Honour `Range` only if the video's ETag still matches", "schema": {"type": "string"}},
            ],
            "responses": {
                "200": video("The whole video"),
                "206": video("The requested byte range"),
                "202": {
                    "description": "No video yet: it is queued or being rendered from the episode's trace; ask again after `Retry-After` seconds",
                    "headers": {"retry-after": {"schema": {"type": "integer"}, "description": "Seconds"}},
                    "content": {"application/json": {"schema": {
                        "type": "object",
                        "required": ["status", "progress"],
                        "properties": {
                            "status": {"type": "string", "enum": ["queued", "rendering"]},
                            "progress": {"type": "number", "format": "double", "minimum": 0, "maximum": 1, "description": "Share of the render done"},
                        },
                    }}},
                },
                "404": error("No such submission, episode or video, or not the caller's (a team never sees its test-split videos)"),
                "409": error("The video cannot be rendered (`video_render_failed`, `status: failed`): the replay of the episode's trace disagrees with the stored result, or the render failed; `error` says why"),
                "416": {"description": "The range starts past the end (`Content-Range: bytes */SIZE`)", "headers": {"content-range": {"schema": {"type": "string"}}}},
            },
            "security": [{TEAM: []}, {ORGANISER: []}],
        }
    });
    serde_json::from_value(item).expect("the video route's description is a path item")
}

pub(super) const TRACE_PATH: &str = "/api/v1/submissions/{id}/episodes/{episode_key}/trace";

/// `GET /api/v1/submissions/{id}/episodes/{episode_key}/trace` (`crate::http::video::api_trace`).
pub(super) fn trace_item() -> utoipa::openapi::PathItem {
    let item = serde_json::json!({
        "get": {
            "tags": ["submissions"],
            "summary": "One episode's trace (gzipped JSON): what `kitchen-r replay` reproduces the episode from",
            "description": "The episode configuration and every answer of the policy, with the outcome a replay must reproduce bit for bit. Who may have it is who may see the episode's video: the team its dev episodes, the organiser dev and test.",
            "operationId": "api_trace",
            "parameters": [
                {"name": "id", "in": "path", "required": true, "description": "The submission id", "schema": {"type": "integer", "format": "int64"}, "example": 1},
                {"name": "episode_key", "in": "path", "required": true, "description": "The episode's key, e.g. `dev-0007`", "schema": {"type": "string"}, "example": "dev-0001"},
            ],
            "responses": {
                "200": {
                    "description": "The trace, gzipped JSON (`kitchen-r replay FILE` reads it as it is)",
                    "headers": {"etag": {"schema": {"type": "string"}, "description": "The file's sha256, quoted"}},
                    "content": {"application/gzip": {"schema": {"type": "string", "format": "binary"}}},
                },
                "404": {"description": "No such submission, episode or trace, or not the caller's (a team never gets its test-split traces)", "content": {"application/json": {"schema": {"$ref": "#/components/schemas/ErrorBody"}}}},
            },
            "security": [{TEAM: []}, {ORGANISER: []}],
        }
    });
    serde_json::from_value(item).expect("the trace route's description is a path item")
}
