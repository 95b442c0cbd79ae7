//! What a run prints: one JSON object (`--json`) or a table for people.

use serde::Serialize;

use super::phases::{SeedSummary, Verified};
use super::server::DbSize;
use super::stats::Side;

#[derive(Debug, Clone, Serialize)]
pub(super) struct Report {
    pub params: Params,
    /// `"spawned"` (this binary's `serve` on a fresh database) or the `--server` URL.
    pub server: String,
    /// Lines of each uploaded plan file and the size of one, bytes.
    pub plan_lines: usize,
    pub plan_file_bytes: usize,
    pub seed: SeedSummary,
    pub reads: Side,
    /// Mean size of a successful read's body, bytes.
    pub read_body_bytes: u64,
    pub uploads: Side,
    /// Uploads the open loop scheduled (`uploads_per_s × seconds`, rounded up).
    pub uploads_due: u64,
    pub verify: Verified,
    /// Only for a spawned server, measured after it stopped.
    pub db: Option<DbReport>,
    /// Failed reads and uploads of the measured phase.
    pub failed_requests: u64,
    /// Every acknowledged upload that was checked is present with its EM.
    pub all_verified: bool,
}

#[derive(Debug, Clone, Serialize)]
pub(super) struct Params {
    pub submissions: usize,
    pub teams: usize,
    pub readers: usize,
    pub uploads_per_s: f64,
    pub seconds: f64,
    pub read_path: String,
    pub seed_concurrency: usize,
    pub max_in_flight_uploads: usize,
    pub verify_seeded: bool,
}

#[derive(Debug, Clone, Serialize)]
pub(super) struct DbReport {
    /// The files as the stopped server left them.
    pub at_stop: DbSize,
    /// After folding the WAL into the database (`None` when that failed).
    pub checkpointed: Option<DbSize>,
    /// Plan submissions acknowledged: seeded plus measured.
    pub acknowledged: u64,
    /// Plan submissions in the database (`None` when it could not be counted); can exceed the
    /// acknowledged ones by uploads stored after the client gave up on them.
    pub stored: Option<u64>,
    /// Database (+ WAL) after the checkpoint, else as left, per stored (else acknowledged) plan
    /// submission.
    pub kib_per_submission: f64,
    /// The server exited on SIGTERM (else it was killed).
    pub stopped_gracefully: bool,
}

impl DbReport {
    pub(super) fn new(
        at_stop: DbSize,
        checkpoint: Option<(DbSize, Option<u64>)>,
        acknowledged: u64,
        stopped_gracefully: bool,
    ) -> DbReport {
        let checkpointed = checkpoint.map(|c| c.0);
        let stored = checkpoint.and_then(|c| c.1);
        let bytes = checkpointed.unwrap_or(at_stop).total();
        DbReport {
            at_stop,
            checkpointed,
            acknowledged,
            stored,
            kib_per_submission: bytes as f64 / 1024.0 / (stored.unwrap_or(acknowledged).max(1) as f64),
            stopped_gracefully,
        }
    }
}

pub(super) fn print(r: &Report) {
    let p = &r.params;
    println!(
        "server     {}; {} teams; {}-line dev plan files ({:.1} KiB)",
        r.server,
        p.teams,
        r.plan_lines,
        r.plan_file_bytes as f64 / 1024.0
    );
    let s = &r.seed;
    println!(
        "seeded     {} plan files in {:.1} s ({:.0}/s, {} at a time); {} failed{}, {} retried",
        s.ok,
        s.seconds,
        s.per_s,
        p.seed_concurrency,
        s.failed,
        failures(&s.failures),
        s.retries
    );
    println!(
        "load       {} readers on GET {} ({:.1} KiB answers), {} uploads/s ({} due) for {} s",
        p.readers,
        p.read_path,
        r.read_body_bytes as f64 / 1024.0,
        p.uploads_per_s,
        r.uploads_due,
        p.seconds
    );
    println!();
    println!(
        "{:<8} {:>9} {:>9} {:>7} {:>9} {:>9} {:>9} {:>9} {:>9}",
        "side", "requests", "ok", "failed", "ok/s", "p50 ms", "p90 ms", "p99 ms", "max ms"
    );
    for (name, side) in [("reads", &r.reads), ("uploads", &r.uploads)] {
        print!(
            "{:<8} {:>9} {:>9} {:>7} {:>9.1}",
            name, side.requests, side.ok, side.failed, side.throughput_per_s
        );
        match side.latency_ms {
            Some(l) => println!(" {:>9.2} {:>9.2} {:>9.2} {:>9.2}", l.p50, l.p90, l.p99, l.max),
            None => println!(" {:>9} {:>9} {:>9} {:>9}", "-", "-", "-", "-"),
        }
    }
    println!();
    for (name, side) in [("reads", &r.reads), ("uploads", &r.uploads)] {
        if side.failed > 0 {
            println!("failures   {name}:{}", failures(&side.failures));
        }
    }
    let v = &r.verify;
    println!(
        "verified   {} of {} acknowledged uploads present with their EM ({} missing, {} wrong EM, {} errors{})",
        v.verified,
        v.checked,
        v.missing,
        v.wrong_em,
        v.errors.values().sum::<u64>(),
        failures(&v.errors)
    );
    println!(
        "leaderboard best EM per team as acknowledged for {} teams, {} mismatches",
        v.leaderboard_teams, v.leaderboard_mismatches
    );
    match &r.db {
        Some(d) => {
            let mib = |b: u64| b as f64 / 1_048_576.0;
            let size = d.checkpointed.map_or_else(
                || "not checkpointed".to_string(),
                |c| format!("{:.1} MiB checkpointed", mib(c.total())),
            );
            println!(
                "database   {size} ({:.1} MiB + WAL {:.1} MiB at stop) for {} plan submissions = {:.1} KiB per submission{}",
                mib(d.at_stop.db_bytes),
                mib(d.at_stop.wal_bytes),
                d.stored
                    .map_or_else(|| format!("{} acknowledged", d.acknowledged), |n| n.to_string()),
                d.kib_per_submission,
                if d.stopped_gracefully {
                    ""
                } else {
                    " (server killed, not stopped gracefully)"
                }
            );
        }
        None => println!("database   not measured (--server)"),
    }
}

/// ` 503 ×3, timeout ×1` (empty when none).
fn failures(f: &std::collections::BTreeMap<String, u64>) -> String {
    f.iter()
        .map(|(k, n)| format!(" {k} ×{n}"))
        .collect::<Vec<_>>()
        .join(",")
}
