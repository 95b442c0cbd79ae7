//! The leaderboard as a terminal table: the columns of each track (planning: EM; control: SR
//! then MSE; integrated: M then P), baseline rows marked; a policy board's heading names its
//! observation track (standard or privileged) and grasp mode (abstract or physical).

use serde_json::Value;

/// Score columns of a track: (header, key in `scores`).
fn columns(track: &str) -> &'static [(&'static str, &'static str)] {
    match track {
        "control" => &[("SR", "sr"), ("MSE", "mse")],
        "integrated" => &[("M", "m"), ("P", "p"), ("SR", "sr"), ("MSE", "mse")],
        _ => &[("EM", "em")],
    }
}

/// A score cell: 4 decimals, `inf` for an infinite P (sent as the string "inf"), `-` if unset.
fn cell(v: &Value) -> String {
    match v {
        Value::Number(n) => n.as_f64().map_or("-".into(), |f| format!("{f:.4}")),
        Value::String(s) => s.clone(),
        _ => "-".into(),
    }
}

pub(crate) fn print_table(board: &Value) {
    let track = board["track"].as_str().unwrap_or("planning");
    let observations = match board["observations"].as_str() {
        Some(o) => format!(", {o} observations"),
        None => String::new(),
    };
    let grasp = match board["grasp_mode"].as_str() {
        Some(g) => format!(", {g} grasp"),
        None => String::new(),
    };
    println!(
        "{track} track{observations}{grasp}, {} split",
        board["split"].as_str().unwrap_or("?")
    );
    let rows = board["rows"].as_array().cloned().unwrap_or_default();
    if rows.is_empty() {
        println!("no submissions yet");
        return;
    }
    let width = rows
        .iter()
        .filter_map(|r| r["team"].as_str().map(|t| t.chars().count()))
        .max()
        .unwrap_or(4)
        .max(4);
    let cols = columns(track);
    let mut header = format!("{:>4}  {:<width$}", "rank", "team");
    for (h, _) in cols {
        header.push_str(&format!("  {h:>8}"));
    }
    println!("{header}  {:>10}  {:<9}  submitted (UTC)", "submission", "state");
    for r in rows {
        let rank = if r["baseline"] == true {
            "base".to_string()
        } else {
            r["rank"].to_string()
        };
        let mut line = format!("{rank:>4}  {:<width$}", r["team"].as_str().unwrap_or("?"));
        for (_, key) in cols {
            line.push_str(&format!("  {:>8}", cell(&r["scores"][*key])));
        }
        println!(
            "{line}  {:>10}  {:<9}  {}",
            r["submission_id"].to_string(),
            r["state"].as_str().unwrap_or("finished"),
            r["submitted_at"].as_str().unwrap_or("?")
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cells_show_infinite_p_and_missing_scores() {
        assert_eq!(cell(&Value::String("inf".into())), "inf");
        assert_eq!(cell(&serde_json::json!(0.5)), "0.5000");
        assert_eq!(cell(&Value::Null), "-");
        assert_eq!(columns("integrated")[0], ("M", "m"));
    }
}
