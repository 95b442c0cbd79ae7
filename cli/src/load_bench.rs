//! `kitchen-r bench load`: the deadline-hour load benchmark of the server
//! (docs/measured/load-benchmark.md).
//!
//! It starts this binary's own `serve` on loopback with a fresh database (or targets `--server`),
//! creates T teams, seeds N plan submissions over HTTP, then for a fixed time runs R leaderboard
//! readers (closed loop) beside an open-loop uploader at U plan files per second, and prints
//! p50/p90/p99/max and throughput of both sides. Afterwards every acknowledged upload is looked
//! up, the leaderboard's best per team is compared with the EMs the uploads were answered with,
//! and the server is stopped to measure its database per submission.
//!
//! Policy: the spawned server runs with every per-team limit lifted (daily quotas, concurrent
//! runs), so what is measured is the server's speed, not its refusals; every request has a
//! timeout, the whole run a deadline, and the server dies with the benchmark on any exit path.
//! Plan files are the first `--plan-lines` instructions of the server's own dev split with their
//! true plans, some with a step dropped (a random share per file), so EMs and the ranking vary.

mod client;
mod phases;
mod report;
mod server;
mod stats;

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use anyhow::{Context, bail};
use clap::Args;

use client::{Ack, Api, PlanFiles, Rng, Team, bounded};
use phases::{Load, Measured, SeedSummary, Verified};
use report::{DbReport, Params, Report};
use server::{DbSize, Spawned};

/// The defaults are the target: 20,000 submissions from 100 teams, 32 leaderboard
/// readers and 20 uploads/s for 60 s.
#[derive(Args, Debug, Clone)]
pub(crate) struct LoadArgs {
    /// Plan submissions seeded before the measurement, round-robin over the teams.
    #[arg(long, default_value_t = 20_000)]
    pub submissions: usize,
    /// Teams created (each uploads with its own token).
    #[arg(long, default_value_t = 100)]
    pub teams: usize,
    /// Leaderboard readers, each a closed loop on one connection (0 = none).
    #[arg(long, default_value_t = 32)]
    pub readers: usize,
    /// Plan uploads per second during the measurement, open loop (0 = none).
    #[arg(long, default_value_t = 20.0)]
    pub uploads_per_s: f64,
    /// Length of the measurement, seconds.
    #[arg(long, default_value_t = 60.0)]
    pub seconds: f64,
    /// Lines per plan file: the first N dev instructions (the dev split has 163).
    #[arg(long, default_value_t = 163)]
    pub plan_lines: usize,
    /// Uploads in flight while seeding (and lookups while verifying).
    #[arg(long, default_value_t = 8)]
    pub seed_concurrency: usize,
    /// What the readers GET.
    #[arg(long, default_value = "/api/v1/leaderboard?track=planning&split=dev")]
    pub read_path: String,
    /// Most measured uploads in flight; uploads due while it is reached wait (and their latency
    /// runs from their due time).
    #[arg(long, default_value_t = 256)]
    pub max_in_flight_uploads: usize,
    /// Timeout of every request, seconds.
    #[arg(long, default_value_t = 30.0)]
    pub request_timeout_s: f64,
    /// Deadline of the whole run (seeding, measurement, verification), seconds.
    #[arg(long, default_value_t = 1800.0)]
    pub deadline_s: f64,
    /// Also look up every seeded upload afterwards (by default only the measured ones).
    #[arg(long)]
    pub verify_seeded: bool,
    /// Seed of the plan files' variations.
    #[arg(long, default_value_t = 7)]
    pub rng_seed: u64,
    /// Load an already running server instead of starting one (its quotas must allow the
    /// uploads; the database size is then not measured).
    #[arg(long, value_name = "URL")]
    pub server: Option<String>,
    /// Organiser token of `--server` (a spawned server gets a generated one).
    #[arg(long, env = "KITCHEN_R_ADMIN_TOKEN", hide_env_values = true)]
    pub admin_token: Option<String>,
    /// Keep the spawned server's database at PATH (which must not exist) instead of a
    /// temporary directory.
    #[arg(long, value_name = "PATH", conflicts_with = "server")]
    pub keep_db: Option<PathBuf>,
    /// Print one JSON object instead of a table (progress still goes to stderr).
    #[arg(long)]
    pub json: bool,
}

impl LoadArgs {
    fn check(&self) -> anyhow::Result<()> {
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if !positive(self.seconds) || !positive(self.request_timeout_s) || !positive(self.deadline_s) {
            bail!("--seconds, --request-timeout-s and --deadline-s must be positive");
        }
        if !(self.uploads_per_s.is_finite() && (0.0..=100_000.0).contains(&self.uploads_per_s)) {
            bail!("--uploads-per-s must be between 0 and 100000");
        }
        if self.teams == 0 || self.plan_lines == 0 {
            bail!("--teams and --plan-lines must be at least 1");
        }
        if !self.read_path.starts_with('/') {
            bail!("--read-path must start with '/'");
        }
        Ok(())
    }

    fn params(&self) -> Params {
        Params {
            submissions: self.submissions,
            teams: self.teams,
            readers: self.readers,
            uploads_per_s: self.uploads_per_s,
            seconds: self.seconds,
            read_path: self.read_path.clone(),
            seed_concurrency: self.seed_concurrency,
            max_in_flight_uploads: self.max_in_flight_uploads,
            verify_seeded: self.verify_seeded,
        }
    }
}

pub(crate) fn run(args: LoadArgs) -> anyhow::Result<()> {
    args.check()?;
    let dir = tempfile::Builder::new()
        .prefix("kitchen-r-load-")
        .tempdir()
        .context("creating a temporary directory")?;
    let (mut spawned, base, admin) = match &args.server {
        Some(url) => {
            let admin = args
                .admin_token
                .clone()
                .context("--server needs the organiser token (--admin-token or KITCHEN_R_ADMIN_TOKEN)")?;
            (None, url.clone(), admin)
        }
        None => {
            let s = spawn(&args, dir.path())?;
            let base = s.0.http.clone();
            (Some(s.0), base, s.1)
        }
    };
    let rt = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    let deadline = Duration::from_secs_f64(args.deadline_s);
    let outcome = rt.block_on(async { tokio::time::timeout(deadline, drive(&args, &base, &admin)).await });
    let done = match outcome {
        Ok(Ok(done)) => done,
        Ok(Err(e)) => return Err(with_log(e, spawned.as_ref())),
        Err(_) => bail!(
            "the benchmark ran past its deadline of {} s (--deadline-s)",
            args.deadline_s
        ),
    };
    let db = spawned.as_mut().map(|s| {
        let graceful = s.stop();
        let at_stop = DbSize::of(&s.db);
        let checkpoint = match rt.block_on(server::checkpoint(&s.db)) {
            Ok(stored) => Some((DbSize::of(&s.db), stored)),
            Err(e) => {
                eprintln!("warning: {e:#}");
                None
            }
        };
        DbReport::new(at_stop, checkpoint, done.plan_submissions, graceful)
    });
    rt.shutdown_timeout(Duration::from_secs(5));
    let report = Report {
        params: args.params(),
        server: if spawned.is_some() { "spawned".into() } else { base },
        plan_lines: done.files.lines(),
        plan_file_bytes: done.files.file(args.rng_seed, 0).len(),
        failed_requests: done.measured.reads.failed + done.measured.uploads.failed,
        all_verified: done.verified.verified == done.verified.checked,
        seed: done.seed,
        reads: done.measured.reads,
        read_body_bytes: done.measured.read_body_bytes,
        uploads: done.measured.uploads,
        uploads_due: done.measured.uploads_due,
        verify: done.verified,
        db,
    };
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        report::print(&report);
    }
    Ok(())
}

/// Start the server under load with the benchmark's configuration; returns it and its
/// organiser token.
fn spawn(args: &LoadArgs, dir: &std::path::Path) -> anyhow::Result<(Spawned, String)> {
    let db = match &args.keep_db {
        Some(p) if p.exists() => bail!(
            "--keep-db {}: already exists (the benchmark starts from an empty database)",
            p.display()
        ),
        Some(p) => std::path::absolute(p).context("--keep-db")?,
        None => dir.join("bench.db"),
    };
    let config = dir.join("bench.toml");
    std::fs::write(&config, server::config_toml(&server::bench_config())?)
        .context("writing the server configuration")?;
    let admin = format!("bench-admin-{:016x}", run_id());
    Ok((Spawned::start(&config, &db, dir, &admin)?, admin))
}

fn with_log(e: anyhow::Error, spawned: Option<&Spawned>) -> anyhow::Error {
    match spawned {
        Some(s) => anyhow::anyhow!("{e:#}\nthe server's log ends with:\n{}", s.log_tail()),
        None => e,
    }
}

/// What the phases produced.
struct Done {
    files: Arc<PlanFiles>,
    seed: SeedSummary,
    measured: Measured,
    verified: Verified,
    plan_submissions: u64,
}

async fn drive(args: &LoadArgs, base: &str, admin: &str) -> anyhow::Result<Done> {
    let api = Api::new(base, Duration::from_secs_f64(args.request_timeout_s))?;
    let dev = api.dev_split().await?;
    if dev.is_empty() {
        bail!("the server's dev split is empty");
    }
    let files = Arc::new(PlanFiles::new(&dev, args.plan_lines));
    let teams = Arc::new(create_teams(&api, admin, args.teams, args.seed_concurrency).await?);
    eprintln!("teams: {} created", teams.len());
    let seeded = phases::seed(
        &api,
        &teams,
        &files,
        args.rng_seed,
        args.submissions,
        args.seed_concurrency,
    )
    .await?;
    eprintln!(
        "measuring: {} readers, {} uploads/s for {} s",
        args.readers, args.uploads_per_s, args.seconds
    );
    let load = Load {
        readers: args.readers,
        read_path: args.read_path.clone(),
        uploads_per_s: args.uploads_per_s,
        duration: Duration::from_secs_f64(args.seconds),
        max_in_flight: args.max_in_flight_uploads,
        seed: args.rng_seed,
        first_upload: args.submissions as u64,
    };
    let measured = phases::measure(&api, &teams, &files, &load).await?;
    let all: Vec<Ack> = seeded.acks.iter().chain(&measured.acks).copied().collect();
    let check = if args.verify_seeded {
        &all[..]
    } else {
        &measured.acks[..]
    };
    eprintln!("verifying: {} acknowledged uploads", check.len());
    let verified = phases::verify(&api, &teams, check, &all, args.seed_concurrency).await?;
    Ok(Done {
        files,
        seed: seeded.summary,
        measured,
        verified,
        plan_submissions: all.len() as u64,
    })
}

/// Teams `bench-<run>-000`, … (a fresh prefix per run, so `--server` can be loaded twice).
async fn create_teams(api: &Api, admin: &str, n: usize, concurrency: usize) -> anyhow::Result<Vec<Team>> {
    let prefix = format!("bench-{:06x}", run_id() & 0xff_ffff);
    let made = bounded(
        n,
        concurrency,
        |i| {
            let (api, admin, name) = (api.clone(), admin.to_string(), format!("{prefix}-{i:03}"));
            async move { api.create_team(&admin, &name).await }
        },
        |_| {},
    )
    .await?;
    let mut teams = made.into_iter().collect::<anyhow::Result<Vec<Team>>>()?;
    teams.sort_by(|a, b| a.name.cmp(&b.name));
    Ok(teams)
}

/// A number that differs between runs (clock and process id), for names and tokens.
fn run_id() -> u64 {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64);
    Rng(nanos ^ (u64::from(std::process::id()) << 32)).next_u64()
}
