//! `kitchen-r eval --record DIR`: the episode videos, written locally as the server's workers
//! record them, and what they cost. The built-in oracle is served on a loopback port for the
//! run, so its episodes go through the workers' runner (the one that records) unchanged.

use std::sync::Arc;

use anyhow::Context;
use kitchen_r_contract::server::{PolicyFactory, ServeOptions, serve_policy};
use kitchen_r_core::GraspMode;
use kitchen_r_episode::oracle::OraclePolicy;
use kitchen_r_episode::policy::Policy;
use kitchen_r_sim::Assets;
use kitchen_r_worker::job::local::{LocalEpisode, LocalReport};

/// The oracle policy served on `127.0.0.1:<free port>` until dropped.
pub(crate) struct LoopbackOracle {
    url: String,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl LoopbackOracle {
    /// `grasp`: the mode of the twin it drives (`eval --grasp`; `None` = configs/sim.toml's).
    pub(crate) fn start(grasp: Option<GraspMode>) -> anyhow::Result<LoopbackOracle> {
        let assets = Arc::new(Assets::load_default().context("loading the benchmark assets")?);
        // One oracle per episode in flight; as many as the cores run.
        let concurrency = std::thread::available_parallelism().map_or(1, |n| n.get()) as u32;
        let factory: PolicyFactory = Arc::new(move || {
            let oracle = OraclePolicy::new(&assets).with_max_concurrency(concurrency);
            Box::new(match grasp {
                Some(g) => oracle.with_grasp_mode(g),
                None => oracle,
            }) as Box<dyn Policy>
        });
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .enable_all()
            .build()
            .context("starting the runtime")?;
        let listener = rt
            .block_on(tokio::net::TcpListener::bind("127.0.0.1:0"))
            .context("binding a loopback port for the oracle")?;
        let url = format!("http://{}", listener.local_addr()?);
        let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
        let thread = std::thread::spawn(move || {
            let shutdown = async {
                let _ = stopped.await;
            };
            if let Err(e) = rt.block_on(serve_policy(listener, factory, ServeOptions::default(), shutdown)) {
                eprintln!("the loopback oracle stopped: {e}");
            }
        });
        Ok(LoopbackOracle {
            url,
            stop: Some(stop),
            thread: Some(thread),
        })
    }

    pub(crate) fn url(&self) -> &str {
        &self.url
    }
}

impl Drop for LoopbackOracle {
    fn drop(&mut self) {
        if let Some(s) = self.stop.take() {
            let _ = s.send(());
        }
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// The progress line of an episode's video.
pub(crate) fn print_video(e: &LocalEpisode) {
    if let Some(v) = &e.video {
        eprintln!(
            "    video {}: {} frames, {} bytes, composed and encoded in {:.2} s",
            v.path.display(),
            v.frames,
            v.bytes,
            v.encode_s
        );
    }
    if !e.video_error.is_empty() {
        eprintln!("    no video: {}", e.video_error);
    }
}

/// Means over the episodes that wrote a video (the cost figures of docs/measured/video.md).
pub(crate) fn print_video_totals(r: &LocalReport) {
    let videos: Vec<_> = r.episodes.iter().filter_map(|e| e.video.as_ref()).collect();
    if videos.is_empty() {
        return;
    }
    let n = videos.len() as f64;
    let bytes: u64 = videos.iter().map(|v| v.bytes).sum();
    let frames: usize = videos.iter().map(|v| v.frames).sum();
    let encode: f64 = videos.iter().map(|v| v.encode_s).sum();
    println!(
        "videos {}: mean {:.0} bytes, {:.0} frames, {:.2} s composing and encoding per episode ({:.1} ms per frame)",
        videos.len(),
        bytes as f64 / n,
        frames as f64 / n,
        encode / n,
        1e3 * encode / frames.max(1) as f64
    );
}
