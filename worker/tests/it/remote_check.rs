//! `check-policy` logic: a good endpoint passes every check; each bad one fails the check that
//! names what is wrong.

use crate::remote_support;

use std::sync::Arc;
use std::time::Duration;

use kitchen_r_contract::check::{Report, Verdict, check_policy};
use kitchen_r_contract::server::ServeOptions;
use kitchen_r_contract::{AllowedNetworks, Credentials, RemoteConfig};
use kitchen_r_episode::policy::HORIZON;
use kitchen_r_proto::policy::v1 as pb;
use remote_support::*;

fn probe(url: &str) -> Report {
    let cfg = RemoteConfig {
        call_deadline_s: 1.0,
        startup_deadline_s: 2.0,
        allowed_networks: AllowedNetworks::ALL,
        ..RemoteConfig::default()
    };
    let r = check_policy(url, &Credentials::default(), &cfg, &cameras(), "");
    for c in &r.checks {
        eprintln!("{c}");
    }
    r
}

fn assert_fails(r: &Report, check: &str, needle: &str) {
    assert!(!r.passed());
    let c = r.get(check).unwrap_or_else(|| panic!("no {check} line"));
    assert_eq!(c.verdict, Verdict::Fail, "{c}");
    assert!(c.detail.contains(needle), "{c} lacks {needle:?}");
}

#[test]
fn a_good_endpoint_passes_every_check() {
    let server = TestServer::start(still(), ServeOptions::default());
    let r = probe(&server.url());
    assert!(r.passed());
    assert_eq!(r.checks.len(), 12);
    assert!(r.checks.iter().all(|c| c.verdict == Verdict::Pass));
    let batch = &r.get("act-batch").unwrap().detail;
    assert!(batch.starts_with("max_batch 0: no batching"), "{batch}");
    let track = &r.get("privileged").unwrap().detail;
    assert!(track.starts_with("standard track"), "{track}");
    assert!(r.get("cameras").unwrap().detail.contains("base 128x128 RAW_RGB8"));
    let v = &r.get("v1.1").unwrap().detail;
    assert!(
        v.contains("history 1 frame(s); executes the organiser's 8"),
        "{v}"
    );
}

#[test]
fn a_batching_endpoint_has_its_actbatch_checked_against_its_acts() {
    let opts = ServeOptions {
        max_batch: 8,
        ..ServeOptions::default()
    };
    let server = TestServer::start(still(), opts);
    let r = probe(&server.url());
    assert!(r.passed());
    let batch = &r.get("act-batch").unwrap().detail;
    assert!(
        batch.starts_with("max_batch 8: 4 valid chunks for 4 observations of 4 episodes")
            && batch.ends_with("each equal to its Act's answer"),
        "{batch}"
    );
}

/// A policy asking for `history` frames and `execute` actions per chunk (contract v1.1).
fn v1_1(history: usize, execute: Option<usize>) -> TestServer {
    let f: kitchen_r_contract::server::PolicyFactory = Arc::new(move || {
        Box::new(Scripted {
            spec: kitchen_r_episode::policy::PolicySpec {
                observation_history: history,
                actions_executed_per_chunk: execute,
                ..spec(HORIZON)
            },
            answer: Arc::new(move |i| {
                assert_eq!(i.history.len(), history - 1, "padded to the history asked for");
                // A learned model's slip, within the default tolerance: reported, not failed.
                let mut c = vec![STILL; HORIZON];
                c[0][9] = 1.0001;
                Ok(c)
            }),
        }) as Box<dyn kitchen_r_episode::policy::Policy>
    });
    TestServer::start(f, ServeOptions::default())
}

#[test]
fn the_v1_1_fields_are_checked_and_shown() {
    let good = v1_1(3, Some(4));
    let r = probe(&good.url());
    assert!(r.passed());
    let v = &r.get("v1.1").unwrap().detail;
    assert!(
        v.contains("history 3 frame(s); executes 4 actions per chunk (its choice)"),
        "{v}"
    );
    let act = &r.get("act-again").unwrap().detail;
    assert!(act.contains("for step 4 (3 frame(s))"), "{act}");
    assert!(
        act.contains("warning: 1 corrections: 1 gripper values clamped"),
        "{act}"
    );

    let r = probe(&v1_1(2, Some(17)).url());
    assert_fails(&r, "v1.1", "actions_executed_per_chunk is 17, must be between 1");
    assert_eq!(r.get("reset").unwrap().verdict, Verdict::Skip);
    let r = probe(&v1_1(9, None).url());
    assert_fails(&r, "v1.1", "observation_history is 9, must be between 1 and 8");
}

#[test]
fn each_bad_endpoint_is_named() {
    let nan = TestServer::start(
        factory(HORIZON, Arc::new(|_| Ok(vec![[f64::NAN; 10]; HORIZON]))),
        ServeOptions::default(),
    );
    assert_fails(&probe(&nan.url()), "act", "not finite");

    let short = TestServer::start(
        factory(8, Arc::new(|_| Ok(vec![STILL; 8]))),
        ServeOptions::default(),
    );
    assert_fails(&probe(&short.url()), "shape", "horizon 8");

    let thermal = ServeOptions {
        cameras: vec![pb::CameraRequest {
            name: "thermal".into(),
            width: 64,
            height: 64,
            encoding: pb::ImageEncoding::RawRgb8 as i32,
            depth: false,
        }],
        ..ServeOptions::default()
    };
    assert_fails(
        &probe(&TestServer::start(still(), thermal).url()),
        "cameras",
        "\"thermal\"",
    );

    let slow = TestServer::start(
        factory(
            HORIZON,
            Arc::new(|_| {
                std::thread::sleep(Duration::from_millis(1500));
                Ok(vec![STILL; HORIZON])
            }),
        ),
        ServeOptions::default(),
    );
    assert_fails(&probe(&slow.url()), "act", "did not answer within 1.0 s");

    let small = ServeOptions {
        max_request_bytes: 1 << 20,
        ..ServeOptions::default()
    };
    let r = probe(&TestServer::start(still(), small).url());
    assert_eq!(r.get("act").unwrap().verdict, Verdict::Pass);
    assert_fails(&r, "large-image", "1024x1024");

    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let r = probe(&format!("http://127.0.0.1:{port}"));
    assert_fails(&r, "reachable", "connection");
    assert!(r.checks[1..].iter().all(|c| c.verdict == Verdict::Skip));

    assert_fails(&probe("ftp://example.org:21"), "reachable", "scheme");
}
