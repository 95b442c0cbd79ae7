//! What a worker records, through the `metrics` facade: nothing happens unless the process
//! installed a recorder (`kitchen-r worker --metrics ADDR`, or `kitchen-r serve`, whose
//! in-process slots then show in the server's `/metrics`). No label carries a job, run or
//! endpoint: policy calls are labelled by kind only.

use std::time::Instant;

use kitchen_r_episode::policy::{ACTION_DIM, Policy, PolicyError, PolicyInput, PolicySpec};
use kitchen_r_proto::worker::v1 as pb;

const EPISODES: &str = "kitchen_r_worker_episodes_total";
const EPISODE_DURATION: &str = "kitchen_r_worker_episode_duration_seconds";
const LEASES_HELD: &str = "kitchen_r_worker_leases_held";
const POLICY_CALL: &str = "kitchen_r_worker_policy_call_duration_seconds";

/// Counts a leased job as held while it lives (`kitchen_r_worker_leases_held`).
pub(crate) struct LeaseHeld(());

impl LeaseHeld {
    pub(crate) fn new() -> LeaseHeld {
        describe();
        metrics::gauge!(LEASES_HELD).increment(1.0);
        LeaseHeld(())
    }
}

impl Drop for LeaseHeld {
    fn drop(&mut self) {
        metrics::gauge!(LEASES_HELD).decrement(1.0);
    }
}

fn describe() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        metrics::describe_counter!(
            EPISODES,
            "Episodes this worker ran, by result (ok, platform_error, dropped: the server cancelled the lease, released: given back while draining)"
        );
        metrics::describe_histogram!(
            EPISODE_DURATION,
            metrics::Unit::Seconds,
            "Wall time of the episodes this worker ran"
        );
        metrics::describe_gauge!(LEASES_HELD, "Jobs this worker holds a lease on now");
        metrics::describe_histogram!(
            POLICY_CALL,
            metrics::Unit::Seconds,
            "Latency of calls to participants' policy endpoints, by call (reset, act), errors included"
        );
    });
}

/// An episode ended on this worker: `dropped` when the server cancelled its lease, `released`
/// when it was stopped to be given back.
pub(crate) fn episode_ran(result: &pb::EpisodeResult, dropped: bool, released: bool) {
    let outcome = match () {
        () if dropped => "dropped",
        () if released => "released",
        () if !result.platform_error.is_empty() => "platform_error",
        () => "ok",
    };
    metrics::counter!(EPISODES, "result" => outcome).increment(1);
    metrics::histogram!(EPISODE_DURATION).record(result.wall_ms as f64 / 1000.0);
}

/// A policy whose calls are timed into `kitchen_r_worker_policy_call_duration_seconds`.
pub(crate) struct Timed<'a>(pub &'a mut dyn Policy);

impl Timed<'_> {
    fn time<T>(call: &'static str, f: impl FnOnce() -> T) -> T {
        let started = Instant::now();
        let out = f();
        metrics::histogram!(POLICY_CALL, "call" => call).record(started.elapsed().as_secs_f64());
        out
    }
}

impl Policy for Timed<'_> {
    fn spec(&self) -> &PolicySpec {
        self.0.spec()
    }

    fn reset(&mut self, episode_id: &str, task_index: usize, sub_task: &str) -> Result<(), PolicyError> {
        Self::time("reset", || self.0.reset(episode_id, task_index, sub_task))
    }

    fn act(&mut self, input: &PolicyInput<'_>) -> Result<Vec<[f64; ACTION_DIM]>, PolicyError> {
        Self::time("act", || self.0.act(input))
    }

    fn wants_images(&self) -> bool {
        self.0.wants_images()
    }
}
