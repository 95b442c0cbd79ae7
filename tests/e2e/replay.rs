//! Replay on demand (issue #26) through the real binary: `eval --trace` writes one trace per
//! episode, `replay --check-only` reproduces it bit for bit, `replay --video` writes the MP4
//! `eval --record` would, and a tampered trace is refused without writing anything.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use crate::support::{bin, oracle_policy};

fn kr(args: &[&str]) -> Output {
    Command::new(bin()).args(args).output().expect("run kitchen-r")
}

fn ok(args: &[&str]) -> String {
    let out = kr(args);
    assert!(
        out.status.success(),
        "kitchen-r {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// The one trace file `eval --trace dir` wrote.
fn only_trace(dir: &Path) -> PathBuf {
    let files: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(files.len(), 1, "{files:?}");
    assert!(files[0].to_string_lossy().ends_with(".trace.json"), "{files:?}");
    files[0].clone()
}

fn eval_config(dir: &Path, toml: &str) -> String {
    let path = dir.join("eval.toml");
    std::fs::write(&path, toml).unwrap();
    path.to_string_lossy().into_owned()
}

#[test]
fn an_eval_trace_replays_bit_identically_into_a_playable_video_and_a_tampered_one_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let traces = dir.path().join("traces");
    let cfg = eval_config(dir.path(), "max_plan_steps = 2\n");
    let t = traces.to_string_lossy().into_owned();
    let args = [
        "eval",
        "--episodes",
        "1",
        "--jobs",
        "1",
        "--config",
        &cfg,
        "--trace",
        &t,
    ];
    ok(&args);
    let trace = only_trace(&traces);
    let trace_s = trace.to_string_lossy().into_owned();

    let checked = ok(&["replay", &trace_s, "--check-only"]);
    assert!(checked.contains("agrees with the recorded outcome"), "{checked}");
    assert!(checked.contains("overall"), "the outcome table: {checked}");

    let mp4 = dir.path().join("episode.mp4");
    let out = ok(&["replay", &trace_s, "--video", &mp4.to_string_lossy()]);
    assert!(out.contains("frames"), "{out}");
    let b = std::fs::read(&mp4).unwrap();
    assert!(b.len() > 1000, "{} bytes", b.len());
    assert_eq!(&b[4..8], b"ftyp");
    assert!(b.windows(4).any(|w| w == b"av1C"), "an AV1 track");

    // The first executed action's forward speed changed: refused, exit 1, no video written.
    let mut json: serde_json::Value = serde_json::from_slice(&std::fs::read(&trace).unwrap()).unwrap();
    let act = (json["calls"].as_array_mut().unwrap().iter_mut())
        .find_map(|c| c.get_mut("act"))
        .expect("an act call");
    let v = act["chunk"][0][0].as_f64().unwrap();
    act["chunk"][0][0] = serde_json::json!(v + 0.05);
    let tampered = dir.path().join("tampered.trace.json");
    std::fs::write(&tampered, serde_json::to_vec(&json).unwrap()).unwrap();
    let bad_video = dir.path().join("tampered.mp4");
    let out = kr(&[
        "replay",
        &tampered.to_string_lossy(),
        "--video",
        &bad_video.to_string_lossy(),
    ]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("disagrees with the recorded episode"), "{err}");
    assert!(!bad_video.exists(), "a refused replay writes no video");
}

#[test]
fn an_endpoint_episode_with_failures_and_teleports_replays_bit_identically() {
    let dir = tempfile::tempdir().unwrap();
    let traces = dir.path().join("traces");
    // Tasks that run out of time fail, and the next one starts where the expert stood.
    let cfg = eval_config(
        dir.path(),
        "max_plan_steps = 3\ntask_time_limit = 4.0\nteleport_on_failure = true\n",
    );
    let (_policy, url) = oracle_policy();
    let t = traces.to_string_lossy().into_owned();
    let args = [
        "eval",
        "--policy",
        &url,
        "--privileged",
        "--episodes",
        "1",
        "--jobs",
        "1",
        "--config",
        &cfg,
        "--trace",
        &t,
    ];
    ok(&args);
    let trace = only_trace(&traces);
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(&trace).unwrap()).unwrap();
    assert_eq!(json["run"]["expert_starts"], true, "{}", json["run"]);
    let failed = json["outcome"]["tasks"]
        .as_array()
        .unwrap()
        .iter()
        .any(|t| t["success"] == false);
    assert!(failed, "{}", json["outcome"]);
    let checked = ok(&["replay", &trace.to_string_lossy(), "--check-only"]);
    assert!(checked.contains("agrees with the recorded outcome"), "{checked}");
}
