//! Storage budgets and trace sizes (docs/contest/video.md), end to end: the largest trace a legal
//! policy makes (one action of each chunk executed, every task failed, actions that do not
//! compress) is stored, reaches a worker in chunks (`FetchTrace`, never inside a lease reply, whose
//! gRPC limit is 4 MiB) and renders into a playable video; and a server whose storage budget
//! exceeds its volume's free space warns at start, or refuses under `--strict`.

use crate::remote_support;
use crate::support;

use std::process::Command;
use std::sync::Arc;
use std::time::Instant;

use kitchen_r_contract::server::{PolicyFactory, ServeOptions};
use kitchen_r_episode::policy::{HORIZON as H, Policy, PolicyError, PolicyInput, PolicySpec};
use serde_json::{Value, json};
use support::*;

/// A legal policy whose trace is as large as a trace gets: it executes one action of each chunk
/// (the least `[control] min_actions_executed_per_chunk` allows) and answers every chunk with
/// actions that vary in every digit (gzip gains little), while barely moving, so each task runs
/// to its time limit and fails.
struct Noisy {
    spec: PolicySpec,
    state: u64,
}

impl Noisy {
    /// xorshift: deterministic noise.
    fn next(&mut self) -> f64 {
        self.state ^= self.state << 13;
        self.state ^= self.state >> 7;
        self.state ^= self.state << 17;
        (self.state >> 11) as f64 / (1u64 << 53) as f64
    }
}

impl Policy for Noisy {
    fn spec(&self) -> &PolicySpec {
        &self.spec
    }
    fn reset(&mut self, _: &str, _: usize, _: &str) -> Result<(), PolicyError> {
        Ok(())
    }
    fn act(&mut self, _: &PolicyInput<'_>) -> Result<Vec<[f64; 10]>, PolicyError> {
        let mut chunk = vec![remote_support::STILL; H];
        for a in &mut chunk {
            // Every value full of digits, each small: the base creeps, the hand trembles.
            a[0] = (self.next() - 0.5) * 1e-3;
            a[1] = (self.next() - 0.5) * 1e-3;
            for v in &mut a[2..5] {
                *v += (self.next() - 0.5) * 1e-2;
            }
            for v in &mut a[5..9] {
                *v += (self.next() - 0.5) * 1e-2;
            }
            let norm = a[5..9].iter().map(|q| q * q).sum::<f64>().sqrt();
            a[5..9].iter_mut().for_each(|q| *q /= norm);
            a[9] = 0.5 + self.next() * 0.5;
        }
        Ok(chunk)
    }
}

fn noisy() -> PolicyFactory {
    Arc::new(|| {
        Box::new(Noisy {
            spec: PolicySpec {
                name: "noisy".into(),
                horizon: H,
                actions_executed_per_chunk: Some(1),
                ..PolicySpec::default()
            },
            state: 0x9E37_79B9_7F4A_7C15,
        }) as Box<dyn Policy>
    })
}

/// The committed benchmark with dev-0007, the first of the longest plans (8 tasks), also as
/// `dev-0000`, the first of the dev split, so a one-episode run is the longest episode there is.
fn longest_first(dir: &std::path::Path) -> std::path::PathBuf {
    let repo = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets");
    let assets = dir.join("assets");
    copy_dir(&repo, &assets);
    let dev = std::fs::read_to_string(repo.join("dataset/dev.jsonl")).unwrap();
    let longest = dev.lines().find(|l| l.contains("\"dev-0007\"")).unwrap();
    let v: Value = serde_json::from_str(longest).unwrap();
    assert_eq!(v["plan"].as_array().unwrap().len(), 8, "{v}");
    let first = longest.replace("\"dev-0007\"", "\"dev-0000\"");
    std::fs::write(assets.join("dataset/dev.jsonl"), format!("{first}\n{dev}")).unwrap();
    assets
}

fn copy_dir(from: &std::path::Path, to: &std::path::Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap().flatten() {
        let target = to.join(e.file_name());
        match e.file_type().unwrap().is_dir() {
            true => copy_dir(&e.path(), &target),
            false => drop(std::fs::copy(e.path(), target).unwrap()),
        }
    }
}

/// The longest default episode (8 tasks of 120 s), one action of each chunk executed, every
/// task failed, noise in every value: the largest trace a legal policy makes, far past the
/// 4 MiB a lease reply could carry. Its video is asked for, rendered from the trace fetched in
/// chunks, and plays.
#[test]
fn the_largest_trace_a_legal_policy_makes_renders_into_a_playable_video() {
    let policy = remote_support::TestServer::start(noisy(), ServeOptions::default());
    let tmp = tempfile::tempdir().unwrap();
    let assets = longest_first(tmp.path());
    let fx = ControlFixture::new(&format!(
        "assets = \"{}\"\n[control]\noffline_mse = false\n[quota]\nconcurrent_runs = 0\n[video]\nprerender = \"none\"\n",
        assets.display()
    ));
    let server = fx.serve(1);
    let videos = fx.dir.path().join("db/videos");
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
        let id = reg["id"].as_i64().unwrap();
        let started = Instant::now();
        wait_for(&server, id, &alpha, "the dev run", finished).await;
        let evaluated = started.elapsed();
        let ep = until_status(&server, id, &alpha, "available").await;
        let tasks = ep["tasks"].as_array().unwrap();
        assert!(tasks.len() == 8 && tasks.iter().all(|t| t["success"] == false), "{ep:#}");
        let trace = largest(&videos, ".json.gz");
        assert!(trace > 4 << 20, "the trace is {trace} bytes: no larger than a lease reply may be");
        let url = ep["video_url"].as_str().unwrap().to_string();
        let started = Instant::now();
        let r = until_video(&server, &url, &alpha).await;
        assert_eq!(r.status(), 200);
        let mp4 = r.bytes().await.unwrap();
        let rendered = started.elapsed();
        let frames = decode_frames(&mp4);
        // One frame per control step: 120 s of each task at 10 Hz.
        assert!(frames >= 8 * 1200, "{frames} frames");
        eprintln!(
            "largest trace: {trace} bytes gzipped; evaluation {:.0} s; video {} bytes, {frames} frames, rendered in {:.0} s",
            evaluated.as_secs_f64(),
            mp4.len(),
            rendered.as_secs_f64()
        );
    });
}

/// Poll the one episode of submission `id` until its video has `status`.
async fn until_status(server: &Server, id: i64, token: &str, status: &str) -> Value {
    for _ in 0..600 {
        let (_, v) = get_json(server, &format!("/api/v1/submissions/{id}"), Some(token)).await;
        let ep = &v["latest_run"]["evaluation"]["episodes"][0];
        if ep["video"]["status"] == status {
            return ep.clone();
        }
        tokio::time::sleep(std::time::Duration::from_millis(300)).await;
    }
    panic!("the episode's video never became {status}");
}

/// GET `url` until it answers other than 202 (rendering); a failed render says why.
async fn until_video(server: &Server, url: &str, token: &str) -> reqwest::Response {
    let start = Instant::now();
    loop {
        let r = client()
            .get(server.url(url))
            .bearer_auth(token)
            .send()
            .await
            .unwrap();
        if r.status() != 202 {
            return r;
        }
        let v: Value = r.json().await.unwrap();
        assert!(v["status"] == "queued" || v["status"] == "rendering", "{v}");
        assert!(start.elapsed().as_secs() < 900, "the render never finished: {v}");
        tokio::time::sleep(std::time::Duration::from_millis(500)).await;
    }
}

/// The largest file under `dir` whose name ends with `suffix`, bytes.
fn largest(dir: &std::path::Path, suffix: &str) -> u64 {
    let mut best = 0;
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else if p.to_string_lossy().ends_with(suffix) {
                best = best.max(e.metadata().unwrap().len());
            }
        }
    }
    best
}

/// How many frames of `mp4` decode with PyAV (FFmpeg's decoders).
fn decode_frames(mp4: &[u8]) -> i64 {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("episode.mp4");
    std::fs::write(&file, mp4).unwrap();
    let script =
        "import av, sys\nc = av.open(sys.argv[1])\nprint(sum(1 for _ in c.decode(c.streams.video[0])))";
    let o = ok(Command::new("python3")
        .args(["-c", script])
        .arg(&file)
        .output()
        .unwrap());
    out(&o).trim().parse().unwrap()
}

/// A total budget no disk holds (1 PiB, set as a deployment does, from the environment): `serve`
/// warns at start and serves; with `--strict` it refuses, naming the key and the largest budget
/// that fits.
#[test]
fn a_budget_larger_than_the_volume_warns_at_start_and_is_refused_when_strict() {
    let fx = ControlFixture::new("");
    let config = fx.dir.path().join("server.toml");
    let serve = |strict: bool| {
        let mut cmd = Command::new(bin());
        cmd.args(["serve", "--workers", "0", "--config"])
            .arg(&config)
            .env("KITCHEN_R_ADMIN_TOKEN", ADMIN)
            .env("KITCHEN_R_VIDEO_TOTAL_MAX_BYTES", "1125899906842624")
            .env("RUST_LOG", "warn");
        if strict {
            cmd.arg("--strict");
        }
        cmd
    };
    let o = serve(true).output().unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("[video] total_max_bytes") && err.contains("strict"),
        "{err}"
    );
    assert!(err.contains("lower total_max_bytes"), "{err}");
    // Without --strict: the same words as a warning, and the server listens.
    let mut child = serve(false)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let stdout = std::io::BufReader::new(child.stdout.take().unwrap());
    let listening = std::io::BufRead::lines(stdout)
        .map_while(Result::ok)
        .any(|l| l.starts_with("listening "));
    let _ = child.kill();
    let o = child.wait_with_output().unwrap();
    assert!(
        listening,
        "the server did not start: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let warned = String::from_utf8_lossy(&o.stderr);
    assert!(warned.contains("[video] total_max_bytes"), "{warned}");
    assert!(!warned.contains("refused"), "{warned}");
}
