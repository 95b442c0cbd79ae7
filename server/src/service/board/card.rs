//! A board row's results card (docs/reference/leaderboard.md#results-cards), from the run the
//! row shows and the episodes it recorded: pure, the service reads the store.

use std::collections::BTreeSet;

use kitchen_r_core::GraspMode;
use kitchen_r_core::observations::{ObservationTrack, PrivilegedScope};
use sha2::{Digest, Sha256};

use crate::episodes::JobSpec;
use crate::leaderboard::Card;
use crate::store::board::ShownRun;

/// What a card says for a value this server did not store when the run was made.
pub(crate) const UNKNOWN: &str = "unknown";

/// The dataset digest a scorer version names (`control/1+dataset-<digest>`).
pub(crate) fn dataset_of(scorer_version: &str) -> String {
    match scorer_version.split_once("+dataset-") {
        Some((_, digest)) if !digest.is_empty() => digest.to_string(),
        _ => UNKNOWN.into(),
    }
}

/// The distinct episode rules of `specs`, one line each, sorted, in the keys of
/// `configs/eval.toml` (what a local `kitchen-r eval` takes them from), and the first 16 hex
/// digits of the sha256 of those lines joined by newlines: equal for runs made under equal
/// rules, whatever their instructions and endpoints.
pub(crate) fn rules<'a>(specs: impl IntoIterator<Item = &'a JobSpec>) -> (Vec<String>, String) {
    let lines: BTreeSet<String> = (specs.into_iter())
        .map(|s| {
            format!(
                "seed={} task_time_limit={} execute={} teleport_on_failure={} max_plan_steps={} \
                 grasp={} privileged_observations={}",
                s.seed,
                s.task_time_limit_s,
                s.actions_executed_per_chunk,
                s.teleport_on_failure,
                s.max_plan_steps,
                s.grasp.as_str(),
                match s.privileged_observations {
                    None => "none",
                    Some(PrivilegedScope::Episode) => "episode",
                    Some(PrivilegedScope::SubTask) => "sub_task",
                },
            )
        })
        .collect();
    if lines.is_empty() {
        return (Vec::new(), UNKNOWN.into());
    }
    let lines: Vec<String> = lines.into_iter().collect();
    let digest = Sha256::digest(lines.join("\n"));
    let hash = digest.iter().take(8).map(|b| format!("{b:02x}")).collect();
    (lines, hash)
}

/// A policy row's card: `specs` are the recorded episodes' job specs.
pub(crate) fn policy(
    run: &ShownRun,
    specs: &[&JobSpec],
    grasp: GraspMode,
    observations: ObservationTrack,
) -> Card {
    let (config, config_hash) = rules(specs.iter().copied());
    Card {
        run_id: run.id,
        binary_version: run.binary_version.clone().unwrap_or_else(|| UNKNOWN.into()),
        config_hash,
        config,
        dataset: dataset_of(&run.scorer_version),
        seeds: specs
            .iter()
            .map(|s| s.seed)
            .collect::<BTreeSet<_>>()
            .into_iter()
            .collect(),
        grasp_mode: Some(grasp),
        observations: Some(observations),
        episodes: specs.len() as u64,
        scorer_version: run.scorer_version.clone(),
    }
}

/// A planning row's card: plan files have no episode rules and no seed.
pub(crate) fn planning(run: &ShownRun, instructions: u64) -> Card {
    Card {
        run_id: run.id,
        binary_version: run.binary_version.clone().unwrap_or_else(|| UNKNOWN.into()),
        config_hash: "n/a".into(),
        config: Vec::new(),
        dataset: dataset_of(&run.scorer_version),
        seeds: Vec::new(),
        grasp_mode: None,
        observations: None,
        episodes: instructions,
        scorer_version: run.scorer_version.clone(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_dataset_is_read_from_the_scorer_version_or_unknown() {
        assert_eq!(dataset_of("control/1+dataset-0123abcd"), "0123abcd");
        assert_eq!(dataset_of("control/1"), "unknown");
        assert_eq!(rules([]), (Vec::new(), "unknown".to_string()));
    }
}
