//! `kitchen-r policy oracle --listen ADDR`: the organisers' reference oracle served over the
//! participant contract (`kitchen_r.policy.v1.Policy` + `grpc.health.v1`), so a reference run
//! goes through exactly the transport a participant's policy does.
//!
//! The oracle drives from privileged world state, which only organiser-created reference runs
//! send: an Act without `Observation.privileged` is answered FAILED_PRECONDITION.

use std::io::Write;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::{Args, Subcommand};
use kitchen_r_contract::server::{PolicyFactory, ServeOptions, TlsIdentity, serve_policy};
use kitchen_r_episode::oracle::OraclePolicy;
use kitchen_r_episode::policy::{ACTION_DIM, Policy, PolicyError, PolicyInput, PolicySpec};
use kitchen_r_sim::Assets;

#[derive(Args, Debug)]
pub(crate) struct PolicyArgs {
    #[command(subcommand)]
    pub command: PolicyCommand,
}

#[derive(Subcommand, Debug)]
pub(crate) enum PolicyCommand {
    /// Serve the privileged oracle expert over gRPC (reference runs only).
    Oracle(OracleArgs),
}

#[derive(Args, Debug)]
pub(crate) struct OracleArgs {
    /// Listen address; port 0 picks a free port (printed in the `listening grpc=...` line).
    #[arg(long, value_name = "ADDR", default_value = "127.0.0.1:50061")]
    pub listen: String,
    /// Serve over TLS with this PEM certificate chain (needs --tls-key); clients then use https://.
    #[arg(long, value_name = "FILE", requires = "tls_key")]
    pub tls_cert: Option<std::path::PathBuf>,
    /// The PEM private key of --tls-cert.
    #[arg(long, value_name = "FILE", requires = "tls_cert")]
    pub tls_key: Option<std::path::PathBuf>,
    /// Episodes the server may run against this endpoint at once (GetSpec's max_concurrency);
    /// each episode gets its own oracle instance.
    #[arg(long, value_name = "N", default_value_t = 1)]
    pub max_concurrency: u32,
    /// Answer every Act only after this many milliseconds, like a learned policy's inference
    /// (the oracle itself answers in microseconds); for measuring how workers cope with slow
    /// policies (`benchmarks/bench-slow-policy.sh`). At most 60000.
    #[arg(long, value_name = "MS", default_value_t = 0,
          value_parser = clap::value_parser!(u64).range(0..=60_000))]
    pub delay_ms: u64,
    /// Declare batched decisions in GetSpec (`max_batch`): workers running several episodes
    /// against this endpoint then send their pending decisions in ActBatch calls of up to N.
    /// 0 or 1 = Acts only (the default). Each decision is answered exactly as its Act would be.
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub max_batch: u32,
}

/// A policy that takes `delay` over every chunk, without using a core while it waits.
struct Delayed {
    inner: OraclePolicy,
    delay: Duration,
}

impl Policy for Delayed {
    fn spec(&self) -> &PolicySpec {
        self.inner.spec()
    }
    fn reset(&mut self, episode_id: &str, task_index: usize, sub_task: &str) -> Result<(), PolicyError> {
        self.inner.reset(episode_id, task_index, sub_task)
    }
    fn act(&mut self, input: &PolicyInput<'_>) -> Result<Vec<[f64; ACTION_DIM]>, PolicyError> {
        let started = Instant::now();
        let chunk = self.inner.act(input);
        std::thread::sleep(self.delay.saturating_sub(started.elapsed()));
        chunk
    }
    fn wants_images(&self) -> bool {
        self.inner.wants_images()
    }
}

pub(crate) fn policy(args: PolicyArgs) -> anyhow::Result<()> {
    match args.command {
        PolicyCommand::Oracle(a) => oracle(a),
    }
}

fn oracle(args: OracleArgs) -> anyhow::Result<()> {
    let read = |p: &std::path::Path| std::fs::read(p).with_context(|| format!("reading {}", p.display()));
    let tls = match (&args.tls_cert, &args.tls_key) {
        (Some(c), Some(k)) => Some(TlsIdentity {
            cert_pem: read(c)?,
            key_pem: read(k)?,
        }),
        _ => None,
    };
    let opts = ServeOptions {
        tls,
        max_batch: args.max_batch,
        ..ServeOptions::default()
    };
    let assets = Arc::new(Assets::load_default().context("loading the benchmark assets")?);
    let (concurrency, delay) = (args.max_concurrency, Duration::from_millis(args.delay_ms));
    let factory: PolicyFactory = Arc::new(move || {
        let oracle = OraclePolicy::new(&assets).with_max_concurrency(concurrency);
        if delay.is_zero() {
            Box::new(oracle) as Box<dyn Policy>
        } else {
            Box::new(Delayed { inner: oracle, delay })
        }
    });
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting the runtime")?;
    rt.block_on(async move {
        let listener = tokio::net::TcpListener::bind(&args.listen)
            .await
            .with_context(|| format!("binding {}", args.listen))?;
        // Tests and scripts wait for this exact line.
        println!("listening grpc={}", listener.local_addr()?);
        std::io::stdout().flush()?;
        let shutdown = async {
            let _ = tokio::signal::ctrl_c().await;
        };
        serve_policy(listener, factory, opts, shutdown)
            .await
            .context("serving the oracle policy")
    })
}
