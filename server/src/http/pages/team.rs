//! The team page (`GET /team`), the team login form (`/team/login`) and a leaderboard entry's
//! public summary (`GET /leaderboard/{track}/{split}/{id}`).

use std::fmt::Write as _;

use super::layout::{escape, score};
use crate::leaderboard::{Row, Track};
use crate::service::portal::QuotaView;
use crate::states::{RunState, SubmissionKind};
use crate::store::portal::TeamSubmission;

fn state_words(s: &TeamSubmission) -> &'static str {
    match (s.kind, s.state) {
        (SubmissionKind::Plans, _) => "scored",
        (_, Some(RunState::Active)) => "evaluating",
        (_, Some(RunState::Finished)) => "finished",
        (_, Some(RunState::PlatformFailed)) => "platform failure",
        (_, Some(RunState::Cancelled)) => "cancelled",
        (_, None) => "not scored yet",
    }
}

/// The team page's body: quota left, then every submission newest first.
pub(super) fn body(quota: &QuotaView, subs: &[TeamSubmission]) -> String {
    let mut out = String::from(
        "<h2>Quota left today</h2><div class=scroll><table><tr><th>Split</th><th>Per UTC day</th><th>Used today</th>\
<th>Left</th><th>Resets at (UTC)</th></tr>",
    );
    for q in &quota.splits {
        let _ = write!(
            out,
            "<tr><td>{}</td><td class=n>{}</td><td class=n>{}</td><td class=n>{}</td><td>{}</td></tr>",
            q.split,
            q.limit.map_or_else(|| "unlimited".to_string(), |l| l.to_string()),
            q.used,
            q.remaining()
                .map_or_else(|| "unlimited".to_string(), |l| l.to_string()),
            escape(&q.resets_at),
        );
    }
    out.push_str("</table></div><p>");
    match quota.concurrent_runs {
        0 => {
            let _ = write!(out, "Policy runs evaluating now: {}. ", quota.active_runs);
        }
        n => {
            let _ = write!(
                out,
                "Policy runs evaluating now: {} of at most {n}. ",
                quota.active_runs
            );
        }
    }
    if quota.per_minute > 0 {
        let _ = write!(
            out,
            "Upload attempts are limited to {} per minute and split.",
            quota.per_minute
        );
    }
    out.push_str(
        "</p><p class=muted>Runs the platform could not evaluate and runs the organiser cancelled use no quota.</p>",
    );
    let _ = write!(out, "<h2>Submissions ({})</h2>", subs.len());
    if subs.is_empty() {
        out.push_str("<p>None yet. <a href=\"/contest#steps\">How to take part</a>.</p>");
        return out;
    }
    out.push_str(
        "<div class=scroll><table class=cards><tr><th>Id</th><th>Submitted (UTC)</th><th>Split</th><th>Kind</th>\
<th>State</th><th>EM</th><th>SR</th><th>MSE</th><th>M</th><th>P</th></tr>",
    );
    // `data-label`: the column's name, shown before each value when a narrow screen turns the
    // rows into cards (layout's `table.cards`).
    for s in subs {
        let _ = write!(
            out,
            "<tr><td data-label=Id class=n><a href=\"/submissions/{id}\">{id}</a></td>\
<td data-label=\"Submitted (UTC)\">{}</td><td data-label=Split>{}</td><td data-label=Kind>{}</td>\
<td data-label=State>{}</td><td data-label=EM class=n>{}</td><td data-label=SR class=n>{}</td>\
<td data-label=MSE class=n>{}</td><td data-label=M class=n>{}</td><td data-label=P class=n>{}</td></tr>",
            escape(&crate::clock::rfc3339(s.created_at)),
            escape(&s.split),
            // A policy run's scores mean what its grasp mode made of the episodes (issue #27).
            match (s.kind, s.privileged) {
                (SubmissionKind::Policy, true) => format!("policy (privileged, {} grasp)", s.grasp_mode),
                (SubmissionKind::Policy, false) => format!("policy ({} grasp)", s.grasp_mode),
                _ => "plans".into(),
            },
            state_words(s),
            score(s.scores.em),
            score(s.scores.sr),
            score(s.scores.mse),
            score(s.scores.m),
            score(s.scores.p),
            id = s.id,
        );
    }
    out.push_str("</table></div>");
    out
}

/// The login form; `next` is where to go after it (a local path).
pub(super) fn login(message: Option<&str>, csrf: &str, next: &str) -> String {
    let message = message.map_or_else(String::new, |m| format!("<p class=bad>{}</p>", escape(m)));
    format!(
        "{message}<p>Pages about your team's submissions need your team token once; it opens a \
session that this browser keeps in a cookie (HttpOnly, SameSite=Strict; it holds no token) until it expires, \
you log out, or your team's token is rotated.</p>\
<form method=post action=\"/team/login\">{csrf}<input type=hidden name=next value=\"{}\">\
<label>Team token<br><input type=password name=token autocomplete=current-password required></label><br>\
<button>Log in</button></form><p class=muted>Organisers log in on the <a href=\"/admin\">console</a>.</p>",
        escape(next)
    )
}

/// A leaderboard entry's public summary: exactly what its row on the leaderboard shows.
pub(super) fn entry(track: Track, split: &str, row: &Row) -> String {
    let scores: &[(&str, Option<f64>)] = match track {
        Track::Planning => &[("EM", row.scores.em)],
        Track::Control => &[("SR", row.scores.sr), ("MSE", row.scores.mse)],
        Track::Integrated => &[
            ("M", row.scores.m),
            ("P", row.scores.p),
            ("SR", row.scores.sr),
            ("MSE", row.scores.mse),
        ],
    };
    let rank = match (row.baseline, row.rank) {
        (true, _) => "baseline (organiser reference run, no rank)".to_string(),
        (false, Some(r)) => r.to_string(),
        (false, None) => "–".to_string(),
    };
    let mut out = format!(
        "<table><tr><th>Track</th><td>{}</td></tr><tr><th>Split</th><td>{}</td></tr>\
<tr><th>Rank</th><td>{rank}</td></tr><tr><th>Team</th><td>{}</td></tr>\
<tr><th>Submission</th><td class=n>{}</td></tr>",
        track.as_str(),
        escape(split),
        escape(&row.team),
        row.submission_id,
    );
    if let Some(o) = row.observations {
        let _ = write!(out, "<tr><th>Observations</th><td>{o}</td></tr>");
    }
    if let Some(g) = row.grasp_mode {
        let _ = write!(out, "<tr><th>Grasp mode</th><td>{g}</td></tr>");
    }
    for (name, v) in scores {
        let _ = write!(out, "<tr><th>{name}</th><td class=n>{}</td></tr>", score(*v));
    }
    if let Some(state) = &row.state {
        let _ = write!(out, "<tr><th>State</th><td>{}</td></tr>", escape(state));
    }
    let _ = write!(
        out,
        "<tr><th>Submitted (UTC)</th><td>{}</td></tr></table>\
<p><a href=\"/?split={}#{}\">Back to the leaderboard</a>. The submission's details are for its team only.</p>",
        escape(&row.submitted_at),
        escape(split),
        match row.observations {
            Some(kitchen_r_core::observations::ObservationTrack::Privileged) =>
                format!("{}-privileged", track.as_str()),
            _ => track.as_str().to_string(),
        },
    );
    out
}
