//! Live ROS 2 topics over real DDS through the real binary (docs/twin/live.md): `eval --ros2` and
//! `replay --ros2` publish the episode with RustDDS, and a subscriber on another DDS
//! implementation, Eclipse Cyclone DDS (the PyPI `cyclonedds` wheel, driven by
//! scripts/ros2-watch.py), reads typed `sensor_msgs/Imu`, `nav_msgs/Odometry`,
//! `tf2_msgs/TFMessage`, `sensor_msgs/Image` and `rosgraph_msgs/Clock` messages as a ROS 2 node would, with their
//! stamps and frame ids; the run's results are those of a run without publishing.
//!
//! Discovery stays on loopback: the publisher's configs/live.toml default (`network =
//! "loopback"`: RustDDS uses 127.0.0.1 only, announcing itself by unicast to this host's
//! well-known discovery ports) and the subscriber's Cyclone configuration (interface `lo`, no
//! multicast, Peers 127.0.0.1) send nothing to any other address, so no network namespace or
//! root is needed. Each test takes its own domain id, derived from the process id, so parallel
//! runs on one machine do not see each other.
//!
//! Without the `cyclonedds` module the tests are skipped outside CI (scripts/test.sh installs
//! it from scripts/test-requirements.txt) and fail in CI.

use std::io::{BufRead, BufReader, Read};
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

use serde_json::Value;

use crate::live::{eval_args, results};
use crate::support::{Proc, bin};

fn cyclonedds_ready() -> bool {
    let ok = Command::new("python3")
        .args(["-c", "import cyclonedds.domain"])
        .status()
        .is_ok_and(|s| s.success());
    if !ok {
        assert!(
            std::env::var("CI").is_err(),
            "python3 with the cyclonedds module (scripts/test-requirements.txt) is required in CI"
        );
        eprintln!("skipped: the cyclonedds Python module is not installed (pip install cyclonedds)");
    }
    ok
}

/// A domain id of this test process's own (`offset` tells its tests apart), in 1..=230.
fn domain(offset: u32) -> String {
    (1 + (std::process::id() * 3 + offset) % 230).to_string()
}

fn script() -> String {
    format!("{}/../scripts/ros2-watch.py", env!("CARGO_MANIFEST_DIR"))
}

/// The Cyclone DDS subscriber in `domain`, started and ready (its readers exist).
fn subscriber(domain: &str) -> (Proc, mpsc::Receiver<String>) {
    let mut child = Command::new("python3")
        .args([&script(), "--domain", domain, "--count", "3", "--seconds", "240"])
        .env_remove("CYCLONEDDS_URI")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run python3 scripts/ros2-watch.py");
    let mut err = BufReader::new(child.stderr.take().unwrap());
    let mut line = String::new();
    err.read_line(&mut line).unwrap();
    assert_eq!(line.trim(), "ready", "the subscriber did not start: {line}");
    let (tx, rx) = mpsc::channel();
    let mut out = child.stdout.take().unwrap();
    std::thread::spawn(move || {
        let mut s = String::new();
        let _ = out.read_to_string(&mut s);
        let _ = err.read_to_string(&mut s);
        let _ = tx.send(s);
    });
    (Proc(child), rx)
}

/// Check what the subscriber printed: every topic with the frames and fields a ROS 2 node
/// expects, stamped with sim time, `/odom` and `/imu` of the same control steps.
fn check_messages(printed: &str) {
    let msgs: Vec<Value> = (printed.lines())
        .filter_map(|l| serde_json::from_str::<Value>(l).ok())
        .filter(|v| v.get("topic").is_some())
        .collect();
    let of = |t: &str| -> Vec<&Value> { msgs.iter().filter(|m| m["topic"] == t).collect() };
    // Camera frames go out at most 30 a wall second: a short debug run may send only a few.
    let wanted = [
        ("/imu", 3),
        ("/odom", 3),
        ("/tf", 3),
        ("/camera/base/image_raw", 1),
        ("/clock", 3),
    ];
    for (t, n) in wanted {
        assert!(
            of(t).len() >= n,
            "too few {t} messages; the subscriber printed:\n{printed}"
        );
    }
    for m in of("/odom") {
        assert_eq!(
            (m["frame_id"].as_str(), m["child"].as_str()),
            (Some("odom"), Some("base_link"))
        );
    }
    for m in of("/tf") {
        assert_eq!(
            (m["frame_id"].as_str(), m["child"].as_str()),
            (Some("odom"), Some("base_link"))
        );
        assert_eq!(m["transforms"], 2, "odom->base_link and base_link->ee_link");
    }
    for m in of("/imu") {
        assert_eq!(m["frame_id"], "base_link");
        let qw = m["qw"].as_f64().unwrap();
        assert!((-1.0..=1.0).contains(&qw), "{m}");
    }
    for m in of("/camera/base/image_raw") {
        assert_eq!(m["frame_id"], "base_optical_frame");
        assert_eq!(
            (m["width"].as_u64(), m["height"].as_u64()),
            (Some(128), Some(128))
        );
        assert_eq!(
            (m["encoding"].as_str(), m["bytes"].as_u64()),
            (Some("rgb8"), Some(128 * 128 * 3))
        );
    }
    let stamps = |t: &str| -> Vec<u64> { of(t).iter().map(|m| m["stamp"].as_u64().unwrap()).collect() };
    let (odom, imu, clock) = (stamps("/odom"), stamps("/imu"), stamps("/clock"));
    assert!(odom.iter().all(|s| *s > 0), "sim time stamps: {odom:?}");
    assert!(odom.windows(2).all(|w| w[0] <= w[1]), "in order: {odom:?}");
    assert!(
        odom.iter().any(|s| imu.contains(s)),
        "/odom and /imu of the same steps share stamps: {odom:?} {imu:?}"
    );
    assert!(
        odom.iter().any(|s| clock.contains(s)),
        "/clock carries the steps' sim time: {odom:?} {clock:?}"
    );
}

/// Run `kitchen-r ARGS` publishing in `domain` while the subscriber reads; its stdout, after
/// checking the subscriber got every topic and the run's summary.
fn published_run<S: AsRef<std::ffi::OsStr> + std::fmt::Debug>(args: &[S], domain: &str) -> String {
    let (mut sub, printed) = subscriber(domain);
    let mut run = Command::new(bin());
    run.args(args)
        .env("ROS_DOMAIN_ID", domain)
        .env("RUST_LOG", "warn")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    let mut run = Proc(run.spawn().unwrap());
    let mut stderr = String::new();
    let mut stdout = String::new();
    run.0.stderr.take().unwrap().read_to_string(&mut stderr).unwrap();
    run.0.stdout.take().unwrap().read_to_string(&mut stdout).unwrap();
    let status = run.0.wait().unwrap();
    assert!(status.success(), "{args:?} failed:\n{stderr}");
    assert!(
        stderr.contains(&format!("ros2 topics: domain {domain}")),
        "{stderr}"
    );
    assert!(stderr.contains("samples written to DDS"), "{stderr}");
    let printed = printed
        .recv_timeout(Duration::from_secs(60))
        .expect("the subscriber ends once it has every topic or times out");
    let ok = sub.0.wait().unwrap().success();
    assert!(
        ok,
        "the subscriber missed topics:\n{printed}\nthe run said:\n{stderr}"
    );
    check_messages(&printed);
    stdout
}

#[test]
fn eval_ros2_publishes_typed_topics_a_cyclone_dds_subscriber_reads_and_changes_no_result() {
    if !cyclonedds_ready() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("eval.toml");
    std::fs::write(&cfg, "max_plan_steps = 2\n").unwrap();
    let cfg = cfg.to_string_lossy().into_owned();
    let plain = Command::new(bin()).args(eval_args(&cfg)).output().unwrap();
    assert!(
        plain.status.success(),
        "{}",
        String::from_utf8_lossy(&plain.stderr)
    );
    let mut args = eval_args(&cfg);
    args.extend(["--ros2".into(), "--ros2-wait".into()]);
    let live = published_run(&args, &domain(0));
    assert_eq!(results(&live), results(&String::from_utf8_lossy(&plain.stdout)));
}

#[test]
fn replay_ros2_publishes_a_traced_episode_to_a_cyclone_dds_subscriber() {
    if !cyclonedds_ready() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("eval.toml");
    std::fs::write(&cfg, "max_plan_steps = 1\n").unwrap();
    let traces = dir.path().join("traces");
    let mut args = eval_args(cfg.to_str().unwrap());
    args.extend(["--trace".into(), traces.to_string_lossy().into_owned()]);
    let traced = Command::new(bin()).args(&args).output().unwrap();
    assert!(
        traced.status.success(),
        "{}",
        String::from_utf8_lossy(&traced.stderr)
    );
    let trace = std::fs::read_dir(&traces)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.to_string_lossy().ends_with(".trace.json"))
        .expect("eval --trace wrote a trace");
    let out = published_run(
        &[
            "replay",
            trace.to_str().unwrap(),
            "--ros2",
            "--ros2-wait",
            "--speed",
            "4",
        ],
        &domain(1),
    );
    assert!(out.contains("task 0") && out.contains("success"), "{out}");
}

/// `collect --ros2` shows the episodes it records; what it records is the same.
#[test]
fn collect_ros2_publishes_the_recorded_episode_live() {
    if !cyclonedds_ready() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let (plain, live) = (dir.path().join("plain"), dir.path().join("live"));
    let args = |out: &std::path::Path| -> Vec<String> {
        let a = [
            "collect",
            "--episodes",
            "1",
            "--jobs",
            "1",
            "--format",
            "mcap",
            "--json",
            "--out",
        ];
        let mut a: Vec<String> = a.iter().map(|s| s.to_string()).collect();
        a.push(out.to_string_lossy().into_owned());
        a
    };
    let run = Command::new(bin()).args(args(&plain)).output().unwrap();
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let mut with = args(&live);
    with.extend(["--ros2".to_string(), "--ros2-wait".to_string()]);
    let summary: Value = serde_json::from_str(&published_run(&with, &domain(2))).unwrap();
    assert_eq!(summary["kept"], 1, "{summary}");
    let mcap = |d: &std::path::Path| std::fs::read(d.join("ep00000.mcap")).unwrap();
    assert!(
        mcap(&plain) == mcap(&live),
        "the MCAP recorded while publishing differs"
    );
}
