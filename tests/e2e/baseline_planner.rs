//! The planning baseline (`starter-kit/baselines/planner`, Python standard library only) against
//! a real server on the committed benchmark: it reads the dev and test splits, briefs and
//! top-down images over the public API, its plan files go through `kitchen-r submit plans`, the
//! EM it scores is the figure docs/measured/baseline-planning.md reports (the parser is deterministic, so any change to
//! it or to what the server publishes shows here), and its row is on the planning leaderboard.
//! Its LLM path runs against a fake OpenAI-compatible endpoint; its unit tests run too.

use crate::support;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::Value;
use support::*;

/// The figures of docs/measured/baseline-planning.md: dev split and the public test sample.
const DEV_EM: f64 = 0.9973707274320772;
/// The public sample is built from the public templates, like dev: it cannot rank planners.
const TEST_SAMPLE_EM: f64 = 1.0;

fn planner_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../starter-kit/baselines/planner")
}

fn python(server: &Server, args: &[&str]) -> Output {
    Command::new("python3")
        .args(args)
        .env("PYTHONDONTWRITEBYTECODE", "1")
        .env("KITCHEN_R_SERVER", &server.http)
        .env_remove("OPENAI_API_KEY")
        .output()
        .expect("run python3")
}

fn planner(server: &Server, args: &[&str]) -> Output {
    let run = planner_dir().join("run.py");
    let mut all = vec![run.to_str().unwrap()];
    all.extend_from_slice(args);
    python(server, &all)
}

fn cli(server: &Server, args: &[&str], token: &str) -> Output {
    Command::new(bin())
        .args(args)
        .env("KITCHEN_R_SERVER", &server.http)
        .env("KITCHEN_R_TOKEN", token)
        .env("KITCHEN_R_ADMIN_TOKEN", ADMIN)
        .output()
        .expect("run kitchen-r")
}

/// A team of its own for the planner (the LLM test; the reference row needs no team).
fn baseline_team(server: &Server) -> String {
    let created = ok(cli(server, &["team", "create", "Planner team"], ""));
    out(&created)
        .lines()
        .find_map(|l| l.strip_prefix("token: "))
        .expect("token line")
        .to_string()
}

fn submitted_em(o: Output) -> f64 {
    let v: Value = serde_json::from_str(&out(&ok(o))).expect("submit --json prints JSON");
    v["scores"]["em"].as_f64().expect("an EM")
}

#[test]
fn the_parser_reproduces_its_em_through_the_server_and_shows_on_the_leaderboard() {
    let fx = ControlFixture::new("");
    let server = fx.serve(0);
    let dir = fx.dir.path();

    for (split, expected) in [("dev", DEV_EM), ("test", TEST_SAMPLE_EM)] {
        let file = dir.join(format!("{split}.jsonl"));
        let images = dir.join("topdown");
        let run = ok(planner(
            &server,
            &[
                "--split",
                split,
                "--out",
                file.to_str().unwrap(),
                "--images",
                images.to_str().unwrap(),
            ],
        ));
        assert!(err(&run).contains("parser"), "{}", err(&run));
        for scene in ["kitchen_a", "kitchen_b", "kitchen_c"] {
            assert!(
                images.join(format!("{scene}.png")).exists(),
                "top-down image of {scene}"
            );
        }
        let em = submitted_em(cli(
            &server,
            &[
                "submit",
                "plans",
                file.to_str().unwrap(),
                "--split",
                split,
                "--reference",
                "--json",
            ],
            // The organiser's reference row: the organiser token, no team, no quota.
            ADMIN,
        ));
        assert!(
            (em - expected).abs() < 1e-12,
            "{split}: EM {em}, docs/measured/baseline-planning.md says {expected}"
        );
    }
    // The dev estimate the planner prints is the server's EM.
    let run = ok(planner(
        &server,
        &[
            "--split",
            "dev",
            "--out",
            dir.join("again.jsonl").to_str().unwrap(),
        ],
    ));
    assert!(err(&run).contains(&format!("{DEV_EM:.6}")), "{}", err(&run));

    let board = ok(cli(
        &server,
        &[
            "leaderboard",
            "--track",
            "planning",
            "--split",
            "test",
            "--format",
            "json",
        ],
        "",
    ));
    let v: Value = serde_json::from_str(&out(&board)).unwrap();
    let row = &v["rows"][0];
    assert_eq!(row["team"], "(baseline)", "{v}");
    assert_eq!(row["baseline"], true, "a marked baseline row: {v}");
    assert!(row["rank"].is_null(), "baseline rows are not ranked: {v}");
    assert!(
        (row["scores"]["em"].as_f64().unwrap() - TEST_SAMPLE_EM).abs() < 1e-12,
        "{v}"
    );
}

#[test]
fn the_llm_path_asks_an_openai_compatible_endpoint_and_repairs_invalid_answers() {
    let fx = ControlFixture::new("");
    let server = fx.serve(0);
    let token = baseline_team(&server);
    let fake = planner_dir().join("tests/fake_openai.py");
    let (child, line) = spawn_ready(
        Command::new("python3")
            .arg(&fake)
            .args(["--mode", "invalid-then-valid"])
            .env("PYTHONDONTWRITEBYTECODE", "1"),
        "listening ",
    );
    let _fake = Proc(child);
    let url = format!(
        "http://127.0.0.1:{}",
        line.trim_start_matches("listening ").trim()
    );

    let file = fx.dir.path().join("llm.jsonl");
    let run = ok(planner(
        &server,
        &[
            "--split",
            "dev",
            "--limit",
            "6",
            "--out",
            file.to_str().unwrap(),
            "--llm",
            &url,
            "--model",
            "fake",
        ],
    ));
    // Each answer is prose first (refused by the grammar check), then a valid plan.
    let stats = err(&run);
    assert!(stats.contains("\"requests\": 12"), "{stats}");
    assert!(stats.contains("\"repaired\": 6"), "{stats}");
    assert!(stats.contains("llm-repaired 6"), "{stats}");
    let lines = std::fs::read_to_string(&file).unwrap();
    assert_eq!(lines.lines().count(), 6);
    // The server takes the file (157 dev instructions missing: scored 0, with a warning).
    let em = submitted_em(cli(
        &server,
        &[
            "submit",
            "plans",
            file.to_str().unwrap(),
            "--split",
            "dev",
            "--json",
        ],
        &token,
    ));
    assert!((0.0..1.0).contains(&em), "{em}");
}

/// The planner's own unit tests (parser pieces, LLM path, run.py), standard library unittest.
#[test]
fn the_planners_unit_tests_pass() {
    let run = Command::new("python3")
        .args(["-m", "unittest", "discover", "-s"])
        .arg(planner_dir().join("tests"))
        .env("PYTHONDONTWRITEBYTECODE", "1")
        .output()
        .unwrap();
    assert!(run.status.success(), "{}", err(&run));
}
