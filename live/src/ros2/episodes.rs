//! Episodes published live by a process that is not the command line's: the Python environment
//! (`KitchenREnv(ros2=True)`) and a worker running the dev-split jobs its server marks
//! (`[live] ros2` of server.toml). What `eval --ros2` does, packaged for them: one DDS participant
//! and one publisher thread for the process, shared by all its episodes, each of which runs with
//! the same [`LiveHook`] as `eval --ros2`. As with `eval --jobs N`, one episode at a time holds
//! the topics (the first to start a task while they are free), so a subscriber never sees two
//! robots mixed on one topic.

use std::sync::Arc;
use std::time::Duration;

use kitchen_r_episode::hooks::WrapHook;
use kitchen_r_record::live::{LivePublisher, LiveStats};
use kitchen_r_record::live_hook::LiveHook;
use kitchen_r_record::ros2_frame::topics;
use kitchen_r_sim::SensorsConfig;

use super::{Ros2Config, Ros2Error, Ros2Publisher};

/// Frames an episode may be ahead of the publisher before frames are dropped (as `eval --ros2`:
/// a frame of two 128×128 RGB-D cameras is about 230 kB, so at most ~15 MB waits).
const QUEUE_FRAMES: usize = 64;

/// The DDS participant and the publisher thread; both stop when it is dropped (after what is
/// queued is written, and reliable subscribers had up to a second to acknowledge it).
pub struct Ros2Episodes {
    publisher: Option<LivePublisher>,
    dds: Option<Ros2Publisher>,
    sensors: SensorsConfig,
}

impl Ros2Episodes {
    /// Join the domain of `config` with a writer for each topic of episodes rendered with
    /// `sensors`, and start the publisher thread.
    pub fn start(config: &Ros2Config, sensors: &SensorsConfig) -> Result<Ros2Episodes, Ros2Error> {
        let dds = Ros2Publisher::start(config, &topics(sensors))?;
        let publisher = LivePublisher::start(QUEUE_FRAMES, dds.sink(), vec![dds.sensors_watched()]);
        Ok(Ros2Episodes {
            publisher: Some(publisher),
            dds: Some(dds),
            sensors: sensors.clone(),
        })
    }

    /// The hook an episode runs with to be published, around its own `inner` hook.
    pub fn hook<'a>(&self, inner: &'a mut dyn kitchen_r_episode::runner::StepHook) -> LiveHook<'a> {
        let queue = self.publisher.as_ref().expect("running").queue();
        LiveHook::new(inner, queue, &self.sensors)
    }

    /// The same, as the wrapper `eval`, the workers and driven episodes take; it keeps the
    /// publisher alive while any episode may still use it.
    pub fn wrap(self: &Arc<Self>) -> WrapHook {
        let me = self.clone();
        WrapHook(Arc::new(move |inner| Box::new(me.hook(inner))))
    }

    /// The domain it publishes in.
    pub fn domain_id(&self) -> u16 {
        self.dds.as_ref().map_or(0, |d| d.domain_id())
    }

    /// Samples written to DDS, and samples dropped by it (a full send window, a write error).
    pub fn counts(&self) -> (u64, u64) {
        self.dds.as_ref().map_or((0, 0), |d| d.counts())
    }

    /// Wait until a subscriber reads one of the topics (and the set of subscribed topics has
    /// settled for a second), or `timeout`; whether one did.
    pub fn wait_for_subscriber(&self, timeout: Duration) -> bool {
        self.dds.as_ref().is_some_and(|d| d.wait_for_subscriber(timeout))
    }

    /// Publish what is queued and stop; what the episodes offered and the thread published.
    pub fn finish(mut self) -> LiveStats {
        self.stop()
    }

    fn stop(&mut self) -> LiveStats {
        let stats = self
            .publisher
            .take()
            .map(LivePublisher::finish)
            .unwrap_or_default();
        // The last handle on the participant: reliable subscribers get a moment to catch up.
        drop(self.dds.take());
        stats
    }
}

impl Drop for Ros2Episodes {
    fn drop(&mut self) {
        self.stop();
    }
}
