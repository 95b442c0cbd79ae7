//! The ranking rule (docs/reference/leaderboard.md#ties): competition ranking by overlapping
//! intervals on the primary metric, against the entry holding the rank above; off, one rank each.

use super::intervals::{Interval, Intervals};
use super::*;

/// A finished control row with SR `sr` and SR interval `[lo, hi]`.
fn row(team: &str, sr: f64, (low, high): (f64, f64)) -> Row {
    Row {
        rank: None,
        team: team.into(),
        submission_id: 1,
        scores: Scores {
            sr: Some(sr),
            ..Scores::default()
        },
        submitted_at: String::new(),
        state: Some("finished".into()),
        baseline: false,
        observations: None,
        grasp_mode: None,
        intervals: Intervals {
            sr: Some(Interval { low, high }),
            ..Intervals::default()
        },
        card: None,
    }
}

fn ranks(rows: Vec<Row>, ties: bool) -> Vec<Option<usize>> {
    ranked(rows, Track::Control, ties)
        .iter()
        .map(|r| r.rank)
        .collect()
}

#[test]
fn overlapping_intervals_share_the_rank_above_competition_style() {
    let rows = vec![
        row("a", 0.9, (0.8, 0.95)),
        row("b", 0.6, (0.5, 0.7)),
        row("c", 0.55, (0.45, 0.65)),
        row("d", 0.2, (0.1, 0.3)),
    ];
    assert_eq!(ranks(rows.clone(), true), [Some(1), Some(2), Some(2), Some(4)]);
    assert_eq!(ranks(rows, false), [Some(1), Some(2), Some(3), Some(4)]);
}

/// An entry is compared with the first entry of the rank above, not the one just above it, so
/// a run of close scores does not chain into one rank.
#[test]
fn ties_do_not_chain_past_the_rank_holder() {
    let rows = vec![
        row("a", 0.9, (0.8, 1.0)),
        row("b", 0.8, (0.7, 0.85)),
        row("c", 0.7, (0.6, 0.75)),
        row("d", 0.6, (0.5, 0.65)),
    ];
    // b overlaps a: rank 1. c overlaps b but not a: rank 3; d overlaps c: rank 3.
    assert_eq!(ranks(rows, true), [Some(1), Some(1), Some(3), Some(3)]);
}

#[test]
fn baselines_are_passed_over_and_unscored_entries_never_tie() {
    let mut base = row("(baseline)", 0.85, (0.8, 0.9));
    base.baseline = true;
    let mut evaluating = row("e", 0.88, (0.8, 0.95));
    evaluating.state = Some("active".into());
    let mut unscored = row("u", 0.0, (0.0, 1.0));
    unscored.scores.sr = None;
    let rows = vec![
        row("a", 0.9, (0.8, 0.95)),
        base,
        row("b", 0.86, (0.75, 0.9)),
        evaluating,
        unscored,
    ];
    assert_eq!(ranks(rows, true), [Some(1), None, Some(1), Some(3), Some(4)]);
}

#[test]
fn every_board_says_how_ties_are_decided() {
    assert!(TIES_BY_INTERVAL.contains("1, 2, 2, 4") && TIES_BY_INTERVAL.contains("95 %"));
    assert!(TIES_STRICT.contains("rank of its own"));
}
