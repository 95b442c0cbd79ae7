//! Browser sessions' rows (`sessions`, see its migration): one per login, keyed by the hash of
//! the cookie's random id. The rules (who may log in, how long a session lasts) are
//! `crate::service::sessions`'.

use sqlx::sqlite::SqlitePool;

use super::Team;

/// A new session row.
#[derive(Debug, Clone)]
pub(crate) struct NewSession<'a> {
    pub id_hash: &'a str,
    /// `None`: the organiser.
    pub team_id: Option<i64>,
    pub credential_hash: &'a str,
    pub now: i64,
    pub expires_at: i64,
}

/// Store `s`, deleting the sessions that expired by `s.now` on the way (logins are rare, so the
/// table never holds more than the live sessions and the last few days' dead ones).
pub(crate) async fn insert(pool: &SqlitePool, s: &NewSession<'_>) -> sqlx::Result<()> {
    let mut tx = pool.begin_with("BEGIN IMMEDIATE").await?;
    sqlx::query("DELETE FROM sessions WHERE expires_at <= ?")
        .bind(s.now)
        .execute(&mut *tx)
        .await?;
    sqlx::query(
        "INSERT INTO sessions (id_hash, team_id, credential_hash, created_at, expires_at) VALUES (?, ?, ?, ?, ?)",
    )
    .bind(s.id_hash)
    .bind(s.team_id)
    .bind(s.credential_hash)
    .bind(s.now)
    .bind(s.expires_at)
    .execute(&mut *tx)
    .await?;
    tx.commit().await
}

/// Who a live session belongs to.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum Holder {
    /// An organiser session and the hash of the token it was opened with.
    Organiser { credential_hash: String },
    /// A team session still bound to the team's current token.
    Team(Team),
}

/// The holder of the session `id_hash` at `now`: `None` when there is no such session, it has
/// expired, or (for a team) the team's token changed since the login.
pub(crate) async fn holder(pool: &SqlitePool, id_hash: &str, now: i64) -> sqlx::Result<Option<Holder>> {
    let row: Option<(Option<i64>, String, Option<String>)> = sqlx::query_as(
        "SELECT s.team_id, s.credential_hash, t.name FROM sessions s
         LEFT JOIN teams t ON t.id = s.team_id AND t.token_hash = s.credential_hash
         WHERE s.id_hash = ? AND s.expires_at > ?",
    )
    .bind(id_hash)
    .bind(now)
    .fetch_optional(pool)
    .await?;
    Ok(match row {
        None => None,
        Some((None, credential_hash, _)) => Some(Holder::Organiser { credential_hash }),
        Some((Some(id), _, Some(name))) => Some(Holder::Team(Team { id, name })),
        // The team's token was rotated after this login.
        Some((Some(_), _, None)) => None,
    })
}

/// End the session `id_hash` (logout); true when there was one.
pub(crate) async fn delete(pool: &SqlitePool, id_hash: &str) -> sqlx::Result<bool> {
    let r = sqlx::query("DELETE FROM sessions WHERE id_hash = ?")
        .bind(id_hash)
        .execute(pool)
        .await?;
    Ok(r.rows_affected() > 0)
}

/// Give team `team` the token hash `token_hash` and end every session of the team, in one
/// transaction. Returns the team's name; `None` when there is no such team or it is the
/// organiser's baseline team (whose stored hash is no token's: it cannot log in).
pub(crate) async fn rotate_team_token(
    pool: &SqlitePool,
    team: i64,
    token_hash: &str,
) -> sqlx::Result<Option<String>> {
    let mut tx = pool.begin_with("BEGIN IMMEDIATE").await?;
    let name: Option<String> = sqlx::query_scalar(
        "UPDATE teams SET token_hash = ? WHERE id = ? AND token_hash NOT LIKE '!%' RETURNING name",
    )
    .bind(token_hash)
    .bind(team)
    .fetch_optional(&mut *tx)
    .await?;
    sqlx::query("DELETE FROM sessions WHERE team_id = ?")
        .bind(team)
        .execute(&mut *tx)
        .await?;
    tx.commit().await?;
    Ok(name)
}
