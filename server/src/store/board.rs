//! The maintained leaderboards (`leaderboard_entries`): each team's best entry per track and
//! split, refreshed inside the transaction of every write that adds a scoring run or changes a
//! run's state, so reading a board costs O(teams) however many submissions there are.
//!
//! The ranking rules live here, once, in `refresh_team`: planning by the latest run's EM;
//! control by SR then MSE, integrated by M then P (only finished runs have keys; integrated
//! counts only runs linked to a plans submission); ties to the earlier submission, then the
//! lower id; unscored entries last; organiser reference runs are each their own row (reference
//! plan files: the baseline team's best, marked as a baseline); on the test
//! split a plan file created after the team's first test policy submission is not ranked.
//!
//! The policy tracks have two boards each, one per observation track: runs whose policy received
//! privileged observations (`privileged_observations` in the submission's body) are ranked only
//! among themselves (`observations = 'privileged'`, a team's best with `entry` = -1), never
//! against standard runs; every older body has no such field and is standard.
//!
//! Likewise per grasp mode (docs/twin/robot.md): a policy run's mode is its latest scoring run's
//! `grasp_mode`, and runs of one mode are ranked only among themselves (`grasp_mode` column; a
//! team's best physical entries take `entry` -2 standard, -3 privileged). The organiser's contest
//! mode (`[control] grasp`) picks the board shown first; the store itself has no favourite.

use kitchen_r_core::GraspMode;
use kitchen_r_core::dataset::Split;
use kitchen_r_core::observations::ObservationTrack;
use sqlx::sqlite::SqlitePool;
use sqlx::{FromRow, SqliteConnection};

use crate::states::RunState;

/// The tracks as stored (`leaderboard_entries.track`).
pub(crate) const PLANNING: &str = "planning";
pub(crate) const CONTROL: &str = "control";
pub(crate) const INTEGRATED: &str = "integrated";

/// One ranked row of a board, best first.
#[derive(Debug, Clone, PartialEq, FromRow)]
pub(crate) struct BoardRow {
    pub team: String,
    pub submission_id: i64,
    pub submitted_at: i64,
    /// The latest run's state (policy tracks; `None` for plans or a submission without a run).
    pub state: Option<RunState>,
    pub em: Option<f64>,
    pub sr: Option<f64>,
    pub mse: Option<f64>,
    pub m: Option<f64>,
    pub p: Option<f64>,
    pub baseline: bool,
    /// The grasp mode of the ranked run (planning rows carry the default).
    #[sqlx(try_from = "String")]
    pub grasp_mode: GraspMode,
}

/// The standard abstract-grasp board of `track` (one of the constants above) on `split`, in
/// rank order.
#[cfg(test)]
pub(crate) async fn read(pool: &SqlitePool, track: &str, split: Split) -> sqlx::Result<Vec<BoardRow>> {
    read_observed(
        pool,
        track,
        ObservationTrack::Standard,
        GraspMode::Abstract,
        split,
    )
    .await
}

/// The board of `track`, observation track and grasp mode on `split`, in rank order (planning
/// has only the standard board, whose rows all carry the default mode).
pub(crate) async fn read_observed(
    pool: &SqlitePool,
    track: &str,
    observations: ObservationTrack,
    grasp: GraspMode,
    split: Split,
) -> sqlx::Result<Vec<BoardRow>> {
    sqlx::query_as(
        "SELECT t.name AS team, b.submission_id, b.created_at AS submitted_at, b.state,
                b.em, b.sr, b.mse, b.m, b.p, b.baseline, b.grasp_mode
         FROM leaderboard_entries b JOIN teams t ON t.id = b.team_id
         WHERE b.track = ? AND b.split = ? AND b.observations = ? AND b.grasp_mode = ?
         ORDER BY b.k1 IS NULL, b.k1 DESC, b.k2 IS NULL, b.k2, b.created_at, b.submission_id",
    )
    .bind(track)
    .bind(split.as_str())
    .bind(observations.as_str())
    .bind(grasp.as_str())
    .fetch_all(pool)
    .await
}

/// Refresh the entries the submission `id` takes part in: its own track(s), and, for a test
/// policy submission, the team's test planning entry (whose eligibility depends on it).
pub(crate) async fn refresh_submission(conn: &mut SqliteConnection, id: i64) -> sqlx::Result<()> {
    let Some((team, split, kind)): Option<(i64, String, String)> =
        sqlx::query_as("SELECT team_id, split, kind FROM submissions WHERE id = ?")
            .bind(id)
            .fetch_optional(&mut *conn)
            .await?
    else {
        return Ok(());
    };
    if kind == "plans" {
        refresh_track(conn, PLANNING, team, &split).await
    } else {
        refresh_track(conn, CONTROL, team, &split).await?;
        refresh_track(conn, INTEGRATED, team, &split).await?;
        if split == Split::Test.as_str() {
            refresh_track(conn, PLANNING, team, &split).await?;
        }
        Ok(())
    }
}

/// Refresh the entries fed by the submission that run `run` belongs to.
pub(crate) async fn refresh_run(conn: &mut SqliteConnection, run: i64) -> sqlx::Result<()> {
    let sub: Option<i64> = sqlx::query_scalar("SELECT submission_id FROM scoring_runs WHERE id = ?")
        .bind(run)
        .fetch_optional(&mut *conn)
        .await?;
    match sub {
        Some(id) => refresh_submission(conn, id).await,
        None => Ok(()),
    }
}

/// Recompute every entry from the submissions (start-up; a database from before the table).
pub(crate) async fn rebuild(pool: &SqlitePool) -> sqlx::Result<()> {
    let mut tx = pool.begin_with("BEGIN IMMEDIATE").await?;
    sqlx::query("DELETE FROM leaderboard_entries")
        .execute(&mut *tx)
        .await?;
    let groups: Vec<(i64, String)> = sqlx::query_as("SELECT DISTINCT team_id, split FROM submissions")
        .fetch_all(&mut *tx)
        .await?;
    for (team, split) in groups {
        for track in [PLANNING, CONTROL, INTEGRATED] {
            refresh_track(&mut tx, track, team, &split).await?;
        }
    }
    tx.commit().await
}

/// Replace `team`'s entries on one track and split by what its submissions rank as now. Costs
/// O(that team's submissions to the split), with the `(team_id, split, created_at)` index.
async fn refresh_track(conn: &mut SqliteConnection, track: &str, team: i64, split: &str) -> sqlx::Result<()> {
    sqlx::query("DELETE FROM leaderboard_entries WHERE track = ? AND split = ? AND team_id = ?")
        .bind(track)
        .bind(split)
        .bind(team)
        .execute(&mut *conn)
        .await?;
    let sql = match track {
        PLANNING => {
            return sqlx::query(PLANNING_BEST)
                .bind(track)
                .bind(split)
                .bind(team)
                .execute(&mut *conn)
                .await
                .map(drop);
        }
        CONTROL => policy_best("sr", "mse", ""),
        _ => policy_best("m", "p", "AND json_extract(s.body, '$.plans') IS NOT NULL"),
    };
    for observations in ObservationTrack::ALL {
        for grasp in GraspMode::ALL {
            // Column names and filters come from the constants above, never from input.
            sqlx::query(sqlx::AssertSqlSafe(sql.clone()))
                .bind(track)
                .bind(split)
                .bind(team)
                .bind(observations == ObservationTrack::Privileged)
                .bind(observations.as_str())
                .bind(grasp == GraspMode::Physical)
                .bind(grasp.as_str())
                .execute(&mut *conn)
                .await?;
        }
    }
    Ok(())
}

/// Planning: the team's best plan file by its latest run's EM (binds: track, split, team).
const PLANNING_BEST: &str = "
    INSERT INTO leaderboard_entries
        (track, split, team_id, entry, submission_id, k1, k2, created_at, state, em, baseline)
    SELECT ?1, s.split, s.team_id, 0, s.id, r.em, NULL, s.created_at, NULL, r.em,
           -- The organiser's reference plan files are filed under the reserved team.
           EXISTS (SELECT 1 FROM teams t WHERE t.id = s.team_id AND t.name = '(baseline)')
    FROM submissions s
    LEFT JOIN scoring_runs r ON r.id = (SELECT MAX(id) FROM scoring_runs WHERE submission_id = s.id)
    WHERE s.split = ?2 AND s.team_id = ?3 AND s.kind = 'plans'
      -- Test plan files made after the team's first test policy run are not ranked.
      AND (s.split <> 'test' OR s.id < COALESCE((SELECT MIN(p.id) FROM submissions p
           WHERE p.team_id = s.team_id AND p.split = 'test' AND p.kind = 'policy'), s.id + 1))
    ORDER BY r.em IS NULL, r.em DESC, s.created_at, s.id
    LIMIT 1";

/// Policy tracks: the team's best run on `(primary DESC, secondary ASC)` among finished runs,
/// plus every organiser reference submission as its own entry, of one observation track and
/// grasp mode (binds: track, split, team, privileged as 0/1, the observation track's name,
/// physical as 0/1, the grasp mode's name). A submission's mode is its latest run's.
fn policy_best(primary: &str, secondary: &str, linked: &str) -> String {
    format!(
        "WITH latest AS (
            SELECT s.id, s.split, s.team_id, s.created_at, r.state, r.em, r.sr, r.mse, r.m, r.p,
                   CASE WHEN r.state = 'finished' THEN r.{primary} END AS k1,
                   CASE WHEN r.state = 'finished' THEN r.{secondary} END AS k2,
                   COALESCE(json_extract(s.body, '$.reference'), 0) AS baseline
            FROM submissions s
            LEFT JOIN scoring_runs r
                   ON r.id = (SELECT MAX(id) FROM scoring_runs WHERE submission_id = s.id)
            WHERE s.split = ?2 AND s.team_id = ?3 AND s.kind = 'policy' {linked}
              AND COALESCE(json_extract(s.body, '$.privileged_observations'), 0) = ?4
              AND COALESCE(r.grasp_mode, 'abstract') = ?7
         ), best AS (
            SELECT * FROM latest WHERE NOT baseline
            ORDER BY k1 IS NULL, k1 DESC, k2 IS NULL, k2, created_at, id LIMIT 1
         )
         INSERT INTO leaderboard_entries
             (track, split, team_id, entry, submission_id, k1, k2, created_at, state,
              em, sr, mse, m, p, baseline, observations, grasp_mode)
         SELECT ?1, split, team_id, CASE WHEN baseline THEN id ELSE -(?4 + 2 * ?6) END, id,
                k1, k2, created_at, state, em, sr, mse, m, p, baseline, ?5, ?7
         FROM (SELECT * FROM best UNION ALL SELECT * FROM latest WHERE baseline)"
    )
}

/// The run a board row shows, as its results card and intervals read it: the submission's latest
/// scoring run.
#[derive(Debug, Clone, PartialEq, FromRow)]
pub(crate) struct ShownRun {
    pub id: i64,
    pub scorer_version: String,
    /// NULL for runs made before the server stored it.
    pub binary_version: Option<String>,
    /// The run whose recorded episodes the scores come from (itself, or a rescore's source).
    pub episodes_run: i64,
}

/// The latest scoring run of `submission`, if any.
pub(crate) async fn shown_run(pool: &SqlitePool, submission: i64) -> sqlx::Result<Option<ShownRun>> {
    sqlx::query_as(
        "SELECT id, scorer_version, binary_version, COALESCE(source_run_id, id) AS episodes_run
         FROM scoring_runs WHERE submission_id = ? ORDER BY id DESC LIMIT 1",
    )
    .bind(submission)
    .fetch_optional(pool)
    .await
}
