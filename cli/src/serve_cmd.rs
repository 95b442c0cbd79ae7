//! `kitchen-r serve`: load the layered configuration, apply flags, start the server with its
//! in-process simulation slots and print a readiness line with the bound addresses (tests start
//! it on port 0 and read that line).
//!
//! The in-process slots are an ordinary `kitchen-r worker` running in this process: they lease
//! jobs from the server's own gRPC port over loopback with the worker token, so a contest on one
//! machine and a contest with remote workers go through the same queue and the same code, and
//! get the server's `assets`, `policy.allow_networks` and `control.drain_grace_s`. At shutdown the
//! slots drain first (no more leases, running episodes finish within `control.drain_grace_s`, the
//! rest is released) while the server still serves, then the server stops.

use std::io::Write;
use std::path::PathBuf;
use std::sync::Arc;

use anyhow::Context;
use clap::Args;
use kitchen_r_contract::{AllowedNetworks, RemoteConfig};
use kitchen_r_server::Config;
use kitchen_r_worker::job::Worker;
use kitchen_r_worker::job::WorkerConfig;
use tokio::sync::watch;

use crate::probe_glue::WorkerProbe;

#[derive(Args, Debug, Default)]
pub(crate) struct ServeArgs {
    /// HTTP listen address [config `http`, default 127.0.0.1:8080].
    #[arg(long, value_name = "ADDR")]
    pub http: Option<String>,
    /// gRPC listen address [config `grpc`, default 127.0.0.1:50051].
    #[arg(long, value_name = "ADDR")]
    pub grpc: Option<String>,
    /// SQLite database URL, created if missing [config `db`, default sqlite://data/kitchen-r.db].
    #[arg(long, value_name = "URL")]
    pub db: Option<String>,
    /// In-process simulation slots for policy evaluation; 0 = none (standalone `kitchen-r worker`
    /// processes do the work) [config `workers`, default one per core].
    #[arg(long, value_name = "N")]
    pub workers: Option<usize>,
    /// Configuration file [default: configs/server.toml when present].
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Serve and score this private test set (a directory written by `kitchen-r dataset
    /// generate`, kept outside the repository) instead of the public sample [config `test_set`].
    #[arg(long, value_name = "DIR")]
    pub test_set: Option<PathBuf>,
    /// Refuse to start on what is otherwise a warning: storage budgets larger than the free
    /// space of their volume [config `strict`].
    #[arg(long)]
    pub strict: bool,
}

fn load(args: ServeArgs) -> anyhow::Result<Config> {
    let mut cfg = Config::load(args.config.as_deref())?;
    if let Some(v) = args.http {
        cfg.http = v;
    }
    if let Some(v) = args.grpc {
        cfg.grpc = v;
    }
    if let Some(v) = args.db {
        cfg.db = v;
    }
    if let Some(v) = args.workers {
        cfg.workers = Some(v);
    }
    if let Some(v) = args.test_set {
        cfg.test_set = v;
    }
    cfg.strict |= args.strict;
    cfg.validate()?;
    Ok(cfg)
}

pub(crate) fn serve(args: ServeArgs) -> anyhow::Result<()> {
    init_tracing();
    let cfg = load(args)?;
    let allow = AllowedNetworks::from_cidrs(&cfg.policy.allow_networks)
        .map_err(|e| anyhow::anyhow!("`policy.allow_networks`: {e}"))?;
    let remote = RemoteConfig {
        startup_deadline_s: f64::from(cfg.policy.startup_deadline_ms) / 1000.0,
        call_deadline_s: f64::from(cfg.policy.call_deadline_ms) / 1000.0,
        actions_executed_per_chunk: cfg.control.actions_executed_per_chunk,
        allowed_networks: allow,
        max_batch: cfg.policy.max_batch,
        batch_gather_ms: cfg.policy.batch_gather_ms,
        ..RemoteConfig::default()
    };
    let slots = cfg.worker_slots();
    let allow_networks = cfg.policy.allow_networks.clone();
    let (assets, drain_grace_s) = (cfg.assets_dir(), cfg.control.drain_grace_s);
    let max_episodes = cfg.control.max_episodes;
    let rt = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    rt.block_on(async move {
        // The registration probe's GetSpec announces whether this server runs the privileged
        // track; the workers' RemoteConfig does not (each job grants it or not).
        let probe = Arc::new(WorkerProbe {
            allow,
            remote: RemoteConfig {
                privileged_track: cfg.control.privileged_track,
                ..remote.clone()
            },
        });
        let server = kitchen_r_server::build_with(cfg, probe).await?;
        let (http, grpc) = server.bind().await?;
        let (h, g) = kitchen_r_server::local_addrs(&http, &grpc)?;
        let (stop_tx, stop_rx) = watch::channel(false);
        let workers = if slots > 0 {
            let wc = WorkerConfig {
                server: format!("http://{g}"),
                token: server.worker_token().to_string(),
                slots,
                max_episodes,
                worker_id: format!("serve-{}", std::process::id()),
                allow_networks,
                drain_grace_s,
                assets,
                policy: remote,
                ..WorkerConfig::default()
            };
            let worker = Worker::build(wc).await.context(
                "starting the in-process simulation slots (set `workers = 0` or --workers 0 to serve \
                 without them, e.g. for planning-only content)",
            )?;
            Some(tokio::spawn(worker.run(stopped(stop_rx.clone()))))
        } else {
            None
        };
        let mut out = std::io::stdout().lock();
        if let Some(token) = &server.generated_admin_token {
            writeln!(
                out,
                "admin token (generated for this run; set KITCHEN_R_ADMIN_TOKEN to keep one): {token}"
            )?;
        }
        if let Some(token) = &server.generated_worker_token {
            writeln!(
                out,
                "worker token (generated for this run; set KITCHEN_R_WORKER_TOKEN for remote workers): {token}"
            )?;
        }
        let test_set = server.test_set();
        writeln!(out, "test set: {} ({} instructions)", test_set.notice, test_set.instructions)?;
        writeln!(out, "listening http={h} grpc={g} workers={slots}")?;
        out.flush()?;
        drop(out);
        // The slots drain while the server still takes their reports and releases; the server
        // stops once they are done.
        let (served_tx, served_rx) = watch::channel(false);
        tokio::spawn(async move {
            shutdown_signal().await;
            let _ = stop_tx.send(true);
            if let Some(w) = workers {
                match w.await {
                    Ok(Err(e)) => tracing::error!("in-process workers: {e}"),
                    Err(e) => tracing::error!("in-process workers panicked: {e}"),
                    Ok(Ok(())) => {}
                }
            }
            let _ = served_tx.send(true);
        });
        server.run(http, grpc, stopped(served_rx)).await
    })
}

/// Resolves once the shutdown flag is raised.
async fn stopped(mut rx: watch::Receiver<bool>) {
    while !*rx.borrow_and_update() {
        if rx.changed().await.is_err() {
            return;
        }
    }
}

/// Log to stderr, `RUST_LOG` or `info` (the server and the worker alike).
pub(crate) fn init_tracing() {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .try_init();
}

/// Ctrl-C or SIGTERM: stop accepting and drain.
async fn shutdown_signal() {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let term = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending().await,
        }
    };
    #[cfg(not(unix))]
    let term = std::future::pending::<()>();
    tokio::select! {
        _ = ctrl_c => {},
        _ = term => {},
    }
    tracing::info!("shutting down");
}
