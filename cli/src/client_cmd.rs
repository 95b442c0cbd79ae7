//! Client commands (`team create|rotate-token`, `submit plans`, `submit policy`, `leaderboard`, `rescore`;
//! `submission show|wait` in `submission_cmd`): thin HTTP calls to a running server's `/api/v1`.
//! Output is for people (tables, one-line summaries) unless a machine format is asked for; a refused request exits non-zero with the server's own message.

use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::{Args, Subcommand, ValueEnum};
use serde_json::Value;

use crate::server_client::{ServerArgs, json, runtime, send, url};

#[derive(Args, Debug)]
pub(crate) struct TeamArgs {
    #[command(subcommand)]
    command: TeamCommand,
}

#[derive(Subcommand, Debug)]
enum TeamCommand {
    /// Make a team and print its token (shown once).
    Create {
        /// Team name: 1 to 64 letters, digits, spaces, '-', '_' or '.'.
        name: String,
        #[command(flatten)]
        server: ServerArgs,
        /// Organiser token.
        #[arg(long, env = "KITCHEN_R_ADMIN_TOKEN", hide_env_values = true)]
        admin_token: String,
    },
    /// Give a team a new token and print it (shown once). The old token stops working at once
    /// and every page session opened with it ends. Organiser token (`--admin-token`), or the
    /// team's own token (`--token`) to rotate one's own.
    RotateToken {
        /// The team's id (`team create` printed it; `submission show` names it too).
        id: i64,
        #[command(flatten)]
        server: ServerArgs,
        /// Organiser token.
        #[arg(
            long,
            env = "KITCHEN_R_ADMIN_TOKEN",
            hide_env_values = true,
            conflicts_with = "token"
        )]
        admin_token: Option<String>,
        /// The team's current token (to rotate one's own).
        #[arg(long, env = "KITCHEN_R_TOKEN", hide_env_values = true)]
        token: Option<String>,
    },
}

#[derive(Args, Debug)]
pub(crate) struct SubmitArgs {
    #[command(subcommand)]
    command: SubmitCommand,
}

#[derive(Subcommand, Debug)]
enum SubmitCommand {
    /// Upload a plan file (JSON Lines: {"id": "...", "plan": ["...", ...]} per line).
    Plans {
        /// The plan file.
        file: PathBuf,
        /// Which split the plans are for.
        #[arg(long, value_parser = ["dev", "test"])]
        split: String,
        /// Organiser: file it as the planning board's baseline row (no quota); needs the
        /// organiser token as --token.
        #[arg(long)]
        reference: bool,
        #[command(flatten)]
        server: ServerArgs,
        /// Team token (the organiser token with --reference).
        #[arg(long, env = "KITCHEN_R_TOKEN", hide_env_values = true)]
        token: String,
        /// Print the server's JSON answer instead of a summary.
        #[arg(long)]
        json: bool,
    },
    /// Register a gRPC policy endpoint for evaluation (control track; integrated with --plans).
    /// The server probes health and GetSpec first and refuses with the reason if either fails.
    Policy(crate::policy_submit::PolicySubmitArgs),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum OutputFormat {
    Table,
    Json,
    Csv,
}

#[derive(Args, Debug)]
pub(crate) struct LeaderboardArgs {
    /// Track to rank.
    #[arg(long, default_value = "planning", value_parser = ["planning", "control", "integrated"])]
    track: String,
    /// Split to rank.
    #[arg(long, default_value = "test", value_parser = ["dev", "test"])]
    split: String,
    /// Control and integrated: the board of runs with standard observations, or of runs whose
    /// policy received privileged observations (ranked apart).
    #[arg(long, default_value = "standard", value_parser = ["standard", "privileged"])]
    observations: String,
    /// Control and integrated: the board of runs evaluated in this grasp mode (ranked apart)
    /// [default: the contest's, the server's `[control] grasp`].
    #[arg(long, value_parser = ["abstract", "physical"])]
    grasp_mode: Option<String>,
    /// Output format.
    #[arg(long, value_enum, default_value_t = OutputFormat::Table)]
    format: OutputFormat,
    #[command(flatten)]
    server: ServerArgs,
}

#[derive(Args, Debug)]
pub(crate) struct RescoreArgs {
    /// Rescore every submission of every track (required unless --resimulate: rescoring is never
    /// implicit).
    #[arg(long, required_unless_present = "resimulate", conflicts_with = "resimulate")]
    all: bool,
    /// Simulate this finished policy submission again against the current ground truth, as a
    /// new run (for runs `rescore --all` reported as needing re-simulation). Needs the endpoint.
    #[arg(long, value_name = "SUBMISSION_ID")]
    resimulate: Option<i64>,
    #[command(flatten)]
    server: ServerArgs,
    /// Organiser token.
    #[arg(long, env = "KITCHEN_R_ADMIN_TOKEN", hide_env_values = true)]
    admin_token: String,
}

pub(crate) fn team(args: TeamArgs) -> anyhow::Result<()> {
    match args.command {
        TeamCommand::Create {
            name,
            server,
            admin_token,
        } => runtime()?.block_on(async {
            let req = reqwest::Client::new()
                .post(url(&server, "/api/v1/teams"))
                .bearer_auth(admin_token)
                .json(&serde_json::json!({ "name": name }));
            let v = json(req).await?;
            println!(
                "team {} created (id {})",
                v["name"].as_str().unwrap_or("?"),
                v["id"]
            );
            print_token(&v);
            Ok(())
        }),
        TeamCommand::RotateToken {
            id,
            server,
            admin_token,
            token,
        } => {
            let Some(bearer) = admin_token.or(token) else {
                bail!(
                    "give the organiser token (--admin-token or KITCHEN_R_ADMIN_TOKEN) or the team's own (--token or KITCHEN_R_TOKEN)"
                );
            };
            runtime()?.block_on(async {
                let req = reqwest::Client::new()
                    .post(url(&server, &format!("/api/v1/teams/{id}/token")))
                    .bearer_auth(bearer);
                let v = json(req).await?;
                println!(
                    "team {} (id {}) has a new token; the old one no longer works and its page sessions ended",
                    v["name"].as_str().unwrap_or("?"),
                    v["id"]
                );
                print_token(&v);
                Ok(())
            })
        }
    }
}

fn print_token(v: &Value) {
    println!("token: {}", v["token"].as_str().unwrap_or("?"));
    println!("keep it: it is shown only once; participants pass it as --token or KITCHEN_R_TOKEN");
}

pub(crate) fn submit(args: SubmitArgs) -> anyhow::Result<()> {
    let (file, split, reference, server, token, raw) = match args.command {
        SubmitCommand::Plans {
            file,
            split,
            reference,
            server,
            token,
            json,
        } => (file, split, reference, server, token, json),
        SubmitCommand::Policy(a) => return crate::policy_submit::submit_policy(a),
    };
    let body = std::fs::read(&file).with_context(|| format!("cannot read {}", file.display()))?;
    runtime()?.block_on(async {
        let req = reqwest::Client::new()
            .post(url(
                &server,
                &format!("/api/v1/submissions/plans?split={split}&reference={reference}"),
            ))
            .bearer_auth(token)
            .header(reqwest::header::CONTENT_TYPE, "application/x-ndjson")
            .body(body);
        let v = json(req).await?;
        if raw {
            println!("{v}");
            return Ok(());
        }
        let em = v["scores"]["em"].as_f64().unwrap_or(f64::NAN);
        println!("submission {} ({split}): EM = {em:.6}", v["id"]);
        for w in v["warnings"].as_array().into_iter().flatten() {
            println!("warning: {}", w.as_str().unwrap_or_default());
        }
        Ok(())
    })
}

pub(crate) fn leaderboard(args: LeaderboardArgs) -> anyhow::Result<()> {
    let format = if args.format == OutputFormat::Csv {
        "csv"
    } else {
        "json"
    };
    let observations = match args.observations.as_str() {
        "standard" => String::new(),
        o => format!("&observations={o}"),
    };
    let grasp = (args.grasp_mode.as_deref()).map_or(String::new(), |g| format!("&grasp_mode={g}"));
    let path = format!(
        "/api/v1/leaderboard?track={}&split={}{observations}{grasp}&format={format}",
        args.track, args.split
    );
    runtime()?.block_on(async {
        let resp = send(reqwest::Client::new().get(url(&args.server, &path))).await?;
        let text = resp.text().await?;
        match args.format {
            OutputFormat::Csv | OutputFormat::Json => print!("{text}"),
            OutputFormat::Table => crate::leaderboard_table::print_table(&serde_json::from_str(&text)?),
        }
        if args.format == OutputFormat::Json {
            println!();
        }
        Ok(())
    })
}

pub(crate) fn rescore(args: RescoreArgs) -> anyhow::Result<()> {
    if let Some(id) = args.resimulate {
        return runtime()?.block_on(async {
            let req = reqwest::Client::new()
                .post(url(&args.server, "/api/v1/admin/resimulate"))
                .bearer_auth(&args.admin_token)
                .json(&serde_json::json!({ "submission": id }));
            let v = json(req).await?;
            println!(
                "submission {id}: run {} queued, {} episodes of {} instructions",
                v["run_id"], v["episodes"], v["instructions"]
            );
            Ok(())
        });
    }
    runtime()?.block_on(async {
        let req = reqwest::Client::new()
            .post(url(&args.server, "/api/v1/admin/rescore"))
            .bearer_auth(&args.admin_token);
        let v = json(req).await?;
        println!(
            "rescored {} plan submissions and {} policy runs",
            v["rescored"], v["policy_runs_rescored"]
        );
        let list = |key: &str| v[key].as_array().cloned().unwrap_or_default();
        for f in list("needs_resimulation") {
            println!(
                "needs re-simulation: submission {}: {} (scores kept; simulating again needs the endpoint)",
                f["id"],
                f["error"].as_str().unwrap_or("?")
            );
        }
        for f in list("skipped") {
            println!(
                "skipped: submission {}: {}",
                f["id"],
                f["error"].as_str().unwrap_or("?")
            );
        }
        let failed = list("failed");
        for f in &failed {
            println!(
                "failed: submission {}: {}",
                f["id"],
                f["error"].as_str().unwrap_or("?")
            );
        }
        if !failed.is_empty() {
            bail!("{} submissions could not be rescored", failed.len());
        }
        Ok(())
    })
}
