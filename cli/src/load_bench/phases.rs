//! The three phases of a run: seeding the database, the measured load, and the check that
//! everything the server acknowledged is there.
//!
//! The measured load has two sides. Readers are a closed loop: each of R tasks sends its next
//! request when the previous one is answered, as `wrk` does. Uploads are an open loop: upload k
//! is due at `start + k / U` whatever happened to the earlier ones, and its latency is counted
//! from that due time, not from when it could be sent, so a server that stalls is charged for
//! the whole wait (no coordinated omission). A bound on uploads in flight keeps a stalled server
//! from drowning in requests; uploads it held back past the end are counted as failed.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::{Duration, Instant};

use serde::Serialize;
use tokio::sync::Semaphore;
use tokio::task::JoinSet;
use tokio::time::sleep_until;

use super::client::{Ack, Api, Failure, PlanFiles, Team, bounded};
use super::stats::{Recorder, Side};

/// How often a seed upload refused with 429/503 is retried (seeding is not measured, so a
/// server that sheds load while it is being filled is waited for, as its `Retry-After` asks).
const SEED_ATTEMPTS: u32 = 6;

/// What seeding produced.
#[derive(Debug)]
pub(super) struct Seeded {
    pub acks: Vec<Ack>,
    pub summary: SeedSummary,
}

#[derive(Debug, Clone, Serialize)]
pub(super) struct SeedSummary {
    pub ok: u64,
    pub failed: u64,
    pub failures: BTreeMap<String, u64>,
    /// Refusals (429/503) that were retried and later succeeded or ran out of attempts.
    pub retries: u64,
    pub seconds: f64,
    pub per_s: f64,
}

/// Upload `n` plan files round-robin over the teams, `concurrency` at a time.
pub(super) async fn seed(
    api: &Api,
    teams: &Arc<Vec<Team>>,
    files: &Arc<PlanFiles>,
    seed: u64,
    n: usize,
    concurrency: usize,
) -> anyhow::Result<Seeded> {
    let start = Instant::now();
    let step = (n / 10).max(1);
    let results = bounded(
        n,
        concurrency,
        |k| {
            let (api, teams, files) = (api.clone(), teams.clone(), files.clone());
            async move {
                let team = k % teams.len();
                let mut retries = 0;
                loop {
                    let body = files.file(seed, k as u64);
                    match api.upload(&teams[team].token, body).await {
                        Ok((id, em)) => return (Ok(Ack { team, id, em }), retries),
                        Err(f) if retryable(&f) && retries + 1 < SEED_ATTEMPTS => {
                            retries += 1;
                            let wait = f.retry_after_s.unwrap_or(1).clamp(1, 5);
                            tokio::time::sleep(Duration::from_secs(wait)).await;
                        }
                        Err(f) => return (Err(f), retries),
                    }
                }
            }
        },
        |done| {
            if done % step == 0 || done == n {
                let s = start.elapsed().as_secs_f64();
                eprintln!(
                    "seeding: {done}/{n} plan files ({:.0}/s)",
                    done as f64 / s.max(1e-9)
                );
            }
        },
    )
    .await?;
    let seconds = start.elapsed().as_secs_f64();
    let (mut acks, mut failures, mut retries) = (Vec::new(), BTreeMap::new(), 0);
    for (r, tries) in results {
        retries += u64::from(tries);
        match r {
            Ok(a) => acks.push(a),
            Err(f) => *failures.entry(f.what).or_default() += 1,
        }
    }
    let failed = failures.values().sum();
    let ok = acks.len() as u64;
    Ok(Seeded {
        acks,
        summary: SeedSummary {
            ok,
            failed,
            failures,
            retries,
            seconds,
            per_s: ok as f64 / seconds.max(1e-9),
        },
    })
}

fn retryable(f: &Failure) -> bool {
    f.what == "429" || f.what == "503"
}

/// Parameters of the measured phase.
#[derive(Debug, Clone)]
pub(super) struct Load {
    pub readers: usize,
    pub read_path: String,
    pub uploads_per_s: f64,
    pub duration: Duration,
    pub max_in_flight: usize,
    /// Seed of the plan files and the index of the first measured upload (after the seeded).
    pub seed: u64,
    pub first_upload: u64,
}

/// What the measured phase produced.
#[derive(Debug)]
pub(super) struct Measured {
    pub reads: Side,
    /// Mean size of a successful read's body.
    pub read_body_bytes: u64,
    pub uploads: Side,
    pub uploads_due: u64,
    pub acks: Vec<Ack>,
}

pub(super) async fn measure(
    api: &Api,
    teams: &Arc<Vec<Team>>,
    files: &Arc<PlanFiles>,
    load: &Load,
) -> anyhow::Result<Measured> {
    let start = tokio::time::Instant::now();
    let end = start + load.duration;
    let mut readers = JoinSet::new();
    for _ in 0..load.readers {
        let (api, path) = (api.clone(), load.read_path.clone());
        readers.spawn(async move {
            let (mut rec, mut bytes) = (Recorder::default(), 0);
            while tokio::time::Instant::now() < end {
                let t = Instant::now();
                match api.read(&path).await {
                    Ok(n) => {
                        rec.ok(t.elapsed());
                        bytes += n as u64;
                    }
                    Err(f) => rec.fail(f.what),
                }
            }
            (rec, bytes)
        });
    }
    let (uploads, uploads_due, acks) = upload_open_loop(api, teams, files, load, start).await?;
    let (mut reads, mut bytes) = (Recorder::default(), 0);
    while let Some(r) = readers.join_next().await {
        let (rec, n) = r?;
        reads.merge(rec);
        bytes += n;
    }
    let reads = reads.summary(load.duration);
    Ok(Measured {
        read_body_bytes: bytes / reads.ok.max(1),
        reads,
        uploads: uploads.summary(load.duration),
        uploads_due,
        acks,
    })
}

/// An upload's team, outcome and latency from its due time.
type Sent = (usize, Result<(i64, f64), Failure>, Duration);

/// Uploads due at `start + k / U` for every k before the end, latency counted from the due time.
async fn upload_open_loop(
    api: &Api,
    teams: &Arc<Vec<Team>>,
    files: &Arc<PlanFiles>,
    load: &Load,
    start: tokio::time::Instant,
) -> anyhow::Result<(Recorder, u64, Vec<Ack>)> {
    let mut rec = Recorder::default();
    let mut acks = Vec::new();
    if load.uploads_per_s <= 0.0 {
        tokio::time::sleep(load.duration).await;
        return Ok((rec, 0, acks));
    }
    let interval = Duration::from_secs_f64(1.0 / load.uploads_per_s);
    let due_count = (load.duration.as_secs_f64() * load.uploads_per_s).ceil() as u64;
    let end = start + load.duration;
    let slots = Arc::new(Semaphore::new(load.max_in_flight.max(1)));
    let mut set = JoinSet::new();
    let mut sent = 0u64;
    let collect = |r: Sent, rec: &mut Recorder, acks: &mut Vec<Ack>| {
        let (team, outcome, latency) = r;
        match outcome {
            Ok((id, em)) => {
                rec.ok(latency);
                acks.push(Ack { team, id, em });
            }
            Err(f) => rec.fail(f.what),
        }
    };
    while sent < due_count {
        let due = start + interval.mul_f64(sent as f64);
        sleep_until(due).await;
        let slot = tokio::select! {
            s = slots.clone().acquire_owned() => s?,
            () = sleep_until(end) => break,
        };
        let k = load.first_upload + sent;
        let team = (k as usize) % teams.len();
        let (api, token, body) = (api.clone(), teams[team].token.clone(), files.file(load.seed, k));
        let due_std = due.into_std();
        set.spawn(async move {
            let outcome = api.upload(&token, body).await;
            drop(slot);
            (team, outcome, due_std.elapsed())
        });
        sent += 1;
        while let Some(r) = set.try_join_next() {
            collect(r?, &mut rec, &mut acks);
        }
    }
    while let Some(r) = set.join_next().await {
        collect(r?, &mut rec, &mut acks);
    }
    rec.fail_n("not sent (in-flight bound)", due_count - sent);
    Ok((rec, due_count, acks))
}

/// The check after the run.
#[derive(Debug, Clone, Default, Serialize)]
pub(super) struct Verified {
    /// Acknowledged uploads looked up (`GET /api/v1/submissions/{id}` with the team's token).
    pub checked: u64,
    /// Present with the EM the upload was answered with.
    pub verified: u64,
    pub missing: u64,
    pub wrong_em: u64,
    pub errors: BTreeMap<String, u64>,
    /// Teams whose dev planning leaderboard row shows the best EM they were acknowledged.
    pub leaderboard_teams: u64,
    /// Teams whose row is missing or shows another EM (or rows of teams with no upload).
    pub leaderboard_mismatches: u64,
}

/// Look every acknowledged upload up, then compare the leaderboard's best per team.
pub(super) async fn verify(
    api: &Api,
    teams: &Arc<Vec<Team>>,
    check: &[Ack],
    all: &[Ack],
    concurrency: usize,
) -> anyhow::Result<Verified> {
    let check = Arc::new(check.to_vec());
    let results = bounded(
        check.len(),
        concurrency,
        |k| {
            let (api, teams, check) = (api.clone(), teams.clone(), check.clone());
            async move {
                let a = check[k];
                let path = format!("/api/v1/submissions/{}", a.id);
                let v = api.get_json(&path, Some(&teams[a.team].token)).await?;
                Ok::<bool, Failure>(v["latest_run"]["scores"]["em"].as_f64() == Some(a.em))
            }
        },
        |_| {},
    )
    .await?;
    let mut out = Verified {
        checked: results.len() as u64,
        ..Verified::default()
    };
    for r in results {
        match r {
            Ok(true) => out.verified += 1,
            Ok(false) => out.wrong_em += 1,
            Err(f) if f.what == "404" => out.missing += 1,
            Err(f) => *out.errors.entry(f.what).or_default() += 1,
        }
    }
    leaderboard_check(api, teams, all, &mut out).await;
    Ok(out)
}

async fn leaderboard_check(api: &Api, teams: &[Team], all: &[Ack], out: &mut Verified) {
    let mut best: BTreeMap<&str, f64> = BTreeMap::new();
    for a in all {
        let e = best
            .entry(teams[a.team].name.as_str())
            .or_insert(f64::NEG_INFINITY);
        *e = e.max(a.em);
    }
    let board = match api
        .get_json("/api/v1/leaderboard?track=planning&split=dev", None)
        .await
    {
        Ok(v) => v,
        Err(f) => {
            *out.errors.entry(format!("leaderboard {}", f.what)).or_default() += 1;
            return;
        }
    };
    let ours: BTreeMap<&str, Option<f64>> = teams.iter().map(|t| (t.name.as_str(), None)).collect();
    let mut shown = ours.clone();
    for row in board["rows"].as_array().into_iter().flatten() {
        if let Some(slot) = row["team"].as_str().and_then(|t| shown.get_mut(t)) {
            *slot = slot.or(row["scores"]["em"].as_f64());
        }
    }
    for (team, shown) in shown {
        match (best.get(team), shown) {
            (Some(&b), Some(s)) if b == s => out.leaderboard_teams += 1,
            (None, None) => {}
            _ => out.leaderboard_mismatches += 1,
        }
    }
}
