//! The client commands of the `kitchen-r` binary against a real server: readable output on
//! success, the server's message and a non-zero exit code on failure.

use crate::support;

use std::process::{Command, Output};

use support::*;

fn run(server: &Server, args: &[&str], envs: &[(&str, &str)]) -> Output {
    let mut cmd = Command::new(bin());
    cmd.args(args)
        .env_remove("KITCHEN_R_TOKEN")
        .env_remove("KITCHEN_R_ADMIN_TOKEN")
        .env("KITCHEN_R_SERVER", &server.http);
    for (k, v) in envs {
        cmd.env(k, v);
    }
    cmd.output().expect("run kitchen-r")
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn team_submit_leaderboard_rescore_from_the_command_line() {
    let fx = Fixture::new("");
    let server = fx.serve();

    let out = run(
        &server,
        &["team", "create", "cli team"],
        &[("KITCHEN_R_ADMIN_TOKEN", ADMIN)],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let text = stdout(&out);
    let token = text
        .lines()
        .find_map(|l| l.strip_prefix("token: "))
        .expect("token line")
        .to_string();

    // A participant's first submission: the downloaded dev file as is (ground truth) → EM 1.
    let plans = fx.dir.path().join("dev.jsonl");
    std::fs::copy(fx.dir.path().join("assets/dataset/dev.jsonl"), &plans).unwrap();
    let plans = plans.to_str().unwrap();
    let out = run(
        &server,
        &["submit", "plans", plans, "--split", "dev"],
        &[("KITCHEN_R_TOKEN", &token)],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stdout(&out).contains("EM = 1.000000"), "{}", stdout(&out));

    // The dev file's ids are not test ids: refused, with the server's reason, exit code 1.
    let out = run(
        &server,
        &["submit", "plans", plans, "--split", "test", "--token", &token],
        &[],
    );
    assert_eq!(out.status.code(), Some(1));
    let err = stderr(&out);
    assert!(
        err.contains("line 1") && err.contains("belongs to the dev split"),
        "{err}"
    );

    let out = run(&server, &["leaderboard", "--split", "dev"], &[]);
    assert!(out.status.success(), "{}", stderr(&out));
    let table = stdout(&out);
    assert!(table.contains("cli team") && table.contains("1.0000"), "{table}");
    // Each score with its 95 % interval (EM over the fixture's 3 instructions), then the rule.
    assert!(
        table.contains("EM 95 %") && table.contains("[0.4385, 1.0000]"),
        "{table}"
    );
    assert!(table.contains("\nties: Ranks are shared"), "{table}");

    let out = run(
        &server,
        &["leaderboard", "--split", "dev", "--format", "csv"],
        &[],
    );
    assert!(
        stdout(&out)
            .starts_with("rank,team,submission_id,em,submitted_at,em_low,em_high\n1,cli team,1,1.000000,")
    );

    let out = run(
        &server,
        &["leaderboard", "--split", "dev", "--format", "json"],
        &[],
    );
    let v: serde_json::Value = serde_json::from_str(&stdout(&out)).unwrap();
    assert_eq!(v["rows"][0]["team"], "cli team");
    // The results card (docs/reference/leaderboard.md#results-cards).
    let card = &v["rows"][0]["card"];
    assert_eq!(card["episodes"], 3, "{v}");
    assert_eq!(card["binary_version"], env!("CARGO_PKG_VERSION"), "{v}");
    assert_eq!(v["rows"][0]["intervals"]["em"][1], 1.0, "{v}");

    let out = run(
        &server,
        &["rescore", "--all"],
        &[("KITCHEN_R_ADMIN_TOKEN", ADMIN)],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(
        stdout(&out).contains("rescored 1 plan submissions and 0 policy runs"),
        "{}",
        stdout(&out)
    );

    // Re-simulation names a policy submission; a plan submission is not one.
    let out = run(
        &server,
        &["rescore", "--resimulate", "1"],
        &[("KITCHEN_R_ADMIN_TOKEN", ADMIN)],
    );
    assert_eq!(out.status.code(), Some(1));
    assert!(stderr(&out).contains("policy submission 1"), "{}", stderr(&out));

    // Organiser commands refuse a participant's token.
    let out = run(&server, &["rescore", "--all", "--admin-token", &token], &[]);
    assert_eq!(out.status.code(), Some(1));
    assert!(stderr(&out).contains("organiser token"), "{}", stderr(&out));
}

#[test]
fn serve_refuses_an_invalid_configuration() {
    let fx = Fixture::new("[quota]\ntest_per_dai = 3\n");
    let out = Command::new(bin())
        .args(["serve", "--config"])
        .arg(fx.config_path())
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(stderr(&out).contains("test_per_dai"), "{}", stderr(&out));
}

#[test]
fn dataset_generate_reproduces_the_committed_files() {
    let out = tempfile::tempdir().unwrap();
    let seed = kitchen_r_core::dataset::COMMITTED_SEED.to_string();
    let status = Command::new(bin())
        .args(["dataset", "generate", "--seed", &seed, "--out"])
        .arg(out.path())
        .output()
        .unwrap();
    assert!(status.status.success(), "{}", stderr(&status));
    let committed = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/dataset");
    for f in [
        "dev.jsonl",
        "test.jsonl",
        "test_ground_truth.jsonl",
        "manifest.json",
    ] {
        let (a, b) = (
            std::fs::read(out.path().join(f)).unwrap(),
            std::fs::read(committed.join(f)).unwrap(),
        );
        assert!(a == b, "{f} differs from the committed file");
    }
}
