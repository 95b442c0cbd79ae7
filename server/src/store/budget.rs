//! The storage budgets' accounting (docs/contest/video.md, budgets): the bytes of stored videos AND
//! traces, per team and in all, and which rows an upload evicts to make room. The files are
//! `crate::service`'s; this module only decides, in one write transaction per upload.
//!
//! Policy (`[video] team_max_bytes`, `total_max_bytes`):
//! - a team's own budget: past it, that team's oldest videos go first (a video can be rendered
//!   again from its trace), then its oldest traces;
//! - the total: past it, only teams over their **fair share** lose files: the share is
//!   `min(team_max_bytes, total_max_bytes / teams storing files)`, the uploading team counted
//!   with its upload. Among those teams the oldest video goes first, then the oldest trace. A
//!   team within its share never loses a file to another team's upload;
//! - never evicted: the traces of a test-split run of a submission ranked on a test board (the
//!   organiser verifies a ranked run from them). They count like any file;
//! - when nothing may go, nothing is evicted and the upload is refused with the reason (a render
//!   then waits, `crate::service::renders`).
//!
//! An evicted row keeps its place with a `note` its episode shows; rows without a note are the
//! stored files. Bytes count per row: a file two episodes link counts twice (never under the
//! disk's use).

use std::collections::BTreeMap;

use sqlx::sqlite::SqlitePool;
use sqlx::{Sqlite, Transaction};

/// What an upload asks of the budgets.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Ask<'a> {
    pub team: i64,
    pub incoming: u64,
    pub team_max: u64,
    pub total_max: u64,
    /// Bytes of uploads in flight the budgets must hold too: the team's, and everyone's.
    pub team_pending: u64,
    pub total_pending: u64,
    /// What an evicted row says, per budget and kind of file.
    pub notes: Notes<'a>,
}

/// The notes of evicted rows.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Notes<'a> {
    pub team_video: &'a str,
    pub team_trace: &'a str,
    pub total_video: &'a str,
    pub total_trace: &'a str,
}

/// What [`make_room`] did.
#[derive(Debug, Default)]
pub(crate) struct Room {
    /// Why the upload does not fit, when it does not; nothing was evicted then.
    pub refused: Option<Refusal>,
    /// Rows evicted for the team's budget and for the total.
    pub evicted: [usize; 2],
    /// Files of evicted rows that no stored row names any more: videos, traces.
    pub orphan_videos: Vec<String>,
    pub orphan_traces: Vec<String>,
}

/// Why an upload found no room.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Refusal {
    /// Uploads in flight hold the rest of a budget.
    InFlight,
    /// The team's budget holds only files that may not go (protected traces, uploads).
    TeamProtected,
    /// The total is full and every team storing files is within its fair share (or holds only
    /// protected traces).
    TotalFair,
}

/// A test-split run of a submission on a test board (`t` the `episode_traces` row): its traces
/// are kept. A macro, so the statements that use it stay literal SQL.
macro_rules! protected {
    () => {
        "EXISTS (SELECT 1 FROM scoring_runs r JOIN leaderboard_entries l
         ON l.submission_id = r.submission_id WHERE r.id = t.run_id AND l.split = 'test')"
    };
}
pub(super) use protected;

/// Evict what the budgets need gone for `ask.incoming` more bytes of `ask.team`, in one write
/// transaction (two uploads never pick the same row nor both count the room one freed).
pub(crate) async fn make_room(pool: &SqlitePool, ask: &Ask<'_>) -> sqlx::Result<Room> {
    if ask.team_pending.saturating_add(ask.incoming) > ask.team_max
        || ask.total_pending.saturating_add(ask.incoming) > ask.total_max
    {
        return Ok(refused(Refusal::InFlight));
    }
    let mut tx = pool.begin_with("BEGIN IMMEDIATE").await?;
    let mut room = Room::default();
    let mut videos = Vec::new();
    let mut traces = Vec::new();
    // The team's own budget: its own oldest files.
    let mut used = team_usage(&mut tx).await?;
    let mine = |used: &BTreeMap<i64, u64>| used.get(&ask.team).copied().unwrap_or(0);
    while mine(&used) + ask.team_pending + ask.incoming > ask.team_max {
        let Some(v) = oldest(&mut tx, &[ask.team]).await? else {
            return Ok(refused(Refusal::TeamProtected));
        };
        evict(&mut tx, &v, ask.notes.team_video, ask.notes.team_trace).await?;
        take(&mut used, &v, &mut videos, &mut traces);
        room.evicted[0] += 1;
    }
    // The total: only teams over their fair share give way.
    while used.values().sum::<u64>() + ask.total_pending + ask.incoming > ask.total_max {
        let over = over_share(&used, ask);
        let victim = match over.is_empty() {
            true => None,
            false => oldest(&mut tx, &over).await?,
        };
        let Some(v) = victim else {
            return Ok(refused(Refusal::TotalFair));
        };
        evict(&mut tx, &v, ask.notes.total_video, ask.notes.total_trace).await?;
        take(&mut used, &v, &mut videos, &mut traces);
        room.evicted[1] += 1;
    }
    for sha in videos {
        if !stored(&mut tx, false, &sha).await? {
            room.orphan_videos.push(sha);
        }
    }
    for sha in traces {
        if !stored(&mut tx, true, &sha).await? {
            room.orphan_traces.push(sha);
        }
    }
    tx.commit().await?;
    Ok(room)
}

fn refused(why: Refusal) -> Room {
    Room {
        refused: Some(why),
        ..Room::default()
    }
}

/// The teams over their fair share of the total, the uploading team counted with its upload.
fn over_share(used: &BTreeMap<i64, u64>, ask: &Ask<'_>) -> Vec<i64> {
    let teams = used.len() as u64 + u64::from(!used.contains_key(&ask.team));
    let share = ask.team_max.min(ask.total_max / teams.max(1));
    (used.iter())
        .filter(|&(&t, &bytes)| {
            let extra = if t == ask.team {
                ask.team_pending + ask.incoming
            } else {
                0
            };
            bytes + extra > share
        })
        .map(|(&t, _)| t)
        .collect()
}

/// A stored file that may be evicted.
#[derive(Debug)]
struct Victim {
    trace: bool,
    rowid: i64,
    team: i64,
    sha256: String,
    bytes: i64,
}

/// The next file to evict among `teams`' stored files: the oldest video, else the oldest trace
/// that is not protected.
async fn oldest(tx: &mut Transaction<'_, Sqlite>, teams: &[i64]) -> sqlx::Result<Option<Victim>> {
    // The teams as a JSON array bound to one parameter (`json_each`): the statement stays literal.
    let ids = format!(
        "[{}]",
        teams.iter().map(i64::to_string).collect::<Vec<_>>().join(",")
    );
    let video: Option<(i64, i64, String, i64)> = sqlx::query_as(
        "SELECT rowid, team_id, sha256, bytes FROM episode_videos
         WHERE note IS NULL AND team_id IN (SELECT value FROM json_each(?)) ORDER BY created_at, rowid LIMIT 1",
    )
    .bind(&ids)
    .fetch_optional(&mut **tx)
    .await?;
    if let Some((rowid, team, sha256, bytes)) = video {
        return Ok(Some(Victim {
            trace: false,
            rowid,
            team,
            sha256,
            bytes,
        }));
    }
    let trace: Option<(i64, i64, String, i64)> = sqlx::query_as(concat!(
        "SELECT t.rowid, t.team_id, t.sha256, t.bytes FROM episode_traces t
         WHERE t.note IS NULL AND t.team_id IN (SELECT value FROM json_each(?)) AND NOT ",
        protected!(),
        " ORDER BY t.created_at, t.rowid LIMIT 1"
    ))
    .bind(&ids)
    .fetch_optional(&mut **tx)
    .await?;
    Ok(trace.map(|(rowid, team, sha256, bytes)| Victim {
        trace: true,
        rowid,
        team,
        sha256,
        bytes,
    }))
}

async fn evict(
    tx: &mut Transaction<'_, Sqlite>,
    v: &Victim,
    video_note: &str,
    trace_note: &str,
) -> sqlx::Result<()> {
    let (sql, note) = match v.trace {
        true => ("UPDATE episode_traces SET note = ? WHERE rowid = ?", trace_note),
        false => ("UPDATE episode_videos SET note = ? WHERE rowid = ?", video_note),
    };
    sqlx::query(sql)
        .bind(note)
        .bind(v.rowid)
        .execute(&mut **tx)
        .await?;
    Ok(())
}

/// Count `v` as gone: its team's bytes, and its file to check for orphans.
fn take(used: &mut BTreeMap<i64, u64>, v: &Victim, videos: &mut Vec<String>, traces: &mut Vec<String>) {
    if let Some(b) = used.get_mut(&v.team) {
        *b = b.saturating_sub(v.bytes.max(0) as u64);
    }
    let files = if v.trace { traces } else { videos };
    if !files.contains(&v.sha256) {
        files.push(v.sha256.clone());
    }
}

/// Stored bytes (videos and traces) of every team storing any.
async fn team_usage(tx: &mut Transaction<'_, Sqlite>) -> sqlx::Result<BTreeMap<i64, u64>> {
    let rows: Vec<(i64, i64)> = sqlx::query_as(
        "SELECT team_id, SUM(bytes) FROM (
             SELECT team_id, bytes FROM episode_videos WHERE note IS NULL AND team_id IS NOT NULL
             UNION ALL
             SELECT team_id, bytes FROM episode_traces WHERE note IS NULL AND team_id IS NOT NULL)
         GROUP BY team_id HAVING SUM(bytes) > 0",
    )
    .fetch_all(&mut **tx)
    .await?;
    Ok(rows.into_iter().map(|(t, b)| (t, b.max(0) as u64)).collect())
}

/// Whether a stored row (video, or trace when `trace`) names the file `sha256`.
async fn stored(tx: &mut Transaction<'_, Sqlite>, trace: bool, sha256: &str) -> sqlx::Result<bool> {
    let sql = match trace {
        true => "SELECT 1 FROM episode_traces WHERE sha256 = ? AND note IS NULL LIMIT 1",
        false => "SELECT 1 FROM episode_videos WHERE sha256 = ? AND note IS NULL LIMIT 1",
    };
    let found: Option<i64> = sqlx::query_scalar(sql)
        .bind(sha256)
        .fetch_optional(&mut **tx)
        .await?;
    Ok(found.is_some())
}

/// Bytes of every stored file, videos and traces (as the budgets count them).
pub(crate) async fn stored_bytes(pool: &SqlitePool) -> sqlx::Result<i64> {
    sqlx::query_scalar(
        "SELECT (SELECT COALESCE(SUM(bytes), 0) FROM episode_videos WHERE note IS NULL)
              + (SELECT COALESCE(SUM(bytes), 0) FROM episode_traces WHERE note IS NULL)",
    )
    .fetch_one(pool)
    .await
}
