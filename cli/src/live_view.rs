//! `--foxglove [ADDR]` and `--ros2` of `eval`, `replay` and `collect`: the live view for the
//! run (a Foxglove WebSocket server, DDS topics, or both from one publisher thread), where to
//! connect printed on stderr, and what it published at the end. The transports are
//! kitchen-r-live's, the publishing hook and its queue kitchen-r-record's.

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use anyhow::Context;
use clap::Args;
use kitchen_r_episode::hooks::WrapHook;
use kitchen_r_live::foxglove::{FoxgloveServer, LiveError};
use kitchen_r_live::ros2::{Network, Ros2Config, Ros2Publisher};
use kitchen_r_record::live::{Fanout, LivePublisher, LiveQueue, LiveSink};
use kitchen_r_record::live_hook::LiveHook;
use kitchen_r_record::ros2_frame::topics;
use kitchen_r_sim::SensorsConfig;

/// Frames the episode may be ahead of the publisher before frames are dropped (a frame of two
/// 128×128 RGB-D cameras is about 230 kB, so at most ~15 MB waits).
const QUEUE_FRAMES: usize = 64;

/// How long `--foxglove-wait` and `--ros2-wait` wait for a viewer.
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
    /// Publish the (online) episodes as live ROS 2 topics over DDS (the MCAP recording's topics,
    /// `rt/<topic>`), so a ROS 2 node, `ros2 topic echo` or `ros2 bag record` subscribes with no
    /// bridge. Domain, QoS and network from configs/live.toml [ros2] (loopback only by
    /// default); ROS_DOMAIN_ID overrides the domain. Best effort, like --foxglove.
    #[arg(long)]
    pub ros2: bool,
    /// With --ros2: wait (up to 10 minutes) for a ROS 2 subscriber before the first episode
    /// starts (then a second more, so a node's other subscriptions are matched too).
    #[arg(long, requires = "ros2")]
    pub ros2_wait: bool,
}

impl LiveArgs {
    /// Whether the run is watched live at all.
    pub(crate) fn any(&self) -> bool {
        self.foxglove.is_some() || self.ros2
    }
}

/// The transports and the publisher thread of one run.
pub(crate) struct LiveView {
    server: Option<FoxgloveServer>,
    dds: Option<Ros2Publisher>,
    publisher: LivePublisher,
    sensors: SensorsConfig,
}

fn start_foxglove(addr: SocketAddr, sensors: &SensorsConfig) -> anyhow::Result<FoxgloveServer> {
    let server = FoxgloveServer::start(addr, &topics(sensors)).map_err(|e| match e {
        LiveError::Bind { source, .. } if source.kind() == std::io::ErrorKind::AddrInUse => anyhow::anyhow!(
            "--foxglove {addr}: the address is in use (another live view?); give a free one, e.g. --foxglove 127.0.0.1:{}",
            addr.port().wrapping_add(1)
        ),
        e => anyhow::Error::new(e).context(format!("--foxglove {addr}")),
    })?;
    let url = format!("ws://{}", server.local_addr());
    eprintln!("live view: {url}");
    eprintln!(
        "  Foxglove or Lichtblick: Open connection > Foxglove WebSocket > {url}  \
         (Foxglove desktop: foxglove://open?ds=foxglove-websocket&ds.url={url})"
    );
    Ok(server)
}

fn start_ros2(sensors: &SensorsConfig) -> anyhow::Result<Ros2Publisher> {
    let configs = kitchen_r_sim::config::configs_dir();
    let config = Ros2Config::load_default(&configs).context("--ros2: configs/live.toml")?;
    let topics = topics(sensors);
    let dds = Ros2Publisher::start(&config, &topics).context("--ros2")?;
    let (reach, hint) = match config.network {
        Network::Loopback => ("loopback only", "ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST "),
        Network::All => ("every interface", ""),
    };
    eprintln!(
        "ros2 topics: domain {}, {} topics, {reach} (configs/live.toml [ros2])",
        dds.domain_id(),
        topics.len()
    );
    eprintln!(
        "  ROS 2: {hint}ROS_DOMAIN_ID={} ros2 topic echo /odom   (or ros2 bag record -a)",
        dds.domain_id()
    );
    Ok(dds)
}

impl LiveView {
    /// Start the transports asked for, if any; `sensors`: what the episodes render.
    pub(crate) fn start(args: &LiveArgs, sensors: &SensorsConfig) -> anyhow::Result<Option<LiveView>> {
        if !args.any() {
            return Ok(None);
        }
        let server = args.foxglove.map(|a| start_foxglove(a, sensors)).transpose()?;
        let dds = args.ros2.then(|| start_ros2(sensors)).transpose()?;
        let mut sinks: Vec<Box<dyn LiveSink>> = Vec::new();
        let mut watched = Vec::new();
        if let Some(s) = &server {
            sinks.push(s.sink());
            watched.push(s.sensors_watched());
        }
        if let Some(d) = &dds {
            sinks.push(d.sink());
            watched.push(d.sensors_watched());
        }
        let sink: Box<dyn LiveSink> = match sinks.len() {
            1 => sinks.remove(0),
            _ => Box::new(Fanout(sinks)),
        };
        let view = LiveView {
            publisher: LivePublisher::start(QUEUE_FRAMES, sink, watched),
            server,
            dds,
            sensors: sensors.clone(),
        };
        view.wait(args)?;
        Ok(Some(view))
    }

    /// `--foxglove-wait` and `--ros2-wait`.
    fn wait(&self, args: &LiveArgs) -> anyhow::Result<()> {
        if let (true, Some(s)) = (args.foxglove_wait, &self.server) {
            eprintln!("  waiting for a viewer to connect...");
            if !s.wait_for_client(WAIT) {
                anyhow::bail!(
                    "--foxglove-wait: no viewer connected to ws://{} in {} s",
                    s.local_addr(),
                    WAIT.as_secs()
                );
            }
            eprintln!("  a viewer connected");
        }
        if let (true, Some(d)) = (args.ros2_wait, &self.dds) {
            eprintln!("  waiting for a ROS 2 subscriber...");
            if !d.wait_for_subscriber(WAIT) {
                anyhow::bail!(
                    "--ros2-wait: no subscriber in domain {} in {} s",
                    d.domain_id(),
                    WAIT.as_secs()
                );
            }
            eprintln!("  a ROS 2 subscriber is there");
        }
        Ok(())
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
        if let Some(d) = &self.dds {
            let (written, dropped) = d.counts();
            eprintln!("ros2 topics: {written} samples written to DDS, {dropped} dropped by it");
        }
        drop(self.server);
        // The last handle on the participant: reliable subscribers get a moment to catch up.
        drop(self.dds);
        Ok(())
    }
}

/// `eval`'s and `replay`'s sensors, as their episodes render them.
pub(crate) fn default_sensors() -> anyhow::Result<SensorsConfig> {
    SensorsConfig::load_default().context("reading configs/sensors.toml")
}
