//! The contest archive (docs/contest/archive.md): `kitchen-r admin export` writes everything needed
//! to stand the contest up again into one `.tar.zst`; `kitchen-r admin import` loads it into an
//! empty server, whose boards are then the same, byte for byte in the CSV.
//!
//! Policy: the archive holds the hidden answers (the test split's ground truth) and every team's
//! results, so it is made and read only by the organiser (both routes need the organiser token)
//! and says so in its README and manifest. It holds no secret that opens anything: no token
//! hashes, no sealed endpoint tokens, no sessions, no configured tokens.
//!
//! Layout (docs/contest/archive.md, also the archive's `README.md`): `manifest.json` first
//! (format version, binary version, schema version, every other file's sha256 and size), then
//! `README.md`, `dataset/` (the four files `kitchen-r dataset generate` writes),
//! `configs/server.json`, `db/schema.sql`, `db/<table>.jsonl` ([`crate::store::archive`]),
//! `traces/<aa>/<sha256>.json.gz` and, with `--videos`, `videos/<aa>/<sha256>.mp4`.

use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use super::{AppState, Organiser, now_ms, rfc3339};
use crate::error::ServiceError;
use crate::store::archive as rows;

mod import;

pub(crate) use import::Imported;

/// The `format` tag of every archive's manifest.
pub(crate) const FORMAT: &str = "kitchen-r-contest-archive";
/// The archive layout this build writes. It reads every version up to this one (see the
/// migration rules in docs/contest/archive.md).
pub(crate) const FORMAT_VERSION: u32 = 1;
/// What every export says, in its manifest, its README and the CLI's output.
pub(crate) const NOTICE: &str = "this archive holds the contest's hidden answers (the private test set's ground \
truth) and every team's results: keep it as you keep the test set, and never give it to a participant";

/// `manifest.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) struct Manifest {
    pub format: String,
    pub format_version: u32,
    /// The `kitchen-r` that wrote the archive.
    pub binary_version: String,
    /// The newest database migration applied where it was made (`migrations/`).
    pub schema_version: i64,
    pub created_at: String,
    /// The dataset tag scores were computed against (`dataset-<version>`).
    pub dataset: String,
    pub holds_hidden_answers: bool,
    pub notice: String,
    pub videos: bool,
    pub files: Vec<FileEntry>,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub(crate) struct FileEntry {
    pub path: String,
    pub bytes: u64,
    pub sha256: String,
}

/// A written archive, streamed to the organiser (already unlinked: closing it frees it).
pub(crate) struct Export {
    pub file: tokio::fs::File,
    pub len: u64,
    /// Suggested file name: `kitchen-r-contest-<UTC time>.tar.zst`.
    pub name: String,
}

/// What goes into the tar: bytes made here, or a stored file copied as it is.
enum Source {
    Bytes(Vec<u8>),
    File(PathBuf),
}

impl AppState {
    /// Write the archive (see the module doc); `videos` adds the stored episode videos.
    pub(crate) async fn export_archive(&self, _: Organiser, videos: bool) -> Result<Export, ServiceError> {
        let now = now_ms();
        let mut entries: Vec<(String, Source)> =
            vec![("README.md".into(), Source::Bytes(README.as_bytes().to_vec()))];
        for (name, bytes) in self.dataset_files()? {
            entries.push((format!("dataset/{name}"), Source::Bytes(bytes)));
        }
        entries.push(("configs/server.json".into(), Source::Bytes(self.config_json()?)));
        let pool = self.read_pool();
        entries.push((
            "db/schema.sql".into(),
            Source::Bytes(
                rows::schema_sql(pool)
                    .await
                    .map_err(anyhow::Error::from)?
                    .into_bytes(),
            ),
        ));
        let dir = self.video_dir();
        for table in rows::TABLES.iter().chain([&rows::DERIVED]) {
            if table.name == "episode_videos" && !videos {
                continue;
            }
            let all = rows::dump(pool, table).await?;
            entries.extend(self.files_of(table.name, &all, dir.as_deref()));
            let text: String = all.iter().map(|r| format!("{r}\n")).collect();
            entries.push((
                format!("db/{}.jsonl", table.name),
                Source::Bytes(text.into_bytes()),
            ));
        }
        let manifest = Manifest {
            format: FORMAT.into(),
            format_version: FORMAT_VERSION,
            binary_version: env!("CARGO_PKG_VERSION").into(),
            schema_version: rows::schema_version(pool).await.map_err(anyhow::Error::from)?,
            created_at: rfc3339(now),
            dataset: self.content().dataset_tag(),
            holds_hidden_answers: true,
            notice: NOTICE.into(),
            videos,
            files: Vec::new(),
        };
        let stamp: String = rfc3339(now)
            .chars()
            .filter(|c| c.is_ascii_alphanumeric())
            .collect();
        let path = std::env::temp_dir().join(format!(
            "kitchen-r-export-{}.tar.zst",
            hex::encode(rand::random::<[u8; 8]>())
        ));
        let written = path.clone();
        tokio::task::spawn_blocking(move || write_tar(&written, manifest, entries))
            .await
            .map_err(anyhow::Error::from)??;
        let file = tokio::fs::File::open(&path).await;
        let _ = std::fs::remove_file(&path);
        let file = file.map_err(anyhow::Error::from)?;
        let len = file.metadata().await.map_err(anyhow::Error::from)?.len();
        tracing::info!(bytes = len, videos, "contest archive exported");
        Ok(Export {
            file,
            len,
            name: format!("kitchen-r-contest-{stamp}.tar.zst"),
        })
    }

    /// The dataset as `kitchen-r dataset generate` writes it: (file name, bytes). The test
    /// split's ground truth included.
    pub(crate) fn dataset_files(&self) -> anyhow::Result<Vec<(String, Vec<u8>)>> {
        let dir = scratch_dir("dataset")?;
        let result = (|| {
            kitchen_r_core::dataset::write(&self.content().dataset, &dir)?;
            let mut files = Vec::new();
            for name in [
                "dev.jsonl",
                "test.jsonl",
                "test_ground_truth.jsonl",
                "manifest.json",
            ] {
                files.push((name.to_string(), std::fs::read(dir.join(name))?));
            }
            anyhow::Ok(files)
        })();
        let _ = std::fs::remove_dir_all(&dir);
        result
    }

    /// The effective configuration, with the tokens blanked (a server given an empty token
    /// makes its own).
    fn config_json(&self) -> anyhow::Result<Vec<u8>> {
        let mut cfg = self.config().clone();
        cfg.admin_token = String::new();
        cfg.worker_token = String::new();
        Ok(serde_json::to_vec_pretty(&cfg)?)
    }

    /// The stored files the rows of `table` name: trace and video files, under their content
    /// names. A row whose file is gone (a `note` says why) names none.
    fn files_of(&self, table: &str, all: &[serde_json::Value], dir: Option<&Path>) -> Vec<(String, Source)> {
        let (Some(dir), Some(kind)) = (dir, media_kind(table)) else {
            return Vec::new();
        };
        let mut seen = std::collections::BTreeSet::new();
        let mut out = Vec::new();
        for r in all {
            let Some(sha) = r["sha256"].as_str().filter(|_| r["note"].is_null()) else {
                continue;
            };
            let (stored, archived) = media_paths(dir, kind, sha);
            if seen.insert(sha.to_string()) && stored.exists() {
                out.push((archived, Source::File(stored)));
            }
        }
        out
    }
}

/// `traces` or `videos`: the folder a media table's files go to.
pub(crate) fn media_kind(table: &str) -> Option<&'static str> {
    match table {
        "episode_traces" => Some("traces"),
        "episode_videos" => Some("videos"),
        _ => None,
    }
}

/// Where a media file lives on the server and in the archive.
pub(crate) fn media_paths(dir: &Path, kind: &str, sha: &str) -> (PathBuf, String) {
    let aa = &sha[..2.min(sha.len())];
    match kind {
        "traces" => (
            super::videos::incoming::trace_path(dir, sha),
            format!("traces/{aa}/{sha}.json.gz"),
        ),
        _ => (
            super::videos::incoming::file_path(dir, sha),
            format!("videos/{aa}/{sha}.mp4"),
        ),
    }
}

/// A fresh directory under the temporary directory.
pub(crate) fn scratch_dir(what: &str) -> anyhow::Result<PathBuf> {
    let dir = std::env::temp_dir().join(format!(
        "kitchen-r-{what}-{}",
        hex::encode(rand::random::<[u8; 8]>())
    ));
    std::fs::create_dir_all(&dir)?;
    Ok(dir)
}

/// The sha256 of everything `r` reads, as hex, and its length.
pub(crate) fn sha256_of(mut r: impl Read) -> std::io::Result<(String, u64)> {
    let mut h = Sha256::new();
    let mut buf = vec![0u8; 1 << 16];
    let mut n = 0u64;
    loop {
        let k = r.read(&mut buf)?;
        if k == 0 {
            return Ok((hex::encode(h.finalize()), n));
        }
        h.update(&buf[..k]);
        n += k as u64;
    }
}

/// Hash every entry into the manifest, then write the manifest and the entries, in that order,
/// as a zstd-compressed tar.
fn write_tar(path: &Path, mut manifest: Manifest, entries: Vec<(String, Source)>) -> anyhow::Result<()> {
    for (name, source) in &entries {
        let (sha256, bytes) = match source {
            Source::Bytes(b) => sha256_of(b.as_slice())?,
            Source::File(p) => sha256_of(std::fs::File::open(p)?)?,
        };
        manifest.files.push(FileEntry {
            path: name.clone(),
            bytes,
            sha256,
        });
    }
    let out = std::fs::File::create(path)?;
    let mut tar = tar::Builder::new(zstd::stream::Encoder::new(out, 3)?);
    let mut add = |name: &str, bytes: &[u8]| -> std::io::Result<()> {
        let mut header = tar::Header::new_gnu();
        header.set_size(bytes.len() as u64);
        header.set_mode(0o644);
        header.set_mtime(0);
        tar.append_data(&mut header, name, bytes)
    };
    add("manifest.json", &serde_json::to_vec_pretty(&manifest)?)?;
    for (name, source) in entries {
        match source {
            Source::Bytes(b) => add(&name, &b)?,
            Source::File(p) => add(&name, &std::fs::read(p)?)?,
        }
    }
    let mut zst = tar.into_inner()?;
    zst.flush()?;
    zst.finish()?.sync_all()?;
    Ok(())
}

/// The archive's `README.md`: the archive chapter of the manual.
const README: &str = include_str!("../../../docs/contest/archive.md");
