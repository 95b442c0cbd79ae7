//! `GET /submissions/{id}`: a submission as its team (or the organiser) sees it, rendered from
//! the same [`SubmissionView`] the JSON API answers, so the page never shows more than the API.
//!
//! Policy: on the test split the page shows the aggregate view only (scores, progress counts,
//! failure counts). It checks the split itself and renders no per-episode or per-instruction
//! rows there even if a view carried some: the service already leaves them out, and a page must
//! not be the place where that rule could break.

use std::fmt::Write as _;

use super::layout::{duration, escape, score, scores_table};
use crate::service::portal::Eta;
use crate::service::{EpisodeView, PolicyRunView, SubmissionView};

/// Seconds between reloads while the evaluation is queued or running.
pub(super) const REFRESH_S: u32 = 10;
/// Seconds between reloads while an episode's video renders (the pages run no script, so a
/// reload is how "Rendering video… N %" advances and the player appears).
pub(super) const RENDER_REFRESH_S: u32 = 3;

/// Whether the page should reload itself (an evaluation still going).
pub(super) fn running(v: &SubmissionView) -> bool {
    let state = v
        .latest_run
        .as_ref()
        .and_then(|r| r.evaluation.as_ref())
        .map(|e| e.state);
    matches!(state, Some("queued" | "running"))
}

/// Whether an episode's video is being rendered for the page (issue #26).
pub(super) fn rendering(v: &SubmissionView) -> bool {
    let evaluation = v.latest_run.as_ref().and_then(|r| r.evaluation.as_ref());
    evaluation.is_some_and(|e| e.episodes.iter().any(|ep| video_pending(ep).is_some()))
}

/// The share done of the episode's video render, while it is queued or rendering (the page
/// asks for every available video it shows, except one removed to keep a budget: that one
/// shows why, `video_note`).
fn video_pending(ep: &EpisodeView) -> Option<f64> {
    let v = ep.video.as_ref()?;
    let pending = match v.status.as_str() {
        "queued" | "rendering" => true,
        "available" => ep.video_note.is_none(),
        _ => false,
    };
    pending.then_some(v.progress)
}

/// Whether the episode's video file is there to play (views without a render state, from
/// videos recorded during evaluation, name only stored videos).
fn video_ready(ep: &EpisodeView) -> bool {
    ep.video.as_ref().is_none_or(|v| v.status == "ready")
}

fn state_words(state: &str) -> &'static str {
    match state {
        "queued" => "queued: waiting for a simulation worker",
        "running" => "running",
        "finished" => "finished",
        "platform_failed" => "failed on the platform's side (uses no quota)",
        "cancelled" => "cancelled by the organiser (uses no quota)",
        _ => "unknown",
    }
}

/// The page body of `v`; `eta` while it runs.
pub(super) fn body(v: &SubmissionView, eta: Option<&Eta>) -> String {
    let test = v.split == "test";
    let mut out = format!(
        "<table><tr><th>Team</th><td>{}</td></tr><tr><th>Kind</th><td>{}</td></tr>\
<tr><th>Split</th><td>{}</td></tr><tr><th>Submitted (UTC)</th><td>{}</td></tr>",
        escape(&v.team),
        if v.kind == "policy" {
            "policy endpoint"
        } else {
            "plan file"
        },
        escape(&v.split),
        escape(&v.created_at),
    );
    if let Some(p) = &v.policy {
        let plans = p.plans.map_or_else(String::new, |id| {
            format!(" (integrated: linked to plan submission <a href=\"/submissions/{id}\">{id}</a>)")
        });
        let _ = write!(
            out,
            "<tr><th>Endpoint</th><td><code>{}</code>{plans}</td></tr>\
<tr><th>Observations</th><td>{}</td></tr>",
            escape(&p.endpoint),
            match p.observations {
                kitchen_r_core::observations::ObservationTrack::Privileged => {
                    "<b>privileged</b> (ranked on the privileged boards)"
                }
                kitchen_r_core::observations::ObservationTrack::Standard => "standard",
            }
        );
    }
    let ranked = match &v.unranked_reason {
        None => "yes".to_string(),
        Some(why) => format!("no: {}", escape(why)),
    };
    let _ = write!(out, "<tr><th>Ranked</th><td>{ranked}</td></tr></table>");
    if test {
        out.push_str("<p class=muted>Test split: feedback is aggregate only (scores and counts).</p>");
    }
    let Some(run) = &v.latest_run else {
        out.push_str("<p>Not scored yet.</p>");
        return out;
    };
    if let Some(e) = &run.evaluation {
        out.push_str(&progress(e, eta));
    }
    // A policy run's scores mean what its grasp mode made of the episodes (issue #27).
    let grasp = (run.evaluation.as_ref()).map_or(String::new(), |e| {
        format!(", episodes in the <b>{}</b> grasp mode", e.grasp_mode)
    });
    let _ = write!(
        out,
        "<h2>Scores</h2><p class=muted>Scoring run {} ({}), {}{grasp}.</p>{}",
        run.id,
        escape(&run.scorer_version),
        escape(&run.created_at),
        scores_table(&run.scores)
    );
    if let (Some(total), Some(present)) = (run.instructions_total, run.instructions_present) {
        let _ = write!(
            out,
            "<p>The file had a plan for {present} of {total} instructions.</p>"
        );
    }
    if !test && !run.instructions.is_empty() {
        out.push_str(&instructions(run));
    }
    if let Some(e) = &run.evaluation {
        out.push_str(&failures(e));
        if test && matches!(e.state, "queued" | "running") {
            // The rule is `crate::service::progress`'s; say it where the counts would be.
            out.push_str(
                "<p class=muted>On the test split a run shows its progress only: its scores and failure counts appear once, when it ends.</p>",
            );
        }
        if !test {
            out.push_str(&episodes(e));
        }
    }
    out
}

fn progress(e: &PolicyRunView, eta: Option<&Eta>) -> String {
    let eta = match (e.state, eta) {
        ("queued" | "running", Some(eta)) => {
            format!(
                " Estimated to finish in {} (at {} UTC).",
                duration(eta.in_s),
                escape(&eta.at)
            )
        }
        ("queued" | "running", None) => " An estimate shows once the first episode has finished.".into(),
        _ => String::new(),
    };
    let mut out = format!(
        "<h2>Progress</h2><p><b>{}</b>. <progress max={} value={}></progress> {} of {} episodes done, \
{} running{}.{eta}</p>",
        state_words(e.state),
        e.episodes_total.max(1),
        e.episodes_done,
        e.episodes_done,
        e.episodes_total,
        e.episodes_running,
        match e.episodes_retrying {
            0 => String::new(),
            n => format!(", {n} being retried after a platform failure (no cost to you)"),
        },
    );
    if let Some(at) = &e.finished_at {
        let _ = write!(out, "<p>Finished at {} UTC.</p>", escape(at));
    }
    if e.needs_resimulation {
        out.push_str("<p class=banner>The ground truth changed since these episodes ran: the scores are those of the old ground truth until the organiser simulates the run again.</p>");
    }
    if matches!(e.state, "queued" | "running") {
        let _ = write!(
            out,
            "<p class=muted>This page reloads every {REFRESH_S} s while the run lasts.</p>"
        );
    }
    out
}

fn failures(e: &PolicyRunView) -> String {
    if e.failure_counts.is_empty() {
        return String::new();
    }
    let mut out = String::from("<h2>Failures by kind</h2><table><tr><th>Reason</th><th>Times</th></tr>");
    for c in &e.failure_counts {
        let _ = write!(
            out,
            "<tr><td>{}</td><td class=n>{}</td></tr>",
            escape(&c.reason),
            c.count
        );
    }
    out.push_str("</table>");
    out
}

fn instructions(run: &crate::service::RunView) -> String {
    let mut out = String::from(
        "<h2>Per instruction</h2><div class=scroll><table><tr><th>Instruction</th><th>Plan given</th>\
<th>Steps right</th><th>EM</th></tr>",
    );
    for i in &run.instructions {
        let _ = write!(
            out,
            "<tr><td><code>{}</code></td><td>{}</td><td class=n>{} of {}</td><td class=n>{}</td></tr>",
            escape(&i.id),
            if i.present {
                "yes"
            } else {
                "<span class=bad>missing</span>"
            },
            i.correct_steps,
            i.total_steps,
            score(Some(i.em)),
        );
    }
    out.push_str("</table></div>");
    out
}

fn episodes(e: &PolicyRunView) -> String {
    let mut out = String::new();
    if !e.retrying.is_empty() {
        out.push_str("<h2>Being retried</h2><ul>");
        for r in &e.retrying {
            let _ = write!(
                out,
                "<li><code>{}</code>, attempt {}: {}</li>",
                escape(&r.key),
                r.attempt,
                escape(&r.last_error)
            );
        }
        out.push_str("</ul>");
    }
    if e.episodes.is_empty() {
        return out;
    }
    out.push_str(
        "<h2>Episodes</h2><div class=scroll><table class=stack><tr><th>Episode</th><th>Result</th><th>Tasks</th>\
<th>Wall time</th></tr>",
    );
    for ep in &e.episodes {
        out.push_str(&episode_row(ep));
    }
    out.push_str("</table></div>");
    out
}

fn episode_row(ep: &EpisodeView) -> String {
    let result = match (&ep.failure, ep.success_rate, ep.mse) {
        (Some(f), _, _) => format!("<span class=bad>not run: {}</span>", escape(f)),
        (None, Some(sr), _) => format!("SR {}", score(Some(sr))),
        (None, None, Some(mse)) => format!("MSE {}", score(Some(mse))),
        _ => "–".into(),
    };
    let mode = match ep.mode.as_str() {
        "offline" => "offline (MSE against the expert)",
        _ => "online (in the simulator)",
    };
    let mut tasks = String::from("<ol>");
    for t in ep.tasks.iter().flatten() {
        let outcome = match (ep.mode.as_str(), t.success, t.failure_reason.is_empty()) {
            ("offline", _, true) => format!("MSE {} over {} samples", score(Some(t.mse)), t.mse_samples),
            (_, true, _) => format!("<span class=ok>done</span> in {:.1} s", t.completion_time_s),
            (_, false, false) => format!("<span class=bad>failed</span>: {}", escape(&t.failure_reason)),
            (_, false, true) => "<span class=bad>failed</span>".to_string(),
        };
        // With a plot, each task wears its path colour (the plot's legend).
        let swatch = match ep.plot_url {
            Some(_) => {
                let [r, g, b] = kitchen_r_core::topdown::task_colour(t.index);
                format!("<span style=\"color:#{r:02x}{g:02x}{b:02x}\" title=\"path colour\">&#9632;</span> ")
            }
            None => String::new(),
        };
        let _ = write!(
            tasks,
            "<li>{swatch}<code>{}</code>: {outcome}</li>",
            escape(&t.step)
        );
    }
    tasks.push_str("</ol>");
    format!(
        "<tr><td><code>{}</code><br><span class=muted>{mode}, attempt {}</span>{}</td><td>{result}</td>\
<td>{tasks}</td><td class=n>{}</td></tr>",
        escape(&ep.key),
        ep.attempt,
        media(ep),
        duration(ep.wall_ms as f64 / 1000.0),
    )
}

/// The episode's video and path plot (issue #15, items 1 and 2), placed under the episode's
/// key; only what exists is shown (neither ever on the test split: the view has no URL there).
/// Both are served to the page's session at the API path less its `/api/v1` prefix. A video
/// removed to keep a storage budget, or whose render failed, shows its note instead of a player
/// (never a broken one), and one being rendered says so with its progress (issue #26).
fn media(ep: &EpisodeView) -> String {
    let page = |url: &str| escape(url.strip_prefix("/api/v1").unwrap_or(url));
    let key = escape(&ep.key);
    let mut out = String::new();
    let waiting = ep.video.as_ref().and_then(|v| v.waiting.as_deref());
    if let (Some(_), Some(why)) = (video_pending(ep), waiting) {
        // No room for its video yet (the storage budgets): why, instead of a stuck 0 %.
        let _ = write!(
            out,
            "<br><span class=\"muted video-waiting\" role=status>Video waiting: {}</span>",
            escape(why)
        );
    } else if let Some(progress) = video_pending(ep) {
        // Never a player before its file exists: the page reloads until the render is done.
        let _ = write!(
            out,
            "<br><span class=\"muted video-rendering\" role=status>Rendering video… {:.0} %</span>",
            (progress * 100.0).clamp(0.0, 100.0)
        );
    } else if let Some(video) = ep.video_url.as_deref().filter(|_| video_ready(ep)) {
        let src = page(video);
        // `preload=metadata`: a page of many episodes fetches only each file's header (the
        // server answers byte ranges) until one is played.
        let _ = write!(
            out,
            "<br><video class=episode-video controls preload=\"metadata\" width=256 src=\"{src}\" \
aria-label=\"Episode {key}: both cameras with the task and time captioned\">\
<a href=\"{src}\">the episode video (MP4)</a></video>"
        );
    } else if let Some(note) = ep.video_note.as_deref() {
        let _ = write!(
            out,
            "<br><span class=\"muted video-note\">{}</span>",
            escape(note)
        );
        // Removed to keep a budget but still renderable from its trace: asking renders it.
        if let Some(video) = ep.video_url.as_deref() {
            let _ = write!(out, " <a href=\"{}\">render it again</a>", page(video));
        }
    }
    if let Some(plot) = ep.plot_url.as_deref() {
        let src = page(plot);
        let _ = write!(
            out,
            "<br><a href=\"{src}\"><img class=plot src=\"{src}\" width=240 \
alt=\"Where the robot went in {key}: the base path coloured by task, goal circles, a cross where a failed task ended\"></a>"
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn episode(video_url: Option<&str>, video_note: Option<&str>) -> EpisodeView {
        EpisodeView {
            key: "dev-0001".into(),
            mode: "online".into(),
            success_rate: Some(0.0),
            mse: None,
            failure: None,
            failure_reasons: Vec::new(),
            wall_ms: 1000,
            attempt: 1,
            tasks: Some(Vec::new()),
            log_tail: None,
            plot_url: None,
            video_url: video_url.map(str::to_string),
            video: None,
            video_note: video_note.map(str::to_string),
        }
    }

    #[test]
    fn a_removed_video_shows_its_note_instead_of_a_player() {
        let note = "video removed to keep team <a>'s videos within [video] team_max_bytes (2 GiB)";
        let html = media(&episode(None, Some(note)));
        assert!(!html.contains("<video"), "{html}");
        assert!(html.contains("team &lt;a&gt;&#39;s videos within"), "{html}");
        let html = media(&episode(
            Some("/api/v1/submissions/1/episodes/dev-0001/video.mp4"),
            None,
        ));
        assert!(html.contains("<video"), "{html}");
    }

    #[test]
    fn a_video_being_rendered_shows_its_progress_instead_of_a_player() {
        let url = "/api/v1/submissions/1/episodes/dev-0001/video.mp4";
        let mut ep = episode(Some(url), None);
        ep.video = Some(crate::service::renders::VideoView {
            status: "rendering".into(),
            progress: 0.42,
            url: Some(url.into()),
            error: None,
            waiting: None,
        });
        let html = media(&ep);
        assert!(!html.contains("<video"), "{html}");
        assert!(html.contains("Rendering video… 42 %"), "{html}");
        // Removed to keep a budget, renderable again: its note and a link, never a player.
        let mut evicted = episode(Some(url), Some("video removed to keep team a's videos within"));
        evicted.video = Some(crate::service::renders::VideoView {
            status: "available".into(),
            progress: 0.0,
            url: Some(url.into()),
            error: None,
            waiting: None,
        });
        let html = media(&evicted);
        assert!(!html.contains("<video") && !html.contains("Rendering"), "{html}");
        assert!(
            html.contains("video removed") && html.contains("render it again"),
            "{html}"
        );
        assert!(!rendering_ep(&evicted));
    }

    fn rendering_ep(ep: &EpisodeView) -> bool {
        video_pending(ep).is_some()
    }
}
