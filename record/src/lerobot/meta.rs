//! The metadata rebuilt from the ledger: `meta/info.json` (features and totals, as LeRobot's
//! `DatasetInfo` reads them), `meta/stats.json`, and each episode's `meta/episodes` row.

use serde_json::{Value, json};

use super::episode::StagedEpisode;
use super::ledger::{EpisodeRecord, Spec, chunk_file};
use super::stats::FeatureStats;
use super::tables::EpisodeRow;
use super::{CHUNKS_SIZE, FPS};

/// `info.json` for the episodes of `records` with features `spec`.
pub(super) fn info(spec: Option<&Spec>, records: &[EpisodeRecord], total_tasks: usize) -> Value {
    let mut features = serde_json::Map::new();
    if let Some(spec) = spec {
        for (key, names) in &spec.columns {
            features.insert(
                key.clone(),
                json!({"dtype": "float32", "shape": [names.len()], "names": names, "fps": FPS}),
            );
        }
        for c in &spec.cameras {
            features.insert(
                c.key(),
                json!({
                    "dtype": "video",
                    "shape": [c.height, c.width, 3],
                    "names": ["height", "width", "channels"],
                    "info": {
                        "video.height": c.height,
                        "video.width": c.width,
                        "video.codec": spec.codec.name(),
                        "video.pix_fmt": "yuv420p",
                        "video.is_depth_map": false,
                        "is_depth_map": false,
                        "video.fps": FPS,
                        "video.channels": 3,
                        "has_audio": false
                    }
                }),
            );
        }
    }
    features.insert(
        "timestamp".into(),
        json!({"dtype": "float32", "shape": [1], "names": null, "fps": FPS}),
    );
    for k in ["frame_index", "episode_index", "index", "task_index"] {
        features.insert(
            k.into(),
            json!({"dtype": "int64", "shape": [1], "names": null, "fps": FPS}),
        );
    }
    let episodes = records.len();
    let frames: usize = records.iter().map(|r| r.length).sum();
    json!({
        "codebase_version": "v3.0",
        "robot_type": "kitchen_r_mobile_aloha",
        "total_episodes": episodes,
        "total_frames": frames,
        "total_tasks": total_tasks,
        "chunks_size": CHUNKS_SIZE,
        "data_files_size_in_mb": 100,
        "video_files_size_in_mb": 200,
        "fps": FPS,
        "splits": {"train": format!("0:{episodes}")},
        "data_path": "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet",
        "video_path": "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4",
        "features": features,
    })
}

/// `stats.json`: every feature's statistics aggregated over the episodes.
pub(super) fn stats(records: &[EpisodeRecord]) -> Value {
    let mut stats = serde_json::Map::new();
    if let Some(first) = records.first() {
        for (i, (key, _)) in first.stats.iter().enumerate() {
            let all: Vec<&FeatureStats> = records.iter().map(|r| &r.stats[i].1).collect();
            if let Some(s) = FeatureStats::aggregate(&all) {
                stats.insert(key.clone(), s.to_json());
            }
        }
    }
    Value::Object(stats)
}

/// Statistics of every feature of one episode, in `info.json`'s feature order.
pub(super) fn episode_stats(
    e: &StagedEpisode,
    episode_index: usize,
    first_index: usize,
    task_index: &[i64],
) -> Vec<(String, FeatureStats)> {
    let n = e.len();
    let mut out: Vec<(String, FeatureStats)> = e
        .columns
        .iter()
        .map(|c| (c.key.clone(), FeatureStats::of_rows(&c.values, c.names.len())))
        .collect();
    for (cam, s) in e.cameras.iter().zip(&e.image_stats) {
        out.push((cam.key(), s.clone()));
    }
    let scalar = |f: &dyn Fn(usize) -> f64| -> FeatureStats {
        let v: Vec<f32> = (0..n).map(|k| f(k) as f32).collect();
        FeatureStats::of_rows(&v, 1)
    };
    out.push(("timestamp".into(), scalar(&|k| k as f64 / f64::from(FPS))));
    out.push(("frame_index".into(), scalar(&|k| k as f64)));
    out.push(("episode_index".into(), scalar(&|_| episode_index as f64)));
    out.push(("index".into(), scalar(&|k| (first_index + k) as f64)));
    out.push(("task_index".into(), scalar(&|k| task_index[k] as f64)));
    out
}

pub(super) fn episode_row(r: &EpisodeRecord) -> EpisodeRow {
    let (c, f) = chunk_file(r.file);
    EpisodeRow {
        episode_index: r.episode_index as i64,
        tasks: r.tasks.clone(),
        length: r.length as i64,
        file: (c as i64, f as i64),
        dataset_from_index: r.from_index as i64,
        dataset_to_index: (r.from_index + r.length) as i64,
        from_timestamp: r.from_timestamp,
        to_timestamp: r.from_timestamp + r.length as f64 / f64::from(FPS),
        stats: r.stats.clone(),
        instruction: r.instruction.clone(),
        scene: r.scene.clone(),
        source: format!("ep{:05}", r.collect_index),
    }
}
