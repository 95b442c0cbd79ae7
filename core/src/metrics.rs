//! The contest's metrics, exactly as the paper defines them (§METRICS).
//!
//! - **EM**: mean over ground-truth plans of (correct steps / ground-truth steps). A predicted step
//!   is correct only if it equals the ground-truth step at the same index character for
//!   character; a missing plan scores 0; predicted steps beyond the ground truth's length are
//!   ignored, so padding a plan never helps.
//! - **MSE**: mean squared error between predicted and expert action chunks, averaged over all
//!   predictions.
//! - **P** = 1/EM + mean over instructions of (mean over their tasks of MSE). Lower is better;
//!   EM = 0 gives +inf.
//! - **M** = mean over instructions of (mean over their tasks of (EM_j + SR_j)), EM_j the per-step
//!   exact match and SR_j the task's success.
//!
//! Everything here is total: empty inputs give a defined number (documented per function), never
//! a panic or a NaN, because a scorer that crashes on a participant's odd file is a platform bug.

use std::collections::HashMap;

/// Per-step exact match: `EM_j` for every step j of the ground truth.
///
/// Steps of `predicted` past the end of `ground_truth` are ignored; a predicted plan shorter
/// than the ground truth leaves the remaining steps unmatched.
pub fn step_matches<P: AsRef<str>, G: AsRef<str>>(predicted: &[P], ground_truth: &[G]) -> Vec<bool> {
    ground_truth
        .iter()
        .enumerate()
        .map(|(j, g)| predicted.get(j).is_some_and(|p| p.as_ref() == g.as_ref()))
        .collect()
}

/// How one predicted plan fares against its ground truth.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PlanMatch {
    /// `PS_i`: steps equal to the ground truth at the same index.
    pub correct: usize,
    /// `N_i`: steps in the ground-truth plan.
    pub total: usize,
}

impl PlanMatch {
    /// Score one plan; `None` (no plan submitted) matches nothing.
    pub fn of<P: AsRef<str>, G: AsRef<str>>(predicted: Option<&[P]>, ground_truth: &[G]) -> PlanMatch {
        let correct = predicted.map_or(0, |p| {
            step_matches(p, ground_truth).iter().filter(|m| **m).count()
        });
        PlanMatch {
            correct,
            total: ground_truth.len(),
        }
    }

    /// `PS_i / N_i`. An empty ground-truth plan has nothing to get wrong and scores 1.
    pub fn accuracy(&self) -> f64 {
        if self.total == 0 {
            1.0
        } else {
            self.correct as f64 / self.total as f64
        }
    }
}

/// EM over a split: `ground_truth` is every `(id, plan)` of the split, `predicted` what the
/// participant sent. Ids in `predicted` that are not in `ground_truth` are ignored (the server
/// refuses such files before scoring). No ground truth at all gives 0.
pub fn exact_match<G: AsRef<str>, P: AsRef<str>>(
    ground_truth: &[(&str, &[G])],
    predicted: &HashMap<&str, &[P]>,
) -> f64 {
    let matches: Vec<PlanMatch> = ground_truth
        .iter()
        .map(|(id, gt)| PlanMatch::of(predicted.get(id).copied(), gt))
        .collect();
    mean(matches.iter().map(PlanMatch::accuracy))
}

/// Mean of the accuracies of already scored plans (the EM of a scored split).
pub fn em_of(matches: &[PlanMatch]) -> f64 {
    mean(matches.iter().map(PlanMatch::accuracy))
}

/// MSE charged for a prediction the policy failed to make (timeout, unreachable endpoint, bad
/// chunk). Every value of an action inside the robot's physical ranges (positions within the
/// ±1 m reach box, quaternion components in [-1, 1], gripper in [0, 1], |v|, |ω| < 1) differs
/// from the expert's by at most 2, so a chunk inside those ranges scores at most 4: a failure is
/// never cheaper than an answer. Workers charge it per decision point; the server charges it
/// for an offline task that came back with no sample because of the policy.
pub const FAILED_PREDICTION_MSE: f64 = 4.0;

/// Mean squared error between two equally long action chunks (16×10 values, row-major).
/// `None` when the lengths differ or the chunks are empty: such a chunk is refused upstream,
/// not scored.
pub fn chunk_mse(predicted: &[f32], expert: &[f32]) -> Option<f64> {
    if predicted.len() != expert.len() || predicted.is_empty() {
        return None;
    }
    let sum: f64 = predicted
        .iter()
        .zip(expert)
        .map(|(p, e)| {
            let d = f64::from(*p) - f64::from(*e);
            d * d
        })
        .sum();
    Some(sum / predicted.len() as f64)
}

/// P = 1/EM + mean over instructions of (mean over tasks of MSE).
///
/// `task_mse[i]` holds the per-task MSEs of instruction i. EM ≤ 0 (or NaN) gives +inf; an
/// instruction without tasks contributes 0 and no instructions at all give an MSE term of 0.
pub fn p_score(em: f64, task_mse: &[Vec<f64>]) -> f64 {
    if em.is_nan() || em <= 0.0 {
        return f64::INFINITY;
    }
    1.0 / em + mean(task_mse.iter().map(|tasks| mean(tasks.iter().copied())))
}

/// M = mean over instructions of (mean over tasks of (EM_j + SR_j)).
///
/// `tasks[i]` holds `(EM_j, SR_j)` for each task of instruction i, each 0 or 1. The range is
/// [0, 2]. An instruction without tasks contributes 0; no instructions give 0.
pub fn m_score(tasks: &[Vec<(bool, bool)>]) -> f64 {
    mean(tasks.iter().map(|inst| {
        mean(
            inst.iter()
                .map(|(em, sr)| f64::from(u8::from(*em)) + f64::from(u8::from(*sr))),
        )
    }))
}

/// Arithmetic mean; 0 for no values (so an empty split or plan never yields NaN).
pub fn mean(values: impl IntoIterator<Item = f64>) -> f64 {
    let (sum, n) = values.into_iter().fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    if n == 0 { 0.0 } else { sum / n as f64 }
}

#[cfg(test)]
mod tests {
    use super::*;

    const GT: [&str; 4] = [
        "move to the blue zone",
        "pick the bowl",
        "move to the red zone",
        "place the bowl",
    ];

    #[test]
    fn exact_plan_scores_one() {
        assert_eq!(PlanMatch::of(Some(&GT[..]), &GT).accuracy(), 1.0);
    }

    #[test]
    fn extra_predicted_steps_do_not_help_or_hurt() {
        let mut p: Vec<&str> = GT.to_vec();
        p.push("pick the cup");
        p.push("place the cup");
        assert_eq!(
            PlanMatch::of(Some(&p[..]), &GT),
            PlanMatch { correct: 4, total: 4 }
        );
        let mut wrong = vec!["pick the cup"; 3];
        wrong.push("place the bowl");
        wrong.extend(GT);
        // Only index 3 matches; the correct steps after the ground truth's end count for nothing.
        assert_eq!(PlanMatch::of(Some(&wrong[..]), &GT).accuracy(), 0.25);
    }

    #[test]
    fn short_plan_scores_its_matching_prefix() {
        assert_eq!(PlanMatch::of(Some(&GT[..2]), &GT).accuracy(), 0.5);
    }

    #[test]
    fn shifted_plan_matches_only_at_same_index() {
        let shifted = ["move to the blue zone", "move to the blue zone", "pick the bowl"];
        assert_eq!(PlanMatch::of(Some(&shifted[..]), &GT).correct, 1);
    }

    #[test]
    fn comparison_is_character_exact() {
        let p = [
            "Move to the blue zone",
            "pick the bowl ",
            "move to the red zone",
            "place the bowl",
        ];
        assert_eq!(PlanMatch::of(Some(&p[..]), &GT).correct, 2);
    }

    #[test]
    fn empty_and_missing_plans_score_zero() {
        let empty: [&str; 0] = [];
        assert_eq!(PlanMatch::of(Some(&empty[..]), &GT).accuracy(), 0.0);
        assert_eq!(PlanMatch::of(None::<&[&str]>, &GT).accuracy(), 0.0);
    }

    #[test]
    fn em_averages_per_plan_accuracy_with_missing_ids_at_zero() {
        let gt2 = [
            "move to the green zone",
            "pick the cup",
            "move to the red zone",
            "place the cup",
            "pick the fork",
        ];
        let gt: Vec<(&str, &[&str])> = vec![("a", &GT[..]), ("b", &gt2[..]), ("c", &GT[..])];
        let half = [GT[0], GT[1]];
        let three = ["move to the green zone", "pick the cup", "x", "place the cup"];
        let pred: HashMap<&str, &[&str]> = [("a", &half[..]), ("b", &three[..])].into();
        // a: 2/4, b: 3/5, c missing: 0 → (0.5 + 0.6 + 0) / 3
        let em = exact_match(&gt, &pred);
        assert!((em - 1.1 / 3.0).abs() < 1e-12, "{em}");
    }

    #[test]
    fn em_of_nothing_is_zero_not_nan() {
        let gt: Vec<(&str, &[&str])> = vec![];
        assert_eq!(exact_match(&gt, &HashMap::<&str, &[&str]>::new()), 0.0);
        assert_eq!(em_of(&[]), 0.0);
    }

    #[test]
    fn p_with_zero_em_is_infinite() {
        assert_eq!(p_score(0.0, &[vec![0.1]]), f64::INFINITY);
        assert_eq!(p_score(f64::NAN, &[]), f64::INFINITY);
    }

    #[test]
    fn p_adds_inverse_em_and_mean_of_task_means() {
        // 1/0.5 + mean(mean(0.1, 0.3), mean(0.4)) = 2 + (0.2 + 0.4) / 2 = 2.3
        let p = p_score(0.5, &[vec![0.1, 0.3], vec![0.4]]);
        assert!((p - 2.3).abs() < 1e-12, "{p}");
    }

    #[test]
    fn m_is_mean_of_task_means_of_em_plus_sr() {
        // instruction 1: (1+1, 1+0) → 1.5; instruction 2: (0+1, 0+0, 0+0, 1+1) → 0.75
        let tasks = vec![
            vec![(true, true), (true, false)],
            vec![(false, true), (false, false), (false, false), (true, true)],
        ];
        assert!((m_score(&tasks) - 1.125).abs() < 1e-12);
        assert_eq!(m_score(&[]), 0.0);
    }

    #[test]
    fn chunk_mse_is_mean_of_squared_differences() {
        let a = [0.0f32, 1.0, 2.0, 3.0];
        let b = [0.0f32, 0.0, 0.0, 1.0];
        // (0 + 1 + 4 + 4) / 4
        assert_eq!(chunk_mse(&a, &b), Some(2.25));
        assert_eq!(chunk_mse(&a, &b[..3]), None);
        assert_eq!(chunk_mse(&[], &[]), None);
    }
}
