//! Episode videos end to end (docs/contest/video.md): `kitchen-r serve` with
//! in-process workers runs a team's small dev policy run; each episode's trace is recorded by the
//! worker and uploaded over the worker gRPC service; the video is rendered from it by a worker
//! when first asked for, stored, and served with byte ranges to the team, never to another
//! team; a test-split run's traces and videos are the organiser's only.

use crate::remote_support;
use crate::support;

use std::process::Command;
use std::sync::Arc;

use kitchen_r_contract::server::ServeOptions;
use serde_json::{Value, json};
use support::*;

/// One-task episodes of 3 s of sim time: 30 control steps, so 30 frames. Nothing is
/// pre-rendered: this file's first test asks for every video itself.
const CONFIG: &str = "[control]\noffline_mse = false\nmax_plan_steps = 1\ntask_time_limit_s = 3.0\n\
                      [quota]\nconcurrent_runs = 0\n[video]\ntest_split = true\nprerender = \"none\"\n";
const FRAMES: i64 = 30;

async fn get(server: &Server, path: &str, token: &str, range: Option<&str>) -> reqwest::Response {
    let mut req = client().get(server.url(path)).bearer_auth(token);
    if let Some(r) = range {
        req = req.header("range", r);
    }
    req.send().await.unwrap()
}

/// Decode `mp4` with PyAV (FFmpeg's decoders): the track's sample entry (`avc1` for H.264)
/// and how many frames decode.
fn decode(mp4: &[u8]) -> (String, i64) {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("episode.mp4");
    std::fs::write(&file, mp4).unwrap();
    let script = "import av, sys\nc = av.open(sys.argv[1])\ns = c.streams.video[0]\n\
                  n = sum(1 for _ in c.decode(s))\nprint(s.codec_tag, n)";
    let o = ok(Command::new("python3")
        .args(["-c", script])
        .arg(&file)
        .output()
        .unwrap());
    let text = out(&o);
    let (codec, n) = text.trim().split_once(' ').unwrap();
    (codec.to_string(), n.parse().unwrap())
}

/// Poll `url` (as `token`) until it answers something other than 202 (the render's "rendering");
/// every 202 must carry `Retry-After` and the render's status and progress.
async fn until_rendered(server: &Server, url: &str, token: &str, range: Option<&str>) -> reqwest::Response {
    let start = std::time::Instant::now();
    loop {
        let r = get(server, url, token, range).await;
        if r.status() != 202 {
            return r;
        }
        assert!(r.headers().contains_key("retry-after"), "{:?}", r.headers());
        let v: Value = r.json().await.unwrap();
        assert!(v["status"] == "queued" || v["status"] == "rendering", "{v}");
        let p = v["progress"].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&p), "{v}");
        assert!(
            start.elapsed() < std::time::Duration::from_secs(240),
            "{url} still rendering: {v}"
        );
        tokio::time::sleep(std::time::Duration::from_millis(300)).await;
    }
}

/// The JSON view's episodes of submission `id`, as `token` sees them.
async fn episodes(server: &Server, id: i64, token: &str) -> Vec<Value> {
    let (_, v) = get_json(server, &format!("/api/v1/submissions/{id}"), Some(token)).await;
    v["latest_run"]["evaluation"]["episodes"]
        .as_array()
        .cloned()
        .unwrap_or_default()
}

/// Every file under `dir` whose name ends with `suffix`.
fn files_ending(dir: &std::path::Path, suffix: &str) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    let mut dirs = vec![dir.to_path_buf()];
    while let Some(d) = dirs.pop() {
        for e in std::fs::read_dir(&d).into_iter().flatten().flatten() {
            let p = e.path();
            if p.is_dir() {
                dirs.push(p);
            } else if p.to_string_lossy().ends_with(suffix) {
                out.push(p);
            }
        }
    }
    out
}

/// Make the stored result of `(submission's run, key)` say its first task succeeded, as a
/// damaged or tampered database would: the episode's replay no longer agrees with it.
fn tamper_stored_result(db: &std::path::Path, key: &str) {
    let script = "import json, sqlite3, sys\n\
                  c = sqlite3.connect(sys.argv[1], timeout=30)\n\
                  (tasks,) = c.execute('SELECT tasks FROM episode_results WHERE episode_key = ?', (sys.argv[2],)).fetchone()\n\
                  t = json.loads(tasks)\n\
                  t[0]['success'] = True; t[0]['completion_time_s'] = 1.0; t[0]['failure_reason'] = ''\n\
                  c.execute('UPDATE episode_results SET tasks = ? WHERE episode_key = ?', (json.dumps(t), sys.argv[2]))\n\
                  c.commit()";
    ok(Command::new("python3")
        .args(["-c", script])
        .arg(db)
        .arg(key)
        .output()
        .unwrap());
}

/// Videos on demand: the dev run stores traces, not videos; asking for a video
/// renders it (202 with progress, then the MP4 with ranges, to the team only); a replay that
/// disagrees with the stored result is refused and says so; the trace is downloadable (API and
/// CLI) and replays locally; test-split traces and videos are the organiser's only.
#[test]
fn a_dev_episode_video_is_rendered_on_demand_served_with_ranges_to_its_team_only_and_test_media_to_the_organiser()
 {
    use kitchen_r_episode::policy::HORIZON as H;
    use remote_support::{STILL, TestServer, factory};
    let policy = TestServer::start(
        factory(H, Arc::new(|_| Ok(vec![STILL; H]))),
        ServeOptions::default(),
    );
    let fx = ControlFixture::new(CONFIG);
    let server = fx.serve(2);
    let videos_dir = fx.dir.path().join("db/videos");
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let (alpha, bravo) = (team(&server, "alpha").await, team(&server, "bravo").await);
        let register = |split: &'static str| {
            let (server, alpha, url) = (&server, &alpha, policy.url());
            async move {
                let (status, reg) = register_policy(
                    server,
                    alpha,
                    match split {
                        // The test split always runs in full: it is cancelled once its first
                        // episode is in.
                        "test" => json!({"endpoint": url, "split": split}),
                        _ => json!({"endpoint": url, "split": split, "episodes": 2}),
                    },
                )
                .await;
                assert_eq!(status, 201, "{reg}");
                reg["id"].as_i64().unwrap()
            }
        };
        let (dev, test) = (register("dev").await, register("test").await);
        wait_for(&server, dev, &alpha, "the dev run", finished).await;
        // The traces are uploaded after the results: wait for both episodes' to be in.
        let mut eps = Vec::new();
        for _ in 0..100 {
            eps = episodes(&server, dev, &alpha).await;
            if eps.len() == 2 && eps.iter().all(|e| e["video"]["status"] == "available") {
                break;
            }
            tokio::time::sleep(std::time::Duration::from_millis(200)).await;
        }
        assert!(
            eps.iter().all(|e| e["video"]["status"] == "available"),
            "no trace on the dev episodes: {eps:#?}"
        );
        assert!(
            files_ending(&videos_dir, ".mp4").is_empty(),
            "the evaluation rendered a video"
        );
        // The dev episodes' traces (and the test run's, which goes on meanwhile).
        assert!(files_ending(&videos_dir, ".json.gz").len() >= 2);
        let (key, bad) = (
            eps[0]["key"].as_str().unwrap().to_string(),
            eps[1]["key"].as_str().unwrap().to_string(),
        );
        let url = eps[0]["video_url"].as_str().unwrap().to_string();
        assert_eq!(url, format!("/api/v1/submissions/{dev}/episodes/{key}/video.mp4"));

        // The trace: gzipped JSON to the team, not to another team; the CLI fetches it and
        // `kitchen-r replay` reproduces the episode from it.
        let trace_url = format!("/api/v1/submissions/{dev}/episodes/{key}/trace");
        let r = get(&server, &trace_url, &alpha, None).await;
        assert_eq!(r.status(), 200);
        assert_eq!(r.headers()["content-type"], "application/gzip");
        assert_eq!(&r.bytes().await.unwrap()[..2], &[0x1f, 0x8b]);
        assert_eq!(get(&server, &trace_url, &bravo, None).await.status(), 404);
        let file = fx.dir.path().join("fetched.trace.json.gz");
        let dev_s = dev.to_string();
        let cli = [
            "submission",
            "trace",
            &dev_s,
            &key,
            "-o",
            file.to_str().unwrap(),
            "--server",
            &server.http,
        ];
        ok(Command::new(bin())
            .args(cli)
            .env("KITCHEN_R_TOKEN", &alpha)
            .output()
            .unwrap());
        let replay = ok(Command::new(bin())
            .args(["replay", "--check-only"])
            .arg(&file)
            .output()
            .unwrap());
        assert!(
            out(&replay).contains("agrees with the recorded outcome"),
            "{}",
            out(&replay)
        );

        tamper_stored_result(&fx.dir.path().join("db/kitchen-r.db"), &bad);

        // Test split: once its first episode's trace is in, the organiser cancels the run (the
        // renders wait while evaluation jobs are queued); the team never gets test media.
        let test_trace = format!("/api/v1/submissions/{test}/episodes/test-0001/trace");
        let mut status = 0;
        for _ in 0..300 {
            status = get(&server, &test_trace, ADMIN, None).await.status().as_u16();
            if status == 200 {
                break;
            }
            tokio::time::sleep(std::time::Duration::from_millis(300)).await;
        }
        assert_eq!(status, 200, "the organiser never got the test episode's trace");
        assert_eq!(get(&server, &test_trace, &alpha, None).await.status(), 404);
        let (_, runs) = get_json(&server, "/api/v1/admin/runs", Some(ADMIN)).await;
        let run = (runs["runs"].as_array().unwrap().iter())
            .find(|r| r["submission"] == test)
            .unwrap_or_else(|| panic!("{runs:#}"))["run"]
            .as_i64()
            .unwrap();
        let cancel = client()
            .post(server.url(&format!("/api/v1/admin/runs/{run}/cancel")))
            .bearer_auth(ADMIN)
            .send()
            .await
            .unwrap();
        assert_eq!(cancel.status(), 200);

        // The first request queues the render (202); the video follows.
        let first = get(&server, &url, &alpha, None).await;
        assert_eq!(first.status(), 202);
        let whole = until_rendered(&server, &url, &alpha, None).await;
        assert_eq!(whole.status(), 200);
        assert_eq!(whole.headers()["accept-ranges"], "bytes");
        assert_eq!(whole.headers()["content-type"], "video/mp4");
        let mp4 = whole.bytes().await.unwrap().to_vec();
        let part = get(&server, &url, &alpha, Some("bytes=4-11")).await;
        assert_eq!(part.status(), 206);
        assert_eq!(
            part.headers()["content-range"].to_str().unwrap(),
            format!("bytes 4-11/{}", mp4.len())
        );
        assert_eq!(part.bytes().await.unwrap().as_ref(), &mp4[4..12]);
        assert_eq!(&mp4[4..8], b"ftyp");
        let past = get(&server, &url, &alpha, Some(&format!("bytes={}-", mp4.len()))).await;
        assert_eq!(past.status(), 416);
        let (codec, frames) = decode(&mp4);
        assert_eq!(codec, "avc1");
        assert!(
            (frames - FRAMES).abs() <= 1,
            "{frames} frames for {FRAMES} control steps"
        );

        // Another team: not found, the same as no such video.
        assert_eq!(get(&server, &url, &bravo, None).await.status(), 404);
        // The page route, by the team's session cookie (what the page's <video> requests).
        let page = url.trim_start_matches("/api/v1");
        let r = client()
            .get(server.url(page))
            .header("cookie", page_session(&server, &alpha).await)
            .header("range", "bytes=0-3")
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 206);
        assert_eq!(r.bytes().await.unwrap().as_ref(), &mp4[..4]);

        // The tampered episode: its replay disagrees with the stored result, so no video.
        let bad_url = format!("/api/v1/submissions/{dev}/episodes/{bad}/video.mp4");
        let refused = until_rendered(&server, &bad_url, &alpha, None).await;
        assert_eq!(refused.status(), 409);
        let v: Value = refused.json().await.unwrap();
        assert_eq!(
            (v["status"].as_str(), v["code"].as_str()),
            (Some("failed"), Some("video_render_failed"))
        );
        let why = v["error"].as_str().unwrap();
        assert!(why.contains("replay disagrees with the stored result"), "{v}");
        let eps = episodes(&server, dev, &alpha).await;
        let shown = eps.iter().find(|e| e["key"] == bad.as_str()).unwrap();
        assert_eq!(shown["video"]["status"], "failed", "{shown:#}");
        assert_eq!(
            files_ending(&videos_dir, ".mp4").len(),
            1,
            "a refused render stored a video"
        );
        // The submission page plays the rendered video inline and says why the other has none.
        let html = page_html(&server, &format!("/submissions/{dev}"), &alpha).await;
        assert!(html.contains("<video"), "{html}");
        assert!(html.contains(&format!("src=\"{page}\"")), "{html}");
        assert!(html.contains("replay disagrees with the stored result"), "{html}");

        // Test split: the organiser gets the rendered video; the team never.
        let test_url = format!("/api/v1/submissions/{test}/episodes/test-0001/video.mp4");
        let r = until_rendered(&server, &test_url, ADMIN, Some("bytes=0-7")).await;
        assert_eq!(
            r.status(),
            206,
            "the organiser never got the test episode's video"
        );
        assert_eq!(get(&server, &test_url, &alpha, None).await.status(), 404);
        let (_, v) = get_json(&server, &format!("/api/v1/submissions/{test}"), Some(&alpha)).await;
        assert!(
            !v.to_string().contains("video"),
            "a test view names a video: {v:#}"
        );
        let html = page_html(&server, &format!("/submissions/{test}"), &alpha).await;
        assert!(!html.contains("<video"), "a test page shows a video: {html}");
    });
}

/// A page as the team's browser gets it (session cookie).
/// Pre-rendering (`[video] prerender = "failed"`, the default): a dev episode that
/// failed its task has its video rendered once no evaluation job waits, before anyone asks;
/// the first request gets the MP4 at once, and it plays.
#[test]
fn a_failed_dev_episodes_video_is_rendered_before_anyone_asks() {
    use kitchen_r_episode::policy::HORIZON as H;
    use remote_support::{STILL, TestServer, factory};
    let policy = TestServer::start(
        factory(H, Arc::new(|_| Ok(vec![STILL; H]))),
        ServeOptions::default(),
    );
    let fx = ControlFixture::new(
        "[control]\noffline_mse = false\nmax_plan_steps = 1\ntask_time_limit_s = 3.0\n\
         [quota]\nconcurrent_runs = 0\n",
    );
    let server = fx.serve(1);
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let alpha = team(&server, "alpha").await;
        let (status, reg) = register_policy(
            &server,
            &alpha,
            json!({"endpoint": policy.url(), "split": "dev", "episodes": 1}),
        )
        .await;
        assert_eq!(status, 201, "{reg}");
        let dev = reg["id"].as_i64().unwrap();
        wait_for(&server, dev, &alpha, "the dev run", finished).await;
        // Nobody asks: the video becomes ready by itself.
        let mut eps = Vec::new();
        for _ in 0..300 {
            eps = episodes(&server, dev, &alpha).await;
            if eps.len() == 1 && eps[0]["video"]["status"] == "ready" {
                break;
            }
            tokio::time::sleep(std::time::Duration::from_millis(200)).await;
        }
        assert_eq!(eps[0]["video"]["status"], "ready", "{eps:#?}");
        let url = eps[0]["video_url"].as_str().unwrap().to_string();
        let r = get(&server, &url, &alpha, None).await;
        assert_eq!(r.status(), 200, "the first request gets the pre-rendered video");
        let (codec, frames) = decode(&r.bytes().await.unwrap());
        assert_eq!(codec, "avc1");
        assert!((frames - FRAMES).abs() <= 1, "{frames} frames");
    });
}

async fn page_html(server: &Server, path: &str, token: &str) -> String {
    let r = client()
        .get(server.url(path))
        .header("cookie", page_session(server, token).await)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200, "{path}");
    r.text().await.unwrap()
}
