//! The oracle must be able to do what the benchmark asks: it completes at least 98 % of the
//! tasks of at least 50 dev episodes through the same runner participants are scored by.

use kitchen_r_worker::eval::{EvalOptions, EvalReport, evaluate};

// Blocked (issue 4 stays open): since the twin's servoed-arm change the base is sometimes ejected
// metres during ordinary driving, and the oracle reaches 0.813 of 299 tasks over 50 dev episodes.
// Run it with `cargo test -p kitchen-r-worker --test oracle -- --ignored` once the twin is fixed.
#[test]
#[ignore = "blocked by the twin's base-ejection bug; see issue 4"]
fn oracle_completes_at_least_98_percent_of_dev_tasks() {
    let n = std::env::var("ORACLE_EPISODES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(50);
    let opts = EvalOptions {
        episodes: Some(n),
        jobs: std::thread::available_parallelism().map_or(1, |n| n.get()),
        ..EvalOptions::default()
    };
    let report: EvalReport = evaluate(&opts, &mut |_, _| {}).unwrap();
    let failures: Vec<String> = report
        .episodes
        .iter()
        .flat_map(|e| {
            e.tasks.iter().filter(|t| !t.success).map(move |t| {
                format!(
                    "{} task {} {:?}: {}",
                    e.episode_id,
                    t.index,
                    t.step,
                    t.failure.clone().unwrap_or_default()
                )
            })
        })
        .collect();
    eprintln!(
        "oracle SR {:.4} over {} tasks of {} episodes",
        report.overall.sr,
        report.overall.tasks,
        report.episodes.len()
    );
    for f in &failures {
        eprintln!("failed: {f}");
    }
    assert!(report.episodes.len() >= n);
    assert!(
        report.overall.sr >= 0.98,
        "oracle SR {:.3}; failures:\n{}",
        report.overall.sr,
        failures.join("\n")
    );
}
