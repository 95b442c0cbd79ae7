//! The RustDDS participant, one writer per topic, and the [`LiveSink`] the publisher thread
//! writes through.

use std::collections::HashMap;
use std::net::{IpAddr, Ipv4Addr};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use kitchen_r_record::live::LiveSink;
use kitchen_r_record::ros2_msgs::Ros2Message;
use rustdds::bytes::Bytes;
use rustdds::no_key::{DataWriter, SerializerAdapter};
use rustdds::policy::{Durability as DdsDurability, History};
use rustdds::{
    DomainParticipant, DomainParticipantBuilder, Publisher, QosPolicies, QosPolicyBuilder,
    RepresentationIdentifier, TopicKind,
};

use super::config::{Durability, Network, Reliability, Ros2Config};
use super::{Ros2Error, dds_topic, dds_type};

/// A message's CDR payload without its 4-byte encapsulation header, which RustDDS writes
/// itself from [`RawCdrAdapter::output_encoding`].
struct RawCdr(Bytes);

/// Writes [`RawCdr`] as it is: the bytes were encoded once, by kitchen-r-record.
struct RawCdrAdapter;

impl SerializerAdapter<RawCdr> for RawCdrAdapter {
    type Error = std::convert::Infallible;

    fn output_encoding() -> RepresentationIdentifier {
        RepresentationIdentifier::CDR_LE
    }

    fn to_bytes(value: &RawCdr) -> Result<Bytes, Self::Error> {
        Ok(value.0.clone())
    }
}

type Writer = DataWriter<RawCdr, RawCdrAdapter>;

/// The encapsulation header kitchen-r-record's CDR writer puts first (CDR little-endian).
const CDR_LE_HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// How often the publisher thread asks discovery whether anyone reads camera or LiDAR topics.
const LOOK_EVERY: Duration = Duration::from_millis(500);

/// How long the end of a run waits for reliable subscribers to acknowledge what was written.
const FLUSH: Duration = Duration::from_secs(1);

/// How long the subscribers' set must stay the same before `wait_for_subscriber` returns: a
/// node's readers are discovered one by one, and its side must discover our writers too.
const SETTLE: Duration = Duration::from_secs(1);

struct State {
    publisher: Publisher,
    writers: HashMap<String, Writer>,
    last_look: Option<Instant>,
}

struct Shared {
    participant: DomainParticipant,
    state: Mutex<State>,
    sensors_watched: Arc<AtomicBool>,
    written: AtomicU64,
    dropped: AtomicU64,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Remote readers of our `rt/` topics, by topic name.
    fn readers(&self) -> Vec<String> {
        let mut names: Vec<String> = (self.participant.discovered_readers().iter())
            .map(|r| r.subscription_topic_data.topic_name().clone())
            .filter(|t| t.starts_with("rt/"))
            .collect();
        names.sort();
        names
    }
}

/// A DDS participant publishing an episode's ROS 2 topics; stops when dropped.
pub struct Ros2Publisher {
    shared: Arc<Shared>,
    config: Ros2Config,
}

fn dds_err(what: &str) -> impl FnOnce(rustdds::dds::CreateError) -> Ros2Error + '_ {
    move |e| Ros2Error::Dds(format!("{what}: {e}"))
}

/// The QoS of a topic: `/tf_static` as tf2 expects it, the rest as configured. A reliable
/// writer never blocks: a full send window drops the sample.
fn qos_of(config: &Ros2Config, topic: &str) -> QosPolicies {
    let never_wait = rustdds::Duration::ZERO;
    if topic == "/tf_static" {
        return (QosPolicyBuilder::new().reliable(never_wait))
            .durability(DdsDurability::TransientLocal)
            .history(History::KeepLast { depth: 1 })
            .build();
    }
    let b = QosPolicyBuilder::new().history(History::KeepLast {
        depth: config.depth as i32,
    });
    let b = match config.durability {
        Durability::Volatile => b.durability(DdsDurability::Volatile),
        Durability::TransientLocal => b.durability(DdsDurability::TransientLocal),
    };
    match config.reliability {
        Reliability::Reliable => b.reliable(never_wait),
        Reliability::BestEffort => b.best_effort(),
    }
    .build()
}

impl Ros2Publisher {
    /// Join domain `config.domain_id` and create a writer for each of `topics` (`(topic,
    /// pkg/Name)`) at once, so subscribers discover them before the first message; topics
    /// first seen later get their writer then.
    pub fn start(config: &Ros2Config, topics: &[(String, &'static str)]) -> Result<Ros2Publisher, Ros2Error> {
        let mut builder = DomainParticipantBuilder::new(config.domain_id);
        if config.network == Network::Loopback {
            builder =
                (builder.with_only_networks([IpAddr::V4(Ipv4Addr::LOCALHOST)])).same_host_loopback(true);
        }
        let participant = builder
            .build()
            .map_err(|e| Ros2Error::Dds(format!("joining domain {}: {e}", config.domain_id)))?;
        let publisher = participant
            .create_publisher(&QosPolicies::qos_none())
            .map_err(dds_err("creating the publisher"))?;
        let shared = Arc::new(Shared {
            participant,
            state: Mutex::new(State {
                publisher,
                writers: HashMap::new(),
                last_look: None,
            }),
            sensors_watched: Arc::new(AtomicBool::new(false)),
            written: AtomicU64::new(0),
            dropped: AtomicU64::new(0),
        });
        let p = Ros2Publisher {
            shared,
            config: config.clone(),
        };
        for (topic, ty) in topics {
            p.writer(&mut p.shared.lock(), topic, ty)?;
        }
        Ok(p)
    }

    fn writer<'s>(&self, state: &'s mut State, topic: &str, ty: &str) -> Result<&'s Writer, Ros2Error> {
        if !state.writers.contains_key(topic) {
            let qos = qos_of(&self.config, topic);
            let name = dds_topic(topic);
            let t = (self.shared.participant)
                .create_topic(name.clone(), dds_type(ty), &qos, TopicKind::NoKey)
                .map_err(dds_err(&name))?;
            let w = (state.publisher)
                .create_datawriter_no_key::<RawCdr, RawCdrAdapter>(&t, Some(qos))
                .map_err(dds_err(&name))?;
            state.writers.insert(topic.to_string(), w);
        }
        Ok(&state.writers[topic])
    }

    /// The domain it publishes in.
    pub fn domain_id(&self) -> u16 {
        self.config.domain_id
    }

    /// Whether camera or LiDAR topics have subscribers, for `LivePublisher::start`.
    pub fn sensors_watched(&self) -> Arc<AtomicBool> {
        self.shared.sensors_watched.clone()
    }

    /// The sink the publisher thread hands messages to.
    pub fn sink(&self) -> Box<dyn LiveSink> {
        Box::new(Sink(Ros2Publisher {
            shared: self.shared.clone(),
            config: self.config.clone(),
        }))
    }

    /// Samples written to DDS, and samples dropped (a full send window, or a write error).
    pub fn counts(&self) -> (u64, u64) {
        let s = &self.shared;
        (
            s.written.load(Ordering::Relaxed),
            s.dropped.load(Ordering::Relaxed),
        )
    }

    /// Wait until a subscriber reads one of the topics and the set of subscribed topics has
    /// not changed for a second, or `timeout`; whether one did.
    pub fn wait_for_subscriber(&self, timeout: Duration) -> bool {
        let until = Instant::now() + timeout;
        let mut seen: (Vec<String>, Instant) = (Vec::new(), Instant::now());
        loop {
            let now = self.shared.readers();
            if now != seen.0 {
                seen = (now, Instant::now());
            } else if !seen.0.is_empty() && seen.1.elapsed() >= SETTLE {
                return true;
            }
            if Instant::now() >= until {
                return !seen.0.is_empty();
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    fn publish(&self, msg: &Ros2Message) {
        let mut state = self.shared.lock();
        if state.last_look.is_none_or(|t| t.elapsed() >= LOOK_EVERY) {
            state.last_look = Some(Instant::now());
            let sensors = (self.shared.readers().iter())
                .any(|t| t.starts_with("rt/camera/") || t.starts_with("rt/lidar/"));
            self.shared.sensors_watched.store(sensors, Ordering::Relaxed);
        }
        let payload = match msg.data.strip_prefix(&CDR_LE_HEADER) {
            Some(p) => Bytes::copy_from_slice(p),
            None => return self.dropped(),
        };
        let written = match self.writer(&mut state, &msg.topic, msg.ty) {
            Ok(w) => w.write(RawCdr(payload), None).is_ok(),
            Err(e) => {
                tracing::debug!("ros2 live: {e}");
                false
            }
        };
        match written {
            true => self.shared.written.fetch_add(1, Ordering::Relaxed),
            false => self.shared.dropped.fetch_add(1, Ordering::Relaxed),
        };
    }

    fn dropped(&self) {
        self.shared.dropped.fetch_add(1, Ordering::Relaxed);
    }
}

impl Drop for Ros2Publisher {
    fn drop(&mut self) {
        // The last handle: give reliable subscribers a moment to get the run's last samples.
        if Arc::strong_count(&self.shared) == 1 {
            let until = Instant::now() + FLUSH;
            for w in self.shared.lock().writers.values() {
                let left = until.saturating_duration_since(Instant::now());
                let _ = w.wait_for_acknowledgments(left);
            }
        }
    }
}

/// The publisher thread's side.
struct Sink(Ros2Publisher);

impl LiveSink for Sink {
    fn publish(&mut self, msg: &Ros2Message) {
        self.0.publish(msg);
    }
}
