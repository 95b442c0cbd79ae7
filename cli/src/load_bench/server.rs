//! The server under load: this binary's own `serve`, started on loopback with free ports, a
//! fresh database and a configuration that lifts every per-team limit, so the benchmark's own
//! traffic (thousands of uploads from one token) is measured rather than refused.
//!
//! The process is owned by [`Spawned`], which kills it when dropped: every exit path of the
//! benchmark (error, deadline, panic unwinding) takes the server down with it. The normal path
//! stops it with SIGTERM, the graceful path `serve` handles, so the database is closed cleanly
//! before its size is measured.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use serde_json::Value;

/// How long a fresh server may take to print its readiness line (migrating a new database).
const STARTUP: Duration = Duration::from_secs(120);
/// How long a graceful stop may take before the server is killed.
const STOP: Duration = Duration::from_secs(30);

/// The configuration of the server under load: the defaults with every per-team limit lifted.
pub(super) fn bench_config() -> kitchen_r_server::Config {
    let mut cfg = kitchen_r_server::Config::default();
    // 0 = unlimited: the benchmark uploads tens of thousands of files from a hundred tokens,
    // hundreds per minute per token while seeding.
    cfg.quota.dev_per_day = 0;
    cfg.quota.test_per_day = 0;
    cfg.quota.per_minute = 0;
    cfg.quota.concurrent_runs = 0;
    cfg
}

/// `cfg` as a TOML file `serve --config` reads back to the same value: serialised through
/// serde, so every key the server has is written, under the names the server itself uses.
pub(super) fn config_toml(cfg: &kitchen_r_server::Config) -> anyhow::Result<String> {
    let value = serde_json::to_value(cfg).context("serialising the server configuration")?;
    let mut out = String::new();
    table(&mut out, "", &value)?;
    Ok(out)
}

/// Scalars and arrays of one table first, then its sub-tables under dotted headers. JSON's
/// scalar and array syntax is TOML's (strings, integers, floats, booleans); `null` (an unset
/// option) is left out, which TOML reads back as unset.
fn table(out: &mut String, prefix: &str, v: &Value) -> anyhow::Result<()> {
    let Value::Object(map) = v else {
        bail!("configuration `{prefix}` is not a table");
    };
    if !prefix.is_empty() {
        out.push_str(&format!("\n[{prefix}]\n"));
    }
    for (k, v) in map {
        match v {
            Value::Null | Value::Object(_) => {}
            Value::Array(items) if items.iter().any(Value::is_object) => {
                bail!("configuration `{prefix}.{k}` is an array of tables")
            }
            _ => out.push_str(&format!("{k} = {v}\n")),
        }
    }
    for (k, v) in map {
        if v.is_object() {
            let name = if prefix.is_empty() {
                k.clone()
            } else {
                format!("{prefix}.{k}")
            };
            table(out, &name, v)?;
        }
    }
    Ok(())
}

/// A `kitchen-r serve` child process, killed when dropped.
#[derive(Debug)]
pub(super) struct Spawned {
    child: Option<Child>,
    /// `http://127.0.0.1:PORT`
    pub http: String,
    pub db: PathBuf,
    log: PathBuf,
}

impl Spawned {
    /// Start this binary's `serve` on `db` with the configuration `config_file`, without
    /// in-process simulation slots, and wait for its readiness line. Its stderr goes to
    /// `dir/server.log`.
    pub(super) fn start(config_file: &Path, db: &Path, dir: &Path, admin: &str) -> anyhow::Result<Spawned> {
        let exe = std::env::current_exe().context("locating the kitchen-r binary")?;
        let log = dir.join("server.log");
        let stderr = std::fs::File::create(&log).context("creating the server log")?;
        let mut cmd = Command::new(exe);
        cmd.args([
            "serve",
            "--http",
            "127.0.0.1:0",
            "--grpc",
            "127.0.0.1:0",
            "--workers",
            "0",
        ])
        .arg("--db")
        .arg(format!("sqlite://{}", db.display()))
        .arg("--config")
        .arg(config_file)
        .env("KITCHEN_R_ADMIN_TOKEN", admin)
        .env(
            "RUST_LOG",
            std::env::var("KITCHEN_R_BENCH_SERVER_LOG").unwrap_or("warn".into()),
        )
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(stderr);
        let mut child = cmd.spawn().context("starting `kitchen-r serve`")?;
        let stdout = child.stdout.take().context("the server's stdout")?;
        let mut server = Spawned {
            child: Some(child),
            http: String::new(),
            db: db.to_path_buf(),
            log,
        };
        let (tx, rx) = mpsc::channel();
        // Reads the readiness line, then drains stdout so the server never blocks on it.
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if line.starts_with("listening ") {
                    let _ = tx.send(line);
                }
            }
        });
        let line = match rx.recv_timeout(STARTUP) {
            Ok(line) => line,
            Err(_) => bail!(
                "the server printed no `listening` line within {} s; its log ({}):\n{}",
                STARTUP.as_secs(),
                server.log.display(),
                server.log_tail()
            ),
        };
        let http = line
            .split_whitespace()
            .find_map(|w| w.strip_prefix("http="))
            .with_context(|| format!("no http= in the readiness line {line:?}"))?;
        server.http = format!("http://{http}");
        Ok(server)
    }

    /// The end of the server's log, for error messages.
    pub(super) fn log_tail(&self) -> String {
        let text = std::fs::read_to_string(&self.log).unwrap_or_default();
        let lines: Vec<&str> = text.lines().collect();
        lines[lines.len().saturating_sub(20)..].join("\n")
    }

    /// SIGTERM, then wait for the server to drain and exit; killed after [`STOP`]. Returns
    /// whether it exited on its own.
    pub(super) fn stop(&mut self) -> bool {
        let Some(mut child) = self.child.take() else {
            return false;
        };
        if !terminate(&child) {
            let _ = child.kill();
            let _ = child.wait();
            return false;
        }
        let start = Instant::now();
        while start.elapsed() < STOP {
            match child.try_wait() {
                Ok(Some(status)) => return status.success(),
                Ok(None) => std::thread::sleep(Duration::from_millis(50)),
                Err(_) => break,
            }
        }
        let _ = child.kill();
        let _ = child.wait();
        false
    }
}

impl Drop for Spawned {
    fn drop(&mut self) {
        if let Some(mut child) = self.child.take() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// Send SIGTERM (through `kill`, as this crate forbids `unsafe`); whether it was sent.
#[cfg(unix)]
fn terminate(child: &Child) -> bool {
    Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

#[cfg(not(unix))]
fn terminate(_: &Child) -> bool {
    false
}

/// Sizes of a SQLite database on disk: the main file and its write-ahead log.
#[derive(Debug, Clone, Copy, Default, serde::Serialize)]
pub(super) struct DbSize {
    pub db_bytes: u64,
    pub wal_bytes: u64,
}

impl DbSize {
    pub(super) fn of(db: &Path) -> DbSize {
        let len = |p: PathBuf| std::fs::metadata(p).map_or(0, |m| m.len());
        let mut wal = db.as_os_str().to_owned();
        wal.push("-wal");
        DbSize {
            db_bytes: len(db.to_path_buf()),
            wal_bytes: len(PathBuf::from(wal)),
        }
    }

    pub(super) fn total(&self) -> u64 {
        self.db_bytes + self.wal_bytes
    }
}

/// Fold the write-ahead log a stopped server left into the database file and truncate it
/// (`serve` exits without closing its pools, so SQLite does not do it at exit), so the file
/// size is what the data takes. Returns the plan submissions stored, when the schema says
/// (uploads that timed out on the client's side may have been stored all the same).
pub(super) async fn checkpoint(db: &Path) -> anyhow::Result<Option<u64>> {
    use sqlx::ConnectOptions;
    use sqlx::sqlite::{SqliteConnectOptions, SqliteJournalMode};
    let mut conn = SqliteConnectOptions::new()
        .filename(db)
        .create_if_missing(false)
        .journal_mode(SqliteJournalMode::Wal)
        .connect()
        .await
        .with_context(|| format!("opening {}", db.display()))?;
    let stored: Option<i64> = sqlx::query_scalar("SELECT count(*) FROM submissions WHERE kind = 'plans'")
        .fetch_one(&mut conn)
        .await
        .ok();
    sqlx::query("PRAGMA wal_checkpoint(TRUNCATE)")
        .execute(&mut conn)
        .await
        .context("checkpointing the database")?;
    sqlx::Connection::close(conn).await?;
    Ok(stored.and_then(|n| u64::try_from(n).ok()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bench_config_reads_back_as_written() {
        let cfg = bench_config();
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("bench.toml");
        std::fs::write(&file, config_toml(&cfg).unwrap()).unwrap();
        let back = kitchen_r_server::Config::load(Some(&file)).unwrap();
        // Top-level keys may come from KITCHEN_R_* in the environment; the tables cannot.
        assert_eq!(back.quota, cfg.quota);
        assert_eq!(back.control, cfg.control);
        assert_eq!(back.policy, cfg.policy);
        assert_eq!(back.plans, cfg.plans);
        back.validate().unwrap();
    }
}
