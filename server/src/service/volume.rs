//! The start-up check that the storage budgets fit their volume (docs/contest/video.md): a total
//! budget larger than the free space of the disk the video directory is on would let the disk fill
//! before any budget acts. The server warns, or refuses to start under `strict`.

use std::path::Path;

use super::AppState;
use crate::store;

/// Check `[video] total_max_bytes`, less what is stored already, against the free space of the
/// video directory's volume; a warning (or, with `strict`, an error) saying what to change.
pub(crate) async fn check_volume(state: &AppState) -> anyhow::Result<()> {
    let Some(dir) = state.video_dir() else {
        return Ok(());
    };
    let free = match free_space(&dir) {
        Ok(f) => f,
        Err(e) => {
            tracing::warn!(dir = %dir.display(), error = %e, "cannot read the free space of the video directory's volume");
            return Ok(());
        }
    };
    let stored = store::budget::stored_bytes(state.read_pool()).await?.max(0) as u64;
    let total = state.config().video.total_max_bytes;
    let Some(why) = verdict(total, stored, free, &dir) else {
        return Ok(());
    };
    if state.config().strict {
        anyhow::bail!("{why} (refused: `strict` is on)");
    }
    tracing::warn!("{why}");
    Ok(())
}

/// Why `total` bytes of budget cannot be held by `free` bytes of disk beside `stored` bytes of
/// files already counted, or `None` when they can.
fn verdict(total: u64, stored: u64, free: u64, dir: &Path) -> Option<String> {
    let needed = total.saturating_sub(stored);
    (needed > free).then(|| {
        format!(
            "the storage budget [video] total_max_bytes ({total} bytes, {stored} stored) is larger than the free space of the volume of {} ({free} bytes free): the disk would fill before the budget acts; lower total_max_bytes (KITCHEN_R_VIDEO_TOTAL_MAX_BYTES) to at most {} or give the volume more room",
            dir.display(),
            stored.saturating_add(free)
        )
    })
}

/// The bytes an unprivileged process may still write on the volume `dir` is (or will be) on.
fn free_space(dir: &Path) -> std::io::Result<u64> {
    let mut at = dir;
    while !at.exists() {
        match at.parent() {
            Some(p) if !p.as_os_str().is_empty() => at = p,
            _ => {
                at = Path::new(".");
                break;
            }
        }
    }
    let s = rustix::fs::statvfs(at)?;
    Ok(s.f_bavail.saturating_mul(s.f_frsize))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn budgets_larger_than_the_free_space_are_named_with_the_largest_that_fits() {
        let dir = Path::new("/srv/videos");
        assert_eq!(verdict(100, 0, 100, dir), None);
        // What is stored already is on the disk: only the rest needs free space.
        assert_eq!(verdict(100, 40, 60, dir), None);
        let why = verdict(100, 40, 50, dir).unwrap();
        assert!(why.contains("at most 90"), "{why}");
        assert!(why.contains("/srv/videos"), "{why}");
    }

    #[test]
    fn the_free_space_of_a_directory_not_made_yet_is_its_volumes() {
        let tmp = tempfile::tempdir().unwrap();
        let free = free_space(&tmp.path().join("not/yet")).unwrap();
        assert!(free > 0);
    }
}
