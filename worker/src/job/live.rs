//! `EpisodeSpec.live_ros2` (the server's `[live] ros2`, docs/twin/live.md): the worker publishes
//! the episodes of the jobs that ask for it as live ROS 2 topics, with kitchen-r-live's
//! [`Ros2Episodes`] (what `kitchen-r eval --ros2` publishes) and the domain, network and QoS of
//! its own `configs/live.toml` `[ros2]`.
//!
//! The server asks only for online dev-split episodes; the worker obeys and decides nothing. One
//! DDS participant per worker process, started at the first job that asks (a worker that never
//! gets one joins no domain) and shared by its episodes, one at a time holding the topics.
//! Best effort: the episode runs with the same hook as under `eval --ros2`, which never changes
//! it, and a participant that cannot start is logged once and the jobs run unpublished: live
//! publishing never fails a job.

use std::sync::{Arc, OnceLock};

use kitchen_r_episode::hooks::WrapHook;
use kitchen_r_live::ros2::{Ros2Config, Ros2Episodes};
use kitchen_r_sim::SensorsConfig;

/// The worker's live publisher, started when first needed; cheap to clone (one per process).
#[derive(Clone, Default)]
pub struct LiveRos2 {
    /// `None`: `configs/live.toml` when first needed.
    config: Option<Ros2Config>,
    started: Arc<OnceLock<Option<Arc<Ros2Episodes>>>>,
}

impl std::fmt::Debug for LiveRos2 {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        (f.debug_struct("LiveRos2"))
            .field("config", &self.config)
            .field("started", &self.started.get().map(Option::is_some))
            .finish()
    }
}

impl LiveRos2 {
    /// Publish with `config` rather than `configs/live.toml`'s (a test's own domain).
    pub fn with_config(config: Ros2Config) -> LiveRos2 {
        LiveRos2 {
            config: Some(config),
            started: Arc::default(),
        }
    }

    /// The publisher, started at the first call; `None` when it could not start (logged once).
    pub fn publisher(&self, sensors: &SensorsConfig) -> Option<&Arc<Ros2Episodes>> {
        let started = self.started.get_or_init(|| {
            let config = match &self.config {
                Some(c) => Ok(c.clone()),
                None => Ros2Config::load_default(&kitchen_r_sim::config::configs_dir()),
            };
            match config.and_then(|c| Ros2Episodes::start(&c, sensors)) {
                Ok(p) => {
                    tracing::info!(
                        domain = p.domain_id(),
                        "publishing dev episodes as live ROS 2 topics"
                    );
                    Some(Arc::new(p))
                }
                Err(e) => {
                    tracing::warn!("live ROS 2 topics asked for by the server, not published: {e}");
                    None
                }
            }
        });
        started.as_ref()
    }

    /// The hook wrapper of a job that asks to be published.
    pub(crate) fn watch(&self, sensors: &SensorsConfig) -> Option<WrapHook> {
        self.publisher(sensors).map(Ros2Episodes::wrap)
    }

    /// `(samples written to DDS, samples DDS dropped)`; `None` before the first published job.
    pub fn counts(&self) -> Option<(u64, u64)> {
        Some(self.started.get()?.as_ref()?.counts())
    }
}
