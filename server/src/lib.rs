//! The evaluation server: an axum HTTP API and a tonic gRPC API over one service layer, with
//! submissions, scoring runs and teams in SQLite, and the leaderboard.
//!
//! This crate owns the server's rules (authentication, quotas, plan-file validation, scoring
//! runs, leaderboard order) and its storage. It must not step physics (that is `sim`) nor parse
//! command lines (that is the `kitchen-r` binary, which calls [`build`] then [`Server::run`]).
//!
//! Layout: [`service`] holds the rules; [`http`] and [`grpc`] are thin adapters; [`store`] is
//! every SQL statement; [`plans`] parses and scores plan files; [`content`] holds the dataset.

pub mod config;
pub mod content;
pub mod error;
pub mod grpc;
pub mod http;
pub mod leaderboard;
pub mod plans;
pub mod service;
pub mod store;

use std::future::Future;
use std::net::SocketAddr;

use anyhow::Context;
use tokio::net::TcpListener;
use tokio_stream::wrappers::TcpListenerStream;

pub use config::Config;
pub use error::ServiceError;
pub use service::AppState;

/// A server ready to listen: state loaded, database migrated.
#[derive(Debug)]
pub struct Server {
    state: AppState,
    /// The organiser token generated at start because none was configured; print it once.
    pub generated_admin_token: Option<String>,
}

/// Validate the configuration, load the content, open and migrate the database.
pub async fn build(config: Config) -> anyhow::Result<Server> {
    config.validate()?;
    let assets = config.assets_dir();
    let content = content::Content::load(&assets)
        .with_context(|| format!("loading assets from {}", assets.display()))?;
    let pool = store::connect(&config.db).await?;
    let (admin, generated) = if config.admin_token.is_empty() {
        let t = service::new_token();
        (t.clone(), Some(t))
    } else {
        (config.admin_token.clone(), None)
    };
    let state = AppState::new(pool, config, content, &admin);
    Ok(Server {
        state,
        generated_admin_token: generated,
    })
}

impl Server {
    pub fn state(&self) -> &AppState {
        &self.state
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
        tokio::spawn(async move {
            shutdown.await;
            let _ = tx.send(true);
        });
        let wait = |mut rx: tokio::sync::watch::Receiver<bool>| async move {
            let _ = rx.wait_for(|stop| *stop).await;
        };
        let app = http::router(self.state.clone());
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

async fn grpc_routes(state: AppState) -> anyhow::Result<tonic::transport::server::Router> {
    let (health_reporter, health) = tonic_health::server::health_reporter();
    health_reporter
        .set_serving::<kitchen_r_proto::submission::v1::submissions_server::SubmissionsServer<grpc::SubmissionsService>>()
        .await;
    let reflection = tonic_reflection::server::Builder::configure()
        .register_encoded_file_descriptor_set(kitchen_r_proto::FILE_DESCRIPTOR_SET)
        .register_encoded_file_descriptor_set(tonic_health::pb::FILE_DESCRIPTOR_SET)
        .build_v1()
        .context("building gRPC reflection")?;
    Ok(tonic::transport::Server::builder()
        .add_service(health)
        .add_service(reflection)
        .add_service(grpc::SubmissionsService::new(state).into_server()))
}

/// The addresses a server actually listens on, for the readiness line.
pub fn local_addrs(http: &TcpListener, grpc: &TcpListener) -> std::io::Result<(SocketAddr, SocketAddr)> {
    Ok((http.local_addr()?, grpc.local_addr()?))
}
