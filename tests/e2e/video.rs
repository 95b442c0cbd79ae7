//! Episode videos end to end (issue #15 item 1): `kitchen-r serve` with in-process workers runs
//! a team's small dev policy run; each episode's video is recorded by the worker, uploaded over
//! the worker gRPC service, stored, and served with byte ranges to the team, never to another
//! team; a test-split run's videos are stored but shown to the organiser only.

use crate::remote_support;
use crate::support;

use std::process::Command;
use std::sync::Arc;

use kitchen_r_contract::server::ServeOptions;
use serde_json::{Value, json};
use support::*;

/// One-task episodes of 3 s of sim time: 30 control steps, so 30 frames.
const CONFIG: &str = "[control]\noffline_mse = false\nmax_plan_steps = 1\ntask_time_limit_s = 3.0\n\
                      [quota]\nconcurrent_runs = 0\n[video]\ntest_split = true\n";
const FRAMES: i64 = 30;

async fn get(server: &Server, path: &str, token: &str, range: Option<&str>) -> reqwest::Response {
    let mut req = client().get(server.url(path)).bearer_auth(token);
    if let Some(r) = range {
        req = req.header("range", r);
    }
    req.send().await.unwrap()
}

/// Decode `mp4` with PyAV (FFmpeg's dav1d or libaom): the track's sample entry (`av01` for AV1)
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

#[test]
fn a_dev_episode_video_is_served_with_ranges_to_its_team_only_and_test_videos_to_the_organiser() {
    use kitchen_r_episode::policy::HORIZON as H;
    use remote_support::{STILL, TestServer, factory};
    let policy = TestServer::start(
        factory(H, Arc::new(|_| Ok(vec![STILL; H]))),
        ServeOptions::default(),
    );
    let fx = ControlFixture::new(CONFIG);
    let server = fx.serve(2);
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
                        // The test split always runs in full: only its first episode is awaited.
                        "test" => json!({"endpoint": url, "split": split}),
                        _ => json!({"endpoint": url, "split": split, "episodes": 1}),
                    },
                )
                .await;
                assert_eq!(status, 201, "{reg}");
                reg["id"].as_i64().unwrap()
            }
        };
        let (dev, test) = (register("dev").await, register("test").await);
        let view = wait_for(&server, dev, &alpha, "the dev run", finished).await;
        let ep: Value = view["latest_run"]["evaluation"]["episodes"][0].clone();
        let key = ep["key"].as_str().unwrap().to_string();
        // The result is in before the upload is: wait for the link to appear.
        let mut url = ep["video_url"].as_str().map(str::to_string);
        for _ in 0..100 {
            if url.is_some() {
                break;
            }
            tokio::time::sleep(std::time::Duration::from_millis(200)).await;
            let (_, v) = get_json(&server, &format!("/api/v1/submissions/{dev}"), Some(&alpha)).await;
            url = v["latest_run"]["evaluation"]["episodes"][0]["video_url"]
                .as_str()
                .map(str::to_string);
        }
        let url = url.unwrap_or_else(|| panic!("no video_url on the dev episode: {view:#}"));
        assert_eq!(url, format!("/api/v1/submissions/{dev}/episodes/{key}/video.mp4"));

        let whole = get(&server, &url, &alpha, None).await;
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
        assert_eq!(codec, "av01");
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
        // The submission page plays it inline, at the page route.
        let html = page_html(&server, &format!("/submissions/{dev}"), &alpha).await;
        assert!(html.contains("<video"), "{html}");
        assert!(html.contains(&format!("src=\"{page}\"")), "{html}");

        // Test split: the organiser sees the first episode's video once stored; the team never.
        let test_url = format!("/api/v1/submissions/{test}/episodes/test-0001/video.mp4");
        let mut status = 0;
        for _ in 0..300 {
            status = get(&server, &test_url, ADMIN, Some("bytes=0-7"))
                .await
                .status()
                .as_u16();
            if status == 206 {
                break;
            }
            tokio::time::sleep(std::time::Duration::from_millis(300)).await;
        }
        assert_eq!(status, 206, "the organiser never got the test episode's video");
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
