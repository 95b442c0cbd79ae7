//! The worker's simulation cores, decoupled from its episodes in flight.
//!
//! An episode needs a core only while it simulates: a participant's policy takes 10–100 ms per
//! call, and during that call the episode's thread sleeps on the network. So a worker holds more
//! episodes than it has cores, and each episode holds a *core permit* only while it steps: it
//! takes one before it builds its simulator, gives it back around every policy call
//! (`YieldsCore`) and for the policy's start-up handshake, and takes it again to go on.
//!
//! The permits are handed out first come, first served (a ticket queue), so no episode waits on
//! a core for longer than the episodes ahead of it take to reach their next policy call. The
//! queue also measures how busy the cores are ([`Cores::busy_permit_seconds`]), which the job
//! loop reads to decide whether one more episode would find a free core.

use std::collections::VecDeque;
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::Instant;

use kitchen_r_episode::policy::{ACTION_DIM, Policy, PolicyError, PolicyInput, PolicySpec};

/// Counting permits, one per simulation core; cloning shares them. [`Cores::unlimited`] never
/// makes anyone wait (local evaluation sizes its own thread pool).
#[derive(Debug, Clone)]
pub struct Cores(Option<Arc<Inner>>);

#[derive(Debug)]
struct Inner {
    total: usize,
    state: Mutex<State>,
    turn: Condvar,
}

#[derive(Debug)]
struct State {
    free: usize,
    /// Tickets of the threads waiting for a permit, oldest first.
    waiting: VecDeque<u64>,
    next_ticket: u64,
    /// Permit-seconds spent held, up to `since`.
    busy: f64,
    since: Instant,
}

impl State {
    /// Account the time since the last change at the current number of held permits.
    fn settle(&mut self, total: usize) {
        let now = Instant::now();
        self.busy += (total - self.free) as f64 * now.duration_since(self.since).as_secs_f64();
        self.since = now;
    }
}

impl Default for Cores {
    fn default() -> Cores {
        Cores::unlimited()
    }
}

impl Cores {
    /// `n` permits (at least one).
    pub fn new(n: usize) -> Cores {
        let total = n.max(1);
        Cores(Some(Arc::new(Inner {
            total,
            state: Mutex::new(State {
                free: total,
                waiting: VecDeque::new(),
                next_ticket: 0,
                busy: 0.0,
                since: Instant::now(),
            }),
            turn: Condvar::new(),
        })))
    }

    /// No limit: taking a permit never waits.
    pub fn unlimited() -> Cores {
        Cores(None)
    }

    /// Permits in all (`usize::MAX` when unlimited).
    pub fn total(&self) -> usize {
        self.0.as_ref().map_or(usize::MAX, |i| i.total)
    }

    /// A handle that holds no permit yet.
    pub fn core(&self) -> Core {
        Core {
            cores: self.clone(),
            held: false,
        }
    }

    /// Permit-seconds held since the permits were made: its growth over a window, divided by
    /// the window and [`Cores::total`], is how busy the cores were (0 to 1).
    pub fn busy_permit_seconds(&self) -> f64 {
        match &self.0 {
            Some(i) => {
                let mut s = lock(&i.state);
                s.settle(i.total);
                s.busy
            }
            None => 0.0,
        }
    }

    fn take(&self) {
        let Some(i) = &self.0 else { return };
        let mut s = lock(&i.state);
        let ticket = s.next_ticket;
        s.next_ticket += 1;
        s.waiting.push_back(ticket);
        while !(s.free > 0 && s.waiting.front() == Some(&ticket)) {
            s = i.turn.wait(s).unwrap_or_else(|p| p.into_inner());
        }
        s.waiting.pop_front();
        s.settle(i.total);
        s.free -= 1;
        // The next in line may find a permit too.
        i.turn.notify_all();
    }

    /// Take a permit only when one is free and no episode waits for one (video renders, issue
    /// #26): background work never goes ahead of an episode.
    fn take_background(&self) {
        let Some(i) = &self.0 else { return };
        let mut s = lock(&i.state);
        while !(s.free > 0 && s.waiting.is_empty()) {
            s = i.turn.wait(s).unwrap_or_else(|p| p.into_inner());
        }
        s.settle(i.total);
        s.free -= 1;
    }

    fn give(&self) {
        let Some(i) = &self.0 else { return };
        let mut s = lock(&i.state);
        s.settle(i.total);
        s.free = (s.free + 1).min(i.total);
        i.turn.notify_all();
    }
}

fn lock(m: &Mutex<State>) -> MutexGuard<'_, State> {
    // A panic while holding the lock leaves plain counters behind: still usable.
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// One episode's claim on a core: held or not, given back when dropped.
#[derive(Debug)]
pub struct Core {
    cores: Cores,
    held: bool,
}

impl Core {
    /// Wait for a permit (first come, first served); no-op when already held.
    pub fn hold(&mut self) {
        if !self.held {
            self.cores.take();
            self.held = true;
        }
    }

    /// Wait for a permit that no episode is waiting for (background work); no-op when held.
    pub fn hold_background(&mut self) {
        if !self.held {
            self.cores.take_background();
            self.held = true;
        }
    }

    /// Background work between two steps: give the permit back and take it again once no
    /// episode waits, so an episode never waits on background work for longer than one step.
    pub fn yield_to_episodes(&mut self) {
        if self.held {
            self.release();
            self.hold_background();
        }
    }

    /// Give the permit back while this episode waits on something else; no-op when not held.
    pub fn release(&mut self) {
        if self.held {
            self.cores.give();
            self.held = false;
        }
    }

    /// Run `f` (a wait on the network) without the permit, then take it again.
    pub fn without<T>(&mut self, f: impl FnOnce() -> T) -> T {
        self.release();
        let out = f();
        self.hold();
        out
    }
}

impl Drop for Core {
    fn drop(&mut self) {
        self.release();
    }
}

/// A policy whose calls are made without holding a core: the episode's permit goes back for the
/// call and is taken again before the answer is simulated.
pub(crate) struct YieldsCore<'a> {
    pub(crate) policy: &'a mut dyn Policy,
    pub(crate) core: &'a mut Core,
}

impl Policy for YieldsCore<'_> {
    fn spec(&self) -> &PolicySpec {
        self.policy.spec()
    }

    fn reset(&mut self, episode_id: &str, task_index: usize, sub_task: &str) -> Result<(), PolicyError> {
        let policy = &mut *self.policy;
        self.core
            .without(|| policy.reset(episode_id, task_index, sub_task))
    }

    fn act(&mut self, input: &PolicyInput<'_>) -> Result<Vec<[f64; ACTION_DIM]>, PolicyError> {
        let policy = &mut *self.policy;
        self.core.without(|| policy.act(input))
    }

    fn wants_images(&self) -> bool {
        self.policy.wants_images()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::time::Duration;

    #[test]
    fn no_more_holders_than_permits_and_each_gets_its_turn() {
        let cores = Cores::new(2);
        let (now, peak) = (Arc::new(AtomicUsize::new(0)), Arc::new(AtomicUsize::new(0)));
        let threads: Vec<_> = (0..8)
            .map(|_| {
                let (cores, now, peak) = (cores.clone(), now.clone(), peak.clone());
                std::thread::spawn(move || {
                    let mut core = cores.core();
                    for _ in 0..20 {
                        core.hold();
                        let n = now.fetch_add(1, Ordering::SeqCst) + 1;
                        peak.fetch_max(n, Ordering::SeqCst);
                        std::thread::sleep(Duration::from_micros(200));
                        now.fetch_sub(1, Ordering::SeqCst);
                        // The "policy call": no permit held.
                        core.release();
                        std::thread::sleep(Duration::from_micros(300));
                    }
                })
            })
            .collect();
        for t in threads {
            t.join().unwrap();
        }
        let peak = peak.load(Ordering::SeqCst);
        assert!((1..=2).contains(&peak), "{peak} held at once with 2 permits");
        // Every permit came back.
        let mut all: Vec<Core> = (0..2).map(|_| cores.core()).collect();
        all.iter_mut().for_each(Core::hold);
    }

    #[test]
    fn background_work_yields_its_core_to_a_waiting_episode() {
        let cores = Cores::new(1);
        let mut render = cores.core();
        render.hold_background();
        let got = Arc::new(AtomicUsize::new(0));
        let episode = {
            let (cores, got) = (cores.clone(), got.clone());
            std::thread::spawn(move || {
                let mut core = cores.core();
                core.hold();
                got.store(1, Ordering::SeqCst);
                std::thread::sleep(Duration::from_millis(50));
                // Still the episode's: the render has not taken the permit back meanwhile.
                assert_eq!(got.load(Ordering::SeqCst), 1);
                core.release();
            })
        };
        // Wait until the episode queues for the permit, then yield: the episode goes first.
        while lock(&cores.0.as_ref().unwrap().state).waiting.is_empty() {
            std::thread::sleep(Duration::from_millis(1));
        }
        render.yield_to_episodes();
        got.store(2, Ordering::SeqCst);
        episode.join().unwrap();
    }

    #[test]
    fn a_dropped_core_gives_its_permit_back_and_busy_time_is_counted() {
        let cores = Cores::new(1);
        let before = cores.busy_permit_seconds();
        {
            let mut c = cores.core();
            c.hold();
            std::thread::sleep(Duration::from_millis(20));
        }
        let held = cores.busy_permit_seconds() - before;
        assert!(held >= 0.019, "{held}");
        // Free again: this would wait forever otherwise.
        cores.core().hold();
        assert_eq!(Cores::unlimited().total(), usize::MAX);
        Cores::unlimited().core().hold();
    }
}
