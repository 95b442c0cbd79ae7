//! Live publishing of an episode's ROS 2 messages, off the simulation's critical path.
//!
//! The episode thread's hook ([`crate::live_hook::LiveHook`]) only copies each control step
//! into a [`Frame`] and offers it to a bounded queue; when the queue is full the frame is
//! dropped and counted, never waited for. A publisher thread turns frames into the same
//! ROS 2 messages the MCAP recorder writes ([`crate::ros2_frame`]) and hands them to a
//! [`LiveSink`] (the Foxglove WebSocket server lives in kitchen-r-live). So a slow or stuck
//! subscriber can cost messages, never simulation time, and never changes an episode.
//!
//! One episode is shown at a time: with several episodes in flight (`eval --jobs N`) the first
//! to start a task while the publisher is free holds it until it ends, and the others run
//! unseen, so a viewer never sees two robots' messages mixed on one topic.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::thread::JoinHandle;

use crate::ros2_frame::{self, ImuMemory};
use crate::ros2_msgs::Ros2Message;
use crate::{EpisodeMeta, Frame};

/// Where the publisher thread delivers messages (a transport: Foxglove WebSocket, DDS).
pub trait LiveSink: Send {
    /// Deliver one message; called on the publisher thread only. A transport must not block
    /// here on a subscriber for long (it would only fill the queue and drop frames, but still).
    fn publish(&mut self, msg: &Ros2Message);
}

/// Several transports at once (`--foxglove` with `--ros2`): each gets every message, in turn.
pub struct Fanout(pub Vec<Box<dyn LiveSink>>);

impl LiveSink for Fanout {
    fn publish(&mut self, msg: &Ros2Message) {
        for sink in &mut self.0 {
            sink.publish(msg);
        }
    }
}

/// What the queue carries from the episode thread to the publisher thread.
pub(crate) enum Item {
    /// An episode took the publisher: its static transforms.
    Episode(Box<EpisodeMeta>),
    /// A task started (`/sub_task`).
    Task {
        stamp: f64,
        step: String,
    },
    Frame(Box<Frame>),
    Stop,
}

/// Counters shared by the hooks and the publisher.
#[derive(Debug, Default)]
struct Shared {
    /// Id of the hook holding the publisher; 0 = free.
    owner: AtomicU64,
    next_id: AtomicU64,
    offered: AtomicU64,
    dropped: AtomicU64,
    published: AtomicU64,
    /// Each transport's word on whether anyone watches camera or LiDAR topics: frames carry
    /// rendered images only when one says so.
    sensors_watched: Vec<Arc<AtomicBool>>,
}

/// The episode side of the queue; cheap to clone, one per hook.
#[derive(Debug, Clone)]
pub struct LiveQueue {
    tx: SyncSender<Item>,
    shared: Arc<Shared>,
}

impl LiveQueue {
    /// A new hook's id (never 0).
    pub(crate) fn new_id(&self) -> u64 {
        self.shared.next_id.fetch_add(1, Ordering::Relaxed) + 1
    }

    /// Take the publisher for hook `id` if it is free (or already its own).
    pub(crate) fn claim(&self, id: u64) -> bool {
        let owner = &self.shared.owner;
        owner
            .compare_exchange(0, id, Ordering::AcqRel, Ordering::Acquire)
            .is_ok()
            || owner.load(Ordering::Acquire) == id
    }

    pub(crate) fn release(&self, id: u64) {
        let _ = self
            .shared
            .owner
            .compare_exchange(id, 0, Ordering::AcqRel, Ordering::Acquire);
    }

    pub(crate) fn sensors_watched(&self) -> bool {
        (self.shared.sensors_watched.iter()).any(|w| w.load(Ordering::Relaxed))
    }

    /// Offer `item` without waiting: a full queue drops it.
    pub(crate) fn offer(&self, item: Item) {
        self.shared.offered.fetch_add(1, Ordering::Relaxed);
        match self.tx.try_send(item) {
            Ok(()) => {}
            Err(TrySendError::Full(_)) | Err(TrySendError::Disconnected(_)) => {
                self.shared.dropped.fetch_add(1, Ordering::Relaxed);
            }
        }
    }
}

/// What a live run published, for its summary line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LiveStats {
    /// Items (frames, task starts, episode starts) the episodes offered to the queue.
    pub offered: u64,
    /// Of those, dropped because the queue was full.
    pub dropped: u64,
    /// ROS 2 messages handed to the sink.
    pub published: u64,
}

/// The publisher thread and its queue.
pub struct LivePublisher {
    queue: LiveQueue,
    thread: Option<JoinHandle<()>>,
}

impl LivePublisher {
    /// Start the publisher thread with a queue of `capacity` items (a frame of two 128×128
    /// RGB-D cameras is about 230 kB). `sensors_watched` are the transports' words on whether
    /// camera or LiDAR topics have subscribers: images are copied out of the simulator only
    /// while one says so.
    pub fn start(
        capacity: usize,
        sink: Box<dyn LiveSink>,
        sensors_watched: Vec<Arc<AtomicBool>>,
    ) -> LivePublisher {
        let (tx, rx) = sync_channel(capacity.max(1));
        let shared = Arc::new(Shared {
            sensors_watched,
            ..Shared::default()
        });
        let for_thread = shared.clone();
        let thread = std::thread::Builder::new()
            .name("live-publisher".into())
            .spawn(move || run(rx, sink, &for_thread))
            .expect("spawning the live publisher thread");
        LivePublisher {
            queue: LiveQueue { tx, shared },
            thread: Some(thread),
        }
    }

    /// The queue the episodes' hooks offer to.
    pub fn queue(&self) -> LiveQueue {
        self.queue.clone()
    }

    /// Publish what is queued, stop the thread and count.
    pub fn finish(mut self) -> LiveStats {
        // A blocking send: the queue drains, so this waits only for what is already in it.
        let _ = self.queue.tx.send(Item::Stop);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        let s = &self.queue.shared;
        LiveStats {
            offered: s.offered.load(Ordering::Relaxed),
            dropped: s.dropped.load(Ordering::Relaxed),
            published: s.published.load(Ordering::Relaxed),
        }
    }
}

/// Frames between two re-publications of `/tf_static`, so a viewer that connects mid-episode
/// gets the sensor mounts within a second of sim time (the protocols have no latching here).
const STATIC_EVERY: u64 = 10;

fn run(rx: Receiver<Item>, mut sink: Box<dyn LiveSink>, shared: &Shared) {
    let mut imu: ImuMemory = None;
    let mut statics: Option<Ros2Message> = None;
    let mut frames = 0u64;
    let publish = |sink: &mut Box<dyn LiveSink>, m: &Ros2Message| {
        sink.publish(m);
        shared.published.fetch_add(1, Ordering::Relaxed);
    };
    for item in rx {
        match item {
            Item::Episode(meta) => {
                imu = None;
                let tf = ros2_frame::static_transforms(&meta);
                publish(&mut sink, &tf);
                statics = Some(tf);
            }
            Item::Task { stamp, step } => publish(&mut sink, &ros2_frame::sub_task(stamp, &step)),
            Item::Frame(f) => {
                frames += 1;
                if let Some(tf) = statics.as_mut().filter(|_| frames.is_multiple_of(STATIC_EVERY)) {
                    tf.stamp = f.time;
                    publish(&mut sink, tf);
                }
                for m in ros2_frame::frame_messages(&f, &mut imu) {
                    publish(&mut sink, &m);
                }
            }
            Item::Stop => break,
        }
    }
}
