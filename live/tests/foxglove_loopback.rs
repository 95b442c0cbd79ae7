//! The Foxglove live view on loopback, driven by a real WebSocket client speaking the
//! protocol as Lichtblick does: it gets `serverInfo` and the advertised channels with their
//! `ros2msg` schemas, subscribes, and decodes the CDR of the messages it receives.

use std::net::SocketAddr;
use std::time::{Duration, Instant};

use futures_util::{SinkExt, StreamExt};
use kitchen_r_live::foxglove::FoxgloveServer;
use kitchen_r_record::ros2_frame::frame_messages;
use kitchen_r_record::{CameraFrame, Frame};
use serde_json::Value;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;

fn frame(time: f64) -> Frame {
    Frame {
        time,
        cameras: vec![CameraFrame {
            name: "base".into(),
            width: 4,
            height: 2,
            rgb: vec![7; 24],
            depth: vec![1.5; 8],
        }],
        lidar: None,
        base_pose: [1.0, 2.0, 0.5],
        base_twist: [0.2, 0.1],
        action: [0.0; 10],
        qpos: vec![],
        qvel: vec![],
        ee_pose: [0.3, 0.0, 0.8, 1.0, 0.0, 0.0, 0.0],
        task: 0,
    }
}

type Ws = tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

async fn connect(addr: SocketAddr) -> Ws {
    let mut req = format!("ws://{addr}/").into_client_request().unwrap();
    let offered = "foxglove.websocket.v1".parse().unwrap();
    req.headers_mut().insert("sec-websocket-protocol", offered);
    let (ws, resp) = tokio_tungstenite::connect_async(req).await.unwrap();
    assert_eq!(resp.headers()["sec-websocket-protocol"], "foxglove.websocket.v1");
    ws
}

async fn next_json(ws: &mut Ws) -> Value {
    loop {
        match tokio::time::timeout(Duration::from_secs(10), ws.next()).await {
            Ok(Some(Ok(Message::Text(t)))) => return serde_json::from_str(&t).unwrap(),
            Ok(Some(Ok(_))) => continue,
            other => panic!("no text message: {other:?}"),
        }
    }
}

/// `(subscription, log time, payload)` of the next `messageData`; JSON messages before it are
/// kept in `texts`.
async fn next_message(ws: &mut Ws, texts: &mut Vec<Value>) -> (u32, u64, Vec<u8>) {
    loop {
        match tokio::time::timeout(Duration::from_secs(10), ws.next()).await {
            Ok(Some(Ok(Message::Binary(b)))) if b[0] == 1 => {
                let sub = u32::from_le_bytes(b[1..5].try_into().unwrap());
                let t = u64::from_le_bytes(b[5..13].try_into().unwrap());
                return (sub, t, b[13..].to_vec());
            }
            Ok(Some(Ok(Message::Text(t)))) => texts.push(serde_json::from_str(&t).unwrap()),
            Ok(Some(Ok(_))) => continue,
            other => panic!("no message data: {other:?}"),
        }
    }
}

/// A CDR `std_msgs/Header` at the start of a payload: (sec, nanosec, frame_id).
fn header(cdr: &[u8]) -> (i32, u32, String) {
    assert_eq!(&cdr[..2], [0, 1], "CDR little-endian encapsulation");
    let p = &cdr[4..];
    let sec = i32::from_le_bytes(p[0..4].try_into().unwrap());
    let nsec = u32::from_le_bytes(p[4..8].try_into().unwrap());
    let n = u32::from_le_bytes(p[8..12].try_into().unwrap()) as usize;
    (sec, nsec, String::from_utf8(p[12..12 + n - 1].to_vec()).unwrap())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_gets_the_channels_subscribes_and_decodes_stamped_frames() {
    let topics = vec![("/odom".to_string(), "nav_msgs/Odometry")];
    let server = std::thread::spawn(move || FoxgloveServer::start("127.0.0.1:0".parse().unwrap(), &topics))
        .join()
        .unwrap()
        .unwrap();
    let mut ws = connect(server.local_addr()).await;
    let info = next_json(&mut ws).await;
    assert_eq!(info["op"], "serverInfo");
    assert_eq!(info["capabilities"], serde_json::json!(["time"]));
    let adv = next_json(&mut ws).await;
    assert_eq!(adv["op"], "advertise");
    let odom = &adv["channels"][0];
    assert_eq!(odom["topic"], "/odom");
    assert_eq!(odom["encoding"], "cdr");
    assert_eq!(odom["schemaEncoding"], "ros2msg");
    assert_eq!(odom["schemaName"], "nav_msgs/msg/Odometry");
    assert!(
        odom["schema"]
            .as_str()
            .unwrap()
            .contains("MSG: geometry_msgs/PoseWithCovariance")
    );
    let sub = serde_json::json!({"op": "subscribe", "subscriptions": [{"id": 9, "channelId": odom["id"]}]});
    ws.send(Message::Text(sub.to_string().into())).await.unwrap();

    // The publisher thread's side; a topic first seen now (the camera) is advertised then.
    let mut sink = server.sink();
    let publisher = std::thread::spawn(move || {
        let mut imu = None;
        for i in 1..=40 {
            for m in frame_messages(&frame(2.0 + 0.1 * i as f64), &mut imu) {
                sink.publish(&m);
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    });
    let mut texts = Vec::new();
    let (sub, t, payload) = next_message(&mut ws, &mut texts).await;
    assert_eq!(sub, 9);
    let (sec, nsec, frame_id) = header(&payload);
    assert_eq!(frame_id, "odom");
    assert_eq!(
        sec as u64 * 1_000_000_000 + nsec as u64,
        t,
        "log time = header stamp"
    );
    assert!(t >= 2_100_000_000, "{t}");
    // The camera's channel, first seen in the same frame, was advertised before it (with any
    // other topic first seen then, such as /clock, in one advertisement or several).
    let topics: Vec<&str> = (texts.iter())
        .filter(|t| t["op"] == "advertise")
        .flat_map(|t| t["channels"].as_array().unwrap())
        .map(|c| c["topic"].as_str().unwrap())
        .collect();
    assert!(topics.contains(&"/camera/base/image_raw"), "{texts:?}");
    publisher.join().unwrap();
    drop(ws);
    std::thread::spawn(move || drop(server)).join().unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_subscriber_that_never_reads_never_holds_up_the_publisher() {
    let topics = vec![("/camera/base/image_raw".to_string(), "sensor_msgs/Image")];
    let server = std::thread::spawn(move || FoxgloveServer::start("127.0.0.1:0".parse().unwrap(), &topics))
        .join()
        .unwrap()
        .unwrap();
    let watched = server.sensors_watched();
    let mut ws = connect(server.local_addr()).await;
    let _info = next_json(&mut ws).await;
    let adv = next_json(&mut ws).await;
    let id = adv["channels"][0]["id"].clone();
    let sub = serde_json::json!({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": id}]});
    ws.send(Message::Text(sub.to_string().into())).await.unwrap();
    let until = Instant::now() + Duration::from_secs(10);
    while !watched.load(std::sync::atomic::Ordering::Relaxed) {
        assert!(
            Instant::now() < until,
            "a camera subscription marks the sensors watched"
        );
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    // 2,000 frames of 128x128 RGB (~100 MB) to a client that reads none of them.
    let mut sink = server.sink();
    let big = Frame {
        cameras: vec![CameraFrame {
            name: "base".into(),
            width: 128,
            height: 128,
            rgb: vec![1; 128 * 128 * 3],
            depth: vec![],
        }],
        ..frame(0.0)
    };
    let started = Instant::now();
    std::thread::spawn(move || {
        let mut imu = None;
        for i in 0..2000 {
            let f = Frame {
                time: i as f64 * 0.1,
                ..big.clone()
            };
            for m in frame_messages(&f, &mut imu) {
                sink.publish(&m);
            }
        }
    })
    .join()
    .unwrap();
    assert!(
        started.elapsed() < Duration::from_secs(20),
        "{:?}",
        started.elapsed()
    );
    drop(ws);
    std::thread::spawn(move || drop(server)).join().unwrap();
}
