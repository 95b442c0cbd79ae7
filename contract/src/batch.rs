//! Batched decisions (`ActBatch`, opt-in through GetSpec's `max_batch`): the episodes of one
//! process that drive the same endpoint hand their pending decisions to one shared batcher,
//! which sends them to the policy together.
//!
//! Each episode still has its own [`RemotePolicy`](crate::RemotePolicy) (its own handshake,
//! Resets and chunk checks); only its Act goes through here. One batcher per endpoint, URL,
//! credentials, transport settings, cameras and GetSpec answer (so two teams, two deadlines or
//! a policy that changed its spec never share one), found in a process-wide registry and
//! dropped with the last episode attached to it.
//!
//! A dispatcher thread (its own runtime and connection) gathers decisions and sends a batch
//! when it is full (`max_batch`), when every episode attached is waiting (nothing more can
//! come), or when the oldest pending decision has waited the gather window
//! (`policy.batch_gather_ms`), so long as fewer than [`flights`] batches of the endpoint are in
//! flight (else it waits for one to land, at most a quarter of its call deadline). Two in
//! flight let a policy server overlap one batch's network pass with the next batch's transfer
//! and decoding, where one at a time left it idle between them (measured on an H200: the camera
//! baseline at 0.47× its unbatched rate with one batch in flight). Each episode waits for its
//! own answer under its own call deadline, counted from when it handed its decision in, so batching moves no deadline; a
//! batch call is given the latest of its decisions' deadlines, and a decision whose episode
//! gave up is not sent.

use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::mpsc as sync_mpsc;
use std::sync::{Arc, Mutex, OnceLock, Weak};
use std::time::{Duration, Instant};

use kitchen_r_proto::policy::v1 as pb;
use prost::Message;
use tokio::sync::mpsc;

use crate::conn::Conn;
use crate::endpoint::Endpoint;
use crate::{Credentials, RemoteConfig};
use kitchen_r_episode::policy::PolicyError;

/// ActBatch calls and the decisions they carried, since this process started.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct BatchStats {
    pub calls: u64,
    pub decisions: u64,
}

static CALLS: AtomicU64 = AtomicU64::new(0);
static DECISIONS: AtomicU64 = AtomicU64::new(0);

/// What this process has sent through ActBatch so far (`eval` reports the difference).
pub fn batch_stats() -> BatchStats {
    BatchStats {
        calls: CALLS.load(Ordering::Relaxed),
        decisions: DECISIONS.load(Ordering::Relaxed),
    }
}

const BATCH_CALLS: &str = "kitchen_r_worker_policy_batch_calls_total";
const BATCHED_DECISIONS: &str = "kitchen_r_worker_policy_batched_decisions_total";

fn describe() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        metrics::describe_counter!(BATCH_CALLS, "ActBatch calls sent to policy endpoints");
        metrics::describe_counter!(
            BATCHED_DECISIONS,
            "Decisions sent inside ActBatch calls (divided by the calls: the mean batch size)"
        );
    });
}

type Reply = sync_mpsc::SyncSender<Result<pb::ActionChunk, PolicyError>>;

/// One decision waiting for its chunk.
struct Pending {
    obs: pb::Observation,
    arrived: Instant,
    due: Instant,
    reply: Reply,
}

enum Msg {
    Decide(Box<Pending>),
    /// An episode detached: the "every episode is waiting" rule may now hold.
    Wake,
}

/// The batcher of one endpoint, shared by the episodes attached to it.
struct Shared {
    tx: mpsc::UnboundedSender<Msg>,
    attached: Arc<AtomicUsize>,
}

/// One episode's membership of a batcher; it leaves on drop.
pub(crate) struct Attachment {
    shared: Arc<Shared>,
    max_request_bytes: usize,
}

impl std::fmt::Debug for Attachment {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Attachment").finish_non_exhaustive()
    }
}

impl Drop for Attachment {
    fn drop(&mut self) {
        self.shared.attached.fetch_sub(1, Ordering::SeqCst);
        let _ = self.shared.tx.send(Msg::Wake);
    }
}

fn registry() -> &'static Mutex<HashMap<String, Weak<Shared>>> {
    static REGISTRY: OnceLock<Mutex<HashMap<String, Weak<Shared>>>> = OnceLock::new();
    REGISTRY.get_or_init(Mutex::default)
}

/// Everything that must match for two episodes to share a batcher.
fn key(ep: &Endpoint, creds: &Credentials, cfg: &RemoteConfig, spec: &pb::PolicySpec) -> String {
    format!(
        "{}|{:?}|{:?}|{}|{}|{:?}",
        ep.uri,
        creds.token,
        creds.ca_pem,
        serde_json::to_string(cfg).unwrap_or_default(),
        cfg.privileged_track,
        spec.encode_to_vec()
    )
}

/// The decisions per call for this endpoint: the policy's `max_batch` capped by ours; `None`
/// when either side does not batch.
pub(crate) fn batch_size(spec: &pb::PolicySpec, cfg: &RemoteConfig) -> Option<usize> {
    let n = spec.max_batch.min(cfg.max_batch);
    (n > 1).then_some(n as usize)
}

/// Batches of one endpoint in flight at once: two (a policy pipelines transfer and compute),
/// more when the policy declares more concurrent calls than two batches fill, one when it
/// takes one call at a time.
pub(crate) fn flights(max_concurrency: u32, max_batch: usize) -> usize {
    match max_concurrency as usize {
        0 | 1 => 1,
        n => n.div_ceil(max_batch.max(1)).clamp(2, n),
    }
}

/// Join (or start) the batcher of this endpoint. `None` when the dispatcher thread could not
/// start: the episode then sends its decisions one Act at a time.
pub(crate) fn attach(
    ep: &Endpoint,
    creds: &Credentials,
    cfg: &RemoteConfig,
    spec: &pb::PolicySpec,
    max_batch: usize,
) -> Option<Attachment> {
    let key = key(ep, creds, cfg, spec);
    let mut reg = registry().lock().ok()?;
    reg.retain(|_, w| w.strong_count() > 0);
    let shared = match reg.get(&key).and_then(Weak::upgrade) {
        Some(s) => s,
        None => {
            let s = start(
                ep.clone(),
                creds.clone(),
                cfg.clone(),
                max_batch,
                flights(spec.max_concurrency, max_batch),
            )?;
            reg.insert(key, Arc::downgrade(&s));
            s
        }
    };
    shared.attached.fetch_add(1, Ordering::SeqCst);
    Some(Attachment {
        shared,
        max_request_bytes: cfg.max_request_bytes,
    })
}

fn start(
    ep: Endpoint,
    creds: Credentials,
    cfg: RemoteConfig,
    max_batch: usize,
    max_flights: usize,
) -> Option<Arc<Shared>> {
    let (tx, rx) = mpsc::unbounded_channel();
    let attached = Arc::new(AtomicUsize::new(0));
    let seen = attached.clone();
    std::thread::Builder::new()
        .name("policy-batcher".into())
        .spawn(move || {
            let Ok(rt) = tokio::runtime::Builder::new_current_thread().enable_all().build() else {
                return;
            };
            // The lazy channel spawns its connection task on the runtime it is created in.
            let conn = {
                let _guard = rt.enter();
                Conn::new(ep, &creds, &cfg).map(|c| c.for_batch(max_batch, &cfg))
            };
            // Set-up failed: dropping `rx` makes every decision fail with the reason below.
            let Ok(conn) = conn else { return };
            // Waiting for a batch in flight costs a decision at most a quarter of its deadline.
            let times = (cfg.batch_gather(), cfg.call_deadline() / 4);
            rt.block_on(dispatch(rx, conn, (max_batch, max_flights), times, seen));
        })
        .ok()?;
    Some(Arc::new(Shared { tx, attached }))
}

impl Attachment {
    /// `obs`'s chunk, from whichever batch it joins, within `deadline` of now.
    pub(crate) fn act(
        &self,
        obs: pb::Observation,
        deadline: Duration,
    ) -> Result<pb::ActionChunk, PolicyError> {
        // As tonic's encoding cap words it for a single Act: a batch must not get around it.
        if obs.encoded_len() > self.max_request_bytes {
            return Err(PolicyError::Call(
                "ActBatch: the observation exceeds the request size cap (policy.max_request_bytes)".into(),
            ));
        }
        let (reply, answer) = sync_mpsc::sync_channel(1);
        let now = Instant::now();
        let pending = Pending {
            obs,
            arrived: now,
            due: now + deadline,
            reply,
        };
        let stopped =
            || PolicyError::Call("ActBatch: the connection to the policy could not be set up".into());
        self.shared
            .tx
            .send(Msg::Decide(Box::new(pending)))
            .map_err(|_| stopped())?;
        match answer.recv_timeout(deadline) {
            Ok(r) => r,
            Err(sync_mpsc::RecvTimeoutError::Timeout) => Err(PolicyError::Timeout(deadline.as_secs_f64())),
            Err(sync_mpsc::RecvTimeoutError::Disconnected) => Err(stopped()),
        }
    }
}

/// Gather decisions and send them in batches until every episode has left.
async fn dispatch(
    mut rx: mpsc::UnboundedReceiver<Msg>,
    conn: Conn,
    (max_batch, max_flights): (usize, usize),
    (window, hold): (Duration, Duration),
    attached: Arc<AtomicUsize>,
) {
    let flight = Arc::new(Flight::default());
    let mut pending: Vec<Pending> = Vec::new();
    let mut open = true;
    while open || !pending.is_empty() {
        if pending.is_empty() {
            match rx.recv().await {
                Some(Msg::Decide(p)) => pending.push(*p),
                Some(Msg::Wake) => continue,
                None => break,
            }
        }
        // Gather until the batch is full, nobody else can add a decision, or the oldest has
        // waited the window; then send it if fewer than `max_flights` batches are out, else wait
        // for one to land (at most `hold` more): a policy already busy with that many would only
        // queue it, and the decisions arriving meanwhile join it.
        loop {
            let now = Instant::now();
            let busy = flight.decisions.load(Ordering::SeqCst);
            let ready = !open
                || pending.len() >= max_batch
                || pending.len() + busy >= attached.load(Ordering::SeqCst)
                || now >= pending[0].arrived + window;
            let free = flight.calls.load(Ordering::SeqCst) < max_flights;
            let overdue = pending[0].arrived + window + hold;
            if (ready && free) || now >= overdue {
                break;
            }
            let wake = if ready {
                overdue
            } else {
                pending[0].arrived + window
            };
            tokio::select! {
                m = rx.recv(), if open => match m {
                    Some(Msg::Decide(p)) => pending.push(*p),
                    Some(Msg::Wake) => {}
                    None => open = false,
                },
                () = flight.landed.notified() => {}
                () = tokio::time::sleep_until(tokio::time::Instant::from_std(wake)) => {}
            }
        }
        let now = Instant::now();
        // A decision whose episode stopped waiting is not worth sending.
        pending.retain(|p| p.due > now);
        let take = pending.len().min(max_batch);
        let batch: Vec<Pending> = pending.drain(..take).collect();
        if !batch.is_empty() {
            flight.decisions.fetch_add(batch.len(), Ordering::SeqCst);
            flight.calls.fetch_add(1, Ordering::SeqCst);
            tokio::spawn(send(conn.clone(), batch, flight.clone()));
        }
    }
}

/// The batches and decisions in flight, and a wake-up when a batch comes back.
#[derive(Default)]
struct Flight {
    calls: AtomicUsize,
    decisions: AtomicUsize,
    landed: tokio::sync::Notify,
}

/// One ActBatch call; every decision in it gets its own chunk or the call's failure.
async fn send(mut conn: Conn, batch: Vec<Pending>, flight: Arc<Flight>) {
    let n = batch.len();
    let due = batch.iter().map(|p| p.due).max().unwrap_or_else(Instant::now);
    let mut replies = Vec::with_capacity(n);
    let mut observations = Vec::with_capacity(n);
    for p in batch {
        replies.push(p.reply);
        observations.push(p.obs);
    }
    CALLS.fetch_add(1, Ordering::Relaxed);
    DECISIONS.fetch_add(n as u64, Ordering::Relaxed);
    describe();
    metrics::counter!(BATCH_CALLS).increment(1);
    metrics::counter!(BATCHED_DECISIONS).increment(n as u64);
    let deadline = due.saturating_duration_since(Instant::now());
    let answer = conn
        .act_batch(pb::ObservationBatch { observations }, deadline)
        .await;
    flight.decisions.fetch_sub(n, Ordering::SeqCst);
    flight.calls.fetch_sub(1, Ordering::SeqCst);
    flight.landed.notify_one();
    let cap = conn.max_answer_bytes();
    match answer {
        Ok(b) if b.chunks.len() == n => {
            for (reply, chunk) in replies.into_iter().zip(b.chunks) {
                let r = if chunk.encoded_len() > cap {
                    Err(PolicyError::Call(format!(
                        "ActBatch: the answer for this decision exceeds the {cap}-byte size cap"
                    )))
                } else {
                    Ok(chunk)
                };
                let _ = reply.try_send(r);
            }
        }
        Ok(b) => {
            let why = PolicyError::Call(format!(
                "ActBatch: the policy answered {} chunks for {n} observations (one chunk per \
                 observation, in the same order)",
                b.chunks.len()
            ));
            for reply in replies {
                let _ = reply.try_send(Err(why.clone()));
            }
        }
        Err(e) => {
            for reply in replies {
                let _ = reply.try_send(Err(e.clone()));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::flights;

    #[test]
    fn a_policy_taking_one_call_at_a_time_gets_one_batch_at_a_time() {
        assert_eq!(flights(0, 16), 1);
        assert_eq!(flights(1, 16), 1);
    }

    #[test]
    fn two_batches_fly_unless_the_policy_declares_room_for_more() {
        assert_eq!(flights(16, 16), 2);
        assert_eq!(flights(4, 16), 2);
        assert_eq!(flights(2, 64), 2);
        assert_eq!(flights(64, 16), 4);
        assert_eq!(flights(3, 1), 3);
    }
}
