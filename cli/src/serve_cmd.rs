//! `kitchen-r serve`: load the layered configuration, apply flags, start the server and print a
//! readiness line with the bound addresses (tests start it on port 0 and read that line).

use std::io::Write;
use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use kitchen_r_server::Config;

#[derive(Args, Debug, Default)]
pub struct ServeArgs {
    /// HTTP listen address [config `http`, default 127.0.0.1:8080].
    #[arg(long, value_name = "ADDR")]
    pub http: Option<String>,
    /// gRPC listen address [config `grpc`, default 127.0.0.1:50051].
    #[arg(long, value_name = "ADDR")]
    pub grpc: Option<String>,
    /// SQLite database URL, created if missing [config `db`, default sqlite://data/kitchen-r.db].
    #[arg(long, value_name = "URL")]
    pub db: Option<String>,
    /// Simulation slots for policy evaluation; 0 = one per core [config `workers`].
    #[arg(long, value_name = "N")]
    pub workers: Option<usize>,
    /// Configuration file [default: configs/server.toml when present].
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
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
        cfg.workers = v;
    }
    cfg.validate()?;
    Ok(cfg)
}

pub fn serve(args: ServeArgs) -> anyhow::Result<()> {
    init_tracing();
    let cfg = load(args)?;
    let rt = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    rt.block_on(async move {
        let server = kitchen_r_server::build(cfg).await?;
        let (http, grpc) = server.bind().await?;
        let (h, g) = kitchen_r_server::local_addrs(&http, &grpc)?;
        let mut out = std::io::stdout().lock();
        if let Some(token) = &server.generated_admin_token {
            writeln!(
                out,
                "admin token (generated for this run; set KITCHEN_R_ADMIN_TOKEN to keep one): {token}"
            )?;
        }
        writeln!(out, "listening http={h} grpc={g}")?;
        out.flush()?;
        drop(out);
        server.run(http, grpc, shutdown_signal()).await
    })
}

fn init_tracing() {
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
