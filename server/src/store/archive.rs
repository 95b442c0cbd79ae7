//! The contest archive's rows (docs/contest/archive.md): tables read as JSON objects, one per row,
//! and written back into an empty database with their ids, so every reference between rows
//! survives.
//!
//! The encoding is generic and driven by the schema, so a reader needs no code of ours:
//! - INTEGER and TEXT values are JSON numbers and strings; NULL is `null`;
//! - REAL values are numbers, except the infinities and NaN SQLite can hold (`p` is `+inf`
//!   when EM is 0), written as the strings `"inf"`, `"-inf"` and `"nan"`;
//! - BLOB columns named `*_z` hold zstd-compressed UTF-8 (plan files, per-instruction results,
//!   episode paths): written decompressed, as a JSON string; other BLOBs as base64 strings.
//!
//! Secrets never leave: [`TABLES`] names the columns left out (team token hashes) and the JSON
//! keys stripped from JSON text columns (sealed endpoint tokens). An import gives each team a
//! token hash no token can match (`!imported ...`, like the baseline team's): the organiser
//! issues new tokens.

use std::collections::HashMap;

use base64::Engine;
use serde_json::{Map, Value};
use sqlx::sqlite::{SqliteConnection, SqlitePool, SqliteRow};
use sqlx::{Column, Row, TypeInfo, ValueRef};

use super::packed;

/// One exported table: its name, the order its rows are written in, what is left out.
pub(crate) struct Table {
    pub name: &'static str,
    pub order: &'static str,
    /// Columns never exported (secrets).
    pub omit: &'static [&'static str],
    /// `(column, JSON pointer of the parent object, key)`: a key removed from a JSON text column.
    pub strip: &'static [(&'static str, &'static str, &'static str)],
}

/// The tables of an archive, in the order an import inserts them (referenced rows first).
/// Left out: `sessions` (browser logins), `video_renders` (a cache of work to do),
/// `pending_token_sealing` (start-up bookkeeping) and `leaderboard_entries`, which is derived
/// and rebuilt after an import (it is written to the archive for readers, never read back).
pub(crate) const TABLES: &[Table] = &[
    Table {
        name: "teams",
        order: "id",
        omit: &["token_hash"],
        strip: &[],
    },
    Table {
        name: "submissions",
        order: "id",
        omit: &[],
        strip: &[("body", "", "token_sealed"), ("body", "", "token")],
    },
    Table {
        name: "scoring_runs",
        order: "id",
        omit: &[],
        strip: &[],
    },
    Table {
        name: "instruction_results",
        order: "run_id, instruction_id",
        omit: &[],
        strip: &[],
    },
    Table {
        name: "jobs",
        order: "id",
        omit: &[],
        strip: &[
            ("spec", "/endpoint", "bearer_token_sealed"),
            ("spec", "/endpoint", "bearer_token"),
        ],
    },
    Table {
        name: "episode_results",
        order: "run_id, episode_key",
        omit: &[],
        strip: &[],
    },
    Table {
        name: "episode_traces",
        order: "run_id, episode_key",
        omit: &[],
        strip: &[],
    },
    Table {
        name: "episode_videos",
        order: "run_id, episode_key",
        omit: &[],
        strip: &[],
    },
    Table {
        name: "run_verifications",
        order: "run_id",
        omit: &[],
        strip: &[],
    },
];

/// Written for readers, rebuilt on import.
pub(crate) const DERIVED: Table = Table {
    name: "leaderboard_entries",
    order: "track, split, team_id, entry",
    omit: &[],
    strip: &[],
};

/// Every row of `table` as a JSON object (see the module doc for the encoding).
pub(crate) async fn dump(pool: &SqlitePool, table: &Table) -> anyhow::Result<Vec<Value>> {
    // Table names and orders are this file's constants.
    let sql = format!("SELECT * FROM {} ORDER BY {}", table.name, table.order);
    let rows = sqlx::query(sqlx::AssertSqlSafe(sql)).fetch_all(pool).await?;
    rows.iter().map(|r| row_json(r, table)).collect()
}

fn row_json(row: &SqliteRow, table: &Table) -> anyhow::Result<Value> {
    let mut obj = Map::new();
    for (i, col) in row.columns().iter().enumerate() {
        let name = col.name();
        if table.omit.contains(&name) {
            continue;
        }
        let raw = row.try_get_raw(i)?;
        let value = if raw.is_null() {
            Value::Null
        } else {
            match raw.type_info().name() {
                "INTEGER" => Value::from(row.try_get::<i64, _>(i)?),
                "REAL" => real_json(row.try_get::<f64, _>(i)?),
                "BLOB" => {
                    let blob: Vec<u8> = row.try_get(i)?;
                    match name.ends_with("_z") {
                        true => Value::String(packed::unpack_text(&blob)?),
                        false => Value::String(base64::engine::general_purpose::STANDARD.encode(blob)),
                    }
                }
                _ => Value::String(strip(table, name, row.try_get::<String, _>(i)?)),
            }
        };
        obj.insert(name.to_string(), value);
    }
    Ok(Value::Object(obj))
}

fn real_json(x: f64) -> Value {
    match x {
        x if x.is_nan() => Value::from("nan"),
        f64::INFINITY => Value::from("inf"),
        f64::NEG_INFINITY => Value::from("-inf"),
        x => Value::from(x),
    }
}

/// `text` with the table's stripped keys removed, when it is JSON holding them.
fn strip(table: &Table, column: &str, text: String) -> String {
    let rules: Vec<_> = table.strip.iter().filter(|(c, _, _)| *c == column).collect();
    if rules.is_empty() {
        return text;
    }
    let Ok(mut v) = serde_json::from_str::<Value>(&text) else {
        return text;
    };
    let mut changed = false;
    for (_, pointer, key) in rules {
        if let Some(Value::Object(o)) = v.pointer_mut(pointer) {
            changed |= o.remove(*key).is_some();
        }
    }
    match changed {
        true => v.to_string(),
        false => text,
    }
}

/// Whether the database holds no team and no submission (an import's precondition).
pub(crate) async fn is_empty(pool: &SqlitePool) -> sqlx::Result<(i64, i64)> {
    sqlx::query_as("SELECT (SELECT COUNT(*) FROM teams), (SELECT COUNT(*) FROM submissions)")
        .fetch_one(pool)
        .await
}

/// The declared type of each column of `table` (`INTEGER`, `REAL`, `TEXT`, `BLOB`).
pub(crate) async fn columns(
    conn: &mut SqliteConnection,
    table: &str,
) -> sqlx::Result<HashMap<String, String>> {
    // `table` is one of [`TABLES`]' names.
    let sql = format!("SELECT name, type FROM pragma_table_info('{table}')");
    let rows: Vec<(String, String)> = sqlx::query_as(sqlx::AssertSqlSafe(sql))
        .fetch_all(&mut *conn)
        .await?;
    Ok(rows
        .into_iter()
        .map(|(n, t)| (n, t.to_ascii_uppercase()))
        .collect())
}

/// Insert one exported row into `table`, whose columns are `columns` ([`columns`]). A column the
/// row lacks takes its default (a column added since the archive was made); a column the table
/// lacks is refused (see the archive chapter's migration rules).
pub(crate) async fn insert(
    conn: &mut SqliteConnection,
    table: &Table,
    columns: &HashMap<String, String>,
    row: &Map<String, Value>,
) -> anyhow::Result<()> {
    let mut names: Vec<&str> = row.keys().map(String::as_str).collect();
    if table.name == "teams" {
        names.push("token_hash");
    }
    for n in &names {
        anyhow::ensure!(
            columns.contains_key(*n),
            "{}: column {n:?} is not in this server's schema",
            table.name
        );
    }
    let sql = format!(
        "INSERT INTO {} ({}) VALUES ({})",
        table.name,
        names.join(", "),
        vec!["?"; names.len()].join(", ")
    );
    // Every name was checked against the table's own columns above.
    let mut q = sqlx::query(sqlx::AssertSqlSafe(sql));
    for n in &names {
        let value = match (*n, row.get(*n)) {
            ("token_hash", None) => Value::String(imported_token_hash(row)),
            (_, v) => v.cloned().unwrap_or(Value::Null),
        };
        let ty = columns[*n].as_str();
        q = match (value, ty) {
            (Value::Null, _) => q.bind(None::<i64>),
            (Value::Bool(b), _) => q.bind(b),
            (Value::Number(x), "REAL") => q.bind(x.as_f64()),
            (Value::Number(x), _) => match x.as_i64() {
                Some(i) => q.bind(i),
                None => q.bind(x.as_f64()),
            },
            (Value::String(s), "REAL") => q.bind(match s.as_str() {
                "inf" => f64::INFINITY,
                "-inf" => f64::NEG_INFINITY,
                "nan" => f64::NAN,
                other => anyhow::bail!("{}.{n}: {other:?} is not a number", table.name),
            }),
            (Value::String(s), "BLOB") if n.ends_with("_z") => q.bind(packed::pack_text(&s)),
            (Value::String(s), "BLOB") => q.bind(base64::engine::general_purpose::STANDARD.decode(s)?),
            (Value::String(s), _) => q.bind(s),
            (other, _) => anyhow::bail!("{}.{n}: unexpected value {other}", table.name),
        };
    }
    q.execute(&mut *conn).await?;
    Ok(())
}

/// A token hash no bearer token matches (not hex), unique per team; the baseline team keeps its
/// own, so `store::runs::baseline_team` finds it.
fn imported_token_hash(row: &Map<String, Value>) -> String {
    let name = row.get("name").and_then(Value::as_str).unwrap_or_default();
    match name == super::runs::BASELINE_TEAM {
        true => "!baseline: no token".into(),
        false => format!("!imported {}: no token until the organiser issues one", row["id"]),
    }
}

/// The applied migrations' versions, newest last (the archive's `schema_version`).
pub(crate) async fn schema_version(pool: &SqlitePool) -> sqlx::Result<i64> {
    sqlx::query_scalar("SELECT COALESCE(MAX(version), 0) FROM _sqlx_migrations WHERE success = 1")
        .fetch_one(pool)
        .await
}

/// The `CREATE` statements of the exported tables, for readers (`db/schema.sql`).
pub(crate) async fn schema_sql(pool: &SqlitePool) -> sqlx::Result<String> {
    let rows: Vec<(String, String)> = sqlx::query_as(
        "SELECT name, sql FROM sqlite_master WHERE type = 'table' AND sql IS NOT NULL ORDER BY name",
    )
    .fetch_all(pool)
    .await?;
    let wanted = |n: &str| TABLES.iter().chain([&DERIVED]).any(|t| t.name == n);
    Ok(rows
        .into_iter()
        .filter(|(n, _)| wanted(n))
        .map(|(_, sql)| format!("{sql};\n\n"))
        .collect())
}
