//! Start-up conversion of rows written before plan storage was compressed (migration
//! `20261122250000_compress_plan_storage.sql`): plan files move from `submissions.body` to
//! `body_z`, and a run's `instruction_results` rows into `scoring_runs.instructions_z`. Only
//! the representation changes, never the content; each batch is one transaction, so a server
//! stopped half-way converts the rest at its next start.

use sqlx::sqlite::SqlitePool;
use sqlx::{FromRow, Row};

use super::packed;
use crate::plans::InstructionScore;

const BATCH: i64 = 500;

pub(crate) async fn legacy_rows(pool: &SqlitePool) -> sqlx::Result<()> {
    let (mut bodies, mut runs) = (0, 0);
    loop {
        let n = plan_bodies(pool).await?;
        bodies += n;
        if n == 0 {
            break;
        }
    }
    loop {
        let n = instruction_rows(pool).await?;
        runs += n;
        if n == 0 {
            break;
        }
    }
    if bodies + runs > 0 {
        tracing::info!(
            plan_files = bodies,
            runs,
            "compressed rows stored before 20261122250000"
        );
    }
    Ok(())
}

async fn plan_bodies(pool: &SqlitePool) -> sqlx::Result<usize> {
    let mut tx = pool.begin_with("BEGIN IMMEDIATE").await?;
    let rows =
        sqlx::query("SELECT id, body FROM submissions WHERE kind = 'plans' AND body_z IS NULL LIMIT ?")
            .bind(BATCH)
            .fetch_all(&mut *tx)
            .await?;
    for r in &rows {
        let (id, body): (i64, String) = (r.try_get("id")?, r.try_get("body")?);
        sqlx::query("UPDATE submissions SET body_z = ?, body = '' WHERE id = ?")
            .bind(packed::pack_text(&body))
            .bind(id)
            .execute(&mut *tx)
            .await?;
    }
    tx.commit().await?;
    Ok(rows.len())
}

/// A row of the legacy `instruction_results` table.
#[derive(FromRow)]
struct Legacy {
    instruction_id: String,
    present: bool,
    #[sqlx(try_from = "i64")]
    correct_steps: usize,
    #[sqlx(try_from = "i64")]
    total_steps: usize,
}

async fn instruction_rows(pool: &SqlitePool) -> sqlx::Result<usize> {
    let mut tx = pool.begin_with("BEGIN IMMEDIATE").await?;
    let runs: Vec<i64> = sqlx::query_scalar("SELECT DISTINCT run_id FROM instruction_results LIMIT ?")
        .bind(BATCH)
        .fetch_all(&mut *tx)
        .await?;
    for &run in &runs {
        let rows: Vec<Legacy> = sqlx::query_as(
            "SELECT instruction_id, present, correct_steps, total_steps FROM instruction_results
             WHERE run_id = ? ORDER BY instruction_id",
        )
        .bind(run)
        .fetch_all(&mut *tx)
        .await?;
        let scores: Vec<InstructionScore> = (rows.into_iter())
            .map(|r| InstructionScore {
                id: r.instruction_id,
                present: r.present,
                correct: r.correct_steps,
                total: r.total_steps,
            })
            .collect();
        sqlx::query("UPDATE scoring_runs SET instructions_z = ? WHERE id = ?")
            .bind(packed::pack_instructions(&scores))
            .bind(run)
            .execute(&mut *tx)
            .await?;
        sqlx::query("DELETE FROM instruction_results WHERE run_id = ?")
            .bind(run)
            .execute(&mut *tx)
            .await?;
    }
    tx.commit().await?;
    Ok(runs.len())
}
