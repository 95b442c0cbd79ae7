//! `kitchen-r submission show ID [--json]` and `kitchen-r submission wait ID [--timeout S]`: a
//! submission's state, its latest run's progress and results, as `GET /api/v1/submissions/{id}`
//! gives them to its team (or the organiser); `kitchen-r submission trace ID KEY` downloads an
//! episode's trace (`crate::submission_trace`).
//!
//! Exit codes (the Python client in `starter-kit/` mirrors them): 0 when the run finished (or,
//! for `show`, whenever the submission could be read); 1 on any error, a refused request, or a
//! run that ended `platform_failed` or `cancelled`; [`TIMEOUT_EXIT`] when `wait --timeout` ran
//! out first; 2 for a usage error (clap's).
//!
//! Waiting tolerates what a busy or restarting server does (connection refused, 5xx, 429 with
//! `Retry-After`): it keeps polling until the timeout; a 4xx other than 429 stops at once.

use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use clap::{Args, Subcommand};
use serde_json::Value;

use crate::server_client::{Auth, ServerArgs, error_message, runtime, url};
use crate::submission_view::{self, Snapshot};

/// `wait` ran past `--timeout` (the code coreutils' `timeout` uses).
pub(crate) const TIMEOUT_EXIT: i32 = 124;

#[derive(Args, Debug)]
pub(crate) struct SubmissionArgs {
    #[command(subcommand)]
    command: SubmissionCommand,
}

#[derive(Subcommand, Debug)]
enum SubmissionCommand {
    /// State, progress (with an ETA while running), scores; on dev one row per episode (policy)
    /// or instruction (plans) with each task's result and failure reason.
    Show {
        /// The submission's id (printed by `submit`).
        id: i64,
        /// Print the server's JSON view instead of the summary.
        #[arg(long)]
        json: bool,
        #[command(flatten)]
        auth: Auth,
    },
    /// Poll until the latest run is finished, failed or cancelled (progress on stderr), then
    /// print it as `show` does. Exit 0 only when it finished.
    Wait {
        /// The submission's id.
        id: i64,
        /// Give up after this many seconds (exit code 124); default: wait as long as it takes.
        #[arg(long, value_name = "SECONDS", value_parser = seconds)]
        timeout: Option<f64>,
        /// Print the final JSON view instead of the summary.
        #[arg(long)]
        json: bool,
        #[command(flatten)]
        auth: Auth,
    },
    /// Download one episode's trace (gzipped JSON: the episode's configuration and every answer
    /// of the policy), which `kitchen-r replay FILE` reproduces bit for bit into a video. Dev
    /// episodes of the team's own submissions (the organiser: every episode).
    Trace {
        /// The submission's id.
        id: i64,
        /// The episode's key, e.g. `dev-0001` (`submission show --json` lists them).
        episode_key: String,
        /// Where to write it [default: `<EPISODE_KEY>.trace.json.gz`].
        #[arg(short, long, value_name = "FILE")]
        output: Option<std::path::PathBuf>,
        #[command(flatten)]
        auth: Auth,
    },
}

pub(crate) fn submission(args: SubmissionArgs) -> anyhow::Result<()> {
    match args.command {
        SubmissionCommand::Show { id, json, auth } => runtime()?.block_on(async {
            let snap = fetch(&reqwest::Client::new(), &auth, id)
                .await
                .map_err(|e| e.error)?;
            match json {
                true => println!("{}", snap.view),
                false => submission_view::print(&snap, &auth.server),
            }
            Ok(())
        }),
        SubmissionCommand::Wait {
            id,
            timeout,
            json,
            auth,
        } => {
            let timeout = timeout.map(Duration::from_secs_f64);
            let snap = runtime()?.block_on(wait(&reqwest::Client::new(), &auth, id, timeout))?;
            finish(&snap, &auth.server, json)
        }
        SubmissionCommand::Trace {
            id,
            episode_key,
            output,
            auth,
        } => crate::submission_trace::download(id, &episode_key, output, &auth),
    }
}

/// A `--timeout`: a finite number of seconds, at least 0.
pub(crate) fn seconds(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if (0.0..1e9).contains(&v) => Ok(v),
        _ => Err(format!("{s:?} is not a number of seconds (0 or more)")),
    }
}

/// Print the final view and turn a run that did not finish into an error (exit 1).
pub(crate) fn finish(snap: &Snapshot, server: &ServerArgs, json: bool) -> anyhow::Result<()> {
    match json {
        true => println!("{}", snap.view),
        false => submission_view::print(snap, server),
    }
    match submission_view::state(&snap.view) {
        "finished" => Ok(()),
        state => bail!(
            "submission {}: its run ended {state}{}",
            snap.view["id"],
            submission_view::why_not_finished(&snap.view)
        ),
    }
}

/// A failed poll: whether polling again may help (unreachable, 5xx, 429) and when.
pub(crate) struct FetchError {
    pub error: anyhow::Error,
    pub transient: bool,
    pub retry_after: Option<Duration>,
}

pub(crate) async fn fetch(client: &reqwest::Client, auth: &Auth, id: i64) -> Result<Snapshot, FetchError> {
    let req = client
        .get(url(&auth.server, &format!("/api/v1/submissions/{id}")))
        .bearer_auth(&auth.token)
        .timeout(Duration::from_secs(30));
    let resp = match req.send().await {
        Ok(r) => r,
        Err(e) => {
            return Err(FetchError {
                error: anyhow::Error::new(e).context("cannot reach the server"),
                transient: true,
                retry_after: None,
            });
        }
    };
    let status = resp.status();
    let server_now_ms = resp
        .headers()
        .get(reqwest::header::DATE)
        .and_then(|d| d.to_str().ok())
        .and_then(crate::clock_parse::parse_http_date_ms);
    let retry_after = resp
        .headers()
        .get(reqwest::header::RETRY_AFTER)
        .and_then(|d| d.to_str().ok()?.trim().parse::<f64>().ok())
        .map(|s| Duration::from_secs_f64(s.clamp(0.0, 300.0)));
    let text = resp.text().await.unwrap_or_default();
    if !status.is_success() {
        return Err(FetchError {
            error: anyhow::anyhow!(error_message(status.as_u16(), &text)),
            transient: status.is_server_error() || status.as_u16() == 429,
            retry_after,
        });
    }
    let view: Value = serde_json::from_str(&text)
        .context("the server's answer is not JSON")
        .map_err(|error| FetchError {
            error,
            transient: false,
            retry_after: None,
        })?;
    Ok(Snapshot { view, server_now_ms })
}

/// Poll submission `id` until its latest run has ended; progress lines go to stderr whenever
/// they change. The interval starts at 1 s, grows by half up to 15 s while nothing changes and
/// starts over when something does.
pub(crate) async fn wait(
    client: &reqwest::Client,
    auth: &Auth,
    id: i64,
    timeout: Option<Duration>,
) -> anyhow::Result<Snapshot> {
    const FIRST: Duration = Duration::from_secs(1);
    const MAX: Duration = Duration::from_secs(15);
    let start = Instant::now();
    let mut interval = FIRST;
    let mut last = String::new();
    loop {
        let mut pause = None;
        match fetch(client, auth, id).await {
            Ok(snap) => {
                if submission_view::ended(&snap.view) {
                    return Ok(snap);
                }
                let line = submission_view::progress_line(&snap);
                if line != last {
                    eprintln!("submission {id}: {line}");
                    last = line;
                    interval = FIRST;
                }
            }
            Err(e) if e.transient => {
                eprintln!("submission {id}: {:#} (retrying)", e.error);
                pause = e.retry_after;
            }
            Err(e) => return Err(e.error),
        }
        let mut sleep = pause.unwrap_or(interval).max(Duration::from_millis(200));
        if let Some(limit) = timeout {
            let left = limit.saturating_sub(start.elapsed());
            if left.is_zero() {
                eprintln!(
                    "Error: submission {id}: not finished after {:.0} s (last: {})",
                    limit.as_secs_f64(),
                    if last.is_empty() { "no answer" } else { &last }
                );
                std::process::exit(TIMEOUT_EXIT);
            }
            sleep = sleep.min(left);
        }
        tokio::time::sleep(sleep).await;
        interval = (interval.mul_f64(1.5)).min(MAX);
    }
}
