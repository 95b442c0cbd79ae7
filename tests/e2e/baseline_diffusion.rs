//! The control baseline (`starter-kit/baselines/diffusion_policy`, PyTorch) end to end on CPU: a
//! tiny LeRobot dataset collected by `kitchen-r collect --format lerobot`, a few training steps,
//! the checkpoint saved (under 16 MiB) and loaded again by the server that serves it over the
//! policy contract, `kitchen-r check-policy` passing against it, and an organiser reference run
//! of it finishing on a server this test starts, where it shows as a baseline row of the dev
//! control leaderboard. The score is not asserted: a few steps teach the policy nothing. The
//! baseline's Python unit tests (sample timing and padding, valid actions) run here too.
//!
//! Needs a Python with torch, torchvision, pyarrow, av and the starter kit's gRPC modules:
//! `KITCHEN_R_TORCH_PYTHON`, else `python3` (scripts/test.sh and .ci/run install torch from
//! scripts/test-requirements-torch.txt). Without them the test fails and says what to install.

use crate::support;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::{Value, json};
use support::*;

/// Modules the baseline imports.
const MODULES: &str = "torch, torchvision, pyarrow, av, numpy, grpc, grpc_tools, grpc_health";

fn baseline_dir() -> PathBuf {
    repo().join("starter-kit/baselines/diffusion_policy")
}

fn python() -> String {
    std::env::var("KITCHEN_R_TORCH_PYTHON").unwrap_or_else(|_| "python3".to_string())
}

fn py(args: &[&str]) -> Command {
    let mut cmd = Command::new(python());
    cmd.args(args)
        .env("PYTHONDONTWRITEBYTECODE", "1")
        // Two cores are shared by every test: keep torch to one thread.
        .env("OMP_NUM_THREADS", "1");
    cmd
}

fn assert_python_ready() {
    let check = py(&["-c", &format!("import {MODULES}")]).output();
    let ready = check.as_ref().is_ok_and(|o| o.status.success());
    assert!(
        ready,
        "the diffusion-policy baseline test needs {} with {MODULES}: install them with \
         `{} -m pip install -r scripts/test-requirements-torch.txt -r starter-kit/requirements.txt` \
         (scripts/test.sh does) or point KITCHEN_R_TORCH_PYTHON at a Python that has them; {}",
        python(),
        python(),
        check.map_or_else(|e| e.to_string(), |o| err(&o))
    );
}

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn kr(args: &[&str]) -> Output {
    Command::new(bin())
        .args(args)
        .current_dir(repo())
        .env("RUST_LOG", "warn")
        .output()
        .expect("run kitchen-r")
}

/// One generated episode cut to its first plan step (a short navigation task), so that the
/// debug build collects it in seconds.
fn short_batch(dir: &Path) -> PathBuf {
    let full = dir.join("batch.json");
    ok(kr(&[
        "episodes",
        "generate",
        "--count",
        "1",
        "--out",
        full.to_str().unwrap(),
    ]));
    let mut batch: Value = serde_json::from_str(&std::fs::read_to_string(&full).unwrap()).unwrap();
    let ep = &mut batch[0];
    let first = ep["plan"][0].clone();
    ep["plan"] = json!([first]);
    ep["place_targets"] = json!([]);
    let short = dir.join("short.json");
    std::fs::write(&short, batch.to_string()).unwrap();
    short
}

#[test]
fn the_diffusion_baselines_python_unit_tests_pass() {
    assert_python_ready();
    let tests = baseline_dir().join("tests");
    let run = ok(py(&["-m", "unittest", "discover", "-s", tests.to_str().unwrap()])
        .output()
        .expect("run python -m unittest"));
    assert!(err(&run).contains("OK"), "{}", err(&run));
}

#[tokio::test(flavor = "multi_thread")]
async fn the_diffusion_baseline_trains_serves_passes_check_policy_and_gets_a_baseline_row() {
    assert_python_ready();
    let fx = ControlFixture::new("[control]\nmax_plan_steps = 1\ntask_time_limit_s = 3.0\n");
    let dir = fx.dir.path();

    let batch = short_batch(dir);
    let data = dir.join("collect");
    let collected = ok(kr(&[
        "collect",
        "--episodes-file",
        batch.to_str().unwrap(),
        "--out",
        data.to_str().unwrap(),
        "--format",
        "lerobot",
        "--cameras",
        "base,gripper",
        "--no-depth",
        "--jobs",
        "1",
        "--json",
    ]));
    let summary: Value = serde_json::from_str(&out(&collected)).unwrap();
    assert_eq!(summary["kept"], 1, "{summary}");

    // A few steps of the real model at a small image size, then the checkpoint and the log.
    let ckpt = dir.join("ckpt.pt");
    let train = baseline_dir().join("train.py");
    let trained = ok(py(&[
        train.to_str().unwrap(),
        "--dataset",
        data.to_str().unwrap(),
        "--out",
        ckpt.to_str().unwrap(),
        "--steps",
        "3",
        "--batch",
        "2",
        "--image-size",
        "32",
        "--workers",
        "1",
        "--device",
        "cpu",
    ])
    .output()
    .expect("run train.py"));
    assert!(out(&trained).contains("saved"), "{}", out(&trained));
    let size = std::fs::metadata(&ckpt).expect("checkpoint written").len();
    assert!(size < 16 * 1024 * 1024, "checkpoint of {size} bytes");
    let log: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("train_log.json")).unwrap()).unwrap();
    assert_eq!(log["episodes"], 1, "{log}");
    assert_eq!(log["steps"], 3, "{log}");
    assert_eq!(log["frames"], summary["frames"], "{log}");
    assert!(log["final_loss"].as_f64().is_some_and(f64::is_finite), "{log}");

    // The checkpoint loaded again by the policy server.
    let serve = baseline_dir().join("serve.py");
    let (child, line) = spawn_ready(
        py(&[
            serve.to_str().unwrap(),
            "--checkpoint",
            ckpt.to_str().unwrap(),
            "--listen",
            "127.0.0.1:0",
            "--device",
            "cpu",
            "--steps",
            "2",
            "--concurrency",
            "2",
        ])
        .env("KITCHEN_R_PROTO", repo().join("proto")),
        "listening grpc=",
    );
    let _policy = Proc(child);
    let url = format!("http://{}", line.trim_start_matches("listening grpc=").trim());

    let checked = ok(kr(&["check-policy", &url]));
    let report = out(&checked);
    assert!(report.contains("all checks passed"), "{report}");
    assert!(report.contains("observation history 2"), "{report}");
    assert!(report.contains("executes 8 actions per chunk"), "{report}");

    // The organiser publishes it: a reference run on dev, shown as a baseline row.
    let server = fx.serve(1);
    let body = json!({"endpoint": url, "split": "dev", "episodes": 1, "reference": true});
    let (status, reg) = register_policy(&server, ADMIN, body).await;
    assert_eq!(status, 201, "{reg}");
    let id = reg["id"].as_i64().unwrap();
    let view = wait_for(&server, id, ADMIN, "the baseline's reference run", finished).await;
    assert_eq!(view["latest_run"]["evaluation"]["state"], "finished", "{view:#}");
    let scores = &view["latest_run"]["scores"];
    assert!(scores["sr"].as_f64().is_some(), "{view:#}");
    assert!(scores["mse"].as_f64().is_some_and(f64::is_finite), "{view:#}");
    let (_, board) = get_json(&server, "/api/v1/leaderboard?track=control&split=dev", None).await;
    assert!(
        board["rows"]
            .as_array()
            .unwrap()
            .iter()
            .any(|r| r["baseline"] == true && r["submission_id"] == id),
        "{board:#}"
    );
}
