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
    let r = check_policy(url, &Credentials::default(), &cfg, &cameras());
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
    assert_eq!(r.checks.len(), 9);
    assert!(r.checks.iter().all(|c| c.verdict == Verdict::Pass));
    assert!(r.get("cameras").unwrap().detail.contains("base 128x128 RAW_RGB8"));
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
