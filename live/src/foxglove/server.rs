//! The Foxglove WebSocket server: its own small tokio runtime, one task per client, and the
//! [`LiveSink`] the publisher thread hands messages to.
//!
//! Each client has a bounded queue of message frames, filled with `try_send`: a client that
//! reads too slowly loses messages, and the publisher thread, let alone the episode, never
//! waits for it. Its control messages (`serverInfo`, `advertise`) go on a queue of their own,
//! so a lagging client still learns every topic.

use std::collections::HashMap;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use axum::Router;
use axum::extract::State as AxumState;
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::response::Response;
use futures_util::{SinkExt, StreamExt};
use kitchen_r_record::live::LiveSink;
use kitchen_r_record::ros2_msgs::{Ros2Message, schema, schema_name};
use tokio::sync::{mpsc, oneshot};

use super::protocol::{self, Channel, ClientOp};

/// Message frames a client may lag behind before frames are dropped for it: about a second
/// of an episode's messages at the control rate.
const CLIENT_BACKLOG: usize = 256;

/// Why the server did not start.
#[derive(Debug, thiserror::Error)]
pub enum LiveError {
    #[error("cannot listen on {addr}: {source}")]
    Bind {
        addr: SocketAddr,
        #[source]
        source: std::io::Error,
    },
    #[error("starting the live view's runtime: {0}")]
    Runtime(#[source] std::io::Error),
}

struct Client {
    data: mpsc::Sender<Message>,
    control: mpsc::UnboundedSender<Message>,
    /// Subscription id → channel id.
    subscriptions: HashMap<u32, u32>,
}

#[derive(Default)]
struct Inner {
    channels: Vec<Channel>,
    clients: HashMap<u64, Client>,
    next_client: u64,
    last_time_ns: Option<u64>,
}

struct Shared {
    inner: Mutex<Inner>,
    /// Whether any client subscribes to a camera or LiDAR topic (see `LivePublisher::start`).
    sensors_watched: Arc<AtomicBool>,
    connections: AtomicU64,
    session_id: String,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, Inner> {
        // A panicking client task cannot leave the maps half-updated in a way that matters here.
        self.inner.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn update_sensors_watched(&self, inner: &Inner) {
        let sensor = |id: &u32| {
            inner
                .channels
                .iter()
                .any(|c| c.id == *id && (c.topic.starts_with("/camera/") || c.topic.starts_with("/lidar/")))
        };
        let watched = inner
            .clients
            .values()
            .any(|c| c.subscriptions.values().any(sensor));
        self.sensors_watched.store(watched, Ordering::Relaxed);
    }
}

/// A running live view; stops when dropped.
pub struct FoxgloveServer {
    addr: SocketAddr,
    shared: Arc<Shared>,
    stop: Option<oneshot::Sender<()>>,
    runtime: Option<tokio::runtime::Runtime>,
}

fn channel(id: u32, topic: &str, ty: &str) -> Channel {
    Channel {
        id,
        topic: topic.to_string(),
        schema_name: schema_name(ty),
        schema: schema(ty),
    }
}

impl FoxgloveServer {
    /// Listen on `addr` (port 0: any free one) and advertise `topics` (`(topic, pkg/Name)`)
    /// from the start; topics first seen later are advertised as they appear.
    pub fn start(addr: SocketAddr, topics: &[(String, &'static str)]) -> Result<FoxgloveServer, LiveError> {
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .thread_name("foxglove-ws")
            .enable_all()
            .build()
            .map_err(LiveError::Runtime)?;
        let listener = runtime
            .block_on(tokio::net::TcpListener::bind(addr))
            .map_err(|source| LiveError::Bind { addr, source })?;
        let local = listener
            .local_addr()
            .map_err(|source| LiveError::Bind { addr, source })?;
        let inner = Inner {
            channels: (topics.iter().enumerate())
                .map(|(i, (t, ty))| channel(i as u32 + 1, t, ty))
                .collect(),
            ..Inner::default()
        };
        let session = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_millis());
        let shared = Arc::new(Shared {
            inner: Mutex::new(inner),
            sensors_watched: Arc::new(AtomicBool::new(false)),
            connections: AtomicU64::new(0),
            session_id: format!("kitchen-r-{session}"),
        });
        let app = Router::new().fallback(upgrade).with_state(shared.clone());
        let (stop, stopped) = oneshot::channel::<()>();
        runtime.spawn(async move {
            let serve = axum::serve(listener, app).with_graceful_shutdown(async {
                let _ = stopped.await;
            });
            if let Err(e) = serve.await {
                tracing::warn!("the Foxglove live view stopped: {e}");
            }
        });
        Ok(FoxgloveServer {
            addr: local,
            shared,
            stop: Some(stop),
            runtime: Some(runtime),
        })
    }

    /// The address it listens on.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// Whether camera or LiDAR topics have subscribers, for `LivePublisher::start`.
    pub fn sensors_watched(&self) -> Arc<AtomicBool> {
        self.shared.sensors_watched.clone()
    }

    /// The sink the publisher thread hands messages to.
    pub fn sink(&self) -> Box<dyn LiveSink> {
        Box::new(Sink(self.shared.clone()))
    }

    /// Wait until a client has connected, or `timeout`; whether one did.
    pub fn wait_for_client(&self, timeout: Duration) -> bool {
        let until = Instant::now() + timeout;
        while self.shared.connections.load(Ordering::Relaxed) == 0 {
            if Instant::now() >= until {
                return false;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        true
    }
}

impl Drop for FoxgloveServer {
    fn drop(&mut self) {
        // Closing every client's queues ends its task (with a Close frame), then the listener.
        self.shared.lock().clients.clear();
        if let Some(s) = self.stop.take() {
            let _ = s.send(());
        }
        if let Some(rt) = self.runtime.take() {
            rt.shutdown_timeout(Duration::from_secs(1));
        }
    }
}

async fn upgrade(AxumState(shared): AxumState<Arc<Shared>>, ws: WebSocketUpgrade) -> Response {
    ws.protocols(protocol::SUBPROTOCOLS)
        .on_upgrade(move |socket| serve_client(socket, shared))
}

async fn serve_client(socket: WebSocket, shared: Arc<Shared>) {
    let (data_tx, mut data) = mpsc::channel(CLIENT_BACKLOG);
    let (control_tx, mut control) = mpsc::unbounded_channel();
    let id = {
        let mut inner = shared.lock();
        let id = inner.next_client;
        inner.next_client += 1;
        let _ = control_tx.send(Message::Text(
            protocol::server_info("kitchen-r", &shared.session_id).into(),
        ));
        let _ = control_tx.send(Message::Text(protocol::advertise(&inner.channels).into()));
        let client = Client {
            data: data_tx,
            control: control_tx,
            subscriptions: HashMap::new(),
        };
        inner.clients.insert(id, client);
        id
    };
    shared.connections.fetch_add(1, Ordering::Relaxed);
    let (mut out, mut incoming) = socket.split();
    loop {
        tokio::select! {
            biased;
            m = control.recv() => match m {
                Some(m) => if out.send(m).await.is_err() { break },
                None => break,
            },
            m = data.recv() => match m {
                Some(m) => if out.send(m).await.is_err() { break },
                None => break,
            },
            m = incoming.next() => match m {
                Some(Ok(Message::Text(t))) => on_op(&shared, id, protocol::parse(&t)),
                Some(Ok(Message::Close(_))) | Some(Err(_)) | None => break,
                Some(Ok(_)) => {}
            },
        }
    }
    let _ = out.send(Message::Close(None)).await;
    let mut inner = shared.lock();
    inner.clients.remove(&id);
    shared.update_sensors_watched(&inner);
}

fn on_op(shared: &Shared, id: u64, op: Option<ClientOp>) {
    let mut inner = shared.lock();
    let known: Vec<u32> = inner.channels.iter().map(|c| c.id).collect();
    let Some(client) = inner.clients.get_mut(&id) else {
        return;
    };
    match op {
        Some(ClientOp::Subscribe { subscriptions }) => {
            for s in subscriptions
                .into_iter()
                .filter(|s| known.contains(&s.channel_id))
            {
                client.subscriptions.insert(s.id, s.channel_id);
            }
        }
        Some(ClientOp::Unsubscribe { subscription_ids }) => {
            for s in subscription_ids {
                client.subscriptions.remove(&s);
            }
        }
        None => return,
    }
    shared.update_sensors_watched(&inner);
}

/// The publisher thread's side.
struct Sink(Arc<Shared>);

impl LiveSink for Sink {
    fn publish(&mut self, msg: &Ros2Message) {
        let mut inner = self.0.lock();
        let channel_id = match inner.channels.iter().find(|c| c.topic == msg.topic) {
            Some(c) => c.id,
            None => {
                let c = channel(inner.channels.len() as u32 + 1, &msg.topic, msg.ty);
                let text = protocol::advertise(std::slice::from_ref(&c));
                for client in inner.clients.values() {
                    let _ = client.control.send(Message::Text(text.clone().into()));
                }
                let id = c.id;
                inner.channels.push(c);
                id
            }
        };
        let ns = (msg.stamp.max(0.0) * 1e9).round() as u64;
        if inner.last_time_ns != Some(ns) {
            inner.last_time_ns = Some(ns);
            let time = protocol::time(ns);
            for client in inner.clients.values() {
                let _ = client.data.try_send(Message::Binary(time.clone().into()));
            }
        }
        for client in inner.clients.values() {
            let subs = client.subscriptions.iter().filter(|(_, c)| **c == channel_id);
            for (sub, _) in subs {
                let frame = protocol::message_data(*sub, ns, &msg.data);
                // Full: this client is behind; the frame is dropped for it alone.
                let _ = client.data.try_send(Message::Binary(frame.into()));
            }
        }
    }
}
