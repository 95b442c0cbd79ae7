//! An upload on its way to disk: written to `<dir>/tmp/` while hashed, then moved to its
//! content name. Dropped before that, it removes its partial file; a process killed meanwhile
//! leaves it, and the next start clears `tmp/` ([`clear_partial`]).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use sha2::{Digest, Sha256};
use tokio::io::AsyncWriteExt;

use crate::clock::now_ms;

/// Where the file with hash `sha256` lives under `dir`.
pub(crate) fn file_path(dir: &Path, sha256: &str) -> PathBuf {
    dir.join(&sha256[..2.min(sha256.len())])
        .join(format!("{sha256}.mp4"))
}

/// Where the trace file with hash `sha256` lives under the video directory `dir`:
/// `<dir>/traces/<aa>/<sha256>.json.gz`, beside the videos, so the same `tmp/` and rename serve.
pub(crate) fn trace_path(dir: &Path, sha256: &str) -> PathBuf {
    dir.join("traces")
        .join(&sha256[..2.min(sha256.len())])
        .join(format!("{sha256}.json.gz"))
}

/// Why an upload was not stored.
#[derive(Debug, thiserror::Error)]
pub(crate) enum UploadError {
    #[error("the file is {got} bytes, over the announced {announced}")]
    Longer { got: u64, announced: u64 },
    #[error("the stream ended after {got} of {announced} bytes")]
    Short { got: u64, announced: u64 },
    #[error("the file is {size} bytes, over the server's limit of {limit} (`[video] max_bytes`)")]
    TooLarge { size: u64, limit: u64 },
    /// A budget cannot hold the video even with every older video removed: uploads in flight
    /// hold the rest of it. The message says which budget.
    #[error("{0}")]
    NoRoom(String),
    #[error("storing the video: {0}")]
    Io(#[from] std::io::Error),
    /// Booking or linking failed in the service layer (the database).
    #[error(transparent)]
    Service(#[from] crate::error::ServiceError),
}

/// The folder of partial uploads under the video directory `dir`.
pub(crate) fn tmp_dir(dir: &Path) -> PathBuf {
    dir.join("tmp")
}

/// Remove every file in `<dir>/tmp/`: partial uploads of a process that was killed. Only at
/// start, before anything listens: this server is its video directory's only writer (one
/// replica), so nothing in there is anyone's upload in progress. Returns how many went.
pub(crate) async fn clear_partial(dir: &Path) -> std::io::Result<usize> {
    let mut entries = match tokio::fs::read_dir(tmp_dir(dir)).await {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(0),
        Err(e) => return Err(e),
    };
    let mut removed = 0;
    while let Some(entry) = entries.next_entry().await? {
        if entry.file_type().await?.is_file() {
            tokio::fs::remove_file(entry.path()).await?;
            removed += 1;
        }
    }
    Ok(removed)
}

/// An upload being written: hashed as it comes, removed if dropped before [`Incoming::finish`].
pub(crate) struct Incoming {
    tmp: PathBuf,
    file: Option<tokio::fs::File>,
    hash: Sha256,
    got: u64,
    announced: u64,
}

static UPLOADS: AtomicU64 = AtomicU64::new(0);

impl Incoming {
    /// Start an upload of `announced` bytes into `dir`, refusing one over `limit` at once.
    pub(crate) async fn start(dir: &Path, announced: u64, limit: u64) -> Result<Incoming, UploadError> {
        if announced > limit {
            return Err(UploadError::TooLarge {
                size: announced,
                limit,
            });
        }
        let tmp_dir = tmp_dir(dir);
        tokio::fs::create_dir_all(&tmp_dir).await?;
        let n = UPLOADS.fetch_add(1, Ordering::Relaxed);
        let tmp = tmp_dir.join(format!("{}-{}-{n}.part", std::process::id(), now_ms()));
        let file = tokio::fs::File::create(&tmp).await?;
        Ok(Incoming {
            tmp,
            file: Some(file),
            hash: Sha256::new(),
            got: 0,
            announced,
        })
    }

    pub(crate) async fn write(&mut self, data: &[u8]) -> Result<(), UploadError> {
        self.got += data.len() as u64;
        if self.got > self.announced {
            return Err(UploadError::Longer {
                got: self.got,
                announced: self.announced,
            });
        }
        self.hash.update(data);
        if let Some(f) = &mut self.file {
            f.write_all(data).await?;
        }
        Ok(())
    }

    /// Check the size and make the bytes durable; the file is still in `tmp/` until
    /// [`Complete::place`].
    pub(crate) async fn finish(mut self) -> Result<Complete, UploadError> {
        if self.got != self.announced {
            return Err(UploadError::Short {
                got: self.got,
                announced: self.announced,
            });
        }
        if let Some(mut f) = self.file.take() {
            f.flush().await?;
            f.sync_all().await?;
        }
        Ok(Complete {
            tmp: std::mem::take(&mut self.tmp),
            sha256: hex::encode(std::mem::take(&mut self.hash).finalize()),
            bytes: self.got,
        })
    }
}

impl Drop for Incoming {
    fn drop(&mut self) {
        remove_quietly(&self.tmp);
    }
}

/// A whole upload in `tmp/`, removed if dropped before [`Complete::place`].
pub(crate) struct Complete {
    tmp: PathBuf,
    pub sha256: String,
    pub bytes: u64,
}

impl Complete {
    /// Move the file to its content name under `dir` (kept as it is when that file is there
    /// already: same name, same bytes).
    pub(crate) async fn place(self, dir: &Path) -> Result<PathBuf, UploadError> {
        let dest = file_path(dir, &self.sha256);
        self.place_at(dest).await
    }

    /// Move the file to `dest` (its content name), kept as it is when that file is there.
    pub(crate) async fn place_at(mut self, dest: PathBuf) -> Result<PathBuf, UploadError> {
        if let Some(parent) = dest.parent() {
            tokio::fs::create_dir_all(parent).await?;
        }
        if tokio::fs::try_exists(&dest).await? {
            tokio::fs::remove_file(&self.tmp).await?;
        } else {
            tokio::fs::rename(&self.tmp, &dest).await?;
        }
        self.tmp = PathBuf::new();
        Ok(dest)
    }
}

impl Drop for Complete {
    fn drop(&mut self) {
        remove_quietly(&self.tmp);
    }
}

fn remove_quietly(path: &Path) {
    if !path.as_os_str().is_empty() {
        let _ = std::fs::remove_file(path);
    }
}
