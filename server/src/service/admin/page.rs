//! The console as one HTML page (`GET /admin`), in the style of the public leaderboard page.
//! Every value that comes from the database is escaped: team names, episode keys, worker ids
//! and failure reasons are all written by someone else (a participant or a worker).

use std::fmt::Write;

use super::{Console, JobView};
use crate::leaderboard::render::escape;

/// A number of seconds as `1h 02m`, `3m 05s` or `42s`.
fn duration(s: f64) -> String {
    let s = s.max(0.0).round() as u64;
    match s {
        0..60 => format!("{s}s"),
        60..3600 => format!("{}m {:02}s", s / 60, s % 60),
        _ => format!("{}h {:02}m", s / 3600, (s % 3600) / 60),
    }
}

fn opt(v: Option<&str>) -> String {
    v.map_or_else(|| "–".to_string(), escape)
}

fn jobs_table(title: &str, what: &str, jobs: &[JobView]) -> String {
    let mut out = format!("<h3>{title} ({})</h3><p>{what}</p>", jobs.len());
    if jobs.is_empty() {
        out.push_str("<p><i>None.</i></p>");
        return out;
    }
    out.push_str(
        "<table><tr><th>Job</th><th>Run</th><th>Team</th><th>Episode</th><th>State</th>\
<th>Attempt</th><th>Worker</th><th>Lease until</th><th>Reason</th><th>Updated</th></tr>",
    );
    for j in jobs {
        let _ = write!(
            out,
            "<tr><td class=n>{}</td><td class=n>{}</td><td>{}</td><td>{}</td><td>{}</td>\
<td class=n>{}/{}</td><td>{}</td><td>{}</td><td class=reason>{}</td><td>{}</td></tr>",
            j.job,
            j.run,
            escape(&j.team),
            escape(&j.episode),
            j.state,
            j.attempt,
            j.max_attempts,
            opt(j.worker.as_deref()),
            opt(j.lease_expires_at.as_deref()),
            opt(j.reason.as_deref()),
            escape(&j.updated_at),
        );
    }
    out.push_str("</table>");
    out
}

pub(super) fn console(c: &Console) -> String {
    let q = &c.queue;
    let mut body = String::new();

    // Queue by state.
    let _ = write!(body, "<h2>Queue</h2><table><tr>");
    for state in q.jobs.keys() {
        let _ = write!(body, "<th>{state}</th>");
    }
    body.push_str("<th>Oldest queued</th></tr><tr>");
    for n in q.jobs.values() {
        let _ = write!(body, "<td class=n>{n}</td>");
    }
    let oldest = match (&q.oldest_queued_at, q.oldest_queued_age_s) {
        (Some(at), Some(age)) => format!("{} ago ({})", duration(age), escape(at)),
        _ => "–".into(),
    };
    let _ = write!(body, "<td>{oldest}</td></tr></table>");

    // Each team's share.
    let _ = write!(
        body,
        "<h2>Teams' share</h2><p>Episodes in flight and queued per team (teams with open jobs).</p>"
    );
    if q.teams.is_empty() {
        body.push_str("<p><i>No team has open jobs.</i></p>");
    } else {
        body.push_str(
            "<table><tr><th>Team</th><th>In flight</th><th>Share</th><th>Queued</th><th>Runs</th></tr>",
        );
        for t in &q.teams {
            let _ = write!(
                body,
                "<tr><td>{}</td><td class=n>{}</td><td class=n>{:.0}%</td><td class=n>{}</td><td class=n>{}</td></tr>",
                escape(&t.team),
                t.in_flight,
                t.share * 100.0,
                t.queued,
                t.runs
            );
        }
        body.push_str("</table>");
    }

    // Workers.
    let _ = write!(
        body,
        "<h2>Workers ({})</h2><p>Known by the leases they hold and the results they recorded in the last 24 h.</p>",
        c.workers.workers.len()
    );
    if c.workers.workers.is_empty() {
        body.push_str("<p><i>No worker seen.</i></p>");
    } else {
        body.push_str(
            "<table><tr><th>Worker</th><th>Last seen</th><th>Last heartbeat</th><th>Last report</th>\
<th>Episodes (24 h)</th><th>Current episodes</th></tr>",
        );
        for w in &c.workers.workers {
            let current: Vec<String> = w
                .current
                .iter()
                .map(|e| {
                    let late = if e.expired { " <b>(lease expired)</b>" } else { "" };
                    format!(
                        "run {} {} (job {}, attempt {}){late}",
                        e.run,
                        escape(&e.episode),
                        e.job,
                        e.attempt
                    )
                })
                .collect();
            let _ = write!(
                body,
                "<tr><td>{}</td><td>{} ago</td><td>{}</td><td>{}</td><td class=n>{}</td><td>{}</td></tr>",
                escape(&w.worker),
                duration(w.last_seen_age_s),
                opt(w.last_heartbeat.as_deref()),
                opt(w.last_report.as_deref()),
                w.episodes_24h,
                if current.is_empty() {
                    "idle".to_string()
                } else {
                    current.join("<br>")
                }
            );
        }
        body.push_str("</table>");
    }

    // Runs.
    let _ = write!(
        body,
        "<h2>Runs</h2><p>Active policy runs, then the latest others. ETA: the pace so far \
(time since the first episode started per recorded episode) times the episodes left.</p>"
    );
    if c.runs.runs.is_empty() {
        body.push_str("<p><i>No policy run yet.</i></p>");
    } else {
        body.push_str(
            "<table><tr><th>Run</th><th>Sub.</th><th>Team</th><th>Split</th><th>Observations</th><th>State</th>\
<th>Progress</th><th>Running</th><th>Queued</th><th>Gave up</th><th>Started</th><th>Mean episode</th><th>ETA</th></tr>",
        );
        for r in &c.runs.runs {
            let state = match (&r.cancelled_at, &r.cancelled_by) {
                (Some(at), Some(by)) => format!("cancelled by {} at {}", escape(by), escape(at)),
                _ => r.state.as_str().to_string(),
            };
            let eta = match (&r.eta, r.eta_s) {
                (Some(at), Some(s)) => format!("in {} ({})", duration(s), escape(at)),
                _ => "–".into(),
            };
            let _ = write!(
                body,
                "<tr><td class=n>{}</td><td class=n>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{state}</td>\
<td><progress max={} value={}></progress> {}/{}</td><td class=n>{}</td><td class=n>{}</td><td class=n>{}</td>\
<td>{}</td><td>{}</td><td>{eta}</td></tr>",
                r.run,
                r.submission,
                escape(&r.team),
                escape(&r.split),
                r.observations,
                r.episodes_total.max(1),
                r.episodes_done,
                r.episodes_done,
                r.episodes_total,
                r.episodes_running,
                r.episodes_queued,
                r.episodes_gave_up,
                opt(r.started_at.as_deref()),
                r.mean_episode_s.map_or_else(|| "–".into(), duration),
            );
        }
        body.push_str("</table>");
    }

    // Stuck and failed jobs.
    body.push_str("<h2>Jobs that need attention</h2>");
    body.push_str(&jobs_table(
        "Stuck",
        "Leased past expiry: the worker stopped heartbeating; the reaper requeues them.",
        &q.stuck,
    ));
    body.push_str(&jobs_table(
        "Retrying",
        "Queued or leased again after a failed attempt.",
        &q.retrying,
    ));
    body.push_str(&jobs_table(
        "Failed",
        "The platform gave up after their attempts: <code>kitchen-r admin requeue RUN</code> retries them.",
        &q.failed,
    ));

    format!(
        "<!doctype html><html lang=en><head><meta charset=utf-8><title>Kitchen-R organiser console</title>\
<meta name=viewport content=\"width=device-width,initial-scale=1\"><meta http-equiv=refresh content=15>\
<style>body{{font-family:system-ui,sans-serif;margin:2rem auto;max-width:80rem;padding:0 1rem}}\
table{{border-collapse:collapse;width:100%;margin-bottom:1.5rem}}th,td{{padding:.3rem .5rem;border-bottom:1px solid #ddd;text-align:left;vertical-align:top}}\
td.n{{text-align:right;font-variant-numeric:tabular-nums}}th{{background:#f4f4f4}}td.reason{{max-width:30rem;overflow-wrap:anywhere}}\
form{{display:inline}}@media(max-width:40rem){{table{{display:block;overflow-x:auto}}}}</style></head><body>\
<h1>Kitchen-R organiser console</h1><p>As of {at} (refreshes every 15 s). Actions: \
<code>kitchen-r admin cancel RUN</code>, <code>admin requeue RUN</code>, <code>admin backup FILE</code>. \
<form method=post action=\"/admin/logout\">{CSRF_SLOT}<button>Log out</button></form></p>{body}</body></html>",
        at = escape(&q.at),
    )
}

/// Where the HTTP adapter puts the CSRF field of the console's forms (it owns the session).
pub(crate) const CSRF_SLOT: &str = "<!--csrf-->";

/// The login form (`GET /admin` without a valid session cookie); `csrf` is the form's hidden
/// CSRF field, as the HTTP adapter renders it.
pub(crate) fn login(message: Option<&str>, csrf: &str) -> String {
    let message = message.map_or_else(String::new, |m| format!("<p class=err>{}</p>", escape(m)));
    format!(
        "<!doctype html><html lang=en><head><meta charset=utf-8><title>Kitchen-R organiser console</title>\
<meta name=viewport content=\"width=device-width,initial-scale=1\">\
<style>body{{font-family:system-ui,sans-serif;margin:2rem auto;max-width:30rem;padding:0 1rem}}\
input{{width:100%;padding:.4rem;margin:.5rem 0;box-sizing:border-box}}.err{{color:#a00}}</style></head><body>\
<h1>Organiser console</h1>{message}<form method=post action=\"/admin/login\">{csrf}\
<label>Organiser token <input type=password name=token autocomplete=current-password required></label>\
<button>Log in</button></form></body></html>"
    )
}
