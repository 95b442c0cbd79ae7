//! The pages in a real browser: headless Chromium (Debian's `chromium`) driven by Playwright for
//! Python (`tests/browser/check_pages.py`) against the real `kitchen-r serve` after a small
//! policy evaluation: a team's dev run of a policy that stands still (every task fails, with
//! its reason, and is recorded) and the organiser's reference run of the oracle (tasks done).
//! Videos are rendered on demand from the episodes' traces (docs/contest/video.md): the test asks
//! for each and waits (bounded) until all are rendered before the browser looks.
//!
//! The script opens every page as a visitor, as the team (logged in through the form) and as
//! the organiser (through the console's form), at 1280 px and at 375 px, and fails on console
//! errors, failed or 4xx/5xx same-origin requests, links that answer >= 400, a page wider than
//! 375 px, and a dev submission page without one decoding `<video>` per episode. Screenshots of
//! every page go to `KITCHEN_R_SCREENSHOTS` (else a temporary directory the output names).
//!
//! Without Chromium or Playwright the test is skipped outside CI (`scripts/test.sh` installs
//! Playwright; `.ci/run` installs Chromium) and fails in CI.

use crate::remote_support;
use crate::support::*;

use std::path::Path;
use std::process::Command;
use std::sync::Arc;
use std::time::{Duration, Instant};

use kitchen_r_contract::server::ServeOptions;
use serde_json::{Value, json};

const CHROMIUM: &str = "/usr/bin/chromium";
const EPISODES: usize = 3;
/// Upper bound on the browser script (about 30 pages at two widths; a debug server, 2 cores).
const SCRIPT_DEADLINE: Duration = Duration::from_secs(600);

/// Why the browser test cannot run here, if it cannot.
fn missing() -> Option<String> {
    if !Path::new(CHROMIUM).exists() {
        return Some(format!("no {CHROMIUM}: apt-get install chromium"));
    }
    let playwright = Command::new("python3")
        .args(["-c", "import playwright.sync_api"])
        .status()
        .is_ok_and(|s| s.success());
    (!playwright).then(|| "no Playwright for Python: pip install -r scripts/test-requirements.txt".into())
}

/// The online episodes of a finished dev run: the ones the page must show a video for.
fn online_episodes(view: &Value) -> usize {
    view["latest_run"]["evaluation"]["episodes"]
        .as_array()
        .map_or(0, |eps| eps.iter().filter(|e| e["mode"] == "online").count())
}

/// Upper bound on rendering a run's videos on demand (a debug server, 2 cores).
const RENDER_DEADLINE: Duration = Duration::from_secs(300);

/// Wait until every online episode of submission `id` has its trace, then ask for each video
/// and wait until every one is rendered (200), within [`RENDER_DEADLINE`].
async fn rendered(server: &Server, id: i64, who: &str) {
    let start = Instant::now();
    loop {
        let (_, view) = get_json(server, &format!("/api/v1/submissions/{id}"), Some(who)).await;
        let eps = view["latest_run"]["evaluation"]["episodes"]
            .as_array()
            .cloned()
            .unwrap_or_default();
        let urls: Vec<String> = (eps.iter())
            .filter(|e| e["mode"] == "online")
            .filter_map(|e| e["video_url"].as_str().map(str::to_string))
            .collect();
        let mut ready = urls.len() == EPISODES;
        for url in &urls {
            let r = client()
                .get(server.url(url))
                .bearer_auth(who)
                .send()
                .await
                .unwrap();
            assert!(matches!(r.status().as_u16(), 200 | 202), "{url}: {}", r.status());
            ready &= r.status() == 200;
        }
        if ready {
            return;
        }
        assert!(
            start.elapsed() < RENDER_DEADLINE,
            "submission {id}'s videos not rendered after {RENDER_DEADLINE:?}: {view:#}"
        );
        tokio::time::sleep(Duration::from_millis(500)).await;
    }
}

/// Run `cmd` with its output in `log`, killed after [`SCRIPT_DEADLINE`]; (success, output).
fn run_bounded(cmd: &mut Command, log: &Path) -> (bool, String) {
    let file = std::fs::File::create(log).unwrap();
    let mut child = Proc(
        cmd.stdout(file.try_clone().unwrap())
            .stderr(file)
            .spawn()
            .expect("run python3 tests/browser/check_pages.py"),
    );
    let start = Instant::now();
    let status = loop {
        if let Some(status) = child.0.try_wait().unwrap() {
            break Some(status);
        }
        if start.elapsed() > SCRIPT_DEADLINE {
            child.kill();
            break None;
        }
        std::thread::sleep(Duration::from_millis(200));
    };
    let mut report = std::fs::read_to_string(log).unwrap_or_default();
    if status.is_none() {
        report.push_str(&format!("\nkilled: still running after {SCRIPT_DEADLINE:?}"));
    }
    (status.is_some_and(|s| s.success()), report)
}

#[test]
fn every_page_renders_cleanly_with_playing_videos_in_chromium_at_desktop_and_375_px() {
    use kitchen_r_episode::policy::HORIZON as H;
    use remote_support::{STILL, TestServer, factory};
    if let Some(why) = missing() {
        assert!(
            std::env::var("CI").is_err(),
            "the browser test needs Chromium and Playwright in CI: {why}"
        );
        eprintln!("skipped: {why}");
        return;
    }
    let still = TestServer::start(
        factory(H, Arc::new(|_| Ok(vec![STILL; H]))),
        ServeOptions::default(),
    );
    let (_oracle, oracle_url) = oracle_policy();
    // One short task per episode keeps the run small; no offline episodes (no video of those).
    let fx = ControlFixture::new(
        "[control]\nlease_s = 4\nreaper_interval_s = 1\noffline_mse = false\nmax_plan_steps = 1\n\
         task_time_limit_s = 30.0\n",
    );
    let server = fx.serve(2);
    let rt = tokio::runtime::Runtime::new().unwrap();
    let (token, team_run, reference_run) = rt.block_on(async {
        let token = team(&server, "alpha").await;
        let mut ids = Vec::new();
        for (who, body) in [
            (
                token.as_str(),
                json!({"endpoint": still.url(), "split": "dev", "episodes": EPISODES}),
            ),
            (
                ADMIN,
                json!({"endpoint": oracle_url, "split": "dev", "episodes": EPISODES, "reference": true}),
            ),
        ] {
            let (status, reg) = register_policy(&server, who, body).await;
            assert_eq!(status, 201, "{reg}");
            ids.push(reg["id"].as_i64().unwrap());
        }
        for (id, who) in [(ids[0], token.as_str()), (ids[1], ADMIN)] {
            let view = wait_for(&server, id, who, "a dev run", finished).await;
            assert_eq!(view["latest_run"]["evaluation"]["state"], "finished", "{view:#}");
            assert_eq!(online_episodes(&view), EPISODES, "{view:#}");
        }
        // Videos are rendered on demand: ask for each and wait until all are stored,
        // so the pages show one playing `<video>` per episode.
        for (id, who) in [(ids[0], token.as_str()), (ids[1], ADMIN)] {
            rendered(&server, id, who).await;
        }
        (token, ids[0], ids[1])
    });

    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/browser/check_pages.py");
    let log = fx.dir.path().join("check_pages.log");
    let mut cmd = Command::new("python3");
    cmd.arg(script)
        .args([
            "--base",
            &server.http,
            "--team-token",
            &token,
            "--admin-token",
            ADMIN,
        ])
        .args(["--dev-submission", &format!("team:{team_run}")])
        .args(["--dev-submission", &format!("admin:{reference_run}")])
        .args(["--videos", &EPISODES.to_string()])
        .args(["--page", &format!("/leaderboard/control/dev/{reference_run}")])
        .args(["--chromium", CHROMIUM]);
    let (passed, report) = run_bounded(&mut cmd, &log);
    println!("{report}");
    assert!(passed, "the browser found problems:\n{report}");
    // Every kind of page was opened, and a video per episode of both runs decoded.
    for page in [
        "[visitor] /contest",
        "[visitor] /team/login",
        "[team] /team",
        &format!("[team] /submissions/{team_run}"),
        &format!("[admin] /submissions/{reference_run}"),
        "[admin] /admin",
        &format!("/leaderboard/control/dev/{reference_run}"),
    ] {
        assert!(report.contains(page), "{page} was not opened:\n{report}");
    }
    let decoded = report
        .split_once(" videos decoded")
        .and_then(|(head, _)| head.rsplit(' ').next()?.parse::<usize>().ok())
        .unwrap_or(0);
    assert!(decoded >= 2 * EPISODES, "{decoded} videos decoded:\n{report}");
}
