//! How `submission show`/`wait` print a submission view: state and progress with an ETA, the
//! scores, failure counts, and on the dev split one row per episode (each task's result and
//! failure reason) or per instruction (plan files). Test-split views carry aggregates only (the
//! server leaves the rows out); this prints what is there.
//!
//! The ETA is the server's (`eta_s`) when it sends one, else the finished episodes' pace: time
//! since the run was created, per finished episode, times the episodes left. "Now" is the
//! answer's `Date` header, so a skewed client clock does not skew it.

use serde_json::Value;

use crate::server_client::{ServerArgs, url};

/// One answer of `GET /api/v1/submissions/{id}`.
pub(crate) struct Snapshot {
    pub view: Value,
    /// The server's clock when it answered (its `Date` header), in Unix milliseconds.
    pub server_now_ms: Option<i64>,
}

/// The latest run's state: a policy run's `evaluation.state`; a plan run is scored at upload, so
/// `finished`; `queued` when there is no run yet.
pub(crate) fn state(view: &Value) -> &str {
    let run = &view["latest_run"];
    match run["evaluation"]["state"].as_str() {
        Some(s) => s,
        None if run.is_object() => "finished",
        None => "queued",
    }
}

pub(crate) fn ended(view: &Value) -> bool {
    matches!(state(view), "finished" | "platform_failed" | "cancelled")
}

/// Words after "its run ended STATE" for a run that did not finish.
pub(crate) fn why_not_finished(view: &Value) -> String {
    let e = &view["latest_run"]["evaluation"];
    let top = e["failure_counts"]
        .as_array()
        .and_then(|c| c.first())
        .map(|c| format!("; most frequent failure: {} ({}×)", s(&c["reason"]), c["count"]));
    match state(view) {
        "cancelled" => " (stopped by the organiser; the quota was given back)".into(),
        _ => top.unwrap_or_default(),
    }
}

/// `running: 3/8 episodes done, 2 running, ETA 1m 20s`.
pub(crate) fn progress_line(snap: &Snapshot) -> String {
    let view = &snap.view;
    let e = &view["latest_run"]["evaluation"];
    let st = state(view);
    if !e.is_object() {
        return st.to_string();
    }
    let mut line = format!(
        "{st}: {}/{} episodes done, {} running",
        e["episodes_done"], e["episodes_total"], e["episodes_running"]
    );
    if e["episodes_retrying"].as_u64().unwrap_or(0) > 0 {
        line.push_str(&format!(", {} retrying", e["episodes_retrying"]));
    }
    if let Some(eta) = eta_s(snap) {
        line.push_str(&format!(", ETA {}", duration(eta)));
    }
    line
}

/// Seconds left, while the run is active and at least one episode has finished.
pub(crate) fn eta_s(snap: &Snapshot) -> Option<f64> {
    let run = &snap.view["latest_run"];
    let e = &run["evaluation"];
    if !matches!(e["state"].as_str(), Some("running" | "queued")) {
        return None;
    }
    if let Some(s) = e["eta_s"].as_f64() {
        return Some(s);
    }
    let done = e["episodes_done"].as_i64()?;
    let left = e["episodes_total"].as_i64()? - done;
    let created = crate::clock_parse::parse_rfc3339_ms(run["created_at"].as_str()?)?;
    let now = snap.server_now_ms.unwrap_or_else(now_ms);
    (done > 0 && left > 0).then(|| (now - created).max(0) as f64 / 1000.0 / done as f64 * left as f64)
}

fn now_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as i64)
}

/// The whole view, for people.
pub(crate) fn print(snap: &Snapshot, server: &ServerArgs) {
    let v = &snap.view;
    println!(
        "submission {}: {}, {} split, team {}, created {}",
        v["id"],
        if v["kind"] == "policy" {
            "policy endpoint"
        } else {
            "plan file"
        },
        s(&v["split"]),
        s(&v["team"]),
        s(&v["created_at"])
    );
    println!("page: {}", url(server, &format!("/submissions/{}", v["id"])));
    let p = &v["policy"];
    if p.is_object() {
        let mut extra = Vec::new();
        if p["reference"] == true {
            extra.push("reference run".to_string());
        }
        if let Some(plans) = p["plans"].as_i64() {
            extra.push(format!("with plan submission {plans}"));
        }
        extra.push(format!("max concurrency {}", p["max_concurrency"]));
        if p["observations"] == "privileged" {
            extra.push("privileged observations: ranked on the privileged boards".to_string());
        }
        println!("policy: {} ({})", s(&p["endpoint"]), extra.join(", "));
    }
    let run = &v["latest_run"];
    if !run.is_object() {
        println!("state: queued (no scoring run yet)");
        return;
    }
    println!("run {}: {}", run["id"], progress_line(snap));
    println!("scores: {}", scores(&run["scores"]));
    // A policy run's scores mean what its grasp mode made of the episodes.
    if let Some(g) = run["evaluation"]["grasp_mode"].as_str() {
        println!("grasp mode: {g}");
    }
    if v["ranked"] == false {
        println!("not ranked: {}", s(&v["unranked_reason"]));
    }
    match run["evaluation"].is_object() {
        true => print_evaluation(&run["evaluation"], server),
        false => print_instructions(run, v["split"] == "test"),
    }
}

fn print_evaluation(e: &Value, server: &ServerArgs) {
    if let Some(t) = e["finished_at"].as_str() {
        println!("finished at {t}");
    }
    if e["needs_resimulation"] == true {
        println!("note: the ground truth changed since these episodes ran; scores are the old ones");
    }
    if let Some(r) = e["rescored_from_run"].as_i64() {
        println!("rescored from the episodes of run {r}");
    }
    let counts = arr(&e["failure_counts"]);
    if !counts.is_empty() {
        println!("failures:");
        for c in counts {
            println!("  {:>5} × {}", c["count"].to_string(), s(&c["reason"]));
        }
    }
    for r in arr(&e["retrying"]) {
        println!(
            "retrying {} (attempt {}): {}",
            s(&r["key"]),
            r["attempt"],
            s(&r["last_error"])
        );
    }
    let episodes = arr(&e["episodes"]);
    if episodes.is_empty() {
        if e["episodes_done"].as_i64().unwrap_or(0) > 0 {
            println!("per-episode results are not shown on the test split (aggregate feedback only)");
        }
        return;
    }
    let width = episodes
        .iter()
        .map(|x| s(&x["key"]).len())
        .max()
        .unwrap_or(3)
        .max(7);
    println!("episodes:");
    println!(
        "  {:<width$}  {:<7}  {:<11}  {:>7}  attempt",
        "episode", "mode", "result", "wall"
    );
    for x in episodes {
        let result = match (&x["success_rate"], &x["mse"]) {
            (Value::Number(sr), _) => format!("SR {:.2}", sr.as_f64().unwrap_or(f64::NAN)),
            (_, Value::Number(m)) => format!("MSE {:.4}", m.as_f64().unwrap_or(f64::NAN)),
            _ if x["failure"].is_string() => "not run".into(),
            _ => "-".into(),
        };
        let wall = x["wall_ms"].as_f64().unwrap_or(0.0) / 1000.0;
        println!(
            "  {:<width$}  {:<7}  {:<11}  {:>6.1}s  {}",
            s(&x["key"]),
            s(&x["mode"]),
            result,
            wall,
            x["attempt"]
        );
        print_tasks(x);
        if let Some(f) = x["failure"].as_str() {
            println!("      failure: {f}");
        }
        print_links(x, server);
    }
}

/// One line per task: number (1-based, as the web pages and videos count tasks; the JSON keeps
/// the 0-based `index`), result, the plan step and why it failed.
fn print_tasks(x: &Value) {
    let online = x["mode"] == "online";
    for t in arr(&x["tasks"]) {
        let result = match online {
            true if t["success"] == true => {
                format!("ok {:.1} s", t["completion_time_s"].as_f64().unwrap_or(0.0))
            }
            true => "FAILED".to_string(),
            false => format!(
                "MSE {:.4} ({} samples)",
                t["mse"].as_f64().unwrap_or(f64::NAN),
                t["mse_samples"]
            ),
        };
        let reason = t["failure_reason"].as_str().filter(|r| !r.is_empty());
        println!(
            "      task {:<2} {:<12} {}{}",
            t["index"]
                .as_u64()
                .map_or_else(|| t["index"].to_string(), |i| (i + 1).to_string()),
            result,
            s(&t["step"]),
            reason.map(|r| format!(": {r}")).unwrap_or_default()
        );
    }
}

/// Links the server attaches to an episode (fields named `*_url`, e.g. a video or a path plot),
/// made absolute, and in a link's place the note saying why it is gone (`video_note`: a video
/// removed to keep a storage budget).
fn print_links(x: &Value, server: &ServerArgs) {
    for line in link_lines(x, server) {
        println!("      {line}");
    }
}

fn link_lines(x: &Value, server: &ServerArgs) -> Vec<String> {
    let mut out = Vec::new();
    for (k, v) in x.as_object().into_iter().flatten() {
        let Some(text) = v.as_str() else { continue };
        if let Some(name) = k.strip_suffix("_note") {
            out.push(format!("{name}: {text}"));
        } else if let Some(name) = k.strip_suffix("_url") {
            let link = match text.starts_with('/') {
                true => url(server, text),
                false => text.to_string(),
            };
            out.push(format!("{name}: {link}"));
        }
    }
    out
}

fn print_instructions(run: &Value, test: bool) {
    if let (Some(total), Some(present)) = (
        run["instructions_total"].as_u64(),
        run["instructions_present"].as_u64(),
    ) {
        println!("instructions: {present} of {total} have a plan in the file");
    }
    let rows = arr(&run["instructions"]);
    if rows.is_empty() {
        if test {
            println!("per-instruction results are not shown on the test split (aggregate feedback only)");
        }
        return;
    }
    let width = rows.iter().map(|r| s(&r["id"]).len()).max().unwrap_or(2).max(11);
    println!("  {:<width$}  {:>6}  correct steps", "instruction", "EM");
    for r in rows {
        let note = if r["present"] == false {
            "  (no plan in the file)"
        } else {
            ""
        };
        println!(
            "  {:<width$}  {:>6.4}  {}/{}{note}",
            s(&r["id"]),
            r["em"].as_f64().unwrap_or(0.0),
            r["correct_steps"],
            r["total_steps"]
        );
    }
}

/// `EM = 1.0000, SR = 0.9500`: the scores the run has, `inf` as the server sends it.
fn scores(sc: &Value) -> String {
    let parts: Vec<String> = [("em", "EM"), ("sr", "SR"), ("mse", "MSE"), ("m", "M"), ("p", "P")]
        .iter()
        .filter_map(|(k, name)| match &sc[*k] {
            Value::Number(n) => n.as_f64().map(|f| format!("{name} = {f:.4}")),
            Value::String(t) => Some(format!("{name} = {t}")),
            _ => None,
        })
        .collect();
    match parts.is_empty() {
        true => "none yet".into(),
        false => parts.join(", "),
    }
}

fn s(v: &Value) -> &str {
    v.as_str().unwrap_or("?")
}

fn arr(v: &Value) -> &[Value] {
    v.as_array().map_or(&[], Vec::as_slice)
}

/// `45s`, `3m 05s`, `2h 10m`.
pub(crate) fn duration(secs: f64) -> String {
    let t = secs.max(0.0).round() as u64;
    match t {
        0..60 => format!("{t}s"),
        60..3600 => format!("{}m {:02}s", t / 60, t % 60),
        _ => format!("{}h {:02}m", t / 3600, (t % 3600) / 60),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn eta_is_the_finished_episodes_pace_times_the_episodes_left() {
        let view = json!({"latest_run": {"created_at": "2026-11-22T23:00:00Z", "evaluation": {
            "state": "running", "episodes_done": 2, "episodes_total": 8, "episodes_running": 2}}});
        let now = crate::clock_parse::parse_rfc3339_ms("2026-11-22T23:01:00Z");
        let snap = Snapshot {
            view,
            server_now_ms: now,
        };
        assert_eq!(eta_s(&snap), Some(180.0));
        assert!(progress_line(&snap).ends_with("2/8 episodes done, 2 running, ETA 3m 00s"));
    }

    #[test]
    fn a_removed_video_prints_its_note_where_the_link_was() {
        let server = ServerArgs {
            server: "http://s/".into(),
        };
        let ep = json!({"key": "dev-0001", "plot_url": "/p.png",
                        "video_note": "video removed to keep team t's videos within [video] team_max_bytes (2 GiB)"});
        assert_eq!(
            link_lines(&ep, &server),
            [
                "plot: http://s/p.png",
                "video: video removed to keep team t's videos within [video] team_max_bytes (2 GiB)"
            ]
        );
    }

    #[test]
    fn plan_runs_are_finished_and_runless_submissions_queued() {
        assert_eq!(state(&json!({"latest_run": {"scores": {}}})), "finished");
        assert_eq!(state(&json!({"latest_run": null})), "queued");
        assert!(!ended(
            &json!({"latest_run": {"evaluation": {"state": "running"}}})
        ));
    }
}
