//! Replay on demand (docs/twin/replay.md) through the real binary: `eval --trace` writes one trace
//! per episode, `replay --check-only` reproduces it bit for bit, `replay --video` writes the MP4
//! `eval --record` would, `replay --mcap/--frames` record it at any camera and resolution, and a
//! tampered trace is refused without writing anything.

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
    assert!(b.windows(4).any(|w| w == b"avcC"), "an H.264 track");

    // The MCAP `collect` would write, and the gripper camera alone at 64x48 as PNG files.
    let mcap = dir.path().join("episode.mcap");
    let frames = dir.path().join("frames");
    let (m, f) = (
        mcap.to_string_lossy().into_owned(),
        frames.to_string_lossy().into_owned(),
    );
    let out = ok(&[
        "replay", &trace_s, "--mcap", &m, "--frames", &f, "--camera", "gripper", "--size", "64x48",
        "--every", "5",
    ]);
    assert!(out.contains("agrees with the recorded outcome"), "{out}");
    assert!(
        !dir.path().join("episode.mp4.partial").exists() && !mcap.with_extension("mcap.partial").exists()
    );
    let b = std::fs::read(&mcap).unwrap();
    assert_eq!(&b[..8], b"\x89MCAP0\r\n", "an MCAP file");
    assert!(
        b.windows(25).any(|w| w == b"/camera/gripper/image_raw"),
        "the gripper's topic"
    );
    assert!(
        !b.windows(22).any(|w| w == b"/camera/base/image_raw"),
        "--camera left the base out"
    );
    let pngs: Vec<PathBuf> = std::fs::read_dir(&frames)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert!(pngs.len() > 3, "{pngs:?}");
    for p in &pngs {
        let name = p.file_name().unwrap().to_string_lossy().into_owned();
        assert!(name.ends_with("_gripper.png"), "{name}");
        let png = std::fs::read(p).unwrap();
        let (w, h) = (&png[16..20], &png[20..24]);
        assert_eq!(
            (w, h),
            (&64u32.to_be_bytes()[..], &48u32.to_be_bytes()[..]),
            "{name} is 64x48"
        );
    }
    let steps: usize = out
        .lines()
        .find_map(|l| l.strip_prefix(&format!("mcap {m}: ")))
        .and_then(|l| l.split(' ').next()?.parse().ok())
        .unwrap_or_else(|| panic!("the MCAP's step count: {out}"));
    assert_eq!(
        pngs.len(),
        steps.div_ceil(5),
        "every 5th of {steps} control steps"
    );

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
    let (bad_mcap, bad_frames) = (
        dir.path().join("tampered.mcap"),
        dir.path().join("tampered-frames"),
    );
    let out = kr(&[
        "replay",
        &tampered.to_string_lossy(),
        "--video",
        &bad_video.to_string_lossy(),
        "--mcap",
        &bad_mcap.to_string_lossy(),
        "--frames",
        &bad_frames.to_string_lossy(),
    ]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("disagrees with the recorded episode"), "{err}");
    assert!(!bad_video.exists(), "a refused replay writes no video");
    let left: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert!(
        !left
            .iter()
            .any(|n| n.to_string_lossy().starts_with("tampered")
                && !n.to_string_lossy().ends_with(".trace.json")),
        "a refused replay leaves no MCAP, frames or partial file: {left:?}"
    );
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
