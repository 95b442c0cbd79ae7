//! The dataset on disk: which collection episodes it holds (the `.collect/episodes.jsonl`
//! ledger), which are staged, and the flush that turns staged episodes into the next data,
//! video and episode-metadata files and rewrites the dataset-wide metadata.

use std::collections::BTreeSet;
use std::io::Write;
use std::path::{Path, PathBuf};

use serde_json::Value;

use super::episode::StagedEpisode;
use super::ledger::{EpisodeRecord, Spec, chunk_file};
use super::meta;
use super::tables::{self, DataRows, EpisodeRow};
use super::{CameraSpec, EPISODES_PER_FILE, FPS, LeRobotError, io_err, write_atomic};
use crate::video::{Codec, EncodedVideo};

/// A LeRobotDataset being collected into.
#[derive(Debug)]
pub struct LeRobotDataset {
    root: PathBuf,
    records: Vec<EpisodeRecord>,
    spec: Option<Spec>,
    staged: BTreeSet<usize>,
    per_file: usize,
}

fn rel(kind: &str, file: usize, ext: &str) -> String {
    let (c, f) = chunk_file(file);
    format!("{kind}/chunk-{c:03}/file-{f:03}.{ext}")
}

impl LeRobotDataset {
    /// Open (or start) the dataset at `root`, picking up what an earlier run left.
    pub fn open(root: &Path) -> Result<LeRobotDataset, LeRobotError> {
        let mut ds = LeRobotDataset {
            root: root.to_path_buf(),
            records: Vec::new(),
            spec: None,
            staged: BTreeSet::new(),
            per_file: EPISODES_PER_FILE,
        };
        std::fs::create_dir_all(ds.staging_dir()).map_err(io_err(root))?;
        ds.load_ledger()?;
        let spec_path = ds.spec_path();
        if spec_path.is_file() {
            let text = std::fs::read_to_string(&spec_path).map_err(io_err(&spec_path))?;
            ds.spec = Some(serde_json::from_str(&text).map_err(|e| json_err(&spec_path, e))?);
        }
        let staging = ds.staging_dir();
        let entries = std::fs::read_dir(&staging).map_err(io_err(&staging))?;
        for e in entries.filter_map(Result::ok) {
            let name = e.file_name().to_string_lossy().to_string();
            let index = name
                .strip_prefix("ep")
                .and_then(|n| n.strip_suffix(".json"))
                .and_then(|n| n.parse::<usize>().ok());
            if let Some(i) = index {
                if ds.records.iter().any(|r| r.collect_index == i) {
                    // Appended before an interruption removed its staged files.
                    ds.remove_staged(i)?;
                } else {
                    ds.staged.insert(i);
                }
            }
        }
        Ok(ds)
    }

    /// Refuse a run whose cameras differ from the dataset's (checked before any episode runs,
    /// rather than when its staged episodes would be appended).
    pub fn check_cameras(&self, cameras: &[CameraSpec]) -> Result<(), LeRobotError> {
        match &self.spec {
            Some(s) if s.cameras != cameras => Err(LeRobotError::Mismatch(format!(
                "the dataset at {} was collected with cameras {:?}, this run records {:?}; \
                 collect into another --out",
                self.root.display(),
                s.cameras,
                cameras
            ))),
            _ => Ok(()),
        }
    }

    /// The codec of the dataset's videos, once it has any.
    pub fn codec(&self) -> Option<Codec> {
        self.spec.as_ref().map(|s| s.codec)
    }

    /// The codec a run appends with: `asked` if given, else the dataset's, else H.264; a run
    /// asking for another codec than the dataset's is refused (one file joins clips of one
    /// codec, and LeRobot reads one `video.codec` per feature).
    pub fn resolve_codec(&self, asked: Option<Codec>) -> Result<Codec, LeRobotError> {
        match (asked, self.codec()) {
            (Some(a), Some(d)) if a != d => Err(LeRobotError::Mismatch(format!(
                "the dataset at {} holds {d} videos, this run asks for {a}; pass --video-codec {d} \
                 or collect into another --out",
                self.root.display()
            ))),
            (a, d) => Ok(a.or(d).unwrap_or_default()),
        }
    }

    /// Episodes per data/video file (tests use a small number to exercise several files).
    pub fn with_episodes_per_file(mut self, n: usize) -> Self {
        self.per_file = n.max(1);
        self
    }

    pub fn root(&self) -> &Path {
        &self.root
    }

    /// Where [`super::EpisodeRecorder::finish`] stages kept episodes.
    pub fn staging_dir(&self) -> PathBuf {
        self.root.join(".collect").join("staging")
    }

    fn ledger_path(&self) -> PathBuf {
        self.root.join(".collect").join("episodes.jsonl")
    }

    fn spec_path(&self) -> PathBuf {
        self.root.join(".collect").join("spec.json")
    }

    /// Whether collection episode `index` is in the dataset or staged for it.
    pub fn has(&self, index: usize) -> bool {
        self.staged.contains(&index) || self.records.iter().any(|r| r.collect_index == index)
    }

    /// Episodes in the dataset (not counting staged ones).
    pub fn episodes(&self) -> usize {
        self.records.len()
    }

    /// Note that episode `index` was staged; appends a file when enough are waiting.
    pub fn staged(&mut self, index: usize) -> Result<(), LeRobotError> {
        self.staged.insert(index);
        if self.staged.len() >= self.per_file {
            self.flush()?;
        }
        Ok(())
    }

    /// Forget a staged episode whose staging failed part-way.
    pub fn discard_staged(&mut self, index: usize) -> Result<(), LeRobotError> {
        self.staged.remove(&index);
        self.remove_staged(index)
    }

    /// Append everything staged and write the metadata: the end of a run.
    pub fn finish(&mut self) -> Result<(), LeRobotError> {
        while !self.staged.is_empty() {
            self.flush()?;
        }
        if !self.records.is_empty() {
            self.write_meta()?;
        }
        Ok(())
    }

    fn load_ledger(&mut self) -> Result<(), LeRobotError> {
        let path = self.ledger_path();
        let Ok(text) = std::fs::read_to_string(&path) else {
            return Ok(());
        };
        let mut clean = true;
        for line in text.lines() {
            match serde_json::from_str::<EpisodeRecord>(line) {
                Ok(r) if r.episode_index == self.records.len() => self.records.push(r),
                // A line cut short by an interruption: everything after it is not recorded.
                _ => {
                    clean = false;
                    break;
                }
            }
        }
        if !clean {
            let lines: Vec<String> = self
                .records
                .iter()
                .map(|r| serde_json::to_string(r).unwrap_or_default() + "\n")
                .collect();
            write_atomic(&path, |p| std::fs::write(p, lines.concat()).map_err(io_err(p)))?;
        }
        Ok(())
    }

    fn remove_staged(&self, index: usize) -> Result<(), LeRobotError> {
        let staging = self.staging_dir();
        let prefix = format!("ep{index:05}.");
        let entries = std::fs::read_dir(&staging).map_err(io_err(&staging))?;
        for e in entries.filter_map(Result::ok) {
            if e.file_name().to_string_lossy().starts_with(&prefix) {
                std::fs::remove_file(e.path()).map_err(io_err(&e.path()))?;
            }
        }
        Ok(())
    }

    /// Append up to `per_file` staged episodes (lowest collection index first) as the next file.
    fn flush(&mut self) -> Result<(), LeRobotError> {
        let batch: Vec<usize> = self.staged.iter().copied().take(self.per_file).collect();
        if batch.is_empty() {
            return Ok(());
        }
        let staging = self.staging_dir();
        let episodes: Vec<StagedEpisode> = batch
            .iter()
            .map(|i| StagedEpisode::load(&staging, *i))
            .collect::<Result<_, _>>()?;
        for e in &episodes {
            let spec = Spec::of(e);
            match &self.spec {
                Some(s) if *s != spec => {
                    return Err(LeRobotError::Mismatch(format!(
                        "episode ep{:05} has features {spec:?} but the dataset at {} has {s:?}; \
                         collect into another --out",
                        e.collect_index,
                        self.root.display()
                    )));
                }
                Some(_) => {}
                None => {
                    let path = self.spec_path();
                    let text = serde_json::to_string_pretty(&spec).unwrap_or_default();
                    write_atomic(&path, |p| std::fs::write(p, text).map_err(io_err(p)))?;
                    self.spec = Some(spec);
                }
            }
        }
        let file = self.records.last().map_or(0, |r| r.file + 1);
        let mut tasks = self.tasks();
        let mut next_index = self.records.last().map_or(0, |r| r.from_index + r.length);
        let mut offset = 0.0;
        let mut new = Vec::new();
        let mut rows = Vec::new();
        for (k, e) in episodes.iter().enumerate() {
            let episode_index = self.records.len() + k;
            let task_index: Vec<i64> = e
                .frame_task
                .iter()
                .map(|t| task_id(&mut tasks, &e.tasks[*t as usize]) as i64)
                .collect();
            let record = EpisodeRecord {
                episode_index,
                collect_index: e.collect_index,
                episode_id: e.episode_id.clone(),
                scene: e.scene.clone(),
                instruction: e.instruction.clone(),
                tasks: e.tasks.clone(),
                length: e.len(),
                file,
                from_index: next_index,
                from_timestamp: offset,
                stats: meta::episode_stats(e, episode_index, next_index, &task_index),
            };
            rows.push(DataRows {
                columns: &e.columns,
                episode_index: episode_index as i64,
                first_index: next_index as i64,
                task_index,
            });
            next_index += e.len();
            // Frames of one file's episodes follow each other at 1/fps.
            offset += e.len() as f64 / f64::from(FPS);
            new.push(record);
        }
        let data = self.root.join(rel("data", file, "parquet"));
        write_atomic(&data, |p| tables::write_data(p, &rows, FPS))?;
        if let Some(spec) = &self.spec {
            for cam in &spec.cameras {
                let clips: Vec<EncodedVideo> = batch
                    .iter()
                    .map(|i| EncodedVideo::load(&StagedEpisode::video_path(&staging, *i, &cam.name)))
                    .collect::<Result<_, _>>()?;
                let joined = EncodedVideo::concat(&clips)?;
                let path = self.root.join(rel(&format!("videos/{}", cam.key()), file, "mp4"));
                write_atomic(&path, |p| Ok(joined.write_mp4(p)?))?;
            }
        }
        let meta_rows: Vec<EpisodeRow> = new.iter().map(meta::episode_row).collect();
        let path = self.root.join(rel("meta/episodes", file, "parquet"));
        write_atomic(&path, |p| {
            tables::write_episodes(p, &meta_rows, &self.video_keys())
        })?;
        let lines: String = new
            .iter()
            .map(|r| serde_json::to_string(r).unwrap_or_default() + "\n")
            .collect();
        let ledger = self.ledger_path();
        let mut f = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&ledger)
            .map_err(io_err(&ledger))?;
        f.write_all(lines.as_bytes()).map_err(io_err(&ledger))?;
        self.records.extend(new);
        self.write_meta()?;
        for i in batch {
            self.staged.remove(&i);
            self.remove_staged(i)?;
        }
        Ok(())
    }

    fn video_keys(&self) -> Vec<String> {
        self.spec
            .as_ref()
            .map(|s| s.cameras.iter().map(CameraSpec::key).collect())
            .unwrap_or_default()
    }

    /// Every task in order of first appearance: its position is its `task_index`.
    fn tasks(&self) -> Vec<String> {
        let mut tasks = Vec::new();
        for r in &self.records {
            for t in &r.tasks {
                task_id(&mut tasks, t);
            }
        }
        tasks
    }

    /// Rewrite `info.json`, `stats.json` and `tasks.parquet` from the ledger.
    fn write_meta(&self) -> Result<(), LeRobotError> {
        let tasks = self.tasks();
        let path = self.root.join("meta/tasks.parquet");
        write_atomic(&path, |p| tables::write_tasks(p, &tasks))?;
        let info = meta::info(self.spec.as_ref(), &self.records, tasks.len());
        write_json(&self.root.join("meta/info.json"), &info)?;
        write_json(&self.root.join("meta/stats.json"), &meta::stats(&self.records))
    }
}

/// The index of `task` in `tasks`, appending it when new.
fn task_id(tasks: &mut Vec<String>, task: &str) -> usize {
    match tasks.iter().position(|t| t == task) {
        Some(i) => i,
        None => {
            tasks.push(task.to_string());
            tasks.len() - 1
        }
    }
}

fn json_err(path: &Path, e: serde_json::Error) -> LeRobotError {
    LeRobotError::Json {
        path: path.to_path_buf(),
        message: e.to_string(),
    }
}

fn write_json(path: &Path, v: &Value) -> Result<(), LeRobotError> {
    let text = serde_json::to_string_pretty(v).map_err(|e| json_err(path, e))?;
    write_atomic(path, |p| std::fs::write(p, text).map_err(io_err(p)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_run_appends_with_the_datasets_codec_and_refuses_another() {
        let dir = tempfile::tempdir().unwrap();
        let mut ds = LeRobotDataset::open(dir.path()).unwrap();
        assert_eq!(
            ds.resolve_codec(None).unwrap(),
            Codec::H264,
            "a new dataset: H.264"
        );
        assert_eq!(ds.resolve_codec(Some(Codec::Av1)).unwrap(), Codec::Av1);
        ds.spec = Some(Spec {
            columns: vec![],
            cameras: vec![],
            codec: Codec::Av1,
        });
        assert_eq!(ds.resolve_codec(None).unwrap(), Codec::Av1, "appending keeps AV1");
        let e = ds.resolve_codec(Some(Codec::H264)).unwrap_err().to_string();
        assert!(
            e.contains("holds av1 videos") && e.contains("--video-codec av1"),
            "{e}"
        );
        // A dataset collected before H.264 existed has no codec in its spec: AV1.
        let old: Spec = serde_json::from_str(r#"{"columns": [], "cameras": []}"#).unwrap();
        assert_eq!(old.codec, Codec::Av1);
    }
}
