//! A worker ready to run: its configuration, its cores, what every job needs and its client.
//! The lease loop (`lease.rs`) and render jobs (`render.rs`) are its methods.

use std::sync::Arc;

use super::cores::Cores;
use super::rpc::{Client, connect};
use super::{JobContext, WorkerConfig, WorkerError};

/// A worker ready to run: configuration checked, assets and dataset loaded.
pub struct Worker {
    pub(super) id: String,
    pub(super) cfg: WorkerConfig,
    /// One permit per slot: the episodes in flight share them while they simulate (and a
    /// render job while it replays, `super::render`).
    pub(super) cores: Cores,
    pub(super) ctx: Arc<JobContext>,
    pub(super) client: Client,
}

impl std::fmt::Debug for Worker {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Worker")
            .field("id", &self.id)
            .field("server", &self.cfg.server)
            .field("slots", &self.cfg.slot_count())
            .field("max_episodes", &self.cfg.episode_limit())
            .finish_non_exhaustive()
    }
}

impl Worker {
    /// Validate `cfg`, load what every job needs, and prepare a (lazy) channel to the server:
    /// nothing is sent yet, so a server that is not up is not an error here.
    pub async fn build(cfg: WorkerConfig) -> Result<Worker, WorkerError> {
        cfg.validate()?;
        let c = cfg.clone();
        let ctx = tokio::task::spawn_blocking(move || JobContext::from_worker_config(&c))
            .await
            .map_err(|e| WorkerError::Config(format!("loading the assets: {e}")))??;
        Worker::with_context(cfg, Arc::new(ctx))
    }

    /// As [`Worker::build`] with an already loaded context.
    pub(crate) fn with_context(cfg: WorkerConfig, ctx: Arc<JobContext>) -> Result<Worker, WorkerError> {
        cfg.validate()?;
        let client = connect(&cfg)?;
        Ok(Worker {
            id: cfg.worker_id(),
            cores: Cores::new(cfg.slot_count()),
            cfg,
            ctx,
            client,
        })
    }
}
