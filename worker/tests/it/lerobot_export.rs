//! `collect --format lerobot` read by outside readers (docs/twin/collect.md): pyarrow/pandas
//! check every field LeRobot v3.0 requires, Hugging Face `datasets` loads the Parquet files the
//! way LeRobot does, and PyAV decodes the videos (`tests/read_lerobot.py`), across two runs of the same `--out` (the second resumes and adds
//! a file); where `lerobot` itself is installed, `LeRobotDataset` loads it and a DataLoader
//! iterates a batch (`tests/load_lerobot.py`).

use std::path::Path;
use std::process::Command;

use kitchen_r_record::collect::{CollectConfig, CollectOptions, collect};
use kitchen_r_sim::SensorsConfig;

/// Small cameras (rav1e's minimum is 16 px) keep the test quick.
fn options(out: &Path, episodes: usize) -> CollectOptions {
    let mut sensors = SensorsConfig::default();
    for c in &mut sensors.cameras {
        (c.width, c.height) = (32, 24);
    }
    CollectOptions {
        formats: "lerobot".parse().unwrap(),
        jobs: 2,
        seed: 5,
        config: CollectConfig::default(),
        sensors: Some(sensors),
        // Two episodes per file: three episodes exercise file indices and video offsets.
        lerobot_episodes_per_file: 2,
        ..CollectOptions::new(out, episodes)
    }
}

/// python3 with pyarrow, pandas, datasets and PyAV (required on CI: scripts/test-requirements.txt).
fn readers() -> bool {
    let ok = Command::new("python3")
        .args(["-c", "import pyarrow, pandas, datasets, av"])
        .status()
        .is_ok_and(|s| s.success());
    if !ok && std::env::var("CI").is_ok_and(|v| v == "true") {
        panic!("CI must have python3 with pyarrow, pandas, datasets and av (scripts/test-requirements.txt)");
    }
    if !ok {
        eprintln!("skipping the read-back: python3 with pyarrow, pandas, datasets, av not installed");
    }
    ok
}

/// A Python with `lerobot` installed: `KITCHEN_R_LEROBOT_PYTHON`, else python3 if it has it.
/// Never required: lerobot brings torch, too heavy for CI.
fn lerobot_python() -> Option<String> {
    let candidates = std::env::var("KITCHEN_R_LEROBOT_PYTHON")
        .into_iter()
        .chain(["python3".to_string()]);
    for py in candidates {
        let ok = Command::new(&py)
            .args(["-c", "import lerobot.datasets.lerobot_dataset"])
            .status()
            .is_ok_and(|s| s.success());
        if ok {
            return Some(py);
        }
    }
    eprintln!("skipping LeRobotDataset loading: no Python with lerobot (set KITCHEN_R_LEROBOT_PYTHON)");
    None
}

fn run_script(py: &str, script: &str, root: &Path) -> serde_json::Value {
    let out = Command::new(py)
        .arg(format!("{}/tests/{script}", env!("CARGO_MANIFEST_DIR")))
        .arg(root)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{script} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn three_collected_episodes_open_in_pyarrow_pandas_pyav_and_lerobot() {
    let dir = tempfile::tempdir().unwrap();
    let first = collect(&options(dir.path(), 2)).unwrap();
    assert_eq!((first.kept, first.skipped), (2, 0), "{first:?}");
    let again = collect(&options(dir.path(), 3)).unwrap();
    assert_eq!(
        (again.kept, again.skipped),
        (1, 2),
        "the rerun resumes: {again:?}"
    );
    let mut other = options(dir.path(), 4);
    other.cameras = Some(vec!["gripper".into()]);
    let refused = collect(&other).unwrap_err().to_string();
    assert!(refused.contains("cameras"), "{refused}");
    let root = dir.path().join("lerobot");
    let staged = std::fs::read_dir(root.join(".collect/staging")).unwrap().count();
    assert_eq!(staged, 0, "every staged episode was appended");
    let info: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(root.join("meta/info.json")).unwrap()).unwrap();
    assert_eq!(info["codebase_version"], "v3.0");
    assert_eq!(info["total_episodes"], 3);
    assert_eq!(info["fps"], 10);
    if !readers() {
        return;
    }
    let v = run_script("python3", "read_lerobot.py", &root);
    assert_eq!(v["episodes"], 3);
    assert_eq!(v["data_files"], 2, "{v}");
    assert_eq!(v["episode_files"], 2);
    let videos = v["videos"].as_object().unwrap();
    assert_eq!(videos.len(), 4, "two cameras × two files: {v}");
    assert!(videos.values().all(|f| f["decoded"] == f["frames"]), "{v}");
    assert_eq!(v["frames"], info["total_frames"]);
    assert_eq!(v["hf_datasets"], true, "loaded through datasets: {v}");
    let Some(py) = lerobot_python() else { return };
    let l = run_script(&py, "load_lerobot.py", &root);
    assert_eq!(l["episodes"], 3);
    assert_eq!(l["frames"], info["total_frames"]);
    assert_eq!(l["image_shape"], serde_json::json!([4, 3, 24, 32]), "{l}");
    assert_eq!(l["state_shape"], serde_json::json!([4, 10]));
    assert_eq!(l["action_shape"], serde_json::json!([4, 10]));
    assert!(l["task"].as_str().is_some_and(|t| !t.is_empty()), "{l}");
}
