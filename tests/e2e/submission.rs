//! `kitchen-r submission show|wait` against a real server: the table and `--json` for a dev and a
//! test plan file, a policy run followed from queued (a timeout, exit 124) to finished (exit 0)
//! with one row per episode and task, and `submit policy --wait` on the same waiting code.

use crate::support;

use std::process::{Command, Output};

use serde_json::Value;
use support::*;

fn run(server: &Server, args: &[&str], token: &str) -> Output {
    Command::new(bin())
        .args(args)
        .env_remove("KITCHEN_R_ADMIN_TOKEN")
        .env("KITCHEN_R_SERVER", &server.http)
        .env("KITCHEN_R_TOKEN", token)
        .output()
        .expect("run kitchen-r")
}

#[tokio::test(flavor = "multi_thread")]
async fn show_and_wait_a_plan_file_on_dev_and_on_test() {
    let fx = Fixture::new("");
    let server = fx.serve();
    let token = team(&server, "show team").await;

    // dev-0001 right, dev-0002 one step wrong, dev-0003 missing.
    let plans = support::dev_plans();
    let mut wrong = plans[1].1.clone();
    wrong[1] = "pick the bowl";
    let file = format!(
        "{}\n{}\n",
        line(plans[0].0, &plans[0].1),
        line(plans[1].0, &wrong)
    );
    let (status, sub) = submit(&server, Some(&token), "dev", file).await;
    assert_eq!(status, 201, "{sub}");
    let id = sub["id"].to_string();

    let table = out(&ok(run(&server, &["submission", "show", &id], &token)));
    for want in [
        &format!("submission {id}: plan file, dev split, team show team"),
        &format!("page: {}/submissions/{id}", server.http),
        "run 1: finished",
        "scores: EM = ",
        "instructions: 2 of 3 have a plan in the file",
        "dev-0001 1.0000 4/4",
        "dev-0002 0.8000 4/5",
        "dev-0003 0.0000 0/8 (no plan in the file)",
    ] {
        assert!(squash(&table).contains(want), "{want:?} missing from:\n{table}");
    }

    let json = out(&ok(run(&server, &["submission", "show", &id, "--json"], &token)));
    let v: Value = serde_json::from_str(&json).unwrap();
    assert_eq!(v["id"].to_string(), id);
    assert_eq!(v["latest_run"]["instructions"].as_array().unwrap().len(), 3);

    // A plan file is scored at upload: `wait` returns at once, exit 0, with the same summary.
    let waited = ok(run(
        &server,
        &["submission", "wait", &id, "--timeout", "30"],
        &token,
    ));
    assert!(
        squash(&out(&waited)).contains("dev-0002 0.8000 4/5"),
        "{}",
        out(&waited)
    );

    // Test split: aggregate feedback only, no row names an instruction.
    let test = support::test_plans();
    let file = format!("{}\n", line(test[0].0, &test[0].1));
    let (status, sub) = submit(&server, Some(&token), "test", file).await;
    assert_eq!(status, 201, "{sub}");
    let table = out(&ok(run(
        &server,
        &["submission", "show", &sub["id"].to_string()],
        &token,
    )));
    assert!(table.contains("instructions: 1 of 2 have a plan"), "{table}");
    assert!(table.contains("aggregate feedback only"), "{table}");
    assert!(!table.contains("test-0001"), "{table}");

    // Someone else's submission, or none: exit 1 with the server's words and request id.
    let other = team(&server, "other team").await;
    let refused = run(&server, &["submission", "show", &id], &other);
    assert_eq!(refused.status.code(), Some(1));
    let e = err(&refused);
    assert!(
        e.contains("not found") && e.contains("HTTP 404") && e.contains("request id"),
        "{e}"
    );
    let refused = run(&server, &["submission", "wait", "999"], &token);
    assert_eq!(refused.status.code(), Some(1), "{}", err(&refused));
}

#[tokio::test(flavor = "multi_thread")]
async fn wait_follows_a_policy_run_from_queued_to_finished() {
    let fx = ControlFixture::new("[control]\nlease_s = 4\nreaper_interval_s = 1\noffline_mse = false\n");
    // No simulation slots yet: the run stays queued until a worker joins.
    let server = fx.serve(0);
    let (_oracle, url) = oracle_policy();
    let reg = ok(run(
        &server,
        &[
            "submit",
            "policy",
            &url,
            "--split",
            "dev",
            "--episodes",
            "2",
            "--reference",
        ],
        ADMIN,
    ));
    let id = out(&reg).trim().to_string();
    assert!(id.parse::<i64>().is_ok(), "{}", out(&reg));
    assert!(
        err(&reg).contains(&format!("submission wait {id}")),
        "{}",
        err(&reg)
    );

    let table = out(&ok(run(&server, &["submission", "show", &id], ADMIN)));
    assert!(table.contains("queued: 0/2 episodes done, 0 running"), "{table}");
    assert!(table.contains("reference run"), "{table}");

    let timed_out = run(&server, &["submission", "wait", &id, "--timeout", "2"], ADMIN);
    assert_eq!(timed_out.status.code(), Some(124), "{}", err(&timed_out));
    assert!(
        err(&timed_out).contains("not finished after 2 s"),
        "{}",
        err(&timed_out)
    );

    let _worker = worker(&server, 2, "show-worker");
    let waited = ok(run(&server, &["submission", "wait", &id], ADMIN));
    let table = out(&waited);
    for want in [
        "run 1: finished: 2/2 episodes done",
        "SR = 1.0000",
        "episodes:",
        "dev-",
        "task 1",
        " ok ",
    ] {
        assert!(squash(&table).contains(want), "{want:?} missing from:\n{table}");
    }
    assert!(
        err(&waited).contains("episodes done"),
        "progress on stderr: {}",
        err(&waited)
    );

    let json = out(&ok(run(&server, &["submission", "show", &id, "--json"], ADMIN)));
    let v: Value = serde_json::from_str(&json).unwrap();
    let e = &v["latest_run"]["evaluation"];
    assert_eq!(e["state"], "finished", "{v:#}");
    assert_eq!(e["episodes"].as_array().unwrap().len(), 2, "{v:#}");
    assert!(e["episodes"][0]["tasks"][0]["step"].is_string(), "{v:#}");

    // `submit policy --wait` waits with the same code and prints the same view.
    let direct = ok(run(
        &server,
        &[
            "submit",
            "policy",
            &url,
            "--split",
            "dev",
            "--episodes",
            "1",
            "--reference",
            "--wait",
        ],
        ADMIN,
    ));
    assert!(
        out(&direct).contains("finished: 1/1 episodes done"),
        "{}",
        out(&direct)
    );
    assert!(out(&direct).contains("task 1"), "{}", out(&direct));
}
