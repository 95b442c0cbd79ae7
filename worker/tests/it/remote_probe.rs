//! The registration probe: a good endpoint is accepted with its spec, and each refusal says
//! what failed (private address with the config key, health not SERVING, unusable GetSpec).

use crate::remote_support;

use std::time::Duration;

use kitchen_r_contract::probe::{ProbeFailure, probe_endpoint};
use kitchen_r_contract::{AllowedNetworks, RemoteConfig};
use remote_support::*;
use tonic_health::ServingStatus;

fn cfg() -> RemoteConfig {
    RemoteConfig {
        startup_deadline_s: 1.0,
        call_deadline_s: 2.0,
        ..RemoteConfig::default()
    }
}

fn rt() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap()
}

#[test]
fn a_good_endpoint_is_accepted_with_its_spec() {
    let server = TestServer::start(still(), Default::default());
    let p = rt()
        .block_on(probe_endpoint(
            &server.url(),
            Some("secret"),
            "",
            &AllowedNetworks::default(),
            &cfg(),
        ))
        .unwrap();
    assert_eq!((p.protocol_version, p.max_concurrency), (1, 1));
    assert!(
        p.summary.contains("horizon 16") && p.summary.contains("\"scripted\""),
        "{}",
        p.summary
    );
}

#[test]
fn a_private_address_is_refused_naming_the_class_and_the_key() {
    let err = rt()
        .block_on(probe_endpoint(
            "http://10.1.2.3:50051",
            None,
            "",
            &AllowedNetworks::default(),
            &cfg(),
        ))
        .unwrap_err();
    assert!(matches!(err, ProbeFailure::Refused { .. }), "{err:?}");
    let msg = err.to_string();
    for needle in ["10.1.2.3", "private", "policy.allow_networks", "\"10.0.0.0/8\""] {
        assert!(msg.contains(needle), "{msg} lacks {needle}");
    }
    let err = rt()
        .block_on(probe_endpoint(
            "ftp://x:1",
            None,
            "",
            &AllowedNetworks::default(),
            &cfg(),
        ))
        .unwrap_err();
    assert!(err.to_string().contains("http://HOST:PORT"), "{err}");
}

/// A runtime serving only `grpc.health.v1`, answering NOT_SERVING, and its address.
fn not_serving_health_server() -> (tokio::runtime::Runtime, std::net::SocketAddr) {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .unwrap();
    let listener = rt.block_on(tokio::net::TcpListener::bind("127.0.0.1:0")).unwrap();
    let addr = listener.local_addr().unwrap();
    rt.spawn(async move {
        let (reporter, health) = tonic_health::server::health_reporter();
        reporter.set_service_status("", ServingStatus::NotServing).await;
        tonic::transport::Server::builder()
            .add_service(health)
            .serve_with_incoming(tokio_stream::wrappers::TcpListenerStream::new(listener))
            .await
    });
    (rt, addr)
}

#[test]
fn an_endpoint_not_serving_is_refused_with_its_status() {
    let (rt, addr) = not_serving_health_server();
    let err = rt
        .block_on(probe_endpoint(
            &format!("http://{addr}"),
            None,
            "",
            &AllowedNetworks::default(),
            &cfg(),
        ))
        .unwrap_err();
    assert!(matches!(err, ProbeFailure::NotServing(_)), "{err:?}");
    assert!(err.to_string().contains("NOT_SERVING"), "{err}");

    // Nothing listening at all: unreachable, after the startup deadline.
    let free = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap();
    let err = rt
        .block_on(probe_endpoint(
            &format!("http://{free}"),
            None,
            "",
            &AllowedNetworks::default(),
            &cfg(),
        ))
        .unwrap_err();
    assert!(matches!(err, ProbeFailure::Unreachable(_)), "{err:?}");
    rt.shutdown_timeout(Duration::from_secs(1));
}

#[test]
fn a_bad_spec_is_refused_naming_the_field() {
    let server = TestServer::start(
        factory(8, std::sync::Arc::new(|_| Ok(vec![STILL; 8]))),
        Default::default(),
    );
    let err = rt()
        .block_on(probe_endpoint(
            &server.url(),
            None,
            "",
            &AllowedNetworks::default(),
            &cfg(),
        ))
        .unwrap_err();
    assert!(matches!(err, ProbeFailure::Handshake(_)), "{err:?}");
    assert!(err.to_string().contains("horizon is 8, must be 16"), "{err}");
}

/// Contract v1.1: an execution count under the organiser's minimum is refused with the range;
/// within it the probe reports the policy's choices.
#[test]
fn an_execution_count_outside_the_organisers_range_is_refused() {
    let asks = |k: usize| {
        let f: kitchen_r_contract::server::PolicyFactory = std::sync::Arc::new(move || {
            Box::new(Scripted {
                spec: kitchen_r_episode::policy::PolicySpec {
                    observation_history: 2,
                    actions_executed_per_chunk: Some(k),
                    ..spec(16)
                },
                answer: std::sync::Arc::new(|_| Ok(vec![STILL; 16])),
            }) as Box<dyn kitchen_r_episode::policy::Policy>
        });
        TestServer::start(f, Default::default())
    };
    let strict = RemoteConfig {
        min_actions_executed_per_chunk: 4,
        ..cfg()
    };
    let probe = |server: &TestServer| {
        rt().block_on(probe_endpoint(
            &server.url(),
            None,
            "",
            &AllowedNetworks::default(),
            &strict,
        ))
    };
    let err = probe(&asks(2)).unwrap_err();
    assert!(matches!(err, ProbeFailure::Handshake(_)), "{err:?}");
    assert!(
        err.to_string()
            .contains("actions_executed_per_chunk is 2, must be between 4 (this organiser's minimum) and 16"),
        "{err}"
    );
    let ok = probe(&asks(4)).unwrap();
    assert_eq!((ok.observation_history, ok.actions_executed_per_chunk), (2, 4));
    assert!(ok.summary.ends_with("history 2, executes 4"), "{}", ok.summary);
}

/// With loopback allowed, registration must not tell a closed port from a service that is not a
/// policy on the evaluation host: the same text, after the same startup deadline.
#[test]
fn registration_says_only_unreachable_for_anything_near_the_evaluation_host() {
    use kitchen_r_contract::probe::probe_for_registration;
    let (rt, grpc) = not_serving_health_server();
    let closed = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap();
    let bad_spec = TestServer::start(
        factory(8, std::sync::Arc::new(|_| Ok(vec![STILL; 8]))),
        Default::default(),
    );
    let mut texts = Vec::new();
    for url in [
        format!("http://{grpc}"),
        format!("http://{closed}"),
        bad_spec.url(),
    ] {
        let started = std::time::Instant::now();
        let err = rt
            .block_on(probe_for_registration(
                &url,
                None,
                "",
                &AllowedNetworks::default(),
                &cfg(),
            ))
            .unwrap_err();
        assert!(
            started.elapsed() >= Duration::from_secs(1),
            "{url}: answered early"
        );
        assert!(matches!(err, ProbeFailure::Unreachable(_)), "{err:?}");
        texts.push(err.to_string().replace(url.trim_start_matches("http://"), "ADDR"));
    }
    assert!(texts.iter().all(|t| *t == texts[0]), "{texts:?}");
    rt.shutdown_timeout(Duration::from_secs(1));
}
