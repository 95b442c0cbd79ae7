//! Benchmarks (not tests): oracle episode wall time with both cameras rendered at every policy
//! query, and collection throughput. `kitchen-r eval --jobs 1 --json` and `kitchen-r collect`
//! report the same figures from the command line.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::collect::{CollectConfig, CollectError, CollectOptions, collect};
use kitchen_r_episode::eval::{EvalError, EvalOptions, evaluate};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OracleBench {
    pub episodes: usize,
    /// Wall seconds per episode (world build included), one core.
    pub mean_wall_s: f64,
    pub p50_wall_s: f64,
    pub max_wall_s: f64,
    pub mean_sim_s: f64,
    pub policy_queries: u32,
    pub sr: f64,
}

/// The oracle on the first `episodes` dev instructions, one episode at a time on one thread.
/// The runner renders both cameras for every policy query (after each executed part-chunk).
pub fn oracle_episodes(episodes: usize) -> Result<OracleBench, EvalError> {
    let opts = EvalOptions {
        episodes: Some(episodes),
        jobs: 1,
        ..EvalOptions::default()
    };
    let r = evaluate(&opts, &mut |_, _| {})?;
    let mut walls: Vec<f64> = r.episodes.iter().map(|e| e.wall_time_s).collect();
    walls.sort_by(f64::total_cmp);
    let n = walls.len().max(1) as f64;
    Ok(OracleBench {
        episodes: r.episodes.len(),
        mean_wall_s: walls.iter().sum::<f64>() / n,
        p50_wall_s: walls.get(walls.len() / 2).copied().unwrap_or(0.0),
        max_wall_s: walls.last().copied().unwrap_or(0.0),
        mean_sim_s: r.episodes.iter().map(|e| e.sim_time).sum::<f64>() / n,
        policy_queries: r.episodes.iter().map(|e| e.policy_calls).sum(),
        sr: r.overall.sr,
    })
}

/// Collect `episodes` episodes (both formats, configured sensors) into `out`; episodes/min.
pub fn collection(episodes: usize, jobs: usize, out: &Path) -> Result<f64, CollectError> {
    let s = collect(&CollectOptions {
        jobs,
        config: CollectConfig::load_default()?,
        ..CollectOptions::new(out, episodes)
    })?;
    Ok(s.episodes_per_min)
}
