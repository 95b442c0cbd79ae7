//! openpi WebSocket endpoints end to end (docs/participant/openpi.md): a policy served by openpi's
//! own
//! `WebsocketPolicyServer` (PyPI `openpi-server` 0.1.0, `openpi-client` 0.1.2: the script
//! `tests/openpi/policy_server.py`) passes `check-policy ws://…`, is registered with a team token
//! and scored by the real server and workers; and every way such a policy can misbehave (it
//! raises, so the server sends text; a wrong shape; it hangs; it closes the connection; it never
//! sends metadata) gives a clear reason per task or at registration, never a lost episode.
//!
//! Python: `openpi-server`/`openpi-client` are installed with `--no-deps` (openpi-client 0.1.2
//! declares `numpy<2`, which the test venv's pinned numpy 2 contradicts; the server imports only
//! numpy, msgpack and websockets, which scripts/test-requirements.txt brings): into
//! `target/openpi-py` from `scripts/test-requirements-openpi.txt` when the Python lacks them.

use crate::support;

use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::{Value, json};
use support::*;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The `PYTHONPATH` under which `import openpi_server` works, installing the pinned packages
/// into `target/openpi-py` when needed; `None` when Python cannot (outside CI: skipped).
fn openpi_path() -> Option<String> {
    let dir = root().join("target/openpi-py");
    let importable = |path: &str| {
        Command::new("python3")
            .args([
                "-c",
                "import openpi_server, openpi_client, msgpack, websockets, numpy",
            ])
            .env("PYTHONPATH", path)
            .status()
            .is_ok_and(|s| s.success())
    };
    let path = dir.display().to_string();
    if importable(&path) {
        return Some(path);
    }
    let pip = Command::new("python3")
        .args([
            "-m",
            "pip",
            "install",
            "--quiet",
            "--disable-pip-version-check",
            "--no-deps",
        ])
        .arg("--target")
        .arg(&dir)
        .arg("-r")
        .arg(root().join("scripts/test-requirements-openpi.txt"))
        .status();
    if pip.is_ok_and(|s| s.success()) && importable(&path) {
        return Some(path);
    }
    assert!(
        std::env::var("CI").is_err(),
        "python3 with msgpack and websockets (scripts/test-requirements.txt) and pip is required in CI"
    );
    eprintln!("skipped: openpi-server could not be installed for python3");
    None
}

/// `tests/openpi/policy_server.py --mode MODE` on a free port: the process and its `ws://` URL.
fn openpi_policy(pythonpath: &str, mode: &str, log: Option<&Path>) -> (Proc, String) {
    let mut cmd = Command::new("python3");
    cmd.arg(root().join("tests/openpi/policy_server.py"))
        .args(["--mode", mode])
        .env("PYTHONPATH", pythonpath);
    if let Some(l) = log {
        cmd.arg("--log").arg(l);
    }
    let (child, line) = spawn_ready(&mut cmd, "listening ws=");
    let addr = line.trim_start_matches("listening ws=").trim().to_string();
    (Proc(child), format!("ws://{addr}"))
}

fn check_policy(url: &str) -> std::process::Output {
    Command::new(bin())
        .args(["check-policy", url, "--deadline", "3", "--startup-deadline", "5"])
        .output()
        .unwrap()
}

/// openpi's server behind TLS (`wss://`) with a participant's own certificate: `check-policy
/// --ca` trusts it and every check passes; without the CA the certificate is refused, and the
/// reason says TLS.
#[test]
fn a_wss_endpoint_passes_check_policy_with_its_ca_and_is_refused_without() {
    let Some(py) = openpi_path() else { return };
    let dir = tempfile::tempdir().unwrap();
    let c =
        rcgen::generate_simple_self_signed(vec!["localhost".to_string(), "127.0.0.1".to_string()]).unwrap();
    let (cert, key) = (dir.path().join("cert.pem"), dir.path().join("key.pem"));
    std::fs::write(&cert, c.cert.pem()).unwrap();
    std::fs::write(&key, c.signing_key.serialize_pem()).unwrap();
    let mut cmd = Command::new("python3");
    cmd.arg(root().join("tests/openpi/policy_server.py"))
        .args(["--mode", "hold", "--tls"])
        .args([&cert, &key])
        .env("PYTHONPATH", &py);
    let (child, line) = spawn_ready(&mut cmd, "listening wss=");
    let _policy = Proc(child);
    let url = format!("wss://{}", line.trim_start_matches("listening wss=").trim());

    let check = |ca: Option<&Path>| {
        let mut c = Command::new(bin());
        c.args(["check-policy", &url, "--deadline", "3", "--startup-deadline", "5"]);
        if let Some(ca) = ca {
            c.arg("--ca").arg(ca);
        }
        c.output().unwrap()
    };
    let text = out(&ok(check(Some(&cert))));
    for name in ["reachable", "health", "metadata", "act", "act-again"] {
        assert!(text.contains(&format!("PASS  {name}")), "{text}");
    }
    let refused = check(None);
    let text = format!("{}{}", out(&refused), String::from_utf8_lossy(&refused.stderr));
    assert!(!refused.status.success(), "{text}");
    assert!(
        text.contains("TLS") && text.to_lowercase().contains("certificate"),
        "{text}"
    );
}

#[tokio::test(flavor = "multi_thread")]
async fn an_openpi_server_policy_passes_check_policy_and_is_scored_through_serve() {
    let Some(py) = openpi_path() else { return };
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("observations.jsonl");
    let (_policy, url) = openpi_policy(&py, "hold", Some(&log));

    let o = ok(check_policy(&url));
    let text = out(&o);
    for name in ["keys", "reachable", "health", "metadata", "act", "act-again"] {
        assert!(text.contains(&format!("PASS  {name}")), "{text}");
    }
    assert!(
        text.contains("observation/base_image") && text.contains("[\"policy\"]"),
        "{text}"
    );

    // The hold policy never finishes a task: two tasks of 3 s each per episode.
    let fx = ControlFixture::new(
        "[control]\nlease_s = 4\nreaper_interval_s = 1\nmax_plan_steps = 2\ntask_time_limit_s = 3.0\n",
    );
    let server = fx.serve(2);
    let token = team(&server, "openpi").await;
    let (status, reg) = register_policy(
        &server,
        &token,
        json!({"endpoint": url, "split": "dev", "episodes": 2}),
    )
    .await;
    assert_eq!(status, 201, "{reg}");
    assert!(
        reg["policy"]
            .as_str()
            .unwrap()
            .starts_with("openpi policy at ws://"),
        "{reg}"
    );
    let id = reg["id"].as_i64().unwrap();
    let view = wait_for(&server, id, &token, "the openpi policy's run", finished).await;
    let e = &view["latest_run"]["evaluation"];
    assert_eq!(e["state"], "finished", "{view:#}");
    // Two online episodes and their offline (MSE) twins.
    assert_eq!(e["episodes_done"], 4, "{view:#}");
    let scores = &view["latest_run"]["scores"];
    assert_eq!(scores["sr"].as_f64(), Some(0.0), "{view:#}");
    assert!(scores["mse"].as_f64().is_some_and(f64::is_finite), "{view:#}");
    let eps = e["episodes"].as_array().unwrap();
    for ep in eps.iter().filter(|e| e["mode"] == "online") {
        for t in ep["tasks"].as_array().unwrap() {
            let why = t["failure_reason"].as_str().unwrap();
            assert!(
                why.contains("time limit"),
                "the policy answered every decision: {ep:#}"
            );
        }
    }

    // What the endpoint received: the convention's keys, and canonical plan steps as prompts.
    let seen: Vec<Value> = std::fs::read_to_string(&log)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert!(seen.len() > 10, "{}", seen.len());
    for s in &seen {
        assert_eq!(
            s["keys"],
            json!([
                "observation/base_image",
                "observation/gripper_image",
                "observation/state",
                "prompt"
            ])
        );
        let prompt = s["prompt"].as_str().unwrap();
        let step = (prompt.starts_with("move to the ") && prompt.ends_with(" zone"))
            || prompt.starts_with("pick the ")
            || prompt.starts_with("place the ");
        assert!(step, "{prompt}");
    }
}

/// `kitchen-r eval --policy URL` on the first dev instruction, two 3 s tasks, as JSON.
fn eval(url: &str, dir: &Path) -> Value {
    let cfg = dir.join("eval.toml");
    std::fs::write(
        &cfg,
        "task_time_limit = 3.0\nexecute = 8\nseed = 0\nteleport_on_failure = true\nmax_plan_steps = 2\n\
         episode_budget_s = 120.0\nmax_successive_timeouts = 2\n",
    )
    .unwrap();
    let o = ok(Command::new(bin())
        .args([
            "eval",
            "--policy",
            url,
            "--episodes",
            "1",
            "--jobs",
            "1",
            "--json",
            "--config",
        ])
        .arg(&cfg)
        .output()
        .unwrap());
    serde_json::from_str(&out(&o)).unwrap()
}

fn reasons(report: &Value) -> Vec<String> {
    report["episodes"][0]["tasks"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t["failure_reason"].as_str().unwrap().to_string())
        .collect()
}

#[tokio::test(flavor = "multi_thread")]
async fn misbehaving_openpi_policies_fail_their_tasks_with_clear_reasons() {
    let Some(py) = openpi_path() else { return };
    let dir = tempfile::tempdir().unwrap();
    let cases: [(&str, &[&str]); 4] = [
        (
            "raise",
            &["text message instead of msgpack", "this policy always fails"],
        ),
        ("shape", &["invalid action chunk", "shape (8, 7)"]),
        ("close", &["closed", "time limit"]),
        ("hang", &["did not answer within"]),
    ];
    for (mode, wanted) in cases {
        let (_policy, url) = openpi_policy(&py, mode, None);
        let report = eval(&url, dir.path());
        let why = reasons(&report);
        assert_eq!(why.len(), 2, "{mode}: every task is reported: {report:#}");
        assert!(why.iter().all(|w| !w.is_empty()), "{mode}: {why:?}");
        let all = why.join("\n");
        for w in wanted {
            assert!(all.contains(w), "{mode}: no {w:?} in {all}");
        }
        assert_eq!(report["platform_errors"], 0, "{mode}: {report:#}");
    }

    // No metadata: check-policy says so, and a server refuses the registration.
    let (_policy, url) = openpi_policy(&py, "silent", None);
    let o = check_policy(&url);
    assert!(!o.status.success());
    let text = out(&o);
    assert!(text.contains("PASS  health"), "{text}");
    assert!(
        text.contains("FAIL  metadata") && text.contains("sent no metadata"),
        "{text}"
    );
    let fx = ControlFixture::new("[policy]\nstartup_deadline_ms = 2000\n");
    let server = fx.serve(0);
    let token = team(&server, "silent").await;
    let (status, v) = register_policy(&server, &token, json!({"endpoint": url, "split": "dev"})).await;
    assert_eq!(status, 422, "{v}");
    // A key map is for openpi endpoints only.
    let (status, v) = register_policy(
        &server,
        &token,
        json!({"endpoint": "http://127.0.0.1:1", "split": "dev", "key_map": {}}),
    )
    .await;
    assert_eq!(status, 400, "{v}");
    assert!(v["error"].as_str().unwrap().contains("key_map"), "{v}");
}
