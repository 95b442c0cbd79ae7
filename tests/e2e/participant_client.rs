//! The Python participant client (`starter-kit/kitchen_r_client`, standard library only) against
//! a real server: team, dev plan file, wait, show, leaderboard, the server's errors with their
//! request id and the exit codes of the Rust CLI; and `pip install ./starter-kit` gives the
//! `kitchen-r-client` console script without the policy server.

use crate::support;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::Value;
use support::*;

fn kit() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../starter-kit")
}

/// `python3 -m kitchen_r_client ARGS` with the kit on PYTHONPATH (no install).
fn client(server: &Server, args: &[&str], envs: &[(&str, &str)]) -> Output {
    let mut cmd = Command::new("python3");
    cmd.args(["-m", "kitchen_r_client"])
        .args(args)
        .env("PYTHONPATH", kit())
        .env("PYTHONDONTWRITEBYTECODE", "1")
        .env("KITCHEN_R_SERVER", &server.http)
        .env_remove("KITCHEN_R_TOKEN")
        .env_remove("KITCHEN_R_ADMIN_TOKEN");
    for (k, v) in envs {
        cmd.env(k, v);
    }
    cmd.output().expect("run python3 -m kitchen_r_client")
}

#[test]
fn the_python_client_submits_waits_shows_and_reads_the_leaderboard() {
    let fx = Fixture::new("");
    let server = fx.serve();

    let created = ok(client(
        &server,
        &["team", "create", "py team"],
        &[("KITCHEN_R_ADMIN_TOKEN", ADMIN)],
    ));
    let token = out(&created)
        .lines()
        .find_map(|l| l.strip_prefix("token: "))
        .expect("token line")
        .to_string();
    let auth = [("KITCHEN_R_TOKEN", token.as_str())];

    // The dev ground truth as a participant's plan file: EM 1.
    let file = fx.dir.path().join("plans.jsonl");
    let lines: String = dev_plans().iter().map(|(id, p)| line(id, p) + "\n").collect();
    std::fs::write(&file, lines).unwrap();
    let file = file.to_str().unwrap();
    let sub = ok(client(
        &server,
        &["submit", "plans", file, "--split", "dev"],
        &auth,
    ));
    let text = out(&sub);
    assert!(text.contains("(dev): EM = 1.000000"), "{text}");
    let id = text
        .strip_prefix("submission ")
        .and_then(|t| t.split_whitespace().next())
        .expect("submission id")
        .to_string();

    let waited = ok(client(
        &server,
        &["submission", "wait", &id, "--timeout", "30"],
        &auth,
    ));
    let table = out(&waited);
    for want in [
        "plan file, dev split, team py team",
        "scores: EM = 1.0000",
        "dev-0003 1.0000 8/8",
    ] {
        assert!(squash(&table).contains(want), "{want:?} missing from:\n{table}");
    }
    let shown = ok(client(&server, &["submission", "show", &id, "--json"], &auth));
    let v: Value = serde_json::from_str(&out(&shown)).unwrap();
    assert_eq!(v["id"].to_string(), id);
    assert_eq!(v["latest_run"]["instructions"].as_array().unwrap().len(), 3);

    let board = out(&ok(client(&server, &["leaderboard", "--split", "dev"], &[])));
    assert!(board.contains("py team") && board.contains("1.0000"), "{board}");
    // The same interval and ties line as `kitchen-r leaderboard` (tests/e2e/cli.rs).
    assert!(
        board.contains("[0.4385, 1.0000]") && board.contains("\nties: "),
        "{board}"
    );
    let board = out(&ok(client(
        &server,
        &["leaderboard", "--split", "dev", "--json"],
        &[],
    )));
    let v: Value = serde_json::from_str(&board).unwrap();
    assert_eq!(v["rows"][0]["team"], "py team");
    assert_eq!(v["rows"][0]["card"]["episodes"], 3, "{board}");

    // Refusals: exit 1, the server's message, code and request id on stderr.
    let refused = client(&server, &["submit", "plans", file, "--split", "test"], &auth);
    assert_eq!(refused.status.code(), Some(1), "{}", err(&refused));
    let e = err(&refused);
    assert!(
        e.starts_with("Error: line 1:") && e.contains("belongs to the dev split"),
        "{e}"
    );
    assert!(e.contains("code wrong_split") && e.contains("request id "), "{e}");
    let missing = client(&server, &["submission", "show", "999"], &auth);
    assert_eq!(missing.status.code(), Some(1));
    assert!(
        err(&missing).contains("not found (HTTP 404) [code not_found, request id "),
        "{}",
        err(&missing)
    );
    // A usage error (no token anywhere): exit 2, as clap's.
    let usage = client(&server, &["submission", "show", &id], &[]);
    assert_eq!(usage.status.code(), Some(2), "{}", err(&usage));
}

#[test]
fn the_python_client_follows_a_policy_run_and_times_out_like_the_rust_cli() {
    let fx = ControlFixture::new("[control]\nlease_s = 4\nreaper_interval_s = 1\noffline_mse = false\n");
    // No simulation slots yet: the run stays queued until a worker joins.
    let server = fx.serve(0);
    let (_oracle, url) = oracle_policy();
    let admin = [("KITCHEN_R_TOKEN", ADMIN)];
    let args = [
        "submit",
        "policy",
        &url,
        "--split",
        "dev",
        "--episodes",
        "2",
        "--reference",
    ];
    let reg = ok(client(&server, &args, &admin));
    let id = out(&reg).trim().to_string();
    assert!(id.parse::<i64>().is_ok(), "{}", out(&reg));

    let timed_out = client(&server, &["submission", "wait", &id, "--timeout", "2"], &admin);
    assert_eq!(timed_out.status.code(), Some(124), "{}", err(&timed_out));
    assert!(
        err(&timed_out).contains("not finished after 2 s"),
        "{}",
        err(&timed_out)
    );

    let _worker = worker(&server, 2, "py-worker");
    let waited = ok(client(&server, &["submission", "wait", &id], &admin));
    let table = squash(&out(&waited));
    for want in [
        "finished: 2/2 episodes done",
        "SR = 1.0000",
        "episodes:",
        "task 1 ok",
    ] {
        assert!(table.contains(want), "{want:?} missing from:\n{table}");
    }
    // The same text as the Rust CLI prints. Videos upload after the result is reported (best
    // effort), so a finished run can still gain `video:` lines: compare once both are there.
    let rust_show = || {
        let o = Command::new(bin())
            .args(["submission", "show", &id])
            .env("KITCHEN_R_SERVER", &server.http)
            .env("KITCHEN_R_TOKEN", ADMIN)
            .output()
            .unwrap();
        out(&o)
    };
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    let mut rust = rust_show();
    while rust.matches("video: ").count() < 2 && std::time::Instant::now() < deadline {
        std::thread::sleep(std::time::Duration::from_millis(250));
        rust = rust_show();
    }
    assert_eq!(
        rust.matches("video: ").count(),
        2,
        "both episodes' videos uploaded:\n{rust}"
    );
    let shown = ok(client(&server, &["submission", "show", &id], &admin));
    assert_eq!(rust, out(&shown));

    let args = [
        "submit",
        "policy",
        &url,
        "--split",
        "dev",
        "--episodes",
        "1",
        "--reference",
        "--wait",
    ];
    let direct = ok(client(&server, &args, &admin));
    assert!(
        out(&direct).contains("finished: 1/1 episodes done"),
        "{}",
        out(&direct)
    );
}

#[test]
fn pip_installs_the_console_script_without_the_policy_server() {
    let tmp = tempfile::tempdir().unwrap();
    // Build from a copy, so setuptools' build/ and egg-info stay out of the repository.
    let src = tmp.path().join("kit");
    std::fs::create_dir_all(src.join("kitchen_r_client")).unwrap();
    for f in ["pyproject.toml", "README.md"] {
        std::fs::copy(kit().join(f), src.join(f)).unwrap();
    }
    std::fs::copy(kit().join("policy_server.py"), src.join("policy_server.py")).unwrap();
    for e in std::fs::read_dir(kit().join("kitchen_r_client")).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "py") {
            std::fs::copy(&p, src.join("kitchen_r_client").join(p.file_name().unwrap())).unwrap();
        }
    }
    let target = tmp.path().join("site");
    // Offline: no index, and the environment's setuptools as the build backend.
    let pip = Command::new("python3")
        .args([
            "-m",
            "pip",
            "install",
            "--quiet",
            "--disable-pip-version-check",
            "--no-index",
        ])
        .args(["--no-deps", "--no-build-isolation", "--target"])
        .arg(&target)
        .arg(&src)
        .output()
        .unwrap();
    assert!(pip.status.success(), "pip install failed:\n{}", err(&pip));
    assert!(target.join("kitchen_r_client/cli.py").is_file());
    assert!(
        !target.join("policy_server.py").exists(),
        "the policy server is not part of the package"
    );
    let script = target.join("bin/kitchen-r-client");
    let help = Command::new("python3")
        .arg(&script)
        .arg("--help")
        .env("PYTHONPATH", &target)
        .output()
        .unwrap();
    assert!(help.status.success(), "{}", err(&help));
    for cmd in ["team", "submit", "submission", "leaderboard"] {
        assert!(out(&help).contains(cmd), "{}", out(&help));
    }
}

/// The client's own unit tests (`starter-kit/tests`, standard library unittest).
#[test]
fn the_python_clients_unit_tests_pass() {
    let run = Command::new("python3")
        .args(["-m", "unittest", "discover", "-s"])
        .arg(kit().join("tests"))
        .env("PYTHONDONTWRITEBYTECODE", "1")
        .env_remove("KITCHEN_R_TOKEN")
        .output()
        .unwrap();
    assert!(run.status.success(), "{}", err(&run));
}
