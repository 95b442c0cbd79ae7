//! The runner drives a [`RemotePolicy`] over real loopback sockets: a good policy gets an outcome
//! for every task; NaN, a wrong shape, sleeping past the deadline, a dropped connection and a
//! huge answer each fail tasks with the right reason while the run completes; a private address
//! is refused before any packet is sent.

use crate::remote_support;

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

use kitchen_r_contract::server::ServeOptions;
use kitchen_r_contract::{Credentials, RemoteConfig, RemoteError, RemotePolicy};
use kitchen_r_episode::policy::{HORIZON, Policy};
use kitchen_r_episode::runner::{EpisodeOutcome, RunOptions, run_episode};
use remote_support::*;

fn opts() -> RunOptions {
    RunOptions {
        task_time_limit: 2.0,
        max_tasks: Some(2),
        ..RunOptions::default()
    }
}

fn run(policy: &mut RemotePolicy) -> EpisodeOutcome {
    let mut sim = sim();
    policy.set_scene(&sim.episode().scene.clone());
    run_episode(&mut sim, policy, &opts(), None, &mut ()).unwrap()
}

/// Every task has an outcome; each failure reason contains `needle`.
fn assert_failed_with(out: &EpisodeOutcome, needle: &str) {
    assert_eq!(out.tasks.len(), 2, "{out:?}");
    for t in &out.tasks {
        assert!(!t.success);
        let f = t.failure.as_deref().unwrap_or_default();
        assert!(
            f.contains(needle),
            "task {} failed with {f:?}, expected {needle:?}",
            t.index
        );
    }
}

#[test]
fn a_good_policy_completes_with_an_outcome_for_every_task() {
    let seen = Arc::new(AtomicUsize::new(0));
    let s2 = seen.clone();
    let server = TestServer::start(
        factory(
            HORIZON,
            Arc::new(move |i| {
                // Raw RGB8 at the default 128x128 for both default cameras, nothing privileged.
                let ok = i.observation.images.len() == 2
                    && i.observation.images.iter().all(|c| c.rgb.len() == 128 * 128 * 3)
                    && i.privileged.is_none();
                if ok {
                    s2.fetch_add(1, Ordering::SeqCst);
                }
                Ok(vec![STILL; HORIZON])
            }),
        ),
        ServeOptions::default(),
    );
    let mut p = connect(&server.url(), 10.0);
    assert_eq!(p.spec().horizon, HORIZON);
    assert_eq!(p.spec().cameras, ["base", "gripper"]);
    let out = run(&mut p);
    assert_failed_with(&out, "time limit of 2 s reached");
    assert!(out.policy_calls >= 2);
    assert_eq!(seen.load(Ordering::SeqCst), out.policy_calls as usize);
}

#[test]
fn nan_fails_the_task_with_the_reason() {
    let server = TestServer::start(
        factory(HORIZON, Arc::new(|_| Ok(vec![[f64::NAN; 10]; HORIZON]))),
        ServeOptions::default(),
    );
    assert_failed_with(&run(&mut connect(&server.url(), 10.0)), "value 0 is not finite");
}

#[test]
fn a_wrong_shape_fails_the_task_with_the_reason() {
    let server = TestServer::start(
        factory(HORIZON, Arc::new(|_| Ok(vec![STILL; 3]))),
        ServeOptions::default(),
    );
    assert_failed_with(
        &run(&mut connect(&server.url(), 10.0)),
        "expected 160 values (16 actions of 10), got 30",
    );
}

#[test]
fn sleeping_past_the_deadline_is_a_timeout_that_aborts_the_episode() {
    let server = TestServer::start(
        factory(
            HORIZON,
            Arc::new(|_| {
                std::thread::sleep(Duration::from_millis(1500));
                Ok(vec![STILL; HORIZON])
            }),
        ),
        ServeOptions::default(),
    );
    let mut p = connect(&server.url(), 0.2);
    let mut sim = sim();
    // One timeout aborts: a second call would queue behind the still-sleeping first one.
    let opts = RunOptions {
        max_consecutive_timeouts: 1,
        ..opts()
    };
    let out = run_episode(&mut sim, &mut p, &opts, None, &mut ()).unwrap();
    assert_failed_with(&out, "policy did not answer within 0.2 s");
    assert!(
        out.tasks[0]
            .failure
            .as_deref()
            .unwrap()
            .starts_with("episode aborted: 1 successive timeouts")
    );
}

#[test]
fn a_dropped_connection_fails_the_task_with_the_reason() {
    let server = TestServer::start(still(), ServeOptions::default());
    // Health and GetSpec pass (a few hundred bytes); an Act carrying 2x128x128 RGB does not.
    let proxy = dropping_proxy(server.addr, 20_000);
    let mut p = connect(&format!("http://{proxy}"), 10.0);
    assert_failed_with(&run(&mut p), "connection to the policy dropped");
}

#[test]
fn a_huge_answer_fails_the_task_with_the_reason_not_the_worker() {
    let server = TestServer::start(
        factory(HORIZON, Arc::new(|_| Ok(vec![STILL; 200_000]))),
        ServeOptions::default(),
    );
    assert_failed_with(
        &run(&mut connect(&server.url(), 10.0)),
        "exceeds the 1048576-byte size cap",
    );
}

#[test]
fn a_private_address_is_refused_before_connecting() {
    let err = RemotePolicy::connect(
        "http://10.20.30.40:50051",
        &Credentials::default(),
        &RemoteConfig::default(),
        &cameras(),
    )
    .unwrap_err();
    assert!(matches!(err, RemoteError::Endpoint(_)), "{err:?}");
    let msg = err.to_string();
    assert!(
        msg.contains("10.20.30.40") && msg.contains("policy.allowed_networks.private"),
        "{msg}"
    );
}

#[test]
fn an_endpoint_that_never_answers_fails_at_the_startup_deadline() {
    // A bound but never-accepting port: nothing listens once the listener is dropped.
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let cfg = RemoteConfig {
        startup_deadline_s: 0.5,
        ..RemoteConfig::default()
    };
    let err = RemotePolicy::connect(
        &format!("http://127.0.0.1:{port}"),
        &Credentials::default(),
        &cfg,
        &cameras(),
    )
    .unwrap_err();
    assert!(matches!(err, RemoteError::Unreachable { .. }), "{err:?}");
}
