//! `GET /submissions/{id}`: a submission as its team (or the organiser) sees it, rendered from
//! the same [`SubmissionView`] the JSON API answers, so the page never shows more than the API.
//!
//! Policy: on the test split the page shows the aggregate view only (scores, progress counts,
//! failure counts). It checks the split itself and renders no per-episode or per-instruction
//! rows there even if a view carried some: the service already leaves them out, and a page must
//! not be the place where that rule could break.

use kitchen_r_core::observations::ObservationTrack;
use maud::{Markup, html};

use super::layout::{score, scores_table};
use super::words::duration;
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

/// Whether an episode's video is being rendered for the page.
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

fn going(state: &str) -> bool {
    matches!(state, "queued" | "running")
}

/// The page body of `v`; `eta` while it runs.
pub(super) fn body(v: &SubmissionView, eta: Option<&Eta>) -> Markup {
    let test = v.split == "test";
    html! {
        table {
            tr { th { "Team" } td { (v.team) } }
            tr { th { "Kind" } td { (if v.kind == "policy" { "policy endpoint" } else { "plan file" }) } }
            tr { th { "Split" } td { (v.split) } }
            tr { th { "Submitted (UTC)" } td { (v.created_at) } }
            @if let Some(p) = &v.policy {
                tr {
                    th { "Endpoint" }
                    td {
                        code { (p.endpoint) }
                        @if let Some(id) = p.plans {
                            " (integrated: linked to plan submission " a href={ "/submissions/" (id) } { (id) } ")"
                        }
                    }
                }
                tr {
                    th { "Observations" }
                    td {
                        @match p.observations {
                            ObservationTrack::Privileged => { b { "privileged" } " (ranked on the privileged boards)" }
                            ObservationTrack::Standard => { "standard" }
                        }
                    }
                }
            }
            tr {
                th { "Ranked" }
                td {
                    @match &v.unranked_reason {
                        None => { "yes" }
                        Some(why) => { "no: " (why) }
                    }
                }
            }
        }
        @if test { p.muted { "Test split: feedback is aggregate only (scores and counts)." } }
        @match &v.latest_run {
            None => { p { "Not scored yet." } }
            Some(run) => { (scored(run, test, eta)) }
        }
    }
}

/// What the latest run found: progress, scores, and on the dev split the rows behind them.
fn scored(run: &crate::service::RunView, test: bool, eta: Option<&Eta>) -> Markup {
    html! {
        @if let Some(e) = &run.evaluation { (progress(e, eta)) }
        h2 { "Scores" }
        p.muted {
            "Scoring run " (run.id) " (" (run.scorer_version) "), " (run.created_at)
            // A policy run's scores mean what its grasp mode made of the episodes.
            @if let Some(e) = &run.evaluation { ", episodes in the " b { (e.grasp_mode) } " grasp mode" }
            "."
        }
        (scores_table(&run.scores))
        @if let (Some(total), Some(present)) = (run.instructions_total, run.instructions_present) {
            p { "The file had a plan for " (present) " of " (total) " instructions." }
        }
        @if !test && !run.instructions.is_empty() { (instructions(run)) }
        @if let Some(e) = &run.evaluation {
            (failures(e))
            @if test && going(e.state) {
                // The rule is `crate::service::progress`'s; say it where the counts would be.
                p.muted {
                    "On the test split a run shows its progress only: its scores and failure                      counts appear once, when it ends."
                }
            }
            @if !test { (episodes(e)) }
        }
    }
}

fn progress(e: &PolicyRunView, eta: Option<&Eta>) -> Markup {
    html! {
        h2 { "Progress" }
        p {
            b { (state_words(e.state)) } ". "
            progress max=(e.episodes_total.max(1)) value=(e.episodes_done) {}
            " " (e.episodes_done) " of " (e.episodes_total) " episodes done, " (e.episodes_running) " running"
            @if e.episodes_retrying > 0 {
                ", " (e.episodes_retrying) " being retried after a platform failure (no cost to you)"
            }
            "."
            @match (going(e.state), eta) {
                (true, Some(eta)) => { " Estimated to finish in " (duration(eta.in_s)) " (at " (eta.at) " UTC)." }
                (true, None) => { " An estimate shows once the first episode has finished." }
                (false, _) => {}
            }
        }
        @if let Some(at) = &e.finished_at { p { "Finished at " (at) " UTC." } }
        @if e.needs_resimulation {
            p.banner {
                "The ground truth changed since these episodes ran: the scores are those of the old                  ground truth until the organiser simulates the run again."
            }
        }
        @if going(e.state) { p.muted { "This page reloads every " (REFRESH_S) " s while the run lasts." } }
    }
}

fn failures(e: &PolicyRunView) -> Markup {
    html! {
        @if !e.failure_counts.is_empty() {
            h2 { "Failures by kind" }
            table {
                tr { th { "Reason" } th { "Times" } }
                @for c in &e.failure_counts { tr { td { (c.reason) } td.n { (c.count) } } }
            }
        }
    }
}

fn instructions(run: &crate::service::RunView) -> Markup {
    html! {
        h2 { "Per instruction" }
        div.scroll {
            table {
                tr { th { "Instruction" } th { "Plan given" } th { "Steps right" } th { "EM" } }
                @for i in &run.instructions {
                    tr {
                        td { code { (i.id) } }
                        td { @if i.present { "yes" } @else { span.bad { "missing" } } }
                        td.n { (i.correct_steps) " of " (i.total_steps) }
                        td.n { (score(Some(i.em))) }
                    }
                }
            }
        }
    }
}

fn episodes(e: &PolicyRunView) -> Markup {
    html! {
        @if !e.retrying.is_empty() {
            h2 { "Being retried" }
            ul {
                @for r in &e.retrying {
                    li { code { (r.key) } ", attempt " (r.attempt) ": " (r.last_error) }
                }
            }
        }
        @if !e.episodes.is_empty() {
            h2 { "Episodes" }
            div.scroll {
                table.stack {
                    tr { th { "Episode" } th { "Result" } th { "Tasks" } th { "Wall time" } }
                    @for ep in &e.episodes { (episode_row(ep)) }
                }
            }
        }
    }
}

fn episode_row(ep: &EpisodeView) -> Markup {
    let offline = ep.mode == "offline";
    let mode = match offline {
        true => "offline (MSE against the expert)",
        false => "online (in the simulator)",
    };
    html! {
        tr {
            td {
                code { (ep.key) } br;
                span.muted { (mode) ", attempt " (ep.attempt) }
                (media(ep))
            }
            td {
                @match (&ep.failure, ep.success_rate, ep.mse) {
                    (Some(f), _, _) => { span.bad { "not run: " (f) } }
                    (None, Some(sr), _) => { "SR " (score(Some(sr))) }
                    (None, None, Some(mse)) => { "MSE " (score(Some(mse))) }
                    _ => { "–" }
                }
            }
            td {
                ol {
                    @for t in ep.tasks.iter().flatten() {
                        li {
                            // With a plot, each task wears its path colour (the plot's legend).
                            @if ep.plot_url.is_some() {
                                @let [r, g, b] = kitchen_r_core::topdown::task_colour(t.index);
                                span style=(format!("color:#{r:02x}{g:02x}{b:02x}")) title="path colour" { "■" } " "
                            }
                            code { (t.step) } ": "
                            @match (offline, t.success, t.failure_reason.is_empty()) {
                                (true, _, true) => { "MSE " (score(Some(t.mse))) " over " (t.mse_samples) " samples" }
                                (_, true, _) => { span.ok { "done" } " in " (format!("{:.1}", t.completion_time_s)) " s" }
                                (_, false, false) => { span.bad { "failed" } ": " (t.failure_reason) }
                                (_, false, true) => { span.bad { "failed" } }
                            }
                        }
                    }
                }
            }
            td.n { (duration(ep.wall_ms as f64 / 1000.0)) }
        }
    }
}

/// The episode's video and path plot, placed under the episode's key; only what exists is
/// shown (neither ever on the test split: the view has no URL there). Both are served to the
/// page's session at the API path less its `/api/v1` prefix. A video removed to keep a storage
/// budget, or whose render failed, shows its note instead of a player (never a broken one), and
/// one being rendered says so with its progress (docs/reference/videos.md).
fn media(ep: &EpisodeView) -> Markup {
    let page = |url: &str| url.strip_prefix("/api/v1").unwrap_or(url).to_string();
    let key = &ep.key;
    let waiting = ep.video.as_ref().and_then(|v| v.waiting.as_deref());
    html! {
        @if let (Some(_), Some(why)) = (video_pending(ep), waiting) {
            // No room for its video yet (the storage budgets): why, instead of a stuck 0 %.
            br; span class="muted video-waiting" role="status" { "Video waiting: " (why) }
        } @else if let Some(progress) = video_pending(ep) {
            // Never a player before its file exists: the page reloads until the render is done.
            br;
            span class="muted video-rendering" role="status" {
                "Rendering video… " (format!("{:.0}", (progress * 100.0).clamp(0.0, 100.0))) " %"
            }
        } @else if let Some(video) = ep.video_url.as_deref().filter(|_| video_ready(ep)) {
            @let src = page(video);
            // `preload=metadata`: a page of many episodes fetches only each file's header (the
            // server answers byte ranges) until one is played.
            br;
            video.episode-video controls preload="metadata" width="256" src=(src)
                aria-label={ "Episode " (key) ": both cameras with the task and time captioned" } {
                a href=(src) { "the episode video (MP4)" }
            }
        } @else if let Some(note) = ep.video_note.as_deref() {
            br; span class="muted video-note" { (note) }
            // Removed to keep a budget but still renderable from its trace: asking renders it.
            @if let Some(video) = ep.video_url.as_deref() { " " a href=(page(video)) { "render it again" } }
        }
        @if let Some(plot) = ep.plot_url.as_deref() {
            @let src = page(plot);
            br;
            a href=(src) {
                img.plot src=(src) width="240"
                    alt={ "Where the robot went in " (key) ": the base path coloured by task, goal circles, a cross where a failed task ended" };
            }
        }
    }
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
        let html = media(&episode(None, Some(note))).into_string();
        assert!(!html.contains("<video"), "{html}");
        // Escaped as text: maud leaves `'` as it is (its attributes are double-quoted).
        assert!(html.contains("team &lt;a&gt;'s videos within"), "{html}");
        let html = media(&episode(
            Some("/api/v1/submissions/1/episodes/dev-0001/video.mp4"),
            None,
        ))
        .into_string();
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
        let html = media(&ep).into_string();
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
        let html = media(&evicted).into_string();
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
