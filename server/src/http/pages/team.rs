//! The team page (`GET /team`), the team login form (`/team/login`) and a leaderboard entry's
//! public summary (`GET /leaderboard/{track}/{split}/{id}`).

use kitchen_r_core::observations::ObservationTrack;
use maud::{Markup, PreEscaped, html};

use super::layout::score;
use crate::http::leaderboard::page::card_list;
use crate::leaderboard::render::{fmt_interval, interval_columns};
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

fn or_unlimited(n: Option<impl ToString>) -> String {
    n.map_or_else(|| "unlimited".to_string(), |l| l.to_string())
}

/// The kind column: a policy run's scores mean what its grasp mode made of the episodes.
fn kind_words(s: &TeamSubmission) -> String {
    match (s.kind, s.privileged) {
        (SubmissionKind::Policy, true) => format!("policy (privileged, {} grasp)", s.grasp_mode),
        (SubmissionKind::Policy, false) => format!("policy ({} grasp)", s.grasp_mode),
        _ => "plans".into(),
    }
}

/// The team page's body: quota left, then every submission newest first.
pub(super) fn body(quota: &QuotaView, subs: &[TeamSubmission]) -> Markup {
    html! {
        h2 { "Quota left today" }
        div.scroll {
            table {
                tr { th { "Split" } th { "Per UTC day" } th { "Used today" } th { "Left" } th { "Resets at (UTC)" } }
                @for q in &quota.splits {
                    tr {
                        td { (q.split) } td.n { (or_unlimited(q.limit)) } td.n { (q.used) }
                        td.n { (or_unlimited(q.remaining())) } td { (q.resets_at) }
                    }
                }
            }
        }
        p {
            @match quota.concurrent_runs {
                0 => { "Policy runs evaluating now: " (quota.active_runs) ". " }
                n => { "Policy runs evaluating now: " (quota.active_runs) " of at most " (n) ". " }
            }
            @if quota.per_minute > 0 {
                "Upload attempts are limited to " (quota.per_minute) " per minute and split."
            }
        }
        p.muted { "Runs the platform could not evaluate and runs the organiser cancelled use no quota." }
        h2 { "Submissions (" (subs.len()) ")" }
        @if subs.is_empty() {
            p { "None yet. " a href="/contest#steps" { "How to take part" } "." }
        } @else {
            div.scroll {
                table.cards {
                    tr {
                        th { "Id" } th { "Submitted (UTC)" } th { "Split" } th { "Kind" } th { "State" }
                        th { "EM" } th { "SR" } th { "MSE" } th { "M" } th { "P" }
                    }
                    // `data-label`: the column's name, shown before each value when a narrow
                    // screen turns the rows into cards (layout's `table.cards`).
                    @for s in subs {
                        tr {
                            td data-label="Id" class="n" { a href={ "/submissions/" (s.id) } { (s.id) } }
                            td data-label="Submitted (UTC)" { (crate::clock::rfc3339(s.created_at)) }
                            td data-label="Split" { (s.split) }
                            td data-label="Kind" { (kind_words(s)) }
                            td data-label="State" { (state_words(s)) }
                            td data-label="EM" class="n" { (score(s.scores.em)) }
                            td data-label="SR" class="n" { (score(s.scores.sr)) }
                            td data-label="MSE" class="n" { (score(s.scores.mse)) }
                            td data-label="M" class="n" { (score(s.scores.m)) }
                            td data-label="P" class="n" { (score(s.scores.p)) }
                        }
                    }
                }
            }
        }
    }
}

/// The login form; `csrf` is its hidden CSRF field as the session code renders it, `next` is
/// where to go after it (a local path).
pub(super) fn login(message: Option<&str>, csrf: &str, next: &str) -> Markup {
    html! {
        @if let Some(m) = message { p.bad { (m) } }
        p {
            "Pages about your team's submissions need your team token once; it opens a session \
             that this browser keeps in a cookie (HttpOnly, SameSite=Strict; it holds no token) \
             until it expires, you log out, or your team's token is rotated."
        }
        form method="post" action="/team/login" {
            (PreEscaped(csrf))
            input type="hidden" name="next" value=(next);
            label { "Team token" br; input type="password" name="token" autocomplete="current-password" required; }
            br;
            button { "Log in" }
        }
        p.muted { "Organisers log in on the " a href="/admin" { "console" } "." }
    }
}

/// A leaderboard entry's public summary: exactly what its row on the leaderboard shows.
pub(super) fn entry(track: Track, split: &str, row: &Row) -> Markup {
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
    let anchor = match row.observations {
        Some(ObservationTrack::Privileged) => format!("{}-privileged", track.as_str()),
        _ => track.as_str().to_string(),
    };
    html! {
        table {
            tr { th { "Track" } td { (track.as_str()) } }
            tr { th { "Split" } td { (split) } }
            tr { th { "Rank" } td { (rank) } }
            tr { th { "Team" } td { (row.team) } }
            tr { th { "Submission" } td.n { (row.submission_id) } }
            @if let Some(o) = row.observations { tr { th { "Observations" } td { (o) } } }
            @if let Some(g) = row.grasp_mode { tr { th { "Grasp mode" } td { (g) } } }
            @for ((name, v), (_, iv)) in scores.iter().zip(interval_columns(track)) {
                tr { th { (name) } td.n { (score(*v)) " " (fmt_interval(iv(row))) } }
            }
            @if let Some(state) = &row.state { tr { th { "State" } td { (state) } } }
            tr { th { "Submitted (UTC)" } td { (row.submitted_at) } }
        }
        @if let Some(c) = &row.card {
            h2 { "Results card" }
            p { "What this score was computed with; reproduce it with local " code { "kitchen-r eval" } "." }
            (card_list(c))
        }
        p {
            a href={ "/?split=" (split) "#" (anchor) } { "Back to the leaderboard" }
            ". The submission's details are for its team only."
        }
    }
}
