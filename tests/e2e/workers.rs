//! Operating the workers (docs/control-track-worker.md), every part a real process on loopback:
//! a `kitchen-r worker` stopped with SIGTERM mid-episode drains (its running episode is released
//! and another worker takes it at once, long before the lease would expire), leasing shares the
//! slots across teams (a later small run is not starved by a big slow one), and the settings of
//! both configuration files reach what they configure.

use crate::remote_support;
use crate::support;

use std::process::{Child, Command, ExitStatus};
use std::sync::Arc;
use std::time::{Duration, Instant};

use kitchen_r_contract::server::{PolicyFactory, ServeOptions};
use kitchen_r_episode::policy::{HORIZON, Policy, PolicySpec};
use remote_support::{STILL, Scripted, TestServer};
use serde_json::{Value, json};
use support::*;

/// A policy that stands still, answering each call after `delay`, announcing `max_concurrency`.
fn slow_policy(delay: Duration, max_concurrency: u32) -> TestServer {
    let factory: PolicyFactory = Arc::new(move || {
        Box::new(Scripted {
            spec: PolicySpec {
                max_concurrency,
                ..remote_support::spec(HORIZON)
            },
            answer: Arc::new(move |_| {
                std::thread::sleep(delay);
                Ok(vec![STILL; HORIZON])
            }),
        }) as Box<dyn Policy>
    });
    TestServer::start(factory, ServeOptions::default())
}

/// `kitchen-r worker` with the test token and extra flags, ready.
fn spawn_worker(server: &Server, id: &str, extra: &[&str]) -> Proc {
    let (child, _) = spawn_ready(
        Command::new(bin())
            .args(["worker", "--server", &server.grpc, "--worker-id", id])
            .args(extra)
            .env("KITCHEN_R_WORKER_TOKEN", WORKER_TOKEN)
            .env("RUST_LOG", "warn"),
        "worker ready",
    );
    Proc(child)
}

fn sigterm(child: &Child) {
    let ok = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(ok.success());
}

/// Wait for `child` to exit, at most `limit`.
fn exit_within(child: &mut Child, limit: Duration) -> ExitStatus {
    let t = Instant::now();
    loop {
        if let Some(s) = child.try_wait().unwrap() {
            return s;
        }
        if t.elapsed() >= limit {
            let _ = child.kill();
            let _ = child.wait();
            panic!("the process did not exit within {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn eval(view: &Value) -> &Value {
    &view["latest_run"]["evaluation"]
}

#[test]
fn a_sigtermed_worker_drains_and_its_released_episode_is_taken_at_once() {
    // About 8 calls of 0.5 s per episode: 4 s or more, so a grace of 1 s cannot cover it. (Policy
    // servers run their own runtime: made and dropped outside the test's.)
    let policy = slow_policy(Duration::from_millis(500), 1);
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(drain_case(&policy));
}

async fn drain_case(policy: &TestServer) {
    // Leases of 60 s (the default): a job lost by the worker would come back only after a minute.
    let fx = ControlFixture::new(
        "[control]\nlease_s = 60\nreaper_interval_s = 1\noffline_mse = false\nmax_plan_steps = 1\n\
         task_time_limit_s = 6.0\n",
    );
    let server = fx.serve(0);
    let body = json!({"endpoint": policy.url(), "split": "dev", "episodes": 2, "reference": true});
    let (status, reg) = register_policy(&server, ADMIN, body).await;
    assert_eq!(status, 201, "{reg}");
    let id = reg["id"].as_i64().unwrap();

    let mut first = spawn_worker(&server, "draining", &["--slots", "1", "--drain-grace-s", "1"]);
    wait_for(&server, id, ADMIN, "an episode to start", |e| {
        e["episodes_running"].as_u64().unwrap_or(0) >= 1
    })
    .await;
    tokio::time::sleep(Duration::from_millis(300)).await;
    let term = Instant::now();
    sigterm(&first.0);
    let status = exit_within(&mut first.0, Duration::from_secs(20));
    let drained = term.elapsed();
    assert!(status.success(), "a drained worker exits 0: {status:?}");
    assert!(drained < Duration::from_secs(10), "drained in {drained:?}");
    // The running episode was released, not abandoned: queued again with the reason, at once.
    let view = wait_for(&server, id, ADMIN, "the released episode", |e| {
        e["retrying"].as_array().is_some_and(|r| {
            r.iter()
                .any(|j| j["last_error"].as_str().unwrap_or("").contains("released"))
        })
    })
    .await;
    assert_eq!(eval(&view)["episodes_done"], 0, "{view:#}");
    assert_eq!(eval(&view)["episodes_running"], 0, "{view:#}");
    let released = eval(&view)["retrying"][0]["key"].as_str().unwrap().to_string();

    let _second = spawn_worker(&server, "successor", &["--slots", "1"]);
    wait_for(
        &server,
        id,
        ADMIN,
        "the released episode to be leased again",
        |e| e["episodes_running"].as_u64().unwrap_or(0) >= 1,
    )
    .await;
    let taken = term.elapsed();
    assert!(
        taken < Duration::from_secs(10),
        "the released episode was leased again {taken:?} after SIGTERM (the lease is 60 s)"
    );
    let view = wait_for(&server, id, ADMIN, "the run after the drain", finished).await;
    assert_eq!(eval(&view)["state"], "finished", "{view:#}");
    let eps = eval(&view)["episodes"].as_array().unwrap().clone();
    let mut keys: Vec<&str> = eps.iter().filter_map(|e| e["key"].as_str()).collect();
    keys.sort_unstable();
    keys.dedup();
    assert_eq!((keys.len(), eps.len()), (2, 2), "every episode once: {view:#}");
    assert_eq!(eval(&view)["episodes_done"], 2, "{view:#}");
    let again = eps.iter().find(|e| e["key"] == released.as_str()).unwrap();
    assert!(again["failure"].is_null(), "the released episode ran: {again:#}");
    eprintln!(
        "drain: worker exited {drained:?} after SIGTERM; released episode leased again after {taken:?}"
    );
}

#[test]
fn the_servers_in_process_slots_drain_at_shutdown_too() {
    let policy = slow_policy(Duration::from_millis(500), 1);
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let fx = ControlFixture::new(
            "[control]\nlease_s = 60\nreaper_interval_s = 1\noffline_mse = false\n\
             max_plan_steps = 1\ntask_time_limit_s = 6.0\ndrain_grace_s = 0\n",
        );
        let id = {
            let mut server = fx.serve(1);
            let body = json!({"endpoint": policy.url(), "split": "dev", "episodes": 2, "reference": true});
            let (status, reg) = register_policy(&server, ADMIN, body).await;
            assert_eq!(status, 201, "{reg}");
            let id = reg["id"].as_i64().unwrap();
            wait_for(&server, id, ADMIN, "an episode to start", |e| {
                e["episodes_running"].as_u64().unwrap_or(0) >= 1
            })
            .await;
            let term = Instant::now();
            sigterm(server.child());
            let status = exit_within(server.child(), Duration::from_secs(30));
            assert!(status.success(), "{status:?}");
            eprintln!(
                "serve drained its slots and exited {:?} after SIGTERM",
                term.elapsed()
            );
            id
        };
        // Restarted: the episode is queued (released with its reason), not leased until the
        // 60 s lease expires, and the run finishes with every episode once.
        let server = fx.serve(1);
        let (_, view) = get_json(&server, &format!("/api/v1/submissions/{id}"), Some(ADMIN)).await;
        let retrying = eval(&view)["retrying"].as_array().cloned().unwrap_or_default();
        assert!(
            retrying
                .iter()
                .any(|j| j["last_error"].as_str().unwrap_or("").contains("released")),
            "{view:#}"
        );
        let restarted = Instant::now();
        let view = wait_for(&server, id, ADMIN, "the run after the restart", finished).await;
        assert!(
            restarted.elapsed() < Duration::from_secs(60),
            "{:?}",
            restarted.elapsed()
        );
        assert_eq!(eval(&view)["state"], "finished", "{view:#}");
        assert_eq!(eval(&view)["episodes_done"], 2, "{view:#}");
        let eps = eval(&view)["episodes"].as_array().unwrap();
        assert_eq!(eps.len(), 2, "{view:#}");
        assert_ne!(eps[0]["key"], eps[1]["key"], "{view:#}");
    });
}

#[test]
fn a_later_small_run_starts_within_one_episode_of_a_big_slow_one() {
    let slow = slow_policy(Duration::from_millis(300), 64);
    let quick = slow_policy(Duration::from_millis(1), 1);
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(fairness_case(&slow, &quick));
}

async fn fairness_case(slow: &TestServer, quick: &TestServer) {
    // Fair sharing (docs/control-track-server.md, Lease): team A's slow policy (max_concurrency 64)
    // with 40 episodes, then team B with 2; two slots. Before, B's first episode waited for A's
    // whole backlog.
    let fx =
        ControlFixture::new("[control]\noffline_mse = false\nmax_plan_steps = 1\ntask_time_limit_s = 4.0\n");
    let server = fx.serve(2);
    let a = team(&server, "alpha").await;
    let (status, reg) = register_policy(
        &server,
        &a,
        json!({"endpoint": slow.url(), "split": "dev", "episodes": 40}),
    )
    .await;
    assert_eq!(status, 201, "{reg}");
    let a_id = reg["id"].as_i64().unwrap();
    wait_for(&server, a_id, &a, "both slots busy with A", |e| {
        e["episodes_running"].as_u64().unwrap_or(0) >= 2
    })
    .await;

    let b = team(&server, "bravo").await;
    let (status, reg) = register_policy(
        &server,
        &b,
        json!({"endpoint": quick.url(), "split": "dev", "episodes": 2}),
    )
    .await;
    assert_eq!(status, 201, "{reg}");
    let b_id = reg["id"].as_i64().unwrap();
    let registered = Instant::now();
    wait_for(&server, b_id, &b, "B's first episode", |e| {
        e["episodes_running"].as_u64().unwrap_or(0) + e["episodes_done"].as_u64().unwrap_or(0) >= 1
    })
    .await;
    let waited = registered.elapsed();
    let (_, view) = get_json(&server, &format!("/api/v1/submissions/{a_id}"), Some(&a)).await;
    let a_done = eval(&view)["episodes_done"].as_u64().unwrap();
    let longest = eval(&view)["episodes"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|e| e["wall_ms"].as_u64())
        .max()
        .unwrap_or(0);
    eprintln!(
        "fairness: B's first episode started {waited:?} after registering; A's longest episode \
         {longest} ms; A had {a_done} of 40 done"
    );
    assert!(
        a_done < 10,
        "B waited for A's backlog: {a_done} of A's episodes done first"
    );
    // Within one episode's time (plus the polling of this test and of the lease).
    let bound = Duration::from_millis(longest.max(1_000)) + Duration::from_secs(2);
    assert!(
        waited <= bound,
        "B waited {waited:?}, more than one episode ({bound:?})"
    );
    let view = wait_for(&server, b_id, &b, "B's run", finished).await;
    assert_eq!(eval(&view)["episodes_done"], 2, "{view:#}");
    let (_, view) = get_json(&server, &format!("/api/v1/submissions/{a_id}"), Some(&a)).await;
    assert!(
        eval(&view)["episodes_done"].as_u64().unwrap() < 40,
        "B finished before A's backlog: {view:#}"
    );
}

#[test]
fn the_worker_takes_slots_from_its_config_file_and_refuses_the_second_networks_key() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("worker.toml");
    let run = |text: &str, extra: &[&str]| {
        std::fs::write(&file, text).unwrap();
        let mut cmd = Command::new(bin());
        cmd.args(["worker", "--server", "http://127.0.0.1:9", "--config"])
            .arg(&file)
            .args(extra)
            .env("KITCHEN_R_WORKER_TOKEN", WORKER_TOKEN)
            .env("RUST_LOG", "warn");
        cmd
    };
    // `slots` in the file is used (it was overwritten by the core count), and the flag wins.
    let (child, ready) = spawn_ready(
        &mut run("slots = 3\nmax_episodes = 5\ndrain_grace_s = 7\n", &[]),
        "worker ready",
    );
    drop(Proc(child));
    assert!(
        ready.contains(" slots=3 max_episodes=5 ") && ready.ends_with("drain_grace_s=7"),
        "{ready}"
    );
    let (child, ready) = spawn_ready(
        &mut run(
            "slots = 3\nmax_episodes = 5\n",
            &["--slots", "2", "--max-episodes", "9", "--drain-grace-s", "0"],
        ),
        "worker ready",
    );
    drop(Proc(child));
    assert!(
        ready.contains(" slots=2 max_episodes=9 ") && ready.ends_with("drain_grace_s=0"),
        "{ready}"
    );
    // Unset, a worker holds 8 episodes per slot.
    let (child, ready) = spawn_ready(&mut run("slots = 2\n", &[]), "worker ready");
    drop(Proc(child));
    assert!(ready.contains(" slots=2 max_episodes=16 "), "{ready}");
    // The transport's own allow-list switch is refused, naming the one key to use.
    let out = run(
        "allow_networks = [\"10.0.0.0/8\"]\n[policy.allowed_networks]\nprivate = true\n",
        &[],
    )
    .output()
    .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("policy.allowed_networks") && err.contains("`allow_networks`"),
        "{err}"
    );
}

#[test]
fn the_servers_assets_setting_reaches_its_in_process_simulators() {
    // The planning fixture's assets have scenes and a catalogue but no robot: the server itself
    // serves from them, and in-process slots must load their simulators from there too, so they
    // refuse to start, naming the directory (they used to load the checkout's assets instead).
    let fx = Fixture::new("");
    let mut child = Command::new(bin())
        .args(["serve", "--workers", "1", "--config"])
        .arg(fx.config_path())
        .env("KITCHEN_R_ADMIN_TOKEN", ADMIN)
        .env("RUST_LOG", "warn")
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let status = exit_within(&mut child, Duration::from_secs(60));
    let mut err = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut err).unwrap();
    assert!(!status.success(), "{err}");
    let assets = fx.dir.path().join("assets");
    assert!(
        err.contains(&assets.display().to_string()) && err.contains("kitchen_r_aloha.urdf"),
        "{err}"
    );
}
