//! `EpisodeSpec.live_ros2` (the server's `[live] ros2`, docs/twin/live.md): a job that asks for it
//! is published live as ROS 2 topics over DDS, which a subscriber on another DDS implementation,
//! Eclipse Cyclone DDS (the PyPI `cyclonedds` wheel driven by scripts/ros2-watch.py, as in
//! tests/e2e/ros2_live.rs), reads typed and stamped; the same job without it (how the server
//! leases every test-split job: `grpc_worker::tests::live_ros2_is_sent_with_online_dev_jobs_only`)
//! publishes nothing; both give the same result.
//!
//! Loopback only on both sides (configs/live.toml's default network and the script's Cyclone
//! configuration), in a domain of this process's own. Without the `cyclonedds` module the test
//! is skipped outside CI and fails in CI.

use std::io::{BufRead, BufReader, Read};
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::time::Duration;

use kitchen_r_contract::server::{PolicyFactory, ServeOptions};
use kitchen_r_contract::{AllowedNetworks, RemoteConfig};
use kitchen_r_episode::oracle::OraclePolicy;
use kitchen_r_episode::policy::Policy;
use kitchen_r_live::ros2::Ros2Config;
use kitchen_r_proto::worker::v1 as pb;
use kitchen_r_sim::Assets;
use kitchen_r_worker::job::{JobContext, JobControl, LiveRos2, execute_job};
use serde_json::Value;

use crate::job_execute::job;
use crate::remote_support::TestServer;

fn cyclonedds_ready() -> bool {
    let ok = (Command::new("python3")
        .args(["-c", "import cyclonedds.domain"])
        .status())
    .is_ok_and(|s| s.success());
    if !ok {
        assert!(
            std::env::var("CI").is_err(),
            "python3 with cyclonedds is required in CI"
        );
        eprintln!("skipped: the cyclonedds Python module is not installed (pip install cyclonedds)");
    }
    ok
}

/// Kills the subscriber if the test fails before it ends.
struct Killed(Child);

impl Drop for Killed {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn subscriber(domain: u16) -> Killed {
    let script = format!("{}/../scripts/ros2-watch.py", env!("CARGO_MANIFEST_DIR"));
    let mut child = Command::new("python3")
        .args([
            &script,
            "--domain",
            &domain.to_string(),
            "--count",
            "3",
            "--seconds",
            "60",
        ])
        .env_remove("CYCLONEDDS_URI")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run python3 scripts/ros2-watch.py");
    let mut line = String::new();
    BufReader::new(child.stderr.as_mut().unwrap())
        .read_line(&mut line)
        .unwrap();
    assert_eq!(line.trim(), "ready", "the subscriber did not start: {line}");
    Killed(child)
}

#[test]
fn a_live_ros2_job_is_published_to_a_cyclone_dds_subscriber_and_one_without_publishes_nothing() {
    if !cyclonedds_ready() {
        return;
    }
    let domain = (1 + (std::process::id() * 3 + 1) % 230) as u16;
    let mut ctx = JobContext::load(RemoteConfig::default(), AllowedNetworks::default(), 1).unwrap();
    ctx.live = LiveRos2::with_config(Ros2Config {
        domain_id: domain,
        ..Ros2Config::default()
    });
    let assets = Arc::new(Assets::load_default().unwrap());
    let f: PolicyFactory = Arc::new(move || Box::new(OraclePolicy::new(&assets)) as Box<dyn Policy>);
    let server = TestServer::start(f, ServeOptions::default());
    let mut sub = subscriber(domain);
    let publisher = ctx
        .live
        .publisher(&ctx.sensors)
        .expect("the DDS participant starts");
    assert!(
        publisher.wait_for_subscriber(Duration::from_secs(20)),
        "no subscriber discovered"
    );

    let quiet = job(&server.url(), pb::EvalMode::Online, 1, true);
    let plain = execute_job(&quiet, &ctx, &JobControl::default());
    assert_eq!(
        ctx.live.counts(),
        Some((0, 0)),
        "a job without live_ros2 publishes nothing"
    );
    assert!(!plain.log_tail.contains("ROS 2"), "{}", plain.log_tail);

    let mut live = quiet.clone();
    live.episode.as_mut().unwrap().live_ros2 = true;
    let published = execute_job(&live, &ctx, &JobControl::default());
    assert!(
        published.log_tail.contains("published live as ROS 2 topics"),
        "{}",
        published.log_tail
    );
    assert_eq!(published.platform_error, "", "{}", published.log_tail);
    assert!(published.tasks.iter().all(|t| t.success), "{:?}", published.tasks);
    eprintln!(
        "episode wall: {} ms without live_ros2, {} ms published to a subscriber reading every message",
        plain.wall_ms, published.wall_ms
    );
    // Debug text, bit for bit (the path's NaNs, no object held, are equal as text only).
    let result = |r: &pb::EpisodeResult| format!("{:?}", (&r.tasks, &r.path));
    assert!(
        result(&published) == result(&plain),
        "publishing changed the result"
    );

    let mut printed = String::new();
    sub.0.stdout.take().unwrap().read_to_string(&mut printed).unwrap();
    let ok = sub.0.wait().unwrap().success();
    let (written, _) = ctx.live.counts().unwrap();
    assert!(
        ok && written > 0,
        "the subscriber missed topics ({written} written):\n{printed}"
    );
    let msgs: Vec<Value> = (printed.lines())
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect();
    let of = |t: &str| -> Vec<&Value> { msgs.iter().filter(|m| m["topic"] == t).collect() };
    for (topic, frame) in [
        ("/odom", "odom"),
        ("/tf", "odom"),
        ("/imu", "base_link"),
        ("/camera/base/image_raw", "base_optical_frame"),
    ] {
        let got = of(topic);
        assert!(!got.is_empty(), "no {topic}:\n{printed}");
        let stamps: Vec<u64> = got.iter().map(|m| m["stamp"].as_u64().unwrap()).collect();
        assert!(stamps.iter().all(|s| *s > 0), "sim-time stamps: {stamps:?}");
        assert!(
            stamps.windows(2).all(|w| w[0] <= w[1]),
            "{topic} in order: {stamps:?}"
        );
        assert!(got.iter().all(|m| m["frame_id"] == frame), "{topic}: {got:?}");
    }
    assert!(of("/odom").iter().all(|m| m["child"] == "base_link"));
}
