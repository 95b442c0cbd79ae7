//! What a worker's report may say, checked against the leased job, and how much text of it is
//! stored.
//!
//! Policy: workers hold the worker token, but a report is still input. Its task results must
//! fit the job's plan: task indices within the episode's tasks (the plan's steps, capped by
//! `max_plan_steps`), each at most once, each naming its plan step; an offline task's MSE at
//! most the failed-prediction MSE (no sample scores worse) and its sample count sane (at most
//! one per [`MIN_SAMPLE_SPACING_S`] of the task's time limit). A report that does not fit is
//! refused as INVALID_ARGUMENT saying what is wrong, and nothing is recorded: the lease stays
//! as it was, so the worker may report again or the lease expires and the job is retried.
//!
//! Text that a participant's endpoint controls (its error messages end up in task failure
//! reasons, platform errors and the log tail) is capped when stored, whatever the worker sent:
//! [`MAX_REASON_CHARS`] per failure reason or error, [`MAX_LOG_LINE_CHARS`] per log line (the
//! tail itself keeps its last 64 KiB). A cut text ends in `…`.

use std::collections::HashSet;

use kitchen_r_core::metrics::FAILED_PREDICTION_MSE;

use crate::episodes::{JobSpec, Mode, TaskOutcome};

/// Most characters of a stored failure reason, platform error or release reason.
pub(crate) const MAX_REASON_CHARS: usize = 512;
/// Most characters of one stored log-tail line.
pub(crate) const MAX_LOG_LINE_CHARS: usize = 1024;
/// Offline samples are taken at decision points, at most one per control step (0.1 s at the
/// paper's 10 Hz); a tenth of that leaves room for any worker's control rate.
const MIN_SAMPLE_SPACING_S: f64 = 0.01;

/// Why the task results of a report do not fit `spec`; `Ok` when they do.
pub(super) fn check_tasks(tasks: &[TaskOutcome], spec: &JobSpec) -> Result<(), String> {
    let count = spec.task_count();
    if tasks.len() > count {
        return Err(format!(
            "{} task results for an episode of {count} tasks",
            tasks.len()
        ));
    }
    let max_samples = (spec.task_time_limit_s / MIN_SAMPLE_SPACING_S).ceil() as u64 + 1;
    let mut seen = HashSet::new();
    for t in tasks {
        let i = t.index as usize;
        if i >= count {
            return Err(format!(
                "task index {i} is out of range: the episode has {count} tasks (0..={})",
                count.saturating_sub(1)
            ));
        }
        if !seen.insert(i) {
            return Err(format!("task index {i} is reported twice"));
        }
        if t.step != spec.plan[i] {
            return Err(format!(
                "task {i} names step {:?}, but the plan's step {i} is {:?}",
                cap_text(&t.step, 80),
                spec.plan[i]
            ));
        }
        if spec.mode == Mode::Offline && t.mse > FAILED_PREDICTION_MSE + 1e-9 {
            return Err(format!(
                "task {i}: MSE {} is above the failed-prediction MSE {FAILED_PREDICTION_MSE}",
                t.mse
            ));
        }
        if spec.mode == Mode::Offline && u64::from(t.mse_samples) > max_samples {
            return Err(format!(
                "task {i}: {} MSE samples, more than a task of {} s can have ({max_samples})",
                t.mse_samples, spec.task_time_limit_s
            ));
        }
    }
    Ok(())
}

/// `s` cut to at most `max` characters (on a character boundary), ending in `…` when cut.
pub(crate) fn cap_text(s: &str, max: usize) -> String {
    match s.char_indices().nth(max) {
        None => s.to_string(),
        Some(_) => {
            let keep = max.saturating_sub(1);
            let end = s.char_indices().nth(keep).map_or(s.len(), |(i, _)| i);
            format!("{}…", &s[..end])
        }
    }
}

/// Every task's failure reason capped at [`MAX_REASON_CHARS`].
pub(super) fn cap_reasons(tasks: &mut [TaskOutcome]) {
    for t in tasks {
        if t.failure_reason.chars().nth(MAX_REASON_CHARS).is_some() {
            t.failure_reason = cap_text(&t.failure_reason, MAX_REASON_CHARS);
        }
    }
}

/// Every line of a log capped at [`MAX_LOG_LINE_CHARS`].
pub(super) fn cap_log_lines(log: &str) -> String {
    let capped: Vec<String> = log.split('\n').map(|l| cap_text(l, MAX_LOG_LINE_CHARS)).collect();
    capped.join("\n")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_is_cut_on_a_character_boundary_with_an_ellipsis() {
        assert_eq!(cap_text("abc", 3), "abc");
        assert_eq!(cap_text("abcd", 3), "ab…");
        let long = "é".repeat(600);
        let cut = cap_text(&long, MAX_REASON_CHARS);
        assert_eq!(cut.chars().count(), MAX_REASON_CHARS);
        assert!(cut.ends_with("é…"));
        let mut tasks = vec![TaskOutcome {
            failure_reason: "x".repeat(6 << 10),
            ..TaskOutcome::default()
        }];
        cap_reasons(&mut tasks);
        assert_eq!(tasks[0].failure_reason.chars().count(), MAX_REASON_CHARS);
        let log = format!("short\n{}\nend", "y".repeat(5000));
        let lines: Vec<usize> = cap_log_lines(&log).lines().map(|l| l.chars().count()).collect();
        assert_eq!(lines, vec![5, MAX_LOG_LINE_CHARS, 3]);
    }
}
