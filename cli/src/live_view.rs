//! `--foxglove [ADDR]` of `eval` and `replay`: the Foxglove live view for the run, where to
//! connect printed on stderr, and what it published at the end. The server is
//! kitchen-r-live's, the publishing hook and its queue kitchen-r-record's.

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use anyhow::Context;
use clap::Args;
use kitchen_r_episode::eval::WrapHook;
use kitchen_r_live::foxglove::{FoxgloveServer, LiveError};
use kitchen_r_record::live::{LivePublisher, LiveQueue};
use kitchen_r_record::live_hook::LiveHook;
use kitchen_r_record::ros2_frame::topics;
use kitchen_r_sim::SensorsConfig;

/// Frames the episode may be ahead of the publisher before frames are dropped (a frame of two
/// 128×128 RGB-D cameras is about 230 kB, so at most ~15 MB waits).
const QUEUE_FRAMES: usize = 64;

/// How long `--foxglove-wait` waits for a viewer.
const WAIT: Duration = Duration::from_secs(600);

#[derive(Args, Debug, Clone)]
pub(crate) struct LiveArgs {
    /// Serve the (online) episodes live to Foxglove or Lichtblick (Foxglove WebSocket protocol) on ADDR
    /// [default ADDR: 127.0.0.1:8765]; open a connection to the printed ws:// URL. Publishing is
    /// best effort: a slow viewer misses messages, the episode never waits and its results do
    /// not change. Loopback unless you give another address.
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = kitchen_r_live::foxglove::DEFAULT_ADDR)]
    pub foxglove: Option<SocketAddr>,
    /// With --foxglove: wait (up to 10 minutes) for a viewer to connect before the first
    /// episode starts, so it is seen from its first step.
    #[arg(long, requires = "foxglove")]
    pub foxglove_wait: bool,
}

/// The server and the publisher thread of one run.
pub(crate) struct LiveView {
    server: FoxgloveServer,
    publisher: LivePublisher,
    sensors: SensorsConfig,
}

impl LiveView {
    /// Start the view if `--foxglove` was given; `sensors`: what the episodes render.
    pub(crate) fn start(args: &LiveArgs, sensors: &SensorsConfig) -> anyhow::Result<Option<LiveView>> {
        let Some(addr) = args.foxglove else {
            return Ok(None);
        };
        let server = FoxgloveServer::start(addr, &topics(sensors)).map_err(|e| match e {
            LiveError::Bind { source, .. } if source.kind() == std::io::ErrorKind::AddrInUse => anyhow::anyhow!(
                "--foxglove {addr}: the address is in use (another live view?); give a free one, e.g. --foxglove 127.0.0.1:{}",
                addr.port().wrapping_add(1)
            ),
            e => anyhow::Error::new(e).context(format!("--foxglove {addr}")),
        })?;
        let publisher = LivePublisher::start(QUEUE_FRAMES, server.sink(), server.sensors_watched());
        let url = format!("ws://{}", server.local_addr());
        eprintln!("live view: {url}");
        eprintln!(
            "  Foxglove or Lichtblick: Open connection > Foxglove WebSocket > {url}  \
             (Foxglove desktop: foxglove://open?ds=foxglove-websocket&ds.url={url})"
        );
        let view = LiveView {
            server,
            publisher,
            sensors: sensors.clone(),
        };
        if args.foxglove_wait {
            eprintln!("  waiting for a viewer to connect...");
            if !view.server.wait_for_client(WAIT) {
                anyhow::bail!(
                    "--foxglove-wait: no viewer connected to {url} in {} s",
                    WAIT.as_secs()
                );
            }
            eprintln!("  a viewer connected");
        }
        Ok(Some(view))
    }

    pub(crate) fn queue(&self) -> LiveQueue {
        self.publisher.queue()
    }

    pub(crate) fn sensors(&self) -> &SensorsConfig {
        &self.sensors
    }

    /// The wrapper `eval` runs every episode with.
    pub(crate) fn wrap(&self) -> WrapHook {
        let (queue, sensors) = (self.queue(), self.sensors.clone());
        WrapHook(Arc::new(move |inner| {
            Box::new(LiveHook::new(inner, queue.clone(), &sensors))
        }))
    }

    /// Publish what is queued, then stop; the summary on stderr.
    pub(crate) fn finish(self) -> anyhow::Result<()> {
        let stats = self.publisher.finish();
        eprintln!(
            "live view: {} messages published; {} of {} steps and task starts dropped for a full queue",
            stats.published, stats.dropped, stats.offered
        );
        drop(self.server);
        Ok(())
    }
}

/// `eval`'s and `replay`'s sensors, as their episodes render them.
pub(crate) fn default_sensors() -> anyhow::Result<SensorsConfig> {
    SensorsConfig::load_default().context("reading configs/sensors.toml")
}
