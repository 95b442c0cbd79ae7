//! The oracle served over gRPC drives an episode to the same outcome, bit for bit, as the
//! in-process oracle (privileged state and chunks cross the wire in full precision); without
//! privileged state it refuses with FAILED_PRECONDITION and a reason.

use crate::remote_support;

use std::sync::Arc;

use kitchen_r_contract::server::{PolicyFactory, ServeOptions};
use kitchen_r_episode::oracle::{OraclePolicy, expert_options};
use kitchen_r_episode::policy::Policy;
use kitchen_r_episode::runner::{RunOptions, run_episode};
use kitchen_r_sim::Assets;
use remote_support::*;

fn oracle_server() -> TestServer {
    let assets = Arc::new(Assets::load_default().unwrap());
    let f: PolicyFactory = Arc::new(move || Box::new(OraclePolicy::new(&assets)) as Box<dyn Policy>);
    TestServer::start(f, ServeOptions::default())
}

fn opts() -> RunOptions {
    RunOptions {
        max_tasks: Some(3),
        ..RunOptions {
            execute: 8,
            ..expert_options()
        }
    }
}

#[test]
fn the_oracle_over_grpc_gives_the_in_process_numbers() {
    let mut local = OraclePolicy::new(&Assets::load_default().unwrap());
    let mut sim_a = sim();
    let a = run_episode(&mut sim_a, &mut local, &opts(), None, &mut ()).unwrap();

    let server = oracle_server();
    let mut remote = connect(&server.url(), 30.0);
    let mut sim_b = sim();
    remote.set_scene(&sim_b.episode().scene.clone());
    let b = run_episode(&mut sim_b, &mut remote, &opts(), None, &mut ()).unwrap();

    assert!(a.tasks.iter().any(|t| t.success), "{a:?}");
    assert_eq!(a.tasks, b.tasks);
    assert_eq!(a.sim_time.to_bits(), b.sim_time.to_bits());
    assert_eq!(a.policy_calls, b.policy_calls);
}

#[test]
fn the_served_oracle_refuses_a_run_without_privileged_state() {
    let server = oracle_server();
    let mut remote = connect(&server.url(), 30.0);
    let mut sim = sim();
    let opts = RunOptions {
        privileged: false,
        max_tasks: Some(1),
        ..RunOptions::default()
    };
    let out = run_episode(&mut sim, &mut remote, &opts, None, &mut ()).unwrap();
    let f = out.tasks[0].failure.as_deref().unwrap();
    assert!(
        f.contains("FailedPrecondition") && f.contains("only organiser reference runs send"),
        "{f}"
    );
}
