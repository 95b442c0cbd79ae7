//! `kitchen-r admin import`: an archive checked whole (every file against the manifest's sha256,
//! nothing unlisted, nothing outside the archive's root), then loaded into an empty server in one
//! transaction, its stored files put in place and the boards rebuilt.
//!
//! Refused: a server that holds any team or submission (an import never merges), an archive of
//! a newer format or schema than this build's, and one made on another dataset (the boards
//! would be scored against other answers): the organiser starts the server on the archive's
//! `dataset/` first.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Component, Path};

use bytes::Bytes;
use futures_util::{Stream, StreamExt};
use serde::Serialize;
use tokio::io::AsyncWriteExt;

use super::{FORMAT, FORMAT_VERSION, Manifest, NOTICE, media_paths, scratch_dir, sha256_of};
use crate::error::ServiceError;
use crate::service::{AppState, Organiser};
use crate::store::archive as rows;
use crate::store::board;

/// What an import loaded.
#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub(crate) struct Imported {
    /// Rows loaded per table.
    pub rows: BTreeMap<String, usize>,
    /// Trace and video files put in place.
    pub files: usize,
    pub format_version: u32,
    /// The `kitchen-r` that made the archive.
    pub binary_version: String,
    pub dataset: String,
    /// Teams have no token after an import: the organiser issues new ones
    /// (`kitchen-r team rotate-token ID`, `POST /api/v1/teams/{id}/token`).
    pub teams_without_token: Vec<String>,
    pub notice: String,
}

impl AppState {
    /// Load the archive `body` streams (see the module doc).
    pub(crate) async fn import_archive<S, E>(&self, _: Organiser, body: S) -> Result<Imported, ServiceError>
    where
        S: Stream<Item = Result<Bytes, E>> + Unpin,
        E: std::fmt::Display,
    {
        self.refuse_non_empty().await?;
        let dir = scratch_dir("import")?;
        let result = self.import_in(&dir, body).await;
        let _ = std::fs::remove_dir_all(&dir);
        result
    }

    async fn refuse_non_empty(&self) -> Result<(), ServiceError> {
        let (teams, subs) = rows::is_empty(self.pool()).await.map_err(anyhow::Error::from)?;
        if teams + subs > 0 {
            return Err(ServiceError::Conflict(format!(
                "this server is not empty ({teams} team(s), {subs} submission(s)): an archive is \
                 imported only into a fresh server (start one on a new --db)"
            )));
        }
        Ok(())
    }

    async fn import_in<S, E>(&self, dir: &Path, mut body: S) -> Result<Imported, ServiceError>
    where
        S: Stream<Item = Result<Bytes, E>> + Unpin,
        E: std::fmt::Display,
    {
        let file = dir.join("archive.tar.zst");
        let mut out = tokio::fs::File::create(&file)
            .await
            .map_err(anyhow::Error::from)?;
        while let Some(chunk) = body.next().await {
            let chunk = chunk.map_err(|e| ServiceError::BadRequest(format!("the upload broke off: {e}")))?;
            out.write_all(&chunk).await.map_err(anyhow::Error::from)?;
        }
        out.flush().await.map_err(anyhow::Error::from)?;
        drop(out);
        let root = dir.join("archive");
        let unpacked = root.clone();
        let manifest = tokio::task::spawn_blocking(move || unpack_checked(&file, &unpacked))
            .await
            .map_err(anyhow::Error::from)?
            .map_err(ServiceError::BadRequest)?;
        self.check_compatible(&manifest, &root).await?;
        let files = self.place_media(&root, &manifest)?;
        let mut report = self.load_rows(&root, &manifest).await?;
        report.files = files;
        board::rebuild(self.pool()).await.map_err(anyhow::Error::from)?;
        self.inner.leaderboard.invalidate();
        tracing::info!(
            files,
            binary = manifest.binary_version,
            "contest archive imported"
        );
        Ok(report)
    }

    /// The archive's format, schema and dataset against this server's.
    async fn check_compatible(&self, m: &Manifest, root: &Path) -> Result<(), ServiceError> {
        let refuse = |why: String| Err(ServiceError::Conflict(why));
        if m.format != FORMAT || m.format_version > FORMAT_VERSION {
            return refuse(format!(
                "the archive is {} version {}; this kitchen-r {} reads {FORMAT} up to version \
                 {FORMAT_VERSION}: import it with a newer kitchen-r",
                m.format,
                m.format_version,
                env!("CARGO_PKG_VERSION")
            ));
        }
        let ours = rows::schema_version(self.pool())
            .await
            .map_err(anyhow::Error::from)?;
        if m.schema_version > ours {
            return refuse(format!(
                "the archive's database schema ({}) is newer than this server's ({ours}): \
                 import it with kitchen-r {} or later",
                m.schema_version, m.binary_version
            ));
        }
        for (name, bytes) in self.dataset_files()? {
            let theirs = std::fs::read(root.join("dataset").join(&name)).unwrap_or_default();
            if theirs != bytes {
                return refuse(format!(
                    "this server's dataset differs from the archive's (dataset/{name}; the archive \
                     was scored against {}, this server serves {}): start the server on the \
                     archive's dataset (extract dataset/ and pass it with --test-set, with the \
                     same assets) and import again",
                    m.dataset,
                    self.content().dataset_tag()
                ));
            }
        }
        Ok(())
    }

    /// Copy the archive's trace and video files into the video directory.
    fn place_media(&self, root: &Path, m: &Manifest) -> Result<usize, ServiceError> {
        let media: Vec<_> = (m.files.iter())
            .filter(|f| f.path.starts_with("traces/") || f.path.starts_with("videos/"))
            .collect();
        if media.is_empty() {
            return Ok(0);
        }
        let Some(dir) = self.video_dir() else {
            return Err(ServiceError::Conflict(
                "the archive holds traces, but this server stores none ([video] enabled = false, \
                 or an in-memory database): enable videos and import again"
                    .into(),
            ));
        };
        for f in &media {
            let (kind, name) = f.path.split_once('/').unwrap_or_default();
            let sha = name.rsplit('/').next().unwrap_or_default();
            let sha = sha.split('.').next().unwrap_or_default();
            let (stored, _) = media_paths(&dir, kind, sha);
            if let Some(parent) = stored.parent() {
                std::fs::create_dir_all(parent).map_err(anyhow::Error::from)?;
            }
            std::fs::copy(root.join(&f.path), &stored).map_err(anyhow::Error::from)?;
        }
        Ok(media.len())
    }

    /// Every table's rows, in one transaction, after checking again that nothing is there.
    async fn load_rows(&self, root: &Path, m: &Manifest) -> Result<Imported, ServiceError> {
        let mut tx = self
            .pool()
            .begin_with("BEGIN IMMEDIATE")
            .await
            .map_err(anyhow::Error::from)?;
        let mut counts = BTreeMap::new();
        let mut teams = Vec::new();
        for table in rows::TABLES {
            let path = root.join(format!("db/{}.jsonl", table.name));
            if !path.exists() && (table.name == "episode_videos" || table.name == "run_verifications") {
                continue;
            }
            let text = std::fs::read_to_string(&path)
                .map_err(|e| ServiceError::BadRequest(format!("db/{}.jsonl: {e}", table.name)))?;
            let columns = rows::columns(&mut tx, table.name)
                .await
                .map_err(anyhow::Error::from)?;
            let mut n = 0;
            for (i, line) in text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty()) {
                let bad = |e: String| {
                    ServiceError::BadRequest(format!("db/{}.jsonl line {}: {e}", table.name, i + 1))
                };
                let row: serde_json::Map<String, serde_json::Value> =
                    serde_json::from_str(line).map_err(|e| bad(e.to_string()))?;
                if table.name == "teams"
                    && let Some(name) = row.get("name").and_then(|v| v.as_str())
                    && name != crate::store::runs::BASELINE_TEAM
                {
                    teams.push(name.to_string());
                }
                rows::insert(&mut tx, table, &columns, &row)
                    .await
                    .map_err(|e| bad(format!("{e:#}")))?;
                n += 1;
            }
            counts.insert(table.name.to_string(), n);
        }
        tx.commit().await.map_err(anyhow::Error::from)?;
        Ok(Imported {
            rows: counts,
            files: 0,
            format_version: m.format_version,
            binary_version: m.binary_version.clone(),
            dataset: m.dataset.clone(),
            teams_without_token: teams,
            notice: NOTICE.into(),
        })
    }
}

/// Unpack `file` into `root`, refusing any entry that is not a plain file under it, and check
/// every file against the manifest: the same set of paths, each with its size and sha256.
fn unpack_checked(file: &Path, root: &Path) -> Result<Manifest, String> {
    let bad = |e: std::io::Error| format!("not a readable .tar.zst archive: {e}");
    let zst = zstd::stream::Decoder::new(std::fs::File::open(file).map_err(bad)?).map_err(bad)?;
    let mut tar = tar::Archive::new(zst);
    let mut seen = BTreeSet::new();
    for entry in tar.entries().map_err(bad)? {
        let mut entry = entry.map_err(bad)?;
        let path = entry.path().map_err(bad)?.into_owned();
        let plain = path.components().all(|c| matches!(c, Component::Normal(_)));
        if !plain || !entry.header().entry_type().is_file() {
            return Err(format!(
                "the archive holds {}, which is not a plain file under its root",
                path.display()
            ));
        }
        let name = path.to_string_lossy().into_owned();
        let dest = root.join(&path);
        std::fs::create_dir_all(dest.parent().unwrap_or(root)).map_err(|e| e.to_string())?;
        let mut out = std::fs::File::create(&dest).map_err(|e| e.to_string())?;
        std::io::copy(&mut entry, &mut out).map_err(bad)?;
        if !seen.insert(name.clone()) {
            return Err(format!("the archive holds {name} twice"));
        }
    }
    let text = std::fs::read(root.join("manifest.json"))
        .map_err(|_| "the archive has no manifest.json".to_string())?;
    let m: Manifest = serde_json::from_slice(&text).map_err(|e| format!("manifest.json: {e}"))?;
    seen.remove("manifest.json");
    let listed: BTreeSet<String> = m.files.iter().map(|f| f.path.clone()).collect();
    if let Some(extra) = seen.difference(&listed).next() {
        return Err(format!(
            "{extra} is in the archive but not in its manifest: the archive was altered"
        ));
    }
    for f in &m.files {
        let opened = std::fs::File::open(root.join(&f.path))
            .map_err(|_| format!("{} is in the manifest but not in the archive", f.path))?;
        let (sha, bytes) = sha256_of(opened).map_err(|e| e.to_string())?;
        if sha != f.sha256 || bytes != f.bytes {
            return Err(format!(
                "{} does not match the manifest (sha256 {sha}, {bytes} bytes; the manifest says {}, \
                 {} bytes): the archive was altered or damaged; nothing was imported",
                f.path, f.sha256, f.bytes
            ));
        }
    }
    Ok(m)
}
