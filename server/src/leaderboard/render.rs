//! Leaderboard renderings: CSV (RFC 4180 quoting, one header per track) and the self-contained
//! HTML page. Scores print with six decimals; +inf prints as `inf`.
//!
//! CSV injection (OWASP): a spreadsheet evaluates a cell that starts with `=`, `+`, `-`, `@`,
//! a tab or a carriage return as a formula, and team names are chosen by participants
//! (`-1-1`, `=HYPERLINK(...)`). Every text cell goes through [`text_cell`], which prefixes such
//! a cell with `'` and quotes it; numbers the server prints itself (ranks, ids, scores, which
//! may legitimately be negative) are written as they are.

use std::fmt::Write as _;

use kitchen_r_core::GraspMode;
use kitchen_r_core::dataset::Split;
use kitchen_r_core::observations::ObservationTrack;

use super::{Leaderboard, Row, Track};
use crate::scores::fmt_score;

/// A score column: its header and how to read it from a row.
type Column = (&'static str, fn(&Row) -> Option<f64>);

/// The score columns of a track.
fn columns(track: Track) -> &'static [Column] {
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

fn rank(r: &Row) -> String {
    r.rank.map_or_else(String::new, |n| n.to_string())
}

/// Planning: `rank,team,submission_id,em,submitted_at`. Policy tracks add their scores, the
/// run state and the baseline flag, then the board every row is ranked on (`standard` or
/// `privileged`) and last the grasp mode its run ran in (`abstract` or `physical`):
/// `rank,team,submission_id,sr,mse,state,baseline,submitted_at,observations,grasp_mode`.
pub(crate) fn csv(board: &Leaderboard) -> String {
    let cols = columns(board.track);
    let policy = board.track != Track::Planning;
    let mut out = String::from("rank,team,submission_id");
    for (name, _) in cols {
        let _ = write!(out, ",{name}");
    }
    out.push_str(if policy {
        ",state,baseline,submitted_at,observations,grasp_mode\n"
    } else {
        ",submitted_at\n"
    });
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
        out.push('\n');
    }
    out
}

/// HTML-escape text (team names are untrusted).
pub(crate) fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
        .replace('\'', "&#39;")
}

fn describe(track: Track) -> &'static str {
    match track {
        Track::Planning => "best plan submission per team by Exact Match",
        Track::Control => "best policy per team by success rate SR, then lower MSE",
        Track::Integrated => "best policy + plans pair per team by M, then lower P",
    }
}

/// How a policy board's heading and anchor name its observation track; planning has none.
fn board_label(board: &Leaderboard) -> (&'static str, &'static str, String) {
    match board.observations {
        None => ("", "", String::new()),
        Some(ObservationTrack::Standard) => (
            " — standard observations",
            "",
            " Standard observations: cameras, the sub-task and the robot's state relative to the \
episode start."
                .into(),
        ),
        Some(ObservationTrack::Privileged) => (
            " — privileged observations",
            "-privileged",
            " <b>Privileged observations</b>: these policies also received the robot's pose in the \
scene, the current task's goal and key objects' poses (on the test split only what the sub-task \
names), so they are ranked apart from standard runs."
                .into(),
        ),
    }
}

/// How a policy board's heading, anchor and note name its grasp mode; planning has none. The
/// contest's mode gets no anchor suffix, so links to `#control` keep working whatever it is.
fn grasp_label(board: &Leaderboard, contest: GraspMode) -> (String, String, String) {
    let Some(mode) = board.grasp_mode else {
        return (String::new(), String::new(), String::new());
    };
    let rule = match mode {
        GraspMode::Abstract => {
            "the <b>abstract grasp</b>: an object whose grasp point lies between the closing fingers is carried at its offset from the gripper"
        }
        GraspMode::Physical => {
            "the <b>physical grasp</b>: force-limited finger joints, only friction contacts hold an object"
        }
    };
    let note = match mode == contest {
        true => format!(" Episodes ran with {rule} (this contest's grasp mode)."),
        false => format!(
            " Episodes ran with {rule}, not this contest's {contest} grasp: these runs were evaluated before the organiser changed the mode and are ranked only among themselves."
        ),
    };
    let anchor = match mode == contest {
        true => String::new(),
        false => format!("-{mode}"),
    };
    (format!(" — {mode} grasp"), anchor, note)
}

fn table(board: &Leaderboard, contest: GraspMode) -> String {
    let cols = columns(board.track);
    let policy = board.track != Track::Planning;
    let mut head = String::from("<tr><th>Rank</th><th>Team</th>");
    for (name, _) in cols {
        let _ = write!(head, "<th>{}</th>", name.to_uppercase());
    }
    head.push_str("<th>Submission</th><th>Submitted (UTC)</th></tr>");
    let mut rows = String::new();
    for r in &board.rows {
        let label = if r.baseline { " <i>(baseline)</i>" } else { "" };
        let class = if r.baseline { " class=baseline" } else { "" };
        let _ = write!(
            rows,
            "<tr{class}><td>{}</td><td>{}{label}</td>",
            rank(r),
            escape(&r.team)
        );
        for (_, get) in cols {
            let _ = write!(rows, "<td class=n>{}</td>", fmt_score(get(r)));
        }
        let state = match (policy, r.state.as_deref()) {
            (true, Some("active")) => " (evaluating)",
            (true, Some("platform_failed")) => " (platform failure)",
            (true, Some("cancelled")) => " (cancelled)",
            _ => "",
        };
        // The entry's public summary: what this row shows, on a page of its own.
        let _ = write!(
            rows,
            "<td class=n><a href=\"/leaderboard/{}/{}/{id}\">{id}</a>{state}{privileged}{grasp}</td><td>{}</td></tr>",
            board.track.as_str(),
            board.split,
            escape(&r.submitted_at),
            id = r.submission_id,
            privileged = if r.observations == Some(ObservationTrack::Privileged) {
                " (privileged)"
            } else {
                ""
            },
            // A run of another grasp mode than the contest's says so on its row.
            grasp =
                (r.grasp_mode.filter(|m| *m != contest)).map_or(String::new(), |m| format!(" ({m} grasp)")),
        );
    }
    if board.rows.is_empty() {
        let _ = write!(
            rows,
            "<tr><td colspan={}>No submissions yet.</td></tr>",
            cols.len() + 4
        );
    }
    let track = board.track.as_str();
    let (heading, anchor, note) = board_label(board);
    let (grasp_heading, grasp_anchor, grasp_note) = grasp_label(board, contest);
    let mut query = match board.observations {
        Some(ObservationTrack::Privileged) => "&amp;observations=privileged".to_string(),
        _ => String::new(),
    };
    if let Some(mode) = board.grasp_mode.filter(|m| *m != contest) {
        query.push_str(&format!("&amp;grasp_mode={mode}"));
    }
    format!(
        "<h2 id={track}{anchor}{grasp_anchor}>{title} track{heading}{grasp_heading}</h2><p>{what} (ties: earlier submission first).{note}{grasp_note} \
<a href=\"/api/v1/leaderboard?track={track}&amp;split={split}{query}&amp;format=csv\">CSV</a> · \
<a href=\"/api/v1/leaderboard?track={track}&amp;split={split}{query}\">JSON</a></p>\
<table><thead>{head}</thead><tbody>{rows}</tbody></table>",
        title = track[..1].to_uppercase() + &track[1..],
        what = describe(board.track),
        split = board.split,
    )
}

/// The integrity rules as an HTML list: the leaderboard page and the contest home show this
/// one text.
pub(crate) const INTEGRITY_RULES: &str = "<ul>\
<li>Test-split feedback is aggregate only: a submission shows its scores and counts of failure \
reasons, never a result per instruction or task.</li>\
<li>A policy endpoint receives each task's sub-task sentence (a ground-truth plan step) but no \
instruction id: episode ids are opaque.</li>\
<li>Because a test-split policy run shows the endpoint the test plans' steps, a team's test plan \
files created after its first test-split policy run are scored but not ranked, and an integrated \
test run must link a plan file created before that run.</li>\
<li>A policy that refuses or fails its offline (MSE) episodes is charged the failure penalty at \
every decision point, as if it had answered badly.</li></ul>";

/// The public page: one table per board, all of one split; `contest` is the organiser's grasp
/// mode (`[control] grasp`), named at the top, and boards of the other mode are labelled as such.
pub(crate) fn page(split: Split, boards: &[Leaderboard], public_sample: bool, contest: GraspMode) -> String {
    let other = match split {
        Split::Dev => Split::Test,
        Split::Test => Split::Dev,
    };
    let tables: String = boards.iter().map(|b| table(b, contest)).collect();
    let banner = match (split, public_sample) {
        (Split::Test, true) => format!(
            "<p class=banner><b>{}</b>: this server scores the repository's public test \
sample, whose answers anyone can rebuild from public files. Rankings here show the tools work; \
they do not rank planners.</p>",
            crate::content::PUBLIC_SAMPLE_NOTICE
        ),
        _ => String::new(),
    };
    format!(
        "<!doctype html><html lang=en><head><meta charset=utf-8><title>Kitchen-R leaderboard</title>\
<meta name=viewport content=\"width=device-width,initial-scale=1\">\
<style>body{{font-family:system-ui,sans-serif;margin:2rem auto;max-width:60rem;padding:0 1rem}}\
table{{border-collapse:collapse;width:100%;margin-bottom:2rem}}th,td{{padding:.4rem .6rem;border-bottom:1px solid #ddd;text-align:left}}\
td.n{{text-align:right;font-variant-numeric:tabular-nums}}th{{background:#f4f4f4}}tr.baseline{{color:#555;background:#fafafa}}\
.banner{{background:#fff4d6;border:1px solid #e0b84a;padding:.6rem .8rem}}\
@media(max-width:40rem){{table{{display:block;overflow-x:auto}}}}</style></head><body>\
<h1>Kitchen-R leaderboard</h1>{banner}<p><a href=\"/contest\">The contest: tracks, metrics, \
how to take part, data and rules</a> · <a href=\"/team\">Team page</a></p><p><b>{split}</b> split. <a href=\"/?split={other}\">Show the {other} split</a>. \
Baseline rows are organiser reference runs and take no rank. Policies that received \
privileged observations are ranked on boards of their own, labelled privileged.</p>\
<p class=grasp>Grasp mode of this contest: <b>{contest}</b> (policy episodes' control and \
integrated scores are from it; runs of another grasp mode are ranked on boards of their own, \
labelled).</p>{tables}\
<h2>Rules that keep the test split honest</h2>{INTEGRITY_RULES}</body></html>"
    )
}
