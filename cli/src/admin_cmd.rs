//! `kitchen-r admin queue|workers|runs|cancel RUN|requeue RUN|backup FILE`: the organiser's
//! console over the server's `/api/v1/admin` routes (docs/organiser-console.md). Human tables by
//! default, the server's JSON with `--json`; a refused request exits non-zero with the
//! server's own message.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use clap::{Args, Subcommand};
use serde_json::Value;

use crate::server_client::{ServerArgs, json, runtime, send, url};

#[derive(Args, Debug)]
pub(crate) struct AdminArgs {
    #[command(subcommand)]
    command: AdminCommand,
    /// Server base URL.
    #[arg(
        long,
        env = "KITCHEN_R_SERVER",
        default_value = "http://127.0.0.1:8080",
        global = true
    )]
    server: String,
    /// Organiser token.
    #[arg(long, env = "KITCHEN_R_ADMIN_TOKEN", hide_env_values = true, global = true)]
    admin_token: Option<String>,
    /// Print the server's JSON answer instead of tables.
    #[arg(long, global = true)]
    json: bool,
}

#[derive(Subcommand, Debug)]
enum AdminCommand {
    /// Jobs by state, the oldest queued job's age, each team's share, stuck and failed jobs.
    Queue,
    /// Workers with their last heartbeat or report and the episodes they hold now.
    Workers,
    /// Policy runs with progress and ETA (active ones, then the latest others).
    Runs,
    /// Cancel an active run: no more leases, workers stop at their next heartbeat, late
    /// reports are ignored, the team gets its quota back.
    Cancel {
        /// The run id (`admin runs` lists them).
        run: i64,
    },
    /// Put a run's failed and stuck jobs back in the queue with their attempts reset.
    Requeue {
        /// The run id.
        run: i64,
    },
    /// Write a consistent copy of the live database to FILE (the server keeps serving).
    Backup {
        /// Where to write the copy (a SQLite database file).
        file: PathBuf,
        /// Replace FILE if it exists.
        #[arg(long)]
        force: bool,
    },
    /// Replay every stored trace of a policy run here, bit for bit, and check each replay
    /// against the result the server stored; any disagreement marks the run unverified on the
    /// console (exit status 1).
    Verify {
        /// The run id (`admin runs` lists them).
        run: i64,
    },
    /// Run N of a policy run's episodes again against the same endpoint, as the workers ran
    /// them, and report the difference from the stored results with 95 % Wilson intervals.
    Reevaluate {
        /// The run id.
        run: i64,
        /// How many of the run's episodes to run again (the first N in key order).
        #[arg(long)]
        episodes: usize,
    },
    /// Write the contest archive (.tar.zst): dataset with the hidden test answers, configs,
    /// teams without secrets, submissions, runs, scores and traces, with a sha256 manifest.
    Export {
        /// Where to write the archive.
        #[arg(long)]
        out: PathBuf,
        /// Include the stored episode videos (they can be rendered again from the traces).
        #[arg(long)]
        videos: bool,
        /// Replace OUT if it exists.
        #[arg(long)]
        force: bool,
    },
    /// Load a contest archive into this server, which must be empty; the archive is checked
    /// against its sha256 manifest first and refused whole if anything was altered.
    Import {
        /// The archive `admin export` wrote.
        archive: PathBuf,
    },
}

pub(crate) fn admin(args: AdminArgs) -> anyhow::Result<()> {
    let Some(token) = args.admin_token.clone().filter(|t| !t.is_empty()) else {
        bail!("the organiser token is needed: --admin-token or KITCHEN_R_ADMIN_TOKEN");
    };
    let server = ServerArgs {
        server: args.server.clone(),
    };
    match &args.command {
        AdminCommand::Verify { run } => return crate::verify_cmd::verify(&server, &token, *run, args.json),
        AdminCommand::Reevaluate { run, episodes } => {
            return crate::reevaluate_cmd::reevaluate(&server, &token, *run, *episodes, args.json);
        }
        AdminCommand::Export { out, videos, force } => {
            return crate::archive_cmd::export(&server, &token, out, *videos, *force);
        }
        AdminCommand::Import { archive } => {
            return crate::archive_cmd::import(&server, &token, archive, args.json);
        }
        _ => {}
    }
    let client = reqwest::Client::new();
    runtime()?.block_on(async {
        let get = |path: &str| client.get(url(&server, path)).bearer_auth(&token);
        let post = |path: &str| client.post(url(&server, path)).bearer_auth(&token);
        match args.command {
            AdminCommand::Backup { file, force } => {
                return backup(post("/api/v1/admin/backup"), &file, force).await;
            }
            AdminCommand::Queue => {
                let v = json(get("/api/v1/admin/queue")).await?;
                print_or(args.json, &v, print_queue)
            }
            AdminCommand::Workers => {
                let v = json(get("/api/v1/admin/workers")).await?;
                print_or(args.json, &v, print_workers)
            }
            AdminCommand::Runs => {
                let v = json(get("/api/v1/admin/runs")).await?;
                print_or(args.json, &v, print_runs)
            }
            AdminCommand::Cancel { run } => {
                let v = json(post(&format!("/api/v1/admin/runs/{run}/cancel"))).await?;
                print_or(args.json, &v, |v| {
                    println!(
                        "run {run} cancelled by {} at {}: {} jobs cancelled, {} leases revoked \
(their workers stop at the next heartbeat); the team's quota is given back",
                        s(&v["cancelled_by"]),
                        s(&v["cancelled_at"]),
                        v["jobs_cancelled"],
                        v["leases_revoked"]
                    );
                })
            }
            AdminCommand::Requeue { run } => {
                let v = json(post(&format!("/api/v1/admin/runs/{run}/requeue"))).await?;
                print_or(args.json, &v, |v| {
                    println!(
                        "run {run}: {} jobs back in the queue ({} were stuck), each with {} attempts",
                        v["jobs_requeued"], v["stuck"], v["attempts"]
                    );
                })
            }
            AdminCommand::Verify { .. }
            | AdminCommand::Reevaluate { .. }
            | AdminCommand::Export { .. }
            | AdminCommand::Import { .. } => unreachable!("handled above"),
        }
        Ok(())
    })
}

fn print_or(raw: bool, v: &Value, human: impl FnOnce(&Value)) {
    if raw {
        println!("{v}");
    } else {
        human(v);
    }
}

/// A JSON value as text: strings bare, missing as `-`.
fn s(v: &Value) -> String {
    match v {
        Value::String(t) => t.clone(),
        Value::Null => "-".into(),
        other => other.to_string(),
    }
}

fn list(v: &Value) -> Vec<Value> {
    v.as_array().cloned().unwrap_or_default()
}

/// Seconds as `1h 02m`, `3m 05s` or `42s`.
fn duration(v: &Value) -> String {
    let Some(secs) = v.as_f64() else {
        return "-".into();
    };
    let t = secs.max(0.0).round() as u64;
    match t {
        0..60 => format!("{t}s"),
        60..3600 => format!("{}m {:02}s", t / 60, t % 60),
        _ => format!("{}h {:02}m", t / 3600, (t % 3600) / 60),
    }
}

/// Print rows under a header, each column as wide as its widest cell.
fn table(header: &[&str], rows: &[Vec<String>]) {
    let mut width: Vec<usize> = header.iter().map(|h| h.chars().count()).collect();
    for r in rows {
        for (w, c) in width.iter_mut().zip(r) {
            *w = (*w).max(c.chars().count());
        }
    }
    let line = |cells: Vec<String>| {
        let parts: Vec<String> = cells
            .iter()
            .zip(&width)
            .map(|(c, w)| format!("{c:<w$}"))
            .collect();
        println!("{}", parts.join("  ").trim_end());
    };
    line(header.iter().map(|h| h.to_string()).collect());
    for r in rows {
        line(r.clone());
    }
}

fn print_queue(v: &Value) {
    let jobs = &v["jobs"];
    println!(
        "jobs: {} queued, {} leased, {} done, {} failed, {} cancelled",
        jobs["queued"], jobs["leased"], jobs["done"], jobs["failed"], jobs["cancelled"]
    );
    match v["oldest_queued_at"].as_str() {
        Some(at) => println!(
            "oldest queued: {} ago ({at})",
            duration(&v["oldest_queued_age_s"])
        ),
        None => println!("oldest queued: none queued"),
    }
    let teams = list(&v["teams"]);
    println!();
    if teams.is_empty() {
        println!("teams' share: no team has open jobs");
    } else {
        println!("teams' share of the episodes in flight:");
        let rows: Vec<Vec<String>> = teams
            .iter()
            .map(|t| {
                vec![
                    s(&t["team"]),
                    s(&t["in_flight"]),
                    format!("{:.0}%", t["share"].as_f64().unwrap_or(0.0) * 100.0),
                    s(&t["queued"]),
                    s(&t["runs"]),
                ]
            })
            .collect();
        table(&["team", "in flight", "share", "queued", "runs"], &rows);
    }
    for (key, title) in [
        ("stuck", "stuck (leased past expiry; the reaper requeues them)"),
        ("retrying", "retrying after a failed attempt"),
        (
            "failed",
            "failed (the platform gave up; `admin requeue RUN` retries them)",
        ),
    ] {
        let jobs = list(&v[key]);
        println!();
        println!("{title}: {}", jobs.len());
        if jobs.is_empty() {
            continue;
        }
        let rows: Vec<Vec<String>> = jobs
            .iter()
            .map(|j| {
                vec![
                    s(&j["job"]),
                    s(&j["run"]),
                    s(&j["team"]),
                    s(&j["episode"]),
                    format!("{}/{}", j["attempt"], j["max_attempts"]),
                    s(&j["worker"]),
                    s(&j["reason"]),
                ]
            })
            .collect();
        table(
            &["job", "run", "team", "episode", "attempt", "worker", "reason"],
            &rows,
        );
    }
}

fn print_workers(v: &Value) {
    let workers = list(&v["workers"]);
    if workers.is_empty() {
        println!("no worker seen in the last 24 h (workers are known by their leases and reports)");
        return;
    }
    let rows: Vec<Vec<String>> = workers
        .iter()
        .map(|w| {
            let current: Vec<String> = list(&w["current"])
                .iter()
                .map(|e| {
                    let late = if e["expired"] == true {
                        " (lease expired)"
                    } else {
                        ""
                    };
                    format!("run {} {}{late}", e["run"], s(&e["episode"]))
                })
                .collect();
            vec![
                s(&w["worker"]),
                format!("{} ago", duration(&w["last_seen_age_s"])),
                s(&w["last_heartbeat"]),
                s(&w["last_report"]),
                s(&w["episodes_24h"]),
                if current.is_empty() {
                    "idle".into()
                } else {
                    current.join(", ")
                },
            ]
        })
        .collect();
    table(
        &[
            "worker",
            "last seen",
            "last heartbeat",
            "last report",
            "episodes 24h",
            "current",
        ],
        &rows,
    );
}

fn print_runs(v: &Value) {
    let runs = list(&v["runs"]);
    if runs.is_empty() {
        println!("no policy run yet");
        return;
    }
    let rows: Vec<Vec<String>> = runs
        .iter()
        .map(|r| {
            let state = match r["cancelled_by"].as_str() {
                Some(by) => format!("cancelled by {by}"),
                None => s(&r["state"]),
            };
            let eta = match r["eta_s"].as_f64() {
                Some(_) => format!("in {}", duration(&r["eta_s"])),
                None => "-".into(),
            };
            vec![
                s(&r["run"]),
                s(&r["submission"]),
                s(&r["team"]),
                s(&r["split"]),
                s(&r["observations"]),
                state,
                format!(
                    "{}/{} ({:.0}%)",
                    r["episodes_done"],
                    r["episodes_total"],
                    r["progress"].as_f64().unwrap_or(0.0) * 100.0
                ),
                s(&r["episodes_running"]),
                s(&r["episodes_queued"]),
                s(&r["episodes_gave_up"]),
                s(&r["started_at"]),
                duration(&r["mean_episode_s"]),
                eta,
            ]
        })
        .collect();
    table(
        &[
            "run", "sub", "team", "split", "obs", "state", "done", "running", "queued", "gave up", "started",
            "mean ep", "eta",
        ],
        &rows,
    );
}

/// Stream the server's copy into `FILE.partial`, check it, then rename it to `file`.
async fn backup(req: reqwest::RequestBuilder, file: &Path, force: bool) -> anyhow::Result<()> {
    if file.exists() && !force {
        bail!("{} exists: pass --force to replace it", file.display());
    }
    let mut resp = send(req).await?;
    let expected = resp.content_length();
    let mut partial = file.as_os_str().to_owned();
    partial.push(".partial");
    let partial = PathBuf::from(partial);
    let mut out =
        std::fs::File::create(&partial).with_context(|| format!("cannot create {}", partial.display()))?;
    let mut written: u64 = 0;
    let mut head = Vec::new();
    let result: anyhow::Result<()> = async {
        while let Some(chunk) = resp.chunk().await.context("the backup transfer broke off")? {
            if head.len() < 16 {
                head.extend_from_slice(&chunk[..chunk.len().min(16 - head.len())]);
            }
            out.write_all(&chunk)?;
            written += chunk.len() as u64;
        }
        if let Some(n) = expected
            && n != written
        {
            bail!("the backup transfer broke off: {written} of {n} bytes");
        }
        if head != b"SQLite format 3\0" {
            bail!("the server's answer is not a SQLite database");
        }
        out.sync_all()?;
        Ok(())
    }
    .await;
    drop(out);
    if let Err(e) = result {
        let _ = std::fs::remove_file(&partial);
        return Err(e);
    }
    std::fs::rename(&partial, file).with_context(|| format!("cannot write {}", file.display()))?;
    println!(
        "backup written to {} ({written} bytes); restore: stop the server, put it in place of the \
database file (remove any -wal/-shm files beside it), start the server",
        file.display()
    );
    Ok(())
}
