//! The public leaderboard page (`GET /`, and `GET /api/v1/leaderboard?format=html` for one
//! board): one table per board, all of one split, built with maud, which escapes every value
//! (team names are chosen by participants). The service hands over the boards
//! ([`BoardPage`]) and caches what this renders. Scores print as the CSV prints them, each with
//! its 95 % interval below it; the board says in words how ties are decided, and each row's
//! results card folds open in its last column (docs/reference/leaderboard.md).

use kitchen_r_core::GraspMode;
use kitchen_r_core::dataset::Split;
use kitchen_r_core::observations::ObservationTrack;
use maud::{DOCTYPE, Markup, PreEscaped, html};

use crate::leaderboard::render::{columns, fmt_interval, interval_columns, rank};
use crate::leaderboard::{BoardPage, Card, Leaderboard, Row, Track};
use crate::scores::fmt_score;

const STYLE: &str = "body{font-family:system-ui,sans-serif;margin:2rem auto;max-width:60rem;padding:0 1rem}\
table{border-collapse:collapse;width:100%;margin-bottom:2rem}th,td{padding:.4rem .6rem;border-bottom:1px solid #ddd;text-align:left}\
td.n{text-align:right;font-variant-numeric:tabular-nums}th{background:#f4f4f4}tr.baseline{color:#555;background:#fafafa}\
.banner{background:#fff4d6;border:1px solid #e0b84a;padding:.6rem .8rem}\
small.ci{display:block;color:#666;white-space:nowrap}dl.card{margin:.3rem 0;font-size:.85rem}\
dl.card dt{font-weight:600}dl.card dd{margin:0 0 .2rem 0;overflow-wrap:anywhere}\
@media(max-width:40rem){table{display:block;overflow-x:auto}}";

fn describe(track: Track) -> &'static str {
    match track {
        Track::Planning => "best plan submission per team by Exact Match",
        Track::Control => "best policy per team by success rate SR, then lower MSE",
        Track::Integrated => "best policy + plans pair per team by M, then lower P",
    }
}

/// How a policy board's heading, anchor and note name its observation track; planning has none.
fn board_label(board: &Leaderboard) -> (&'static str, &'static str, Markup) {
    match board.observations {
        None => ("", "", html! {}),
        Some(ObservationTrack::Standard) => (
            " — standard observations",
            "",
            html! {
                " Standard observations: cameras, the sub-task and the robot's state relative to \
                 the episode start."
            },
        ),
        Some(ObservationTrack::Privileged) => (
            " — privileged observations",
            "-privileged",
            html! {
                " " b { "Privileged observations" } ": these policies also received the robot's \
                 pose in the scene, the current task's goal and key objects' poses (on the test \
                 split only what the sub-task names), so they are ranked apart from standard runs."
            },
        ),
    }
}

/// How a policy board's heading, anchor and note name its grasp mode; planning has none. The
/// contest's mode gets no anchor suffix, so links to `#control` keep working whatever it is.
fn grasp_label(board: &Leaderboard, contest: GraspMode) -> (String, String, Markup) {
    let Some(mode) = board.grasp_mode else {
        return (String::new(), String::new(), html! {});
    };
    let rule = match mode {
        GraspMode::Abstract => html! {
            "the " b { "abstract grasp" } ": an object whose grasp point lies between the closing \
             fingers is carried at its offset from the gripper"
        },
        GraspMode::Physical => html! {
            "the " b { "physical grasp" } ": force-limited finger joints, only friction contacts \
             hold an object"
        },
    };
    let note = match mode == contest {
        true => html! { " Episodes ran with " (rule) " (this contest's grasp mode)." },
        false => html! {
            " Episodes ran with " (rule) ", not this contest's " (contest) " grasp: these runs \
             were evaluated before the organiser changed the mode and are ranked only among \
             themselves."
        },
    };
    let anchor = match mode == contest {
        true => String::new(),
        false => format!("-{mode}"),
    };
    (format!(" — {mode} grasp"), anchor, note)
}

/// What a policy row's run state adds after its submission id.
fn state_note(policy: bool, r: &Row) -> &'static str {
    match (policy, r.state.as_deref()) {
        (true, Some("active")) => " (evaluating)",
        (true, Some("platform_failed")) => " (platform failure)",
        (true, Some("cancelled")) => " (cancelled)",
        _ => "",
    }
}

/// SR per task kind, each with its interval (policy rows).
fn kinds(r: &Row) -> Markup {
    html! {
        @for (kind, k) in &r.intervals.sr_by_kind {
            small.ci {
                (kind) " " (fmt_score(Some(k.sr))) " " (fmt_interval(Some(k.interval)))
                " (" (k.successes) "/" (k.tasks) ")"
            }
        }
    }
}

/// A row's results card, folded (the board's last column).
fn card(c: &Card) -> Markup {
    html! { details { summary { "card" } (card_list(c)) } }
}

/// A row's results card: what its score was computed with (also the entry's summary page).
pub(in crate::http) fn card_list(c: &Card) -> Markup {
    let seeds = match c.seeds.is_empty() {
        true => "n/a".to_string(),
        false => c.seeds.iter().map(u64::to_string).collect::<Vec<_>>().join(", "),
    };
    html! {
        dl.card {
            dt { "Run" } dd { (c.run_id) " (" (c.scorer_version) ")" }
            dt { "Binary version" } dd { (c.binary_version) }
            dt { "Config hash" } dd { code { (c.config_hash) } }
            @for line in &c.config { dd { code { (line) } } }
            dt { "Dataset" } dd { code { (c.dataset) } }
            dt { "Seeds" } dd { (seeds) }
            @if let Some(g) = c.grasp_mode { dt { "Grasp mode" } dd { (g) } }
            @if let Some(o) = c.observations { dt { "Observations" } dd { (o) } }
            dt { "Episodes" } dd { (c.episodes) }
        }
    }
}

fn table(board: &Leaderboard, contest: GraspMode) -> Markup {
    let cols = columns(board.track);
    let intervals = interval_columns(board.track);
    let policy = board.track != Track::Planning;
    let track = board.track.as_str();
    let (heading, anchor, note) = board_label(board);
    let (grasp_heading, grasp_anchor, grasp_note) = grasp_label(board, contest);
    let mut query = match board.observations {
        Some(ObservationTrack::Privileged) => "&observations=privileged".to_string(),
        _ => String::new(),
    };
    if let Some(mode) = board.grasp_mode.filter(|m| *m != contest) {
        query.push_str(&format!("&grasp_mode={mode}"));
    }
    let api = format!("/api/v1/leaderboard?track={track}&split={}{query}", board.split);
    let title = track[..1].to_uppercase() + &track[1..];
    html! {
        h2 id={ (track) (anchor) (grasp_anchor) } { (title) " track" (heading) (grasp_heading) }
        p {
            (describe(board.track)) ", each score with its 95 % interval." (note) (grasp_note) " "
            a href={ (api) "&format=csv" } { "CSV" } " · " a href=(api) { "JSON" }
        }
        p.ties { b { "Ties: " } (board.ties) }
        table {
            thead {
                tr {
                    th { "Rank" } th { "Team" }
                    @for (name, _) in cols { th { (name.to_uppercase()) } }
                    @if policy { th { "SR by task kind" } }
                    th { "Submission" } th { "Submitted (UTC)" } th { "Results card" }
                }
            }
            tbody {
                @for r in &board.rows {
                    tr class=[r.baseline.then_some("baseline")] {
                        td { (rank(r)) }
                        td { (r.team) @if r.baseline { " " i { "(baseline)" } } }
                        @for ((_, get), (_, iv)) in cols.iter().zip(intervals) {
                            td.n { (fmt_score(get(r))) small.ci { (fmt_interval(iv(r))) } }
                        }
                        @if policy { td { (kinds(r)) } }
                        // The entry's public summary: what this row shows, on a page of its own.
                        td.n {
                            a href={ "/leaderboard/" (track) "/" (board.split) "/" (r.submission_id) } { (r.submission_id) }
                            (state_note(policy, r))
                            @if r.observations == Some(ObservationTrack::Privileged) { " (privileged)" }
                            // A run of another grasp mode than the contest's says so on its row.
                            @if let Some(m) = r.grasp_mode.filter(|m| *m != contest) { " (" (m) " grasp)" }
                        }
                        td { (r.submitted_at) }
                        td { @if let Some(c) = &r.card { (card(c)) } }
                    }
                }
                @if board.rows.is_empty() {
                    tr { td colspan=(cols.len() + 5 + usize::from(policy)) { "No submissions yet." } }
                }
            }
        }
    }
}

/// The integrity rules as an HTML list: the leaderboard page and the contest home show this
/// one text.
pub(in crate::http) fn integrity_rules() -> Markup {
    html! {
        ul {
            li {
                "Test-split feedback is aggregate only: a submission shows its scores and counts of \
                 failure reasons, never a result per instruction or task."
            }
            li {
                "A policy endpoint receives each task's sub-task sentence (a ground-truth plan step) \
                 but no instruction id: episode ids are opaque."
            }
            li {
                "Because a test-split policy run shows the endpoint the test plans' steps, a team's \
                 test plan files created after its first test-split policy run are scored but not \
                 ranked, and an integrated test run must link a plan file created before that run."
            }
            li {
                "A policy that refuses or fails its offline (MSE) episodes is charged the failure \
                 penalty at every decision point, as if it had answered badly."
            }
        }
    }
}

/// The public page: one table per board, all of one split; the contest's grasp mode
/// (`[control] grasp`) is named at the top, and boards of the other mode are labelled as such.
pub(crate) fn render(p: &BoardPage) -> String {
    let (split, contest) = (p.split, p.contest);
    let other = match split {
        Split::Dev => Split::Test,
        Split::Test => Split::Dev,
    };
    html! {
        (DOCTYPE)
        html lang="en" {
            head {
                meta charset="utf-8";
                title { "Kitchen-R leaderboard" }
                meta name="viewport" content="width=device-width,initial-scale=1";
                style { (PreEscaped(STYLE)) }
            }
            body {
                h1 { "Kitchen-R leaderboard" }
                @if split == Split::Test && p.public_sample {
                    p.banner {
                        b { (crate::content::PUBLIC_SAMPLE_NOTICE) } ": this server scores the \
                        repository's public test sample, whose answers anyone can rebuild from \
                        public files. Rankings here show the tools work; they do not rank planners."
                    }
                }
                p {
                    a href="/contest" { "The contest: tracks, metrics, how to take part, data and rules" }
                    " · " a href="/team" { "Team page" }
                }
                p {
                    b { (split) } " split. " a href={ "/?split=" (other) } { "Show the " (other) " split" }
                    ". Baseline rows are organiser reference runs and take no rank. Policies that \
                     received privileged observations are ranked on boards of their own, labelled \
                     privileged."
                }
                p.grasp {
                    "Grasp mode of this contest: " b { (contest) } " (policy episodes' control and \
                     integrated scores are from it; runs of another grasp mode are ranked on boards \
                     of their own, labelled)."
                }
                @for b in &p.boards { (table(b, contest)) }
                h2 { "Rules that keep the test split honest" }
                (integrity_rules())
            }
        }
    }
    .into_string()
}
