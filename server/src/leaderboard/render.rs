//! The leaderboard as CSV (RFC 4180 quoting, one header per track), and the score columns every
//! rendering shares. Scores print with six decimals; +inf prints as `inf`. The HTML page is the
//! HTTP adapter's (`http/leaderboard/page.rs`), built from the same columns.
//!
//! CSV injection (OWASP): a spreadsheet evaluates a cell that starts with `=`, `+`, `-`, `@`,
//! a tab or a carriage return as a formula, and team names are chosen by participants
//! (`-1-1`, `=HYPERLINK(...)`). Every text cell goes through [`text_cell`], which prefixes such
//! a cell with `'` and quotes it; numbers the server prints itself (ranks, ids, scores, which
//! may legitimately be negative) are written as they are.

use std::fmt::Write as _;

use super::intervals::{Interval, KINDS};
use super::{Leaderboard, Row, Track};
use crate::scores::fmt_score;

/// A score column: its header and how to read it from a row.
pub(crate) type Column = (&'static str, fn(&Row) -> Option<f64>);

/// The score columns of a track.
pub(crate) fn columns(track: Track) -> &'static [Column] {
    match track {
        Track::Planning => &[("em", |r| r.scores.em)],
        Track::Control => &[("sr", |r| r.scores.sr), ("mse", |r| r.scores.mse)],
        Track::Integrated => &[
            ("m", |r| r.scores.m),
            ("p", |r| r.scores.p),
            ("sr", |r| r.scores.sr),
            ("mse", |r| r.scores.mse),
        ],
    }
}

fn quote(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// A CSV cell holding text (a team name, a state): quoted as RFC 4180 says, and neutralised
/// when a spreadsheet would evaluate it (see the module documentation).
pub(crate) fn text_cell(s: &str) -> String {
    if s.starts_with(['=', '+', '-', '@', '\t', '\r']) {
        format!("\"'{}\"", s.replace('"', "\"\""))
    } else {
        quote(s)
    }
}

/// A score's 95 % interval (docs/reference/leaderboard.md#intervals): its header and how to
/// read it from a row.
pub(crate) type IntervalColumn = (&'static str, fn(&Row) -> Option<Interval>);

/// The intervals of a track's score columns, in the same order.
pub(crate) fn interval_columns(track: Track) -> &'static [IntervalColumn] {
    match track {
        Track::Planning => &[("em", |r| r.intervals.em)],
        Track::Control => &[("sr", |r| r.intervals.sr), ("mse", |r| r.intervals.mse)],
        Track::Integrated => &[
            ("m", |r| r.intervals.m),
            ("p", |r| r.intervals.p),
            ("sr", |r| r.intervals.sr),
            ("mse", |r| r.intervals.mse),
        ],
    }
}

/// `[low, high]` as the page prints it: six decimals, `inf` for an unbounded end; empty when
/// the score has no interval.
pub(crate) fn fmt_interval(iv: Option<Interval>) -> String {
    iv.map_or_else(String::new, |iv| {
        format!("[{}, {}]", fmt_score(Some(iv.low)), fmt_score(Some(iv.high)))
    })
}

pub(crate) fn rank(r: &Row) -> String {
    r.rank.map_or_else(String::new, |n| n.to_string())
}

/// Planning: `rank,team,submission_id,em,submitted_at`. Policy tracks add their scores, the
/// run state and the baseline flag, then the board every row is ranked on (`standard` or
/// `privileged`) and the grasp mode its run ran in (`abstract` or `physical`):
/// `rank,team,submission_id,sr,mse,state,baseline,submitted_at,observations,grasp_mode`.
///
/// Appended after those (existing columns keep their places): each score's 95 % interval,
/// `<score>_low,<score>_high` in the scores' order; then, on the policy tracks, SR per task kind
/// with its interval, `sr_<kind>,sr_<kind>_low,sr_<kind>_high` for navigation, manipulation,
/// pick and place (empty where the run has no task of that kind).
pub(crate) fn csv(board: &Leaderboard) -> String {
    let cols = columns(board.track);
    let policy = board.track != Track::Planning;
    let mut out = String::from("rank,team,submission_id");
    for (name, _) in cols {
        let _ = write!(out, ",{name}");
    }
    out.push_str(if policy {
        ",state,baseline,submitted_at,observations,grasp_mode"
    } else {
        ",submitted_at"
    });
    let intervals = interval_columns(board.track);
    for (name, _) in intervals {
        let _ = write!(out, ",{name}_low,{name}_high");
    }
    if policy {
        for kind in KINDS {
            let _ = write!(out, ",sr_{kind},sr_{kind}_low,sr_{kind}_high");
        }
    }
    out.push('\n');
    for r in &board.rows {
        let _ = write!(out, "{},{},{}", rank(r), text_cell(&r.team), r.submission_id);
        for (_, get) in cols {
            let _ = write!(out, ",{}", fmt_score(get(r)));
        }
        if policy {
            let state = text_cell(r.state.as_deref().unwrap_or(""));
            let _ = write!(out, ",{state},{}", r.baseline);
        }
        let _ = write!(out, ",{}", text_cell(&r.submitted_at));
        if policy {
            let observations = r.observations.or(board.observations).unwrap_or_default();
            let grasp = r.grasp_mode.or(board.grasp_mode).unwrap_or_default();
            let _ = write!(out, ",{observations},{grasp}");
        }
        for (_, get) in intervals {
            let iv = get(r);
            let _ = write!(
                out,
                ",{},{}",
                fmt_score(iv.map(|i| i.low)),
                fmt_score(iv.map(|i| i.high))
            );
        }
        if policy {
            for kind in KINDS {
                let k = r.intervals.sr_by_kind.get(kind);
                let (sr, low, high) = (
                    k.map(|k| k.sr),
                    k.map(|k| k.interval.low),
                    k.map(|k| k.interval.high),
                );
                let _ = write!(out, ",{},{},{}", fmt_score(sr), fmt_score(low), fmt_score(high));
            }
        }
        out.push('\n');
    }
    out
}
