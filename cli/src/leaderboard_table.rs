//! The leaderboard as a terminal table: the columns of each track (planning: EM; control: SR
//! then MSE; integrated: M then P), baseline rows marked; a policy board's heading names its
//! observation track (standard or privileged) and grasp mode (abstract or physical). Each score
//! is followed by its 95 % interval, and the table ends with how ties are decided
//! (docs/reference/leaderboard.md); `--format json` prints the board with its results cards.

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

/// A score's 95 % interval (`intervals.<key>`, `[low, high]`) as `[0.5800, 0.9200]`; empty when
/// the row has none.
fn interval(v: &Value) -> String {
    match v.as_array().map(Vec::as_slice) {
        Some([low, high]) => format!("[{}, {}]", cell(low), cell(high)),
        _ => String::new(),
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
        header.push_str(&format!("  {h:>8}  {:<18}", format!("{h} 95 %")));
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
            let (score, iv) = (cell(&r["scores"][*key]), interval(&r["intervals"][*key]));
            line.push_str(&format!("  {score:>8}  {iv:<18}"));
        }
        println!(
            "{line}  {:>10}  {:<9}  {}",
            r["submission_id"].to_string(),
            r["state"].as_str().unwrap_or("finished"),
            r["submitted_at"].as_str().unwrap_or("?")
        );
    }
    if let Some(ties) = board["ties"].as_str() {
        println!("ties: {ties}");
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
        assert_eq!(interval(&serde_json::json!([0.25, "inf"])), "[0.2500, inf]");
        assert_eq!(interval(&Value::Null), "");
    }
}
