//! Trajectory collection end to end: the oracle drives dev episodes closed-loop, every control
//! step lands in MCAP and HDF5 files the reference Python readers open, a rerun resumes, and an
//! episode that trips a monitor is discarded with its reason counted.

use std::path::Path;
use std::process::Command;

use kitchen_r_record::collect::{CollectConfig, CollectOptions, ManifestEntry, collect};
use kitchen_r_sim::SensorsConfig;

/// Small cameras keep the test quick; the layout is what is checked, not the pixels.
fn small_sensors() -> SensorsConfig {
    let mut s = SensorsConfig::default();
    for c in &mut s.cameras {
        (c.width, c.height) = (32, 24);
    }
    s
}

fn options(out: &Path, episodes: usize, formats: &str) -> CollectOptions {
    CollectOptions {
        formats: formats.parse().unwrap(),
        jobs: 2,
        seed: 3,
        config: CollectConfig::default(),
        sensors: Some(small_sensors()),
        ..CollectOptions::new(out, episodes)
    }
}

fn manifest(out: &Path) -> Vec<ManifestEntry> {
    let text = std::fs::read_to_string(out.join("manifest.jsonl")).unwrap();
    text.lines().map(|l| serde_json::from_str(l).unwrap()).collect()
}

fn python() -> bool {
    let ok = Command::new("python3")
        .args(["-c", "import mcap, mcap_ros2, h5py"])
        .status()
        .is_ok_and(|s| s.success());
    if !ok && std::env::var("CI").is_ok_and(|v| v == "true") {
        panic!("CI must have python3 with mcap, mcap-ros2-support and h5py");
    }
    if !ok {
        eprintln!("skipping the read-back: python3 with mcap, mcap-ros2-support, h5py not installed");
    }
    ok
}

#[test]
fn two_collected_episodes_read_back_in_the_reference_readers() {
    let dir = tempfile::tempdir().unwrap();
    let s = collect(&options(dir.path(), 2, "mcap,hdf5")).unwrap();
    assert_eq!((s.kept, s.skipped), (2, 0), "{s:?}");
    assert!(s.discarded.is_empty(), "{:?}", s.discarded);
    let entries = manifest(dir.path());
    assert_eq!(entries.len(), 2);
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().ends_with(".partial"))
        .collect();
    assert!(leftovers.is_empty());
    if !python() {
        return;
    }
    for e in &entries {
        let stem = dir.path().join(&e.episode_id);
        let out = Command::new("python3")
            .arg(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/read_recording.py"))
            .arg(stem.with_extension("mcap"))
            .arg(stem.with_extension("hdf5"))
            .output()
            .unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        let (m, h) = (&v["mcap"], &v["hdf5"]);
        let t = e.frames as u64;
        assert!(
            t > 100,
            "an episode of {t} frames is too short to have done its plan"
        );
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
            assert_eq!(m["counts"][topic].as_u64(), Some(t), "{topic}");
        }
        assert_eq!(
            m["first"]["/camera/gripper/image_raw"]["bytes"].as_u64(),
            Some(32 * 24 * 3)
        );
        assert_eq!(m["first"]["/lidar/points"]["width"].as_u64(), Some(360));
        // Odometry is relative to the episode's start, as the policy receives it: after the
        // first 0.1 s step from rest the base is centimetres from the origin (its start in the
        // world is metres from the world's origin).
        let odom = &m["first"]["/odom"];
        let (x, y) = (odom["x"].as_f64().unwrap(), odom["y"].as_f64().unwrap());
        assert!(
            x.hypot(y) < 0.05,
            "the first /odom ({x}, {y}) is not relative to the episode's start"
        );
        let shape = |k: &str| h["shapes"][k].clone();
        assert_eq!(
            shape("observations/images/base"),
            serde_json::json!([t, 24, 32, 3])
        );
        assert_eq!(
            shape("observations/depth/gripper"),
            serde_json::json!([t, 24, 32])
        );
        assert_eq!(shape("observations/qpos"), serde_json::json!([t, 7]));
        assert_eq!(shape("action"), serde_json::json!([t, 10]));
        let plan: Vec<String> = serde_json::from_str(h["attrs"]["plan"].as_str().unwrap()).unwrap();
        assert_eq!(shape("task_start"), serde_json::json!([plan.len()]));
    }
}

#[test]
fn a_rerun_skips_finished_episodes() {
    let dir = tempfile::tempdir().unwrap();
    let first = collect(&options(dir.path(), 1, "mcap")).unwrap();
    assert_eq!(first.kept, 1, "{first:?}");
    let again = collect(&options(dir.path(), 1, "mcap")).unwrap();
    assert_eq!((again.kept, again.skipped), (0, 1));
    assert_eq!(
        manifest(dir.path()).len(),
        1,
        "a skipped episode adds no manifest line"
    );
}

#[test]
fn an_episode_that_trips_a_monitor_is_discarded_with_its_reason_and_grasp_mode() {
    let dir = tempfile::tempdir().unwrap();
    let mut opts = options(dir.path(), 1, "mcap,hdf5");
    opts.config.monitors.move_time_limit = 1.0;
    // `collect --grasp physical`: the episode runs (and the manifest says it ran) in that mode.
    opts.grasp = Some(kitchen_r_core::GraspMode::Physical);
    let s = collect(&opts).unwrap();
    assert_eq!(s.kept, 0);
    assert_eq!(s.discarded.get("time_limit"), Some(&1), "{s:?}");
    let e = &manifest(dir.path())[0];
    assert!(
        !e.kept && e.reason.as_deref().is_some_and(|r| r.contains("1 s limit")),
        "{e:?}"
    );
    assert_eq!(e.grasp_mode, kitchen_r_core::GraspMode::Physical, "{e:?}");
    let files: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.file_name())
        .collect();
    assert_eq!(
        files,
        vec![std::ffi::OsString::from("manifest.jsonl")],
        "discarded files are removed"
    );
}

#[test]
fn cameras_and_no_depth_leave_the_others_out_of_both_formats() {
    let dir = tempfile::tempdir().unwrap();
    let mut opts = options(dir.path(), 1, "mcap,hdf5");
    opts.cameras = Some(vec!["gripper".into()]);
    opts.depth = None;
    let s = collect(&opts).unwrap();
    assert_eq!(s.kept, 1, "{s:?}");
    let mut bad = options(dir.path(), 1, "mcap");
    bad.cameras = Some(vec!["nose".into()]);
    assert!(collect(&bad).is_err_and(|e| e.to_string().contains("nose")));
    if !python() {
        return;
    }
    let stem = dir.path().join("ep00000");
    let out = Command::new("python3")
        .arg(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/read_recording.py"))
        .arg(stem.with_extension("mcap"))
        .arg(stem.with_extension("hdf5"))
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let topics: Vec<&String> = v["mcap"]["counts"].as_object().unwrap().keys().collect();
    assert!(
        topics.iter().any(|t| *t == "/camera/gripper/image_raw"),
        "{topics:?}"
    );
    assert!(
        !topics
            .iter()
            .any(|t| t.contains("/base/") || t.ends_with("/depth")),
        "{topics:?}"
    );
    let datasets: Vec<&String> = v["hdf5"]["shapes"].as_object().unwrap().keys().collect();
    assert!(datasets.iter().any(|d| *d == "observations/images/gripper"));
    assert!(
        !datasets
            .iter()
            .any(|d| d.contains("depth") || d.ends_with("/base")),
        "{datasets:?}"
    );
}

#[test]
fn an_episodes_file_runs_exactly_its_batch_and_resumes() {
    use kitchen_r_core::dataset::Split;
    use kitchen_r_sim::generator::EpisodeParams;
    use kitchen_r_sim::{Assets, EpisodeConfig};

    let assets = Assets::load_default().unwrap();
    let params = EpisodeParams::load_default().unwrap();
    let ins = kitchen_r_episode::eval::instructions(Split::Dev, None).unwrap();
    let batch: Vec<EpisodeConfig> = [7usize, 11]
        .iter()
        .map(|&i| {
            let scene = assets.scene(&ins[i].scene).unwrap();
            let mut c =
                EpisodeConfig::from_instruction(&ins[i], scene, &assets.catalogue, &params, 40 + i as u64)
                    .unwrap();
            c.id = format!("val-{i}");
            c
        })
        .collect();
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("batch.json");
    kitchen_r_sim::episode::save_batch(&batch, &file).unwrap();
    let out = dir.path().join("out");
    let mut opts = options(&out, 99, "mcap");
    opts.batch = Some(kitchen_r_sim::episode::load_batch(&file).unwrap());
    let s = collect(&opts).unwrap();
    assert_eq!(
        (s.requested, s.kept),
        (2, 2),
        "the batch's size, not --episodes: {s:?}"
    );
    let mut ids: Vec<(String, u64)> = manifest(&out)
        .into_iter()
        .map(|e| (e.episode_id, e.seed))
        .collect();
    ids.sort();
    assert_eq!(
        ids,
        vec![("val-11".to_string(), 51), ("val-7".to_string(), 47)],
        "ids and seeds as saved"
    );
    let again = collect(&opts).unwrap();
    assert_eq!((again.kept, again.skipped), (0, 2));
}
