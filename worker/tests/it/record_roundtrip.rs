//! Recordings must open in the reference readers: the Python `mcap` + `mcap-ros2-support`
//! decoders for MCAP and `h5py` for HDF5 (what ROS 2 / Foxglove and ACT tooling use).

use std::collections::BTreeMap;
use std::process::Command;

use kitchen_r_record::hdf5_aloha::{Hdf5Options, Hdf5Recorder};
use kitchen_r_record::mcap_ros2::McapRecorder;
use kitchen_r_record::rate::RateMonitor;
use kitchen_r_record::{CameraFrame, EpisodeMeta, Frame, StaticTransform, TaskSpan};

fn frame(i: usize) -> Frame {
    let cam = |name: &str| CameraFrame {
        name: name.into(),
        width: 8,
        height: 6,
        rgb: (0..8 * 6 * 3).map(|k| ((k + i) % 256) as u8).collect(),
        depth: vec![1.5; 48],
    };
    Frame {
        time: i as f64 * 0.1,
        cameras: vec![cam("base"), cam("gripper")],
        lidar: Some(vec![[1.0, 0.0, 0.2], [0.0, 2.0, 0.2]]),
        base_pose: [1.0 + i as f64 * 0.01, 2.0, 0.5],
        base_twist: [0.1, 0.0],
        action: [0.1, 0.0, 0.4, 0.0, 0.9, 1.0, 0.0, 0.0, 0.0, i as f64 / 10.0],
        qpos: vec![0.0; 7],
        qvel: vec![0.0; 7],
        ee_pose: [0.4, 0.0, 0.9, 1.0, 0.0, 0.0, 0.0],
        task: usize::from(i >= 5),
    }
}

fn python() -> Option<String> {
    let ok = Command::new("python3")
        .args(["-c", "import mcap, mcap_ros2, h5py"])
        .status()
        .is_ok_and(|s| s.success());
    if ok {
        Some("python3".into())
    } else if std::env::var_os("CI").is_some() {
        panic!("CI must have python3 with mcap, mcap-ros2-support and h5py (see .ci/setup)");
    } else {
        eprintln!("skipping: python3 with mcap, mcap-ros2-support, h5py not installed");
        None
    }
}

#[test]
fn mcap_and_hdf5_read_back_in_reference_readers() {
    let dir = tempfile::tempdir().unwrap();
    let meta = EpisodeMeta {
        episode_id: "dev-0001".into(),
        scene: "kitchen_a".into(),
        instruction: "Move the bowl to the green zone.".into(),
        plan: vec!["move to the blue zone".into(), "pick the bowl".into()],
        seed: 7,
        sensor_mounts: vec![StaticTransform {
            parent: "base_link".into(),
            child: "base_optical_frame".into(),
            translation: [0.2, 0.0, 1.0],
            rotation: [1.0, 0.0, 0.0, 0.0],
        }],
    };
    let mcap_path = dir.path().join("ep.mcap");
    let h5_path = dir.path().join("ep.hdf5");
    let mut mcap = McapRecorder::create(&mcap_path, &meta).unwrap();
    let mut h5 = Hdf5Recorder::new(meta, Hdf5Options::default());
    let mut rate = RateMonitor::new(BTreeMap::from([("/odom".to_string(), 9.0)]), 0.5);
    for i in 0..10 {
        mcap.write_frame(&frame(i), Some(&mut rate)).unwrap();
        rate.check(i as f64 * 0.1).unwrap();
        h5.push(frame(i)).unwrap();
    }
    let tasks = vec![
        TaskSpan {
            step: "move to the blue zone".into(),
            start: 0,
            end: 5,
            success: true,
            duration: 0.5,
        },
        TaskSpan {
            step: "pick the bowl".into(),
            start: 5,
            end: 10,
            success: true,
            duration: 0.5,
        },
    ];
    assert_eq!(mcap.counts["/camera/base/image_raw"], 10);
    mcap.finish(&tasks).unwrap();
    h5.finish(&h5_path, &tasks).unwrap();

    let Some(py) = python() else { return };
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/read_recording.py");
    let out = Command::new(py)
        .arg(script)
        .arg(&mcap_path)
        .arg(&h5_path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "reader failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let m = &v["mcap"];
    assert_eq!(m["profile"], "ros2");
    for topic in [
        "/camera/base/image_raw",
        "/camera/base/depth",
        "/camera/gripper/image_raw",
        "/camera/gripper/depth",
        "/lidar/points",
        "/odom",
        "/tf",
        "/cmd_vel",
        "/action",
        "/imu",
    ] {
        assert_eq!(m["counts"][topic], 10, "{topic}: {}", m["counts"]);
    }
    let imu = &m["first"]["/imu"];
    assert_eq!(imu["frame_id"], "base_link");
    assert_eq!(imu["wz"], 0.0);
    assert_eq!(
        imu["acc"],
        serde_json::json!([0.0, 0.0, 9.80665]),
        "gravity on z at rest"
    );
    let yaw_half = 0.25f64;
    assert!((imu["q"][0].as_f64().unwrap() - yaw_half.cos()).abs() < 1e-12);
    assert!((imu["q"][3].as_f64().unwrap() - yaw_half.sin()).abs() < 1e-12);
    assert!(
        imu["cov"][2][0].as_f64().unwrap() > 0.0,
        "covariances are known, not -1 or 0"
    );
    assert_eq!(m["counts"]["/tf_static"], 1);
    let img = &m["first"]["/camera/base/image_raw"];
    assert_eq!(
        (img["width"].as_u64(), img["height"].as_u64()),
        (Some(8), Some(6))
    );
    assert_eq!(img["encoding"], "rgb8");
    assert_eq!(img["bytes"], 8 * 6 * 3);
    assert_eq!(m["first"]["/camera/base/depth"]["encoding"], "32FC1");
    assert_eq!(
        m["first"]["/lidar/points"]["fields"],
        serde_json::json!(["x", "y", "z"])
    );
    assert_eq!(m["first"]["/odom"]["child"], "base_link");
    assert_eq!(m["first"]["/action"]["data"][9], 0.0);
    assert_eq!(
        m["first"]["/tf"]["children"],
        serde_json::json!(["base_link", "ee_link"])
    );
    assert_eq!(
        m["metadata"]["episode"]["instruction"],
        "Move the bowl to the green zone."
    );

    let h = &v["hdf5"];
    assert_eq!(
        h["shapes"]["observations/images/base"],
        serde_json::json!([10, 6, 8, 3])
    );
    assert_eq!(
        h["shapes"]["observations/depth/gripper"],
        serde_json::json!([10, 6, 8])
    );
    assert_eq!(h["shapes"]["observations/qpos"], serde_json::json!([10, 7]));
    assert_eq!(h["shapes"]["action"], serde_json::json!([10, 10]));
    assert_eq!(h["shapes"]["base_action"], serde_json::json!([10, 2]));
    assert_eq!(h["shapes"]["task_start"], serde_json::json!([2]));
    assert_eq!(h["attrs"]["instruction"], "Move the bowl to the green zone.");
    assert_eq!(h["attrs"]["sim"], 1);
    assert_eq!(h["action0"][2], 0.4);
    // Compact by default: deflate (h5py reads it without a plugin), one frame per chunk,
    // depth as uint16 millimetres.
    let img = "observations/images/gripper";
    assert_eq!(h["filters"][img]["compression"], "gzip");
    assert_eq!(h["filters"][img]["chunks"], serde_json::json!([1, 6, 8, 3]));
    assert_eq!(h["dtypes"]["observations/depth/base"], "<u2");
    assert_eq!(h["units"]["observations/depth/base"], "mm");
}
