//! The frame every participant page shares: head, small CSS, navigation. No script anywhere
//! (the Content-Security-Policy of [`super::super::session::html`] allows none); pages that
//! change while an evaluation runs reload themselves with `<meta http-equiv=refresh>`. Pages are
//! built with maud, which escapes every value; only the CSRF field (the session code renders it)
//! goes in as markup.

use maud::{DOCTYPE, Markup, PreEscaped, html};

use crate::scores::fmt_score;

/// At 40rem and narrower (phones, 375 px) the page never scrolls sideways: text cells wrap
/// anywhere (number cells do not), `table.stack` rows become blocks, and `table.cards` rows
/// become cards whose cells carry their column name (`data-label`) in front of the value.
const CSS: &str = "body{font-family:system-ui,sans-serif;margin:1.5rem auto;max-width:64rem;padding:0 1rem;line-height:1.45}\
nav{display:flex;flex-wrap:wrap;gap:.4rem 1rem;align-items:center;border-bottom:1px solid #ddd;padding-bottom:.5rem}\
nav form{margin-left:auto}table{border-collapse:collapse;width:100%;margin:.5rem 0 1.5rem}\
th,td{padding:.3rem .5rem;border-bottom:1px solid #ddd;text-align:left;vertical-align:top}\
th{background:#f4f4f4}td.n{text-align:right;font-variant-numeric:tabular-nums}\
.ok{color:#176b2c}.bad{color:#a00}.muted{color:#666}.banner{background:#fff4d6;border:1px solid #e0b84a;padding:.5rem .8rem}\
.f{font-family:ui-monospace,monospace;background:#f7f7f7;padding:.3rem .5rem;overflow-x:auto}\
.scroll{overflow-x:auto}img,video{max-width:100%;height:auto}img{border:1px solid #ddd}\
figure{display:inline-block;margin:.5rem 1rem .5rem 0;vertical-align:top;max-width:20rem}\
input[type=password]{width:100%;max-width:30rem;padding:.4rem;margin:.4rem 0;box-sizing:border-box}code{overflow-wrap:anywhere}\
ol{padding-left:1.4rem;margin:0}@media(max-width:40rem){table.stack tr:first-child{display:none}table.stack td{display:block;border:0}table.stack tr{display:block;border-bottom:1px solid #ddd}\
th,td{padding:.25rem .35rem}td{overflow-wrap:anywhere}td.n{overflow-wrap:normal}\
table.cards tr:first-child{display:none}table.cards tr{display:block;border-bottom:1px solid #ddd;padding:.3rem 0}\
table.cards td{display:flex;justify-content:space-between;gap:1rem;border:0;padding:.1rem .35rem;text-align:right}\
table.cards td::before{content:attr(data-label);font-weight:600;text-align:left;white-space:nowrap}}";

/// Who the page is for: drives the navigation's right end.
pub(super) enum Viewer<'a> {
    Nobody,
    /// A logged-in team (and the CSRF field of its logout form).
    Team {
        name: &'a str,
        csrf: &'a str,
    },
    Organiser,
}

/// A whole page: `title`, the navigation, `body`; `refresh_s` reloads it while something runs.
pub(super) fn page(title: &str, viewer: &Viewer<'_>, refresh_s: Option<u32>, body: Markup) -> String {
    html! {
        (DOCTYPE)
        html lang="en" {
            head {
                meta charset="utf-8";
                title { (title) " · Kitchen-R" }
                meta name="viewport" content="width=device-width,initial-scale=1";
                @if let Some(s) = refresh_s { meta http-equiv="refresh" content=(s); }
                style { (PreEscaped(CSS)) }
            }
            body {
                nav {
                    a href="/contest" { "Contest" } a href="/" { "Leaderboard" } a href="/team" { "Team page" }
                    @match viewer {
                        Viewer::Nobody => { a href="/team/login" { "Team login" } }
                        Viewer::Team { name, csrf } => {
                            span { "Team " b { (name) } }
                            form method="post" action="/team/logout" { (PreEscaped(csrf)) button { "Log out" } }
                        }
                        Viewer::Organiser => { span { "Organiser (" a href="/admin" { "console" } ")" } }
                    }
                }
                h1 { (title) }
                (body)
            }
        }
    }
    .into_string()
}

/// A score cell's text: six decimals, `inf`, or a dash when absent.
pub(super) fn score(v: Option<f64>) -> String {
    match fmt_score(v) {
        s if s.is_empty() => "–".into(),
        s => s,
    }
}

/// A table of the scores that apply (EM, SR, MSE, M, P), with what each means.
pub(super) fn scores_table(s: &crate::scores::Scores) -> Markup {
    let rows = [
        ("EM", s.em, "plan steps exactly right (higher is better)"),
        (
            "SR",
            s.sr,
            "tasks the policy completed in time (higher is better)",
        ),
        (
            "MSE",
            s.mse,
            "error against the expert's action chunks (lower is better)",
        ),
        ("M", s.m, "mean of EM_j + SR_j per task (higher is better)"),
        ("P", s.p, "1/EM + mean task MSE (lower is better)"),
    ];
    html! {
        table {
            tr { th { "Metric" } th { "Value" } th { "Meaning" } }
            @for (name, v, what) in rows {
                @if v.is_some() { tr { td { (name) } td.n { (score(v)) } td { (what) } } }
            }
        }
    }
}
