//! `kitchen-r admin verify RUN`: replay every stored trace of a policy run on this machine, bit
//! for bit (the replay the workers' renders use), check each replay against its trace and the
//! result the server stored, and record the verdict on the server (the console shows a run with
//! any disagreement as unverified). Exits non-zero when the run is unverified.

use anyhow::{Context, bail};
use kitchen_r_core::scoring::TaskOutcome;
use kitchen_r_episode::runner::TaskRecord;
use kitchen_r_episode::trace::{Trace, replay};
use serde_json::{Value, json};
use sha2::{Digest, Sha256};

use crate::server_client::{ServerArgs, json, runtime, send, url};

pub(crate) fn verify(server: &ServerArgs, token: &str, run: i64, raw: bool) -> anyhow::Result<()> {
    let client = reqwest::Client::new();
    let rt = runtime()?;
    let base = format!("/api/v1/admin/runs/{run}");
    let plan = rt.block_on(json(
        client
            .get(url(server, &format!("{base}/verification")))
            .bearer_auth(token),
    ))?;
    let episodes = plan["episodes"].as_array().cloned().unwrap_or_default();
    if !raw {
        println!(
            "run {run} (submission {}, team {}, {} split): replaying {} episode(s)",
            plan["submission"],
            s(&plan["team"]),
            s(&plan["split"]),
            episodes.len()
        );
    }
    let (mut replayed, mut disagreements, mut skipped) = (0i64, Vec::new(), 0usize);
    for e in &episodes {
        let key = s(&e["key"]);
        if !e["failure"].is_null() {
            skipped += 1;
            continue;
        }
        let outcome = rt
            .block_on(fetch(&client, server, token, &base, e))
            .and_then(|bytes| check(&bytes, e));
        match outcome {
            Ok(()) => {
                replayed += 1;
                if !raw {
                    println!("  {key}: agrees");
                }
            }
            Err(why) => {
                if !raw {
                    println!("  {key}: DISAGREES: {why:#}");
                }
                disagreements.push(json!({"episode": key, "why": format!("{why:#}")}));
            }
        }
    }
    let report = json!({
        "replayed": replayed,
        "disagreements": disagreements,
        "binary_version": env!("CARGO_PKG_VERSION"),
    });
    let verdict = rt.block_on(json(
        client
            .post(url(server, &format!("{base}/verification")))
            .bearer_auth(token)
            .json(&report),
    ))?;
    if raw {
        println!("{verdict}");
    } else {
        if skipped > 0 {
            println!("  ({skipped} episode(s) the platform gave up on have nothing to replay)");
        }
        println!(
            "run {run}: {} ({} of {} episode(s) replayed and agreed; recorded on the server)",
            s(&verdict["verdict"]).to_uppercase(),
            verdict["replayed"],
            verdict["episodes"]
        );
    }
    if verdict["verdict"] != "verified" {
        bail!("run {run} is unverified: its replay disagrees with the stored result");
    }
    Ok(())
}

/// The episode's trace file, checked against the sha256 the server recorded for it.
async fn fetch(
    client: &reqwest::Client,
    server: &ServerArgs,
    token: &str,
    base: &str,
    e: &Value,
) -> anyhow::Result<Vec<u8>> {
    let Some(sha) = e["trace_sha256"].as_str() else {
        match e["trace_note"].as_str() {
            Some(note) => bail!("no trace to replay: {note}"),
            None => bail!("no trace to replay: the worker stored none"),
        }
    };
    let key = s(&e["key"]);
    let resp = send(
        client
            .get(url(server, &format!("{base}/episodes/{key}/trace")))
            .bearer_auth(token),
    )
    .await?;
    let bytes = resp.bytes().await.context("reading the trace")?.to_vec();
    let got = hex(&Sha256::digest(&bytes));
    if got != sha {
        bail!("the trace file's sha256 is {got}, the server recorded {sha}: the file was altered");
    }
    Ok(bytes)
}

/// Replay the trace bit for bit, then compare the replay with the stored result.
fn check(bytes: &[u8], e: &Value) -> anyhow::Result<()> {
    let trace = Trace::from_bytes(bytes).map_err(|err| anyhow::anyhow!("not a trace: {err}"))?;
    let out = replay(&trace, &mut ()).map_err(|err| anyhow::anyhow!("{err}"))?;
    let stored: Vec<TaskOutcome> =
        serde_json::from_value(e["tasks"].clone()).context("the stored result's tasks")?;
    agrees_with_stored(&out.tasks, &stored)
        .map_err(|why| anyhow::anyhow!("the replay disagrees with the stored result: {why}"))
}

/// The same tasks, successes and completion times (the stored result went through JSON; times
/// are compared to a nanosecond), as the workers' render check.
fn agrees_with_stored(replayed: &[TaskRecord], stored: &[TaskOutcome]) -> Result<(), String> {
    if replayed.len() != stored.len() {
        return Err(format!(
            "{} task(s) replayed, {} stored",
            replayed.len(),
            stored.len()
        ));
    }
    let word = |ok: bool| if ok { "success" } else { "failure" };
    for (r, st) in replayed.iter().zip(stored) {
        if r.index != st.index as usize || r.success != st.success {
            return Err(format!(
                "task {}: replayed {}, stored {}",
                r.index,
                word(r.success),
                word(st.success)
            ));
        }
        let time = if r.success { r.sim_time } else { 0.0 };
        if (time - st.completion_time_s).abs() > 1e-9 {
            return Err(format!(
                "task {}: completed at {time} s replayed, {} s stored",
                r.index, st.completion_time_s
            ));
        }
    }
    Ok(())
}

fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect()
}

fn s(v: &Value) -> String {
    match v {
        Value::String(t) => t.clone(),
        Value::Null => "-".into(),
        other => other.to_string(),
    }
}
