//! The evaluation server: an axum HTTP API and a tonic gRPC API over one service layer, with
//! submissions, scoring runs and teams in SQLite, and the leaderboard.
//!
//! This crate owns the server's rules (authentication, quotas, plan-file validation, scoring
//! runs, leaderboard order) and its storage. It must not step physics (that is `sim`) nor parse
//! command lines (that is the `kitchen-r` binary, which calls [`build`] then [`Server::run`]).
//!
//! Layout: [`service`] holds the rules; [`http`] (the only place HTML is built, with maud),
//! [`grpc`] and [`grpc_worker`] are thin adapters; [`store`] is every SQL statement (including
//! the job queue); [`plans`] parses and scores plan files; [`episodes`] defines policy-run
//! episodes and their scoring; [`probe`] is the seam through which the binary supplies the
//! policy endpoint probe; [`content`] holds the dataset; [`leaderboard`] the ranking types, JSON
//! and CSV and the cache; [`metrics`] the Prometheus recorder and metric names (a leaf: adapters
//! and the service record into it).
//!
//! Imports go one way: adapters ([`http`], [`grpc`], [`grpc_worker`]) → [`service`] →
//! [`store`], [`leaderboard`], [`content`], [`episodes`] → [`error`] → [`plans`] → the leaf
//! modules [`scores`], [`schema`], [`clock`], [`states`], [`config`]. Nothing below the service
//! imports the service or an adapter (tests aside), and nothing outside an adapter imports one:
//! schema stand-ins the OpenAPI document needs live with the domain types ([`scores`],
//! [`schema`]), never as an import of [`http`] from the domain.
//! `layering_tests` checks this on the source text, and the workspace's `import_circles` test
//! (`tests/import_circles.rs`, over every crate) that no two files import each other round a
//! circle, which states when a parent module and its children count.

mod clock;
mod config;
mod content;
mod episodes;
mod error;
mod grpc;
mod grpc_worker;
mod http;
#[cfg(test)]
mod layering_tests;
mod leaderboard;
pub mod metrics;
pub mod plans;
mod plots;
mod probe;
mod schema;
mod scores;
mod secrets;
mod service;
mod states;
mod store;
#[cfg(test)]
pub(crate) mod testutil;

use std::future::Future;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use anyhow::Context;
use tokio::net::TcpListener;
use tokio_stream::wrappers::TcpListenerStream;

use service::AppState;

pub use config::{Config, PlanLimits};
pub use content::TestSetInfo;
pub use error::ServiceError;
pub use probe::{BoxFuture, NoProbe, PolicyProbe, ProbeError, ProbedSpec};

/// A server ready to listen: state loaded, database migrated.
#[derive(Debug)]
pub struct Server {
    state: AppState,
    /// The organiser token generated at start because none was configured; print it once.
    pub generated_admin_token: Option<String>,
    /// The worker token generated at start because none was configured (`worker_token` /
    /// `KITCHEN_R_WORKER_TOKEN`); in-process workers use [`Server::worker_token`].
    pub generated_worker_token: Option<String>,
    worker_token: String,
}

/// [`build_with`] and [`NoProbe`]: a server that scores plans but refuses policy registration
/// (503 `policy_evaluation_disabled`), for callers that cannot evaluate policies.
pub async fn build(config: Config) -> anyhow::Result<Server> {
    build_with(config, Arc::new(NoProbe)).await
}

/// Validate the configuration, load the content, open and migrate the database. `probe` checks
/// policy endpoints at registration (the `kitchen-r` binary passes the worker crate's probe).
pub async fn build_with(config: Config, probe: Arc<dyn PolicyProbe>) -> anyhow::Result<Server> {
    config.validate()?;
    if config.metrics {
        metrics::install();
    }
    let assets = config.assets_dir();
    let content = content::Content::load(&assets, config.test_set_dir())
        .with_context(|| format!("loading assets from {}", assets.display()))?;
    if config.contest {
        content.check_contest_ready()?;
    }
    let pool = store::connect(&config.db, config.db_pool.into()).await?;
    let secret_key = secret_key(&config)?;
    let (admin, generated_admin_token) = token_or_generated(&config.admin_token);
    let (worker_token, generated_worker_token) = token_or_generated(&config.worker_token);
    let tokens = service::Tokens {
        admin: &admin,
        worker: &worker_token,
        secret_key: &secret_key,
    };
    let state = AppState::new(pool, config, content, tokens, probe);
    state.seal_stored_tokens().await?;
    // Before anything listens, so no upload of this process is in `tmp/` yet.
    service::videos::clear_partial_uploads(&state).await?;
    service::volume::check_volume(&state).await?;
    Ok(Server {
        state,
        generated_admin_token,
        generated_worker_token,
        worker_token,
    })
}

/// The key that seals endpoint tokens: `[secrets] key_file` (by default beside the database),
/// created at first start; an in-memory database's is new per process.
pub(crate) fn secret_key(config: &Config) -> Result<secrets::SecretKey, secrets::SecretError> {
    match config.secrets.key_path(&config.db) {
        Some(path) => secrets::SecretKey::load_or_create(&path),
        None => Ok(secrets::SecretKey::generate()),
    }
}

fn token_or_generated(configured: &str) -> (String, Option<String>) {
    if configured.is_empty() {
        let t = service::new_token();
        (t.clone(), Some(t))
    } else {
        (configured.to_string(), None)
    }
}

impl Server {
    /// What the served test set is (public sample or private set) and its size, for the
    /// start-up line.
    pub fn test_set(&self) -> &TestSetInfo {
        &self.state.content().test_set
    }

    /// The token workers must present on the `Worker` gRPC service (configured or generated).
    pub fn worker_token(&self) -> &str {
        &self.worker_token
    }

    /// Bind the configured HTTP and gRPC addresses (port 0 picks a free port).
    pub async fn bind(&self) -> anyhow::Result<(TcpListener, TcpListener)> {
        let cfg = self.state.config();
        let http = TcpListener::bind(&cfg.http)
            .await
            .with_context(|| format!("cannot listen on {} (http)", cfg.http))?;
        let grpc = TcpListener::bind(&cfg.grpc)
            .await
            .with_context(|| format!("cannot listen on {} (grpc)", cfg.grpc))?;
        Ok((http, grpc))
    }

    /// Serve HTTP and gRPC until `shutdown` completes, then drain in-flight requests.
    pub async fn run(
        self,
        http: TcpListener,
        grpc: TcpListener,
        shutdown: impl Future<Output = ()> + Send + 'static,
    ) -> anyhow::Result<()> {
        let (tx, rx) = tokio::sync::watch::channel(false);
        let state = self.state.clone();
        tokio::spawn(async move {
            shutdown.await;
            state.begin_shutdown();
            let _ = tx.send(true);
        });
        let wait = |mut rx: tokio::sync::watch::Receiver<bool>| async move {
            let _ = rx.wait_for(|stop| *stop).await;
        };
        tokio::spawn(reaper(self.state.clone(), rx.clone()));
        tokio::spawn(service::videos::sweeper(self.state.clone(), rx.clone()));
        let app = http::router(self.state.clone());
        // The peer's address reaches handlers (the login throttle counts failures per address).
        let app = app.into_make_service_with_connect_info::<std::net::SocketAddr>();
        let http_server = axum::serve(http, app).with_graceful_shutdown(wait(rx.clone()));
        let grpc_server = grpc_routes(self.state.clone())
            .await?
            .serve_with_incoming_shutdown(TcpListenerStream::new(grpc), wait(rx));
        let (h, g) = tokio::join!(http_server.into_future(), grpc_server);
        h.context("http server")?;
        g.context("grpc server")?;
        Ok(())
    }
}

/// The gRPC server's routes under its tower stack ([`grpc::GrpcStackLayer`]).
pub(crate) async fn grpc_routes(state: AppState) -> anyhow::Result<GrpcRouter> {
    let (health_reporter, health) = tonic_health::server::health_reporter();
    health_reporter
        .set_serving::<kitchen_r_proto::submission::v1::submissions_server::SubmissionsServer<grpc::SubmissionsService>>()
        .await;
    health_reporter
        .set_serving::<kitchen_r_proto::worker::v1::worker_server::WorkerServer<grpc_worker::WorkerService>>()
        .await;
    let reflection = tonic_reflection::server::Builder::configure()
        .register_encoded_file_descriptor_set(kitchen_r_proto::FILE_DESCRIPTOR_SET)
        .register_encoded_file_descriptor_set(tonic_health::pb::FILE_DESCRIPTOR_SET)
        .build_v1()
        .context("building gRPC reflection")?;
    Ok(tonic::transport::Server::builder()
        .layer(grpc::GrpcStackLayer::new(state.config()))
        .layer(grpc::CallerLayer::new(state.clone()))
        .add_service(health)
        .add_service(reflection)
        .add_service(grpc::SubmissionsService::new(state.clone()).into_server())
        .add_service(grpc_worker::WorkerService::new(state).into_server()))
}

type GrpcRouter = tonic::transport::server::Router<
    tower::layer::util::Stack<
        grpc::CallerLayer,
        tower::layer::util::Stack<grpc::GrpcStackLayer, tower::layer::util::Identity>,
    >,
>;

/// Requeues expired leases every `control.reaper_interval_s` until shutdown. Leases held by
/// workers that died (or by a previous server process) simply expire and come back here.
async fn reaper(state: AppState, mut stop: tokio::sync::watch::Receiver<bool>) {
    let every = Duration::from_secs(state.config().control.reaper_interval_s.max(1));
    let mut tick = tokio::time::interval(every);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        tokio::select! {
            _ = tick.tick() => {}
            _ = stop.wait_for(|s| *s) => return,
        }
        if let Err(e) = state.reap_expired(service::now_ms()).await {
            tracing::error!(error = %e, "reaper failed; retrying next tick");
        }
    }
}

/// The addresses a server actually listens on, for the readiness line.
pub fn local_addrs(http: &TcpListener, grpc: &TcpListener) -> std::io::Result<(SocketAddr, SocketAddr)> {
    Ok((http.local_addr()?, grpc.local_addr()?))
}
