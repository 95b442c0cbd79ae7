//! The organiser's console as one HTML page (`GET /admin`) and its login form, in the style of the
//! public leaderboard page. The service layer hands over data ([`Console`]); the page is built
//! here with maud, which escapes every value: team names, episode keys, worker ids and failure
//! reasons are all written by someone else (a participant or a worker). Only the CSRF field, which
//! the session code renders, goes in as markup.

use maud::{DOCTYPE, Markup, PreEscaped, html};

use crate::http::pages::words::duration;
use crate::service::admin::{Console, JobView};

fn opt(v: Option<&str>) -> &str {
    v.unwrap_or("–")
}

const CONSOLE_STYLE: &str = "body{font-family:system-ui,sans-serif;margin:2rem auto;max-width:80rem;padding:0 1rem}\
table{border-collapse:collapse;width:100%;margin-bottom:1.5rem}th,td{padding:.3rem .5rem;border-bottom:1px solid #ddd;text-align:left;vertical-align:top}\
td.n{text-align:right;font-variant-numeric:tabular-nums}th{background:#f4f4f4}td.reason{max-width:30rem;overflow-wrap:anywhere}\
form{display:inline}@media(max-width:40rem){table{display:block;overflow-x:auto}}";

const LOGIN_STYLE: &str = "body{font-family:system-ui,sans-serif;margin:2rem auto;max-width:30rem;padding:0 1rem}\
input{width:100%;padding:.4rem;margin:.5rem 0;box-sizing:border-box}.err{color:#a00}";

fn jobs_table(title: &str, what: Markup, jobs: &[JobView]) -> Markup {
    html! {
        h3 { (title) " (" (jobs.len()) ")" }
        p { (what) }
        @if jobs.is_empty() {
            p { i { "None." } }
        } @else {
            table {
                tr { th { "Job" } th { "Run" } th { "Team" } th { "Episode" } th { "State" } th { "Attempt" } th { "Worker" } th { "Lease until" } th { "Reason" } th { "Updated" } }
                @for j in jobs {
                    tr {
                        td.n { (j.job) } td.n { (j.run) } td { (j.team) } td { (j.episode) } td { (j.state) }
                        td.n { (j.attempt) "/" (j.max_attempts) }
                        td { (opt(j.worker.as_deref())) } td { (opt(j.lease_expires_at.as_deref())) }
                        td.reason { (opt(j.reason.as_deref())) } td { (j.updated_at) }
                    }
                }
            }
        }
    }
}

/// The console; `csrf` is the hidden CSRF field of its forms, as the session code renders it.
pub(super) fn console(c: &Console, csrf: &str) -> String {
    let q = &c.queue;
    let oldest = match (&q.oldest_queued_at, q.oldest_queued_age_s) {
        (Some(at), Some(age)) => format!("{} ago ({at})", duration(age)),
        _ => "–".into(),
    };
    let page = html! {
        (DOCTYPE)
        html lang="en" {
            head {
                meta charset="utf-8";
                title { "Kitchen-R organiser console" }
                meta name="viewport" content="width=device-width,initial-scale=1";
                meta http-equiv="refresh" content="15";
                style { (PreEscaped(CONSOLE_STYLE)) }
            }
            body {
                h1 { "Kitchen-R organiser console" }
                p {
                    "As of " (q.at) " (refreshes every 15 s). Actions: "
                    code { "kitchen-r admin cancel RUN" } ", " code { "admin requeue RUN" } ", " code { "admin backup FILE" } ". "
                    form method="post" action="/admin/logout" { (PreEscaped(csrf)) button { "Log out" } }
                }

                h2 { "Queue" }
                table {
                    tr { @for state in q.jobs.keys() { th { (state) } } th { "Oldest queued" } }
                    tr { @for n in q.jobs.values() { td.n { (n) } } td { (oldest) } }
                }

                h2 { "Teams' share" }
                p { "Episodes in flight and queued per team (teams with open jobs)." }
                @if q.teams.is_empty() {
                    p { i { "No team has open jobs." } }
                } @else {
                    table {
                        tr { th { "Team" } th { "In flight" } th { "Share" } th { "Queued" } th { "Runs" } }
                        @for t in &q.teams {
                            tr {
                                td { (t.team) } td.n { (t.in_flight) } td.n { (format!("{:.0}%", t.share * 100.0)) }
                                td.n { (t.queued) } td.n { (t.runs) }
                            }
                        }
                    }
                }

                h2 { "Workers (" (c.workers.workers.len()) ")" }
                p { "Known by the leases they hold and the results they recorded in the last 24 h." }
                @if c.workers.workers.is_empty() {
                    p { i { "No worker seen." } }
                } @else {
                    table {
                        tr { th { "Worker" } th { "Last seen" } th { "Last heartbeat" } th { "Last report" } th { "Episodes (24 h)" } th { "Current episodes" } }
                        @for w in &c.workers.workers {
                            tr {
                                td { (w.worker) } td { (duration(w.last_seen_age_s)) " ago" }
                                td { (opt(w.last_heartbeat.as_deref())) } td { (opt(w.last_report.as_deref())) }
                                td.n { (w.episodes_24h) }
                                td {
                                    @if w.current.is_empty() { "idle" }
                                    @for (i, e) in w.current.iter().enumerate() {
                                        @if i > 0 { br; }
                                        "run " (e.run) " " (e.episode) " (job " (e.job) ", attempt " (e.attempt) ")"
                                        @if e.expired { " " b { "(lease expired)" } }
                                    }
                                }
                            }
                        }
                    }
                }

                h2 { "Runs" }
                p {
                    "Active policy runs, then the latest others. ETA: the pace so far (time since the first \
                     episode started per recorded episode) times the episodes left."
                }
                @if c.runs.runs.is_empty() {
                    p { i { "No policy run yet." } }
                } @else {
                    table {
                        tr {
                            th { "Run" } th { "Sub." } th { "Team" } th { "Split" } th { "Observations" } th { "State" }
                            th { "Progress" } th { "Running" } th { "Queued" } th { "Gave up" } th { "Started" } th { "Mean episode" } th { "ETA" }
                        }
                        @for r in &c.runs.runs {
                            tr {
                                td.n { (r.run) } td.n { (r.submission) } td { (r.team) } td { (r.split) } td { (r.observations) }
                                td {
                                    @match (&r.cancelled_at, &r.cancelled_by) {
                                        (Some(at), Some(by)) => { "cancelled by " (by) " at " (at) }
                                        _ => { (r.state.as_str()) }
                                    }
                                    @if let Some(v) = c.verifications.iter().find(|v| v.run == r.run) {
                                        @if v.verdict == "verified" { " · verified" } @else { " · " strong { "UNVERIFIED" } }
                                    }
                                }
                                td { progress max=(r.episodes_total.max(1)) value=(r.episodes_done) {} " " (r.episodes_done) "/" (r.episodes_total) }
                                td.n { (r.episodes_running) } td.n { (r.episodes_queued) } td.n { (r.episodes_gave_up) }
                                td { (opt(r.started_at.as_deref())) }
                                td { (r.mean_episode_s.map_or_else(|| "–".into(), duration)) }
                                td {
                                    @match (&r.eta, r.eta_s) {
                                        (Some(at), Some(s)) => { "in " (duration(s)) " (" (at) ")" }
                                        _ => { "–" }
                                    }
                                }
                            }
                        }
                    }
                }

                h2 { "Jobs that need attention" }
                (jobs_table("Stuck", html! { "Leased past expiry: the worker stopped heartbeating; the reaper requeues them." }, &q.stuck))
                (jobs_table("Retrying", html! { "Queued or leased again after a failed attempt." }, &q.retrying))
                (jobs_table("Failed", html! { "The platform gave up after their attempts: " code { "kitchen-r admin requeue RUN" } " retries them." }, &q.failed))
            }
        }
    };
    page.into_string()
}

/// The login form (`GET /admin` without a valid session cookie); `csrf` is the form's hidden
/// CSRF field, as the session code renders it.
pub(super) fn login(message: Option<&str>, csrf: &str) -> String {
    html! {
        (DOCTYPE)
        html lang="en" {
            head {
                meta charset="utf-8";
                title { "Kitchen-R organiser console" }
                meta name="viewport" content="width=device-width,initial-scale=1";
                style { (PreEscaped(LOGIN_STYLE)) }
            }
            body {
                h1 { "Organiser console" }
                @if let Some(m) = message { p.err { (m) } }
                form method="post" action="/admin/login" {
                    (PreEscaped(csrf))
                    label { "Organiser token " input type="password" name="token" autocomplete="current-password" required; }
                    button { "Log in" }
                }
            }
        }
    }
    .into_string()
}
