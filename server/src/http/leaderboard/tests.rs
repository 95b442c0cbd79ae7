//! The leaderboard page's HTML: escaping, and how it names boards (observations, grasp mode).
//! The ranking and the CSV are `crate::leaderboard`'s tests.

use kitchen_r_core::GraspMode;
use kitchen_r_core::dataset::Split;
use kitchen_r_core::observations::ObservationTrack;

use super::render;
use crate::leaderboard::BoardPage;
use crate::leaderboard::tests::{board, control_board};

fn page(
    split: Split,
    boards: &[crate::leaderboard::Leaderboard],
    public_sample: bool,
    contest: GraspMode,
) -> String {
    render(&BoardPage {
        split,
        boards: boards.to_vec(),
        public_sample,
        contest,
    })
}

#[test]
fn html_escapes_team_names() {
    let page = page(Split::Test, &[board("<script>")], true, GraspMode::Abstract);
    assert!(page.contains("public sample"), "{page}");
    assert!(page.contains("&lt;script&gt;") && !page.contains("<script>"));
}

/// Every rendering names the board a policy row is ranked on (the CSV's column is tested with
/// the CSV).
#[test]
fn policy_boards_name_their_observation_track() {
    let privileged = control_board(ObservationTrack::Privileged);
    let html = page(
        Split::Dev,
        &[control_board(ObservationTrack::Standard), privileged],
        false,
        GraspMode::Abstract,
    );
    assert!(
        html.contains("<h2 id=\"control\">Control track — standard observations — abstract grasp</h2>"),
        "{html}"
    );
    assert!(
        html.contains(
            "<h2 id=\"control-privileged\">Control track — privileged observations — abstract grasp</h2>"
        ),
        "{html}"
    );
    assert!(
        html.contains("&amp;observations=privileged&amp;format=csv"),
        "{html}"
    );
    assert!(html.contains("(privileged)</td>"), "{html}");
}

/// Every policy rendering names the grasp mode; a board of another mode than the contest's is
/// labelled as such, row by row, and its links ask for its mode.
#[test]
fn another_grasp_mode_than_the_contests_is_labelled() {
    let mut physical = control_board(ObservationTrack::Standard);
    physical.grasp_mode = Some(GraspMode::Physical);
    physical.rows[0].grasp_mode = Some(GraspMode::Physical);
    let boards = [control_board(ObservationTrack::Standard), physical];
    let html = page(Split::Dev, &boards, false, GraspMode::Physical);
    assert!(
        html.contains("Grasp mode of this contest: <b>physical</b>"),
        "{html}"
    );
    assert!(
        html.contains("<h2 id=\"control\">Control track — standard observations — physical grasp</h2>"),
        "{html}"
    );
    // The abstract board is the other mode here: its own anchor, its rows and links say so.
    assert!(
        html.contains(
            "<h2 id=\"control-abstract\">Control track — standard observations — abstract grasp</h2>"
        ),
        "{html}"
    );
    assert!(html.contains("(abstract grasp)</td>"), "{html}");
    assert!(html.contains("&amp;grasp_mode=abstract&amp;format=csv"), "{html}");
    assert!(!html.contains("(physical grasp)</td>"), "{html}");
}

/// Every score shows its 95 % interval, the board says how ties are decided, and a row's
/// results card folds open in its last column.
#[test]
fn scores_show_their_intervals_ties_in_words_and_the_results_card() {
    let mut b = control_board(ObservationTrack::Standard);
    b.rows[0].card = Some(crate::leaderboard::Card {
        run_id: 9,
        binary_version: "unknown".into(),
        config_hash: "0123456789abcdef".into(),
        config: vec!["seed=7 task_time_limit=120".into()],
        dataset: "feedbeef".into(),
        seeds: vec![7],
        grasp_mode: Some(GraspMode::Abstract),
        observations: Some(ObservationTrack::Standard),
        episodes: 12,
        scorer_version: "control/1+dataset-feedbeef".into(),
    });
    let html = page(Split::Dev, &[b], false, GraspMode::Abstract);
    assert!(
        html.contains("0.250000<small class=\"ci\">[0.100000, 0.500000]</small>"),
        "{html}"
    );
    assert!(html.contains("<b>Ties: </b>Ranks are shared"), "{html}");
    assert!(
        html.contains("<dt>Config hash</dt><dd><code>0123456789abcdef</code></dd>"),
        "{html}"
    );
    assert!(html.contains("<dt>Seeds</dt><dd>7</dd>"), "{html}");
    assert!(html.contains("<dt>Binary version</dt><dd>unknown</dd>"), "{html}");
}
