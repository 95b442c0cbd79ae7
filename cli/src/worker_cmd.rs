//! `kitchen-r worker --server URL [--slots N]`: a standalone simulation worker leasing episodes
//! from a server's gRPC port. Parsing, tracing set-up and the stop signals only; the loop is
//! `kitchen_r_worker::job::Worker`.
//!
//! Settings: `configs/worker.toml` (or `--config FILE`), then flags; a flag that is not given
//! leaves the file's value alone. SIGTERM or Ctrl-C drains the worker: no more leases, running
//! episodes get `drain_grace_s` to finish, the rest is released to the server, exit code 0.

use std::io::Write;
use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use kitchen_r_worker::job::Worker;
use kitchen_r_worker::job::WorkerConfig;

#[derive(Args, Debug)]
pub(crate) struct WorkerArgs {
    /// The server's gRPC address, `http://HOST:PORT` [default: `server` in the config file,
    /// else http://127.0.0.1:50051].
    #[arg(long, env = "KITCHEN_R_WORKER_SERVER", value_name = "URL")]
    server: Option<String>,
    /// Simulation cores: episodes stepping their simulators at once [default: `slots` in the
    /// config file; 0 or unset = the number of cores].
    #[arg(long, value_name = "N")]
    slots: Option<usize>,
    /// Episodes held at once, one thread and simulator each; an episode holds a slot only while
    /// it simulates, so with slow policies more episodes than slots are in flight
    /// [default: `max_episodes` in the config file; 0 or unset = 8 per slot].
    #[arg(long, value_name = "N")]
    max_episodes: Option<usize>,
    /// On SIGTERM/Ctrl-C, seconds running episodes may take to finish before they are released
    /// to the server [default: `drain_grace_s` in the config file, else 30].
    #[arg(long, value_name = "SECONDS")]
    drain_grace_s: Option<u64>,
    /// Worker token the server was configured with.
    #[arg(
        long,
        env = "KITCHEN_R_WORKER_TOKEN",
        value_name = "TOKEN",
        hide_env_values = true
    )]
    token: Option<String>,
    /// Lease owner name [default: HOSTNAME-PID].
    #[arg(long, value_name = "ID")]
    worker_id: Option<String>,
    /// Worker settings [default: configs/worker.toml when present].
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Serve this worker's Prometheus metrics at `http://ADDR/metrics` (episodes run, their
    /// durations, policy call latency, leases held); port 0 picks one and the line
    /// `worker metrics http=ADDR` says which [default: off].
    #[arg(long, env = "KITCHEN_R_WORKER_METRICS", value_name = "ADDR")]
    metrics: Option<String>,
}

pub(crate) fn worker(args: WorkerArgs) -> anyhow::Result<()> {
    crate::serve_cmd::init_tracing();
    let mut cfg = match &args.config {
        Some(p) => WorkerConfig::load(p)?,
        None => WorkerConfig::load_default()?,
    };
    if let Some(s) = args.server {
        cfg.server = s;
    }
    if let Some(t) = args.token {
        cfg.token = t;
    }
    if let Some(id) = args.worker_id {
        cfg.worker_id = id;
    }
    if let Some(n) = args.slots {
        cfg.slots = n;
    }
    if let Some(n) = args.max_episodes {
        cfg.max_episodes = n;
    }
    if let Some(g) = args.drain_grace_s {
        cfg.drain_grace_s = g;
    }
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting the runtime")?;
    let metrics = args.metrics;
    rt.block_on(async move {
        if let Some(addr) = metrics {
            serve_metrics(&addr).await?;
        }
        let (server, slots, grace) = (cfg.server.clone(), cfg.slot_count(), cfg.drain_grace_s);
        let episodes = cfg.episode_limit();
        let worker = Worker::build(cfg).await?;
        let id = worker.id().to_string();
        // Tests and scripts wait for this exact line on stdout (like serve's `listening` line).
        println!(
            "worker ready id={} slots={slots} max_episodes={episodes} server={server} drain_grace_s={grace}",
            worker.id()
        );
        std::io::stdout().flush()?;
        worker.run(stop_signal()).await?;
        println!("worker stopped id={}", id);
        std::io::stdout().flush()?;
        Ok(())
    })
}

/// Install the metrics recorder and serve `/metrics` on `addr` for the life of the process.
async fn serve_metrics(addr: &str) -> anyhow::Result<()> {
    kitchen_r_server::metrics::install();
    let listener = tokio::net::TcpListener::bind(addr)
        .await
        .with_context(|| format!("cannot listen on {addr} (--metrics)"))?;
    println!("worker metrics http={}", listener.local_addr()?);
    tokio::spawn(async move {
        if let Err(e) = kitchen_r_server::metrics::serve(listener, std::future::pending()).await {
            tracing::error!("metrics endpoint: {e}");
        }
    });
    Ok(())
}

/// Ctrl-C or SIGTERM (how containers and orchestrators stop a worker).
async fn stop_signal() {
    let term = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    tokio::select! {
        _ = tokio::signal::ctrl_c() => {}
        () = term => {}
    }
}
