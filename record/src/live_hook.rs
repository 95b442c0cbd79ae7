//! The step hook that publishes an episode live (see [`crate::live`]): wrapped around the
//! episode's other hook, it forwards everything to it and offers each control step to the
//! live queue.
//!
//! It must not change the episode: it never fails a step, never asks the runner to render
//! (it renders itself when someone watches the cameras: rendering reads the world without
//! changing it), and reports all the time it spends, pacing included, as the hook's overhead,
//! which the runner leaves out of the policy's wall-clock budget.
//!
//! Rendering is the one cost publishing puts on the episode's thread (a two-camera RGB-D frame
//! takes a few milliseconds, several times a control step's physics), so camera and LiDAR
//! readings go out at most [`IMAGE_RATE_HZ`] times a wall-clock second, what a screen shows;
//! the state topics (`/odom`, `/tf`, `/imu`, the action) go out at every control step.

use std::time::{Duration, Instant};

use kitchen_r_episode::runner::{StepHook, TaskRecord};
use kitchen_r_sim::{Action, Observation, SensorsConfig, Sim, StepInfo};

use crate::frame::frame_of;
use crate::live::{Item, LiveQueue};
use crate::replay::episode_meta;

/// Camera frames a viewer is sent per wall-clock second, at most.
pub const IMAGE_RATE_HZ: f64 = 30.0;

pub struct LiveHook<'a> {
    inner: &'a mut dyn StepHook,
    queue: LiveQueue,
    sensors: SensorsConfig,
    id: u64,
    holds: bool,
    /// The runner's rendering of this step, when the inner hook asked for one.
    latest: Option<Observation>,
    /// Sim seconds per wall second to keep to (a replay watched live); `None`: flat out.
    speed: Option<f64>,
    /// Wall time and sim time when pacing started.
    paced_from: Option<(Instant, f64)>,
    /// When the last images were sent.
    last_images: Option<Instant>,
    busy: Duration,
}

impl<'a> LiveHook<'a> {
    /// `sensors`: the simulator's sensors (for the `/tf_static` mounts).
    pub fn new(inner: &'a mut dyn StepHook, queue: LiveQueue, sensors: &SensorsConfig) -> LiveHook<'a> {
        LiveHook {
            id: queue.new_id(),
            inner,
            queue,
            sensors: sensors.clone(),
            holds: false,
            latest: None,
            speed: None,
            paced_from: None,
            last_images: None,
            busy: Duration::ZERO,
        }
    }

    /// Keep sim time to `speed` × wall time by sleeping after each step: for watching a replay,
    /// whose outcome does not depend on wall time.
    pub fn paced(mut self, speed: f64) -> Self {
        self.speed = (speed > 0.0).then_some(speed);
        self
    }

    fn pace(&mut self, sim_time: f64) {
        let Some(speed) = self.speed else { return };
        let (wall0, sim0) = *self.paced_from.get_or_insert((Instant::now(), sim_time));
        let due = Duration::from_secs_f64(((sim_time - sim0) / speed).max(0.0));
        if let Some(wait) = due.checked_sub(wall0.elapsed()) {
            std::thread::sleep(wait);
        }
    }

    /// Whether this step's frame carries images: someone watches them, and the last were sent
    /// at least 1/[`IMAGE_RATE_HZ`] s ago.
    fn images_due(&self) -> bool {
        let every = Duration::from_secs_f64(1.0 / IMAGE_RATE_HZ);
        self.queue.sensors_watched() && self.last_images.is_none_or(|t| t.elapsed() >= every)
    }

    fn publish(&mut self, sim: &Sim, action: &Action, info: &StepInfo) {
        let obs = match (self.images_due(), self.latest.take()) {
            (true, Some(o)) => o,
            (true, None) => sim.observe(),
            (false, _) => sim.observe_state(),
        };
        if !obs.images.is_empty() {
            self.last_images = Some(Instant::now());
        }
        let task = info.task.as_ref().map_or(0, |t| t.index);
        let frame = frame_of(sim, obs, action, info, task, true);
        self.queue.offer(Item::Frame(Box::new(frame)));
    }
}

impl Drop for LiveHook<'_> {
    fn drop(&mut self) {
        self.queue.release(self.id);
    }
}

impl StepHook for LiveHook<'_> {
    fn on_step(&mut self, sim: &Sim, action: &Action, info: &StepInfo) -> Result<(), String> {
        let started = Instant::now();
        if self.holds {
            self.publish(sim, action, info);
            self.pace(sim.time());
        }
        self.latest = None;
        self.busy += started.elapsed();
        self.inner.on_step(sim, action, info)
    }

    fn wants_observation(&self) -> bool {
        self.inner.wants_observation()
    }

    fn observation(&mut self, obs: &Observation) {
        if self.holds && self.images_due() {
            let started = Instant::now();
            self.latest = Some(obs.clone());
            self.busy += started.elapsed();
        }
        self.inner.observation(obs);
    }

    fn on_task_start(&mut self, sim: &Sim, index: usize) {
        let started = Instant::now();
        let was = self.holds;
        self.holds = self.queue.claim(self.id);
        if self.holds && !was {
            let meta = episode_meta(sim.episode(), &self.sensors);
            self.queue.offer(Item::Episode(Box::new(meta)));
        }
        if self.holds {
            let step = sim.episode().plan.get(index).cloned().unwrap_or_default();
            self.queue.offer(Item::Task {
                stamp: sim.time(),
                step,
            });
        }
        self.busy += started.elapsed();
        self.inner.on_task_start(sim, index);
    }

    fn on_task_end(&mut self, sim: &Sim, task: &TaskRecord) {
        self.inner.on_task_end(sim, task);
    }

    fn overhead(&self) -> Duration {
        self.busy + self.inner.overhead()
    }
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeSet;
    use std::sync::atomic::AtomicBool;
    use std::sync::{Arc, Mutex};

    use super::*;
    use crate::live::{LivePublisher, LiveSink};
    use crate::ros2_msgs::Ros2Message;
    use kitchen_r_episode::oracle::OraclePolicy;
    use kitchen_r_episode::runner::{EpisodeOutcome, RunOptions, run_episode};

    /// A subscriber far slower than the simulation: every message takes it 5 ms.
    struct Stuck(Arc<Mutex<BTreeSet<(String, &'static str)>>>);

    impl LiveSink for Stuck {
        fn publish(&mut self, msg: &Ros2Message) {
            std::thread::sleep(Duration::from_millis(5));
            self.0.lock().unwrap().insert((msg.topic.clone(), msg.ty));
        }
    }

    fn episode(hook: &mut dyn StepHook) -> EpisodeOutcome {
        let (assets, mut sim) = crate::test_sim::first_dev_sim();
        let run = RunOptions {
            privileged: true,
            max_tasks: Some(2),
            ..RunOptions::default()
        };
        let mut out = run_episode(&mut sim, &mut OraclePolicy::new(&assets), &run, None, hook).unwrap();
        out.wall_time_s = 0.0;
        out
    }

    #[test]
    fn publishing_live_behind_a_stuck_subscriber_drops_messages_and_never_changes_the_episode() {
        let plain = episode(&mut ());
        let seen = Arc::new(Mutex::new(BTreeSet::new()));
        let publisher = LivePublisher::start(
            2,
            Box::new(Stuck(seen.clone())),
            vec![Arc::new(AtomicBool::new(true))],
        );
        let sensors = SensorsConfig::load_default().unwrap();
        let mut inner = ();
        let mut hook = LiveHook::new(&mut inner, publisher.queue(), &sensors);
        let live = episode(&mut hook);
        assert!(hook.overhead() > Duration::ZERO, "the hook's time is reported");
        drop(hook);
        let stats = publisher.finish();
        assert_eq!(live, plain, "bit-identical outcome with publishing on");
        assert!(plain.tasks.iter().all(|t| t.success), "{:?}", plain.tasks);
        assert!(stats.dropped > 0 && stats.published > 0, "{stats:?}");
        let seen = seen.lock().unwrap();
        for (topic, ty) in [
            ("/tf_static", "tf2_msgs/TFMessage"),
            ("/sub_task", "std_msgs/String"),
            ("/odom", "nav_msgs/Odometry"),
            ("/tf", "tf2_msgs/TFMessage"),
            ("/camera/base/image_raw", "sensor_msgs/Image"),
        ] {
            assert!(
                seen.contains(&(topic.to_string(), ty)),
                "{topic} missing from {seen:?}"
            );
        }
    }

    #[test]
    fn only_one_episode_holds_the_publisher_at_a_time() {
        let publisher = LivePublisher::start(4, Box::new(Stuck(Default::default())), Vec::new());
        let (a, b) = (publisher.queue(), publisher.queue());
        let (ida, idb) = (a.new_id(), b.new_id());
        assert!(a.claim(ida) && a.claim(ida));
        assert!(!b.claim(idb));
        a.release(ida);
        assert!(b.claim(idb));
        publisher.finish();
    }
}
