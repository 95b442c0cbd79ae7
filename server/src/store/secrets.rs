//! Endpoint tokens at rest (migration `20261126000200_seal_endpoint_tokens.sql`): the start-up
//! step that seals the plain tokens earlier servers stored, and the sample a start-up check
//! opens. Only the representation changes: each plain `token` of a policy submission's body
//! becomes `token_sealed`, each job's plain `endpoint.bearer_token` becomes
//! `endpoint.bearer_token_sealed` (left empty in the clear). Each batch is one transaction and
//! walks the table by id, so the step is idempotent and a server stopped half-way goes on at its
//! next start; its marker row goes with the last batch, so later starts skip it.

use serde_json::Value;
use sqlx::sqlite::SqlitePool;

use crate::secrets::SecretKey;

const BATCH: i64 = 500;

/// What the step sealed: `(policy submissions, jobs)`.
pub(crate) async fn seal_plain_tokens(pool: &SqlitePool, key: &SecretKey) -> sqlx::Result<(usize, usize)> {
    let pending: bool = sqlx::query_scalar("SELECT EXISTS (SELECT 1 FROM pending_token_sealing)")
        .fetch_one(pool)
        .await?;
    if !pending {
        return Ok((0, 0));
    }
    let bodies = walk(pool, BODIES, |body| seal_body(body, key)).await?;
    let specs = walk(pool, SPECS, |spec| seal_spec(spec, key)).await?;
    sqlx::query("DELETE FROM pending_token_sealing")
        .execute(pool)
        .await?;
    Ok((bodies, specs))
}

/// A table walk: the rows after an id still holding a plain token, and how to write one back.
struct Walk {
    select: &'static str,
    update: &'static str,
}

const BODIES: Walk = Walk {
    select: "SELECT id, body FROM submissions WHERE id > ? AND kind = 'policy'
             AND CASE WHEN json_valid(body) THEN json_type(body, '$.token') END IS NOT NULL
             ORDER BY id LIMIT ?",
    update: "UPDATE submissions SET body = ? WHERE id = ?",
};

const SPECS: Walk = Walk {
    select: "SELECT id, spec FROM jobs WHERE id > ?
             AND CASE WHEN json_valid(spec) THEN json_extract(spec, '$.endpoint.bearer_token') END <> ''
             ORDER BY id LIMIT ?",
    update: "UPDATE jobs SET spec = ? WHERE id = ?",
};

async fn walk(pool: &SqlitePool, w: Walk, rewrite: impl Fn(&str) -> Option<String>) -> sqlx::Result<usize> {
    let (mut after, mut done) = (0_i64, 0);
    loop {
        let mut tx = pool.begin_with("BEGIN IMMEDIATE").await?;
        let rows: Vec<(i64, String)> = sqlx::query_as(w.select)
            .bind(after)
            .bind(BATCH)
            .fetch_all(&mut *tx)
            .await?;
        for (id, text) in &rows {
            if let Some(new) = rewrite(text) {
                sqlx::query(w.update).bind(new).bind(id).execute(&mut *tx).await?;
                done += 1;
            }
        }
        tx.commit().await?;
        match rows.last() {
            Some((id, _)) => after = *id,
            None => return Ok(done),
        }
    }
}

/// A policy body with its plain `token` sealed (or dropped when empty or null).
pub(crate) fn seal_body(body: &str, key: &SecretKey) -> Option<String> {
    let mut v: Value = serde_json::from_str(body).ok()?;
    let obj = v.as_object_mut()?;
    let token = obj.remove("token")?;
    if let Some(t) = token.as_str().map(str::trim).filter(|t| !t.is_empty()) {
        obj.insert("token_sealed".into(), Value::String(key.seal(t)));
    }
    Some(v.to_string())
}

/// A job spec with its plain `endpoint.bearer_token` sealed.
pub(crate) fn seal_spec(spec: &str, key: &SecretKey) -> Option<String> {
    let mut v: Value = serde_json::from_str(spec).ok()?;
    let endpoint = v.get_mut("endpoint")?.as_object_mut()?;
    let token = endpoint.get("bearer_token")?.as_str()?.to_string();
    if token.is_empty() {
        return None;
    }
    endpoint.insert("bearer_token".into(), Value::String(String::new()));
    endpoint.insert("bearer_token_sealed".into(), Value::String(key.seal(&token)));
    Some(v.to_string())
}

/// The newest sealed token stored, for the start-up check that the key opens them.
pub(crate) async fn newest_sealed(pool: &SqlitePool) -> sqlx::Result<Option<String>> {
    sqlx::query_scalar(
        "SELECT json_extract(body, '$.token_sealed') FROM submissions WHERE kind = 'policy'
         AND CASE WHEN json_valid(body) THEN json_type(body, '$.token_sealed') END = 'text'
         ORDER BY id DESC LIMIT 1",
    )
    .fetch_optional(pool)
    .await
}
