//! `kitchen-r submit policy ENDPOINT --split S [--plans ID] [--key-map JSON|FILE]`: register a
//! policy endpoint (gRPC, or openpi WebSocket with its key map) and,
//! with `--wait`, follow the run's progress until it has scores.

use std::time::Duration;

use clap::Args;
use serde_json::json;

use crate::server_client::Auth;
use crate::server_client::{ServerArgs, json as send_json, runtime, url};
use crate::submission_cmd;

#[derive(Args, Debug)]
pub(crate) struct PolicySubmitArgs {
    /// The policy's endpoint, reachable from the server and its workers: gRPC at
    /// `http://HOST:PORT` or `https://HOST:PORT`, or an openpi WebSocket server at
    /// `ws://HOST:PORT` or `wss://HOST:PORT`.
    endpoint: String,
    /// openpi (`ws://`) endpoints: the key map, inline JSON (`{"image_size": [128, 128]}`) or a
    /// JSON file; without it the default keys (`observation/base_image`, ...).
    #[arg(long, value_name = "JSON|FILE")]
    key_map: Option<String>,
    /// Which split to evaluate on.
    #[arg(long, value_parser = ["dev", "test"])]
    split: String,
    /// A plan submission of yours on the same split: the run also gets M and P (integrated track).
    #[arg(long, value_name = "SUBMISSION_ID")]
    plans: Option<i64>,
    /// Dev only: evaluate the first N instructions (the server may cap it further).
    #[arg(long, value_name = "N")]
    episodes: Option<u32>,
    /// Bearer token the workers send to your endpoint.
    #[arg(long, env = "KITCHEN_R_POLICY_TOKEN", hide_env_values = true)]
    endpoint_token: Option<String>,
    /// Organiser: a reference run (privileged state, shown as a baseline row); needs the
    /// organiser token as --token.
    #[arg(long)]
    reference: bool,
    /// Follow the run (progress on stderr) and print it as `submission show` does when it ends;
    /// exit 0 only if it finished (as `submission wait`).
    #[arg(long)]
    wait: bool,
    /// With --wait: give up after this many seconds (exit code 124).
    #[arg(long, value_name = "SECONDS", requires = "wait", value_parser = submission_cmd::seconds)]
    timeout: Option<f64>,
    #[command(flatten)]
    server: ServerArgs,
    /// Team token (the organiser token with --reference).
    #[arg(long, env = "KITCHEN_R_TOKEN", hide_env_values = true)]
    token: String,
    /// Print the server's JSON answers instead of summaries.
    #[arg(long)]
    json: bool,
}

pub(crate) fn submit_policy(a: PolicySubmitArgs) -> anyhow::Result<()> {
    let mut body = json!({"endpoint": a.endpoint, "split": a.split});
    if let Some(p) = a.plans {
        body["plans"] = json!(p);
    }
    if let Some(n) = a.episodes {
        body["episodes"] = json!(n);
    }
    if let Some(t) = &a.endpoint_token {
        body["token"] = json!(t);
    }
    if a.reference {
        body["reference"] = json!(true);
    }
    if let Some(k) = crate::key_map_arg::read(a.key_map.as_deref())? {
        body["key_map"] = k;
    }
    runtime()?.block_on(async {
        let client = reqwest::Client::new();
        let req = client
            .post(url(&a.server, "/api/v1/submissions/policies"))
            .bearer_auth(&a.token)
            .json(&body);
        let v = send_json(req).await?;
        if a.json && !a.wait {
            println!("{v}");
            return Ok(());
        }
        let id = v["id"].as_i64().unwrap_or_default();
        eprintln!(
            "submission {id} accepted: {} episodes of {} instructions queued ({}, {} observations), policy: {}",
            v["episodes"],
            v["instructions"],
            a.split,
            v["observations"].as_str().unwrap_or("standard"),
            v["policy"].as_str().unwrap_or("?")
        );
        if !a.wait {
            println!("{id}");
            eprintln!(
                "follow it with `kitchen-r submission wait {id}` (or `submission show {id}`, or {})",
                url(&a.server, &format!("/submissions/{id}"))
            );
            return Ok(());
        }
        let auth = Auth {
            server: ServerArgs {
                server: a.server.server.clone(),
            },
            token: a.token.clone(),
        };
        let timeout = a.timeout.map(Duration::from_secs_f64);
        let snap = submission_cmd::wait(&client, &auth, id, timeout).await?;
        submission_cmd::finish(&snap, &a.server, a.json)
    })
}
