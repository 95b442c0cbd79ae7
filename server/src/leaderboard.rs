//! The leaderboard: ranking (from the store), its three renderings (JSON, CSV, HTML) and a cache.
//!
//! Policy: rendered bodies are cached per (split, format) and dropped on every write that can
//! change a ranking (a new submission, a rescore), so reads under load are a hash lookup and a
//! reference-count increment. A generation counter makes a render that raced with a write
//! unfit for caching instead of serving stale data.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::sync::RwLock;
use std::sync::atomic::{AtomicU64, Ordering};

use bytes::Bytes;
use kitchen_r_core::dataset::Split;
use serde::Serialize;

use crate::error::ServiceError;
use crate::service::{AppState, Scores, rfc3339};
use crate::store;

/// The ranked tracks. Only the planning track is scored by this server so far.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Track {
    Planning,
}

impl std::str::FromStr for Track {
    type Err = ServiceError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "" | "planning" => Ok(Track::Planning),
            "control" | "integrated" => Err(ServiceError::BadRequest(format!(
                "the {s} track has no entries on this server: only `planning` is scored"
            ))),
            other => Err(ServiceError::BadRequest(format!(
                "unknown track {other:?} (expected `planning`)"
            ))),
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Format {
    Json,
    Csv,
    Html,
}

#[derive(Debug, Clone, Serialize)]
pub struct Leaderboard {
    pub track: Track,
    pub split: Split,
    pub rows: Vec<Row>,
}

#[derive(Debug, Clone, Serialize)]
pub struct Row {
    pub rank: usize,
    pub team: String,
    pub submission_id: i64,
    pub scores: Scores,
    pub submitted_at: String,
}

#[derive(Debug, Default)]
pub struct LeaderboardCache {
    generation: AtomicU64,
    rendered: RwLock<HashMap<(Split, Format), (u64, Bytes)>>,
}

impl LeaderboardCache {
    pub fn invalidate(&self) {
        self.generation.fetch_add(1, Ordering::SeqCst);
        self.rendered.write().unwrap_or_else(|p| p.into_inner()).clear();
    }
}

impl AppState {
    /// The ranking: best plan submission per team, EM descending, then earliest, then id.
    pub async fn leaderboard(&self, track: Track, split: Split) -> Result<Leaderboard, ServiceError> {
        let rows = store::planning_leaderboard(self.pool(), split).await?;
        Ok(Leaderboard {
            track,
            split,
            rows: rows
                .into_iter()
                .enumerate()
                .map(|(i, r)| Row {
                    rank: i + 1,
                    team: r.team,
                    submission_id: r.submission_id,
                    scores: Scores { em: r.em },
                    submitted_at: rfc3339(r.submitted_at),
                })
                .collect(),
        })
    }

    /// The leaderboard rendered in `format`, from the cache when nothing was written since.
    pub async fn leaderboard_rendered(
        &self,
        track: Track,
        split: Split,
        format: Format,
    ) -> Result<Bytes, ServiceError> {
        let cache = self.leaderboard_cache();
        let generation = cache.generation.load(Ordering::SeqCst);
        if let Some((g, body)) = cache
            .rendered
            .read()
            .unwrap_or_else(|p| p.into_inner())
            .get(&(split, format))
            && *g == generation
        {
            return Ok(body.clone());
        }
        let board = self.leaderboard(track, split).await?;
        let body: Bytes = match format {
            Format::Json => serde_json::to_vec(&board).map_err(anyhow::Error::from)?.into(),
            Format::Csv => csv(&board).into(),
            Format::Html => html(&board).into(),
        };
        let mut map = cache.rendered.write().unwrap_or_else(|p| p.into_inner());
        if cache.generation.load(Ordering::SeqCst) == generation {
            map.insert((split, format), (generation, body.clone()));
        }
        Ok(body)
    }
}

fn fmt_score(v: Option<f64>) -> String {
    v.map_or_else(String::new, |v| format!("{v:.6}"))
}

/// `rank,team,submission_id,em,submitted_at`, RFC 4180 quoting.
pub fn csv(board: &Leaderboard) -> String {
    let mut out = String::from("rank,team,submission_id,em,submitted_at\n");
    for r in &board.rows {
        let team = if r.team.contains([',', '"', '\n']) {
            format!("\"{}\"", r.team.replace('"', "\"\""))
        } else {
            r.team.clone()
        };
        let _ = writeln!(
            out,
            "{},{},{},{},{}",
            r.rank,
            team,
            r.submission_id,
            fmt_score(r.scores.em),
            r.submitted_at
        );
    }
    out
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
        .replace('\'', "&#39;")
}

/// The public page at `/`: a self-contained HTML table.
pub fn html(board: &Leaderboard) -> String {
    let other = match board.split {
        Split::Dev => Split::Test,
        Split::Test => Split::Dev,
    };
    let mut rows = String::new();
    for r in &board.rows {
        let _ = write!(
            rows,
            "<tr><td>{}</td><td>{}</td><td class=n>{}</td><td class=n>{}</td><td>{}</td></tr>",
            r.rank,
            escape(&r.team),
            fmt_score(r.scores.em),
            r.submission_id,
            escape(&r.submitted_at)
        );
    }
    if board.rows.is_empty() {
        rows.push_str("<tr><td colspan=5>No submissions yet.</td></tr>");
    }
    format!(
        "<!doctype html><html lang=en><head><meta charset=utf-8><title>Kitchen-R leaderboard</title>\
<meta name=viewport content=\"width=device-width,initial-scale=1\">\
<style>body{{font-family:system-ui,sans-serif;margin:2rem auto;max-width:56rem;padding:0 1rem}}\
table{{border-collapse:collapse;width:100%}}th,td{{padding:.4rem .6rem;border-bottom:1px solid #ddd;text-align:left}}\
td.n{{text-align:right;font-variant-numeric:tabular-nums}}th{{background:#f4f4f4}}</style></head><body>\
<h1>Kitchen-R leaderboard</h1><p>Planning track, <b>{split}</b> split: best submission per team by Exact Match \
(ties: earlier submission first). <a href=\"/?split={other}\">Show the {other} split</a> · \
<a href=\"/api/v1/leaderboard?track=planning&amp;split={split}&amp;format=csv\">CSV</a> · \
<a href=\"/api/v1/leaderboard?track=planning&amp;split={split}\">JSON</a></p>\
<table><thead><tr><th>Rank</th><th>Team</th><th>EM</th><th>Submission</th><th>Submitted (UTC)</th></tr></thead>\
<tbody>{rows}</tbody></table></body></html>",
        split = board.split,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn board(team: &str) -> Leaderboard {
        Leaderboard {
            track: Track::Planning,
            split: Split::Test,
            rows: vec![Row {
                rank: 1,
                team: team.into(),
                submission_id: 7,
                scores: Scores { em: Some(0.5) },
                submitted_at: "2026-01-01T00:00:00Z".into(),
            }],
        }
    }

    #[test]
    fn csv_quotes_and_formats() {
        assert_eq!(
            csv(&board("a,b")),
            "rank,team,submission_id,em,submitted_at\n1,\"a,b\",7,0.500000,2026-01-01T00:00:00Z\n"
        );
    }

    #[test]
    fn html_escapes_team_names() {
        let page = html(&board("<script>"));
        assert!(page.contains("&lt;script&gt;") && !page.contains("<script>"));
    }

    #[test]
    fn only_the_planning_track_is_accepted() {
        assert_eq!("".parse::<Track>().unwrap(), Track::Planning);
        assert!("control".parse::<Track>().is_err());
        assert!("nope".parse::<Track>().is_err());
    }
}
