//! The Foxglove live view through the real binary (docs/twin/live.md): `eval --foxglove` serves the
//! episode on loopback, a client speaking the Foxglove WebSocket protocol as Lichtblick does
//! gets the channel list with `ros2msg` schemas, subscribes, and decodes the CDR messages'
//! stamps and frames while the episode runs; the run's results are those of a run without it.

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use futures_util::{SinkExt, StreamExt};
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;

use crate::support::{Proc, bin, oracle_policy};

/// `eval` of one episode with a `--json` report (the Foxglove and ROS 2 tests add their flags).
pub(crate) fn eval_args(cfg: &str) -> Vec<String> {
    let args = [
        "eval",
        "--episodes",
        "1",
        "--jobs",
        "1",
        "--json",
        "--config",
        cfg,
    ];
    args.iter().map(|s| s.to_string()).collect()
}

/// A report (`eval --json`) less its wall times: what must not change with a viewer (Foxglove
/// here, ROS 2 in `ros2_live`).
pub(crate) fn results(report: &str) -> Value {
    fn strip(v: &mut Value) {
        match v {
            Value::Object(m) => {
                m.retain(|k, _| !k.contains("wall"));
                m.values_mut().for_each(strip);
            }
            Value::Array(a) => a.iter_mut().for_each(strip),
            _ => {}
        }
    }
    let mut r: Value = serde_json::from_str(report).unwrap_or_else(|e| panic!("{e}: {report}"));
    strip(&mut r);
    r
}

/// A `std_msgs/Header` at the start of a CDR payload: (stamp in ns, frame_id, bytes read).
fn header(cdr: &[u8]) -> (u64, String, usize) {
    assert_eq!(&cdr[..4], [0, 1, 0, 0], "CDR little-endian encapsulation");
    let p = &cdr[4..];
    let sec = i32::from_le_bytes(p[0..4].try_into().unwrap()) as u64;
    let nsec = u32::from_le_bytes(p[4..8].try_into().unwrap()) as u64;
    let n = u32::from_le_bytes(p[8..12].try_into().unwrap()) as usize;
    let frame = String::from_utf8(p[12..12 + n - 1].to_vec()).unwrap();
    (sec * 1_000_000_000 + nsec, frame, 12 + n)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn eval_foxglove_serves_the_episode_live_to_a_protocol_client_and_changes_no_result() {
    watched_eval(&[]).await;
}

/// A policy endpoint's episodes, run as the workers run them, are watched alike.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_endpoint_policys_episode_is_watched_live_with_its_results_unchanged() {
    let (_oracle, url) = oracle_policy();
    watched_eval(&["--policy", &url, "--privileged"]).await;
}

/// `eval --episodes 1 … EXTRA` without and with `--foxglove`: a viewer connects, checks the
/// channels and decodes messages of three topics; the two runs' results must be equal.
async fn watched_eval(extra: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("eval.toml");
    std::fs::write(&cfg, "max_plan_steps = 2\n").unwrap();
    let cfg = cfg.to_string_lossy().into_owned();
    let plain = Command::new(bin())
        .args(eval_args(&cfg))
        .args(extra)
        .output()
        .unwrap();
    assert!(
        plain.status.success(),
        "{}",
        String::from_utf8_lossy(&plain.stderr)
    );

    let mut cmd = Command::new(bin());
    cmd.args(eval_args(&cfg))
        .args(extra)
        .args(["--foxglove", "127.0.0.1:0", "--foxglove-wait"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    let mut live = Proc(cmd.spawn().unwrap());
    let stderr = live.0.stderr.take().unwrap();
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for l in BufReader::new(stderr).lines().map_while(Result::ok) {
            let _ = tx.send(l);
        }
    });
    let url = loop {
        let l = rx
            .recv_timeout(Duration::from_secs(120))
            .expect("the live view's address");
        if let Some(u) = l.strip_prefix("live view: ") {
            break u.to_string();
        }
    };
    assert!(url.starts_with("ws://127.0.0.1:"), "{url}");
    let mut req = url.as_str().into_client_request().unwrap();
    let offered = "foxglove.websocket.v1".parse().unwrap();
    req.headers_mut().insert("sec-websocket-protocol", offered);
    let (mut ws, resp) = tokio_tungstenite::connect_async(req).await.unwrap();
    assert_eq!(resp.headers()["sec-websocket-protocol"], "foxglove.websocket.v1");

    let mut text = Vec::new();
    while text.len() < 2 {
        match tokio::time::timeout(Duration::from_secs(30), ws.next()).await {
            Ok(Some(Ok(Message::Text(t)))) => text.push(serde_json::from_str::<Value>(&t).unwrap()),
            other => panic!("serverInfo and advertise expected: {other:?}"),
        }
    }
    assert_eq!(text[0]["op"], "serverInfo");
    assert_eq!(text[1]["op"], "advertise");
    let channels = text[1]["channels"].as_array().unwrap();
    let find = |topic: &str| {
        let c = channels.iter().find(|c| c["topic"] == topic);
        c.unwrap_or_else(|| panic!("{topic} not advertised: {channels:?}"))
            .clone()
    };
    let wanted = [
        ("/odom", "nav_msgs/msg/Odometry"),
        ("/tf", "tf2_msgs/msg/TFMessage"),
        ("/tf_static", "tf2_msgs/msg/TFMessage"),
        ("/imu", "sensor_msgs/msg/Imu"),
        ("/camera/base/image_raw", "sensor_msgs/msg/Image"),
        ("/camera/gripper/depth", "sensor_msgs/msg/Image"),
        ("/sub_task", "std_msgs/msg/String"),
    ];
    for (topic, schema) in wanted {
        let c = find(topic);
        assert_eq!(
            (c["schemaName"].as_str(), c["encoding"].as_str()),
            (Some(schema), Some("cdr"))
        );
        assert_eq!(c["schemaEncoding"], "ros2msg");
        assert!(!c["schema"].as_str().unwrap().is_empty());
    }
    let subs: Vec<Value> = ["/odom", "/tf", "/camera/base/image_raw"]
        .iter()
        .enumerate()
        .map(|(i, t)| json!({"id": i, "channelId": find(t)["id"]}))
        .collect();
    let sub = json!({"op": "subscribe", "subscriptions": subs});
    ws.send(Message::Text(sub.to_string().into())).await.unwrap();

    // Until each subscription has delivered a message, checked as a ROS 2 node would read it.
    let mut seen = [0usize; 3];
    let until = Instant::now() + Duration::from_secs(120);
    while seen.contains(&0) {
        assert!(Instant::now() < until, "messages per subscription: {seen:?}");
        let b = match tokio::time::timeout(Duration::from_secs(60), ws.next()).await {
            Ok(Some(Ok(Message::Binary(b)))) if b[0] == 1 => b,
            Ok(Some(Ok(_))) => continue,
            other => panic!("the live view ended before every topic arrived ({seen:?}): {other:?}"),
        };
        let sub = u32::from_le_bytes(b[1..5].try_into().unwrap()) as usize;
        let log_time = u64::from_le_bytes(b[5..13].try_into().unwrap());
        let payload = &b[13..];
        seen[sub] += 1;
        match sub {
            0 => {
                let (stamp, frame, _) = header(payload);
                assert_eq!((stamp, frame.as_str()), (log_time, "odom"));
                assert!(stamp > 0, "sim time stamps");
            }
            // TFMessage: a sequence of TransformStamped, the first odom -> base_link.
            1 => {
                let (stamp, frame, _) = header(&[&payload[..4], &payload[8..]].concat());
                assert_eq!((stamp, frame.as_str()), (log_time, "odom"));
            }
            _ => {
                let (stamp, frame, read) = header(payload);
                assert_eq!((stamp, frame.as_str()), (log_time, "base_optical_frame"));
                let at = 4 + read.next_multiple_of(4);
                let hw: Vec<u32> = (0..2)
                    .map(|i| u32::from_le_bytes(payload[at + 4 * i..at + 4 * i + 4].try_into().unwrap()))
                    .collect();
                assert_eq!(hw, [128, 128], "height and width");
            }
        }
    }
    drop(ws);
    let out = tokio::task::spawn_blocking(move || {
        let mut child = live.0.stdout.take().unwrap();
        let mut s = String::new();
        std::io::Read::read_to_string(&mut child, &mut s).unwrap();
        let status = live.0.wait().unwrap();
        (s, status)
    })
    .await
    .unwrap();
    assert!(out.1.success(), "eval --foxglove failed");
    // The rest of stderr, up to its end: the reader thread may still be behind the exited
    // process (reading only what had arrived lost the summary line under load).
    let mut tail = Vec::new();
    while let Ok(l) = rx.recv_timeout(Duration::from_secs(30)) {
        tail.push(l);
    }
    assert!(tail.iter().any(|l| l.contains("messages published")), "{tail:?}");
    assert_eq!(results(&out.0), results(&String::from_utf8_lossy(&plain.stdout)));
}
