//! The Python starter kit, started as a real process the way a participant runs it, passes every
//! `check-policy` check, and enforces its bearer token. With CI=true its Python packages are
//! required (`pip install -r scripts/test-requirements.txt`); elsewhere the test is skipped
//! when grpcio is missing.

use crate::remote_support;

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};

use kitchen_r_contract::check::{Verdict, check_policy};
use kitchen_r_contract::{AllowedNetworks, Credentials, RemoteConfig};
use remote_support::cameras;

fn kit() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../starter-kit/policy_server.py")
}

fn python_ready() -> bool {
    let ok = Command::new("python3")
        .args(["-c", "import grpc, grpc_tools, grpc_health"])
        .status()
        .is_ok_and(|s| s.success());
    if !ok {
        assert!(
            std::env::var("CI").as_deref() != Ok("true"),
            "CI requires grpcio, grpcio-tools and grpcio-health-checking (scripts/test-requirements.txt)"
        );
        eprintln!("skipped: python3 with grpcio, grpcio-tools and grpcio-health-checking is not installed");
    }
    ok
}

/// Killed on drop, so a failing assertion leaves no server behind.
struct Kit(Child);

impl Drop for Kit {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Start the kit on port 0 and read the address from its readiness line.
fn start(extra: &[&str]) -> (Kit, String) {
    let mut child = Command::new("python3")
        .arg(kit())
        .args(["--listen", "127.0.0.1:0"])
        .args(extra)
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .unwrap();
    let out = child.stdout.take().unwrap();
    let kit = Kit(child);
    let mut line = String::new();
    BufReader::new(out).read_line(&mut line).unwrap();
    let addr = line
        .trim()
        .strip_prefix("listening grpc=")
        .unwrap_or_else(|| panic!("no readiness line: {line:?}"));
    (kit, format!("http://{addr}"))
}

fn cfg() -> RemoteConfig {
    RemoteConfig {
        startup_deadline_s: 20.0,
        allowed_networks: AllowedNetworks::ALL,
        ..RemoteConfig::default()
    }
}

#[test]
fn the_starter_kit_passes_check_policy() {
    if !python_ready() {
        return;
    }
    let (_kit, url) = start(&[]);
    let r = check_policy(&url, &Credentials::default(), &cfg(), &cameras(), "");
    for c in &r.checks {
        eprintln!("{c}");
    }
    assert!(r.passed());
    assert!(r.checks.iter().all(|c| c.verdict == Verdict::Pass));
}

#[test]
fn the_starter_kit_enforces_its_token() {
    if !python_ready() {
        return;
    }
    let (_kit, url) = start(&["--token", "s3cret-token"]);
    let good = Credentials {
        token: Some("s3cret-token".into()),
        ca_pem: None,
    };
    assert!(check_policy(&url, &good, &cfg(), &cameras(), "").passed());
    let r = check_policy(&url, &Credentials::default(), &cfg(), &cameras(), "");
    let c = r.get("protocol").unwrap();
    assert_eq!(c.verdict, Verdict::Fail);
    assert!(c.detail.contains("Unauthenticated"), "{c}");
}
