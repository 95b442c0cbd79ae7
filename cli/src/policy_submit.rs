//! `kitchen-r submit policy ENDPOINT --split S [--plans ID]`: register a policy endpoint and,
//! with `--wait`, follow the run's progress until it has scores.

use std::time::Duration;

use anyhow::bail;
use clap::Args;
use serde_json::{Value, json};

use crate::client_cmd::{ServerArgs, json as send_json, runtime, url};

#[derive(Args, Debug)]
pub(crate) struct PolicySubmitArgs {
    /// The policy's gRPC endpoint, `http://HOST:PORT` or `https://HOST:PORT`, reachable from the
    /// server and its workers.
    endpoint: String,
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
    /// Follow the run (progress on stderr) and print its scores when it finishes.
    #[arg(long)]
    wait: bool,
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
            "submission {id} accepted: {} episodes of {} instructions queued ({}), policy: {}",
            v["episodes"],
            v["instructions"],
            a.split,
            v["policy"].as_str().unwrap_or("?")
        );
        if !a.wait {
            println!("{id}");
            eprintln!("follow it with GET /api/v1/submissions/{id} or rerun with --wait");
            return Ok(());
        }
        let view = follow(&client, &a, id).await?;
        if a.json {
            println!("{view}");
        } else {
            print_scores(&view);
        }
        match view["latest_run"]["evaluation"]["state"].as_str() {
            Some("finished") => Ok(()),
            other => bail!("the run ended in state {}", other.unwrap_or("?")),
        }
    })
}

/// Poll the submission until its run has finished; progress lines go to stderr.
async fn follow(client: &reqwest::Client, a: &PolicySubmitArgs, id: i64) -> anyhow::Result<Value> {
    let mut last = String::new();
    loop {
        let req = client
            .get(url(&a.server, &format!("/api/v1/submissions/{id}")))
            .bearer_auth(&a.token);
        let v = send_json(req).await?;
        let e = &v["latest_run"]["evaluation"];
        let state = e["state"].as_str().unwrap_or("?").to_string();
        let line = format!(
            "{state}: {}/{} episodes done, {} running",
            e["episodes_done"], e["episodes_total"], e["episodes_running"]
        );
        if line != last {
            eprintln!("{line}");
            last = line;
        }
        if state == "finished" || state == "platform_failed" {
            return Ok(v);
        }
        tokio::time::sleep(Duration::from_secs(2)).await;
    }
}

fn print_scores(view: &Value) {
    let s = &view["latest_run"]["scores"];
    let show = |k: &str| match &s[k] {
        Value::Number(n) => n.as_f64().map(|f| format!("{k} = {f:.4}")),
        Value::String(t) => Some(format!("{k} = {t}")),
        _ => None,
    };
    let parts: Vec<String> = ["sr", "mse", "em", "m", "p"]
        .iter()
        .filter_map(|k| show(k))
        .collect();
    println!("submission {}: {}", view["id"], parts.join(", "));
    // Both splits: how often each kind of failure happened (the test split shows only this).
    for c in view["latest_run"]["evaluation"]["failure_counts"]
        .as_array()
        .into_iter()
        .flatten()
    {
        println!("  {:>5} × {}", c["count"], c["reason"].as_str().unwrap_or("?"));
    }
    for e in view["latest_run"]["evaluation"]["episodes"]
        .as_array()
        .into_iter()
        .flatten()
    {
        let reasons: Vec<&str> = e["failure_reasons"]
            .as_array()
            .into_iter()
            .flatten()
            .filter_map(Value::as_str)
            .collect();
        if !reasons.is_empty() || e["failure"].is_string() {
            println!(
                "  {}: {}",
                e["key"].as_str().unwrap_or("?"),
                e["failure"].as_str().map_or(reasons.join("; "), str::to_string)
            );
        }
    }
}
