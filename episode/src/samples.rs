//! Expert training samples straight from parallel simulators: behaviour cloning's data at
//! simulator speed, with no video encoded or decoded on the way (the Python package's
//! `ExpertSamples`).
//!
//! Each episode is collection's episode of the same index and seed ([`collection_episode`]:
//! `kitchen-r collect` builds the same one, with the paper's randomisation when asked), run by
//! the leaderboard's runner with the oracle as the policy, asked every `execute` control steps.
//! A sample is one decision: what a policy asked at that moment is sent (its observation
//! history, the sub-task) and the expert's chunk as the label. The runner renders only the
//! frames a decision shows, so only the samples' frames are rendered.
//!
//! Episodes run on `workers` threads (each with its own simulator and oracle) and come out in
//! episode order whatever the thread count: the same seed gives the same samples. A window
//! bounds how far the threads run ahead of the consumer.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::thread::JoinHandle;

use kitchen_r_core::dataset::Instruction;
use kitchen_r_sim::seeds::sub_seed;
use kitchen_r_sim::{Assets, EpisodeConfig, EpisodeParams, SensorsConfig, Sim, SimConfig, SimError};

use crate::oracle::OraclePolicy;
use crate::policy::{
    ACTION_DIM, Frame, HORIZON, MAX_OBSERVATION_HISTORY, Policy, PolicyError, PolicyInput, PolicySpec,
    Privileged,
};
use crate::runner::{EpisodeOutcome, RunError, RunOptions, run_episode};

/// Episode `index` of a collection with `seed`: instruction `index` modulo their count, its own
/// seed drawn from `seed` and `index`, randomised as `configs/episodes.toml` `[randomise]`
/// switches when `randomise`. `kitchen-r collect` and [`SampleStream`] build episodes with it.
pub fn collection_episode(
    assets: &Assets,
    params: &EpisodeParams,
    instructions: &[Instruction],
    seed: u64,
    index: usize,
    randomise: bool,
) -> Result<EpisodeConfig, SimError> {
    if instructions.is_empty() {
        return Err(SimError::Episode("no instructions to build episodes from".into()));
    }
    let instruction = &instructions[index % instructions.len()];
    let episode_seed = sub_seed(seed, index as u64);
    let mut cfg = instruction_episode(assets, params, instruction, episode_seed, randomise)?;
    cfg.id = format!("ep{index:05}");
    Ok(cfg)
}

/// The episode of `instruction` drawn with episode seed `seed`, with the paper's randomisation
/// (`configs/episodes.toml` `[randomise]`, from the same seed) when `randomise`. Collection,
/// `kitchen-r episodes generate --from-dataset` and the Python environment all build their
/// episodes with it, so the same seed is the same episode everywhere.
pub fn instruction_episode(
    assets: &Assets,
    params: &EpisodeParams,
    instruction: &Instruction,
    seed: u64,
    randomise: bool,
) -> Result<EpisodeConfig, SimError> {
    let scene = assets.scene(&instruction.scene)?;
    let mut cfg = EpisodeConfig::from_instruction(instruction, scene, &assets.catalogue, params, seed)?;
    if randomise {
        kitchen_r_sim::randomise(&mut cfg, scene, &assets.catalogue, params, seed)?;
    }
    Ok(cfg)
}

/// What a stream of samples holds and how it is produced.
#[derive(Debug, Clone, PartialEq)]
pub struct SampleOptions {
    /// Collection seed: the same seed gives the same episodes and samples.
    pub seed: u64,
    /// Episodes in the stream (of this shard).
    pub episodes: usize,
    /// Simulator threads.
    pub workers: usize,
    /// Control steps between decisions: the expert is asked every `execute` steps and its
    /// chunk's first `execute` actions are executed (1..=16).
    pub execute: usize,
    /// Consecutive control steps a sample shows, the newest included (1..=8).
    pub observation_history: usize,
    /// Render the cameras for the samples' frames; false gives the robot state only.
    pub images: bool,
    /// The paper's randomisation (`configs/episodes.toml` `[randomise]`).
    pub randomise: bool,
    /// Drop the samples of tasks the expert failed (they would teach its mistakes).
    pub successful_only: bool,
    /// Task time limit and plan length (`execute` and `privileged` are set here).
    pub run: RunOptions,
    /// This stream's share of the collection: episodes `n` with `n % count == index`, so
    /// several consumers (data loader workers) share one collection without overlap.
    pub shard: (usize, usize),
}

impl Default for SampleOptions {
    fn default() -> Self {
        SampleOptions {
            seed: 0,
            episodes: 1,
            workers: 1,
            execute: 8,
            observation_history: 1,
            images: true,
            randomise: true,
            successful_only: true,
            run: RunOptions::default(),
            shard: (0, 1),
        }
    }
}

impl SampleOptions {
    fn validate(&self) -> Result<(), SampleError> {
        let bad = |m: String| Err(SampleError::Options(m));
        if !(1..=HORIZON).contains(&self.execute) {
            return bad(format!("execute must be 1 to {HORIZON}, not {}", self.execute));
        }
        if !(1..=MAX_OBSERVATION_HISTORY).contains(&self.observation_history) {
            return bad(format!(
                "history must be 1 to {MAX_OBSERVATION_HISTORY} control steps, not {}",
                self.observation_history
            ));
        }
        if self.workers == 0 {
            return bad("workers must be at least 1".into());
        }
        let (index, count) = self.shard;
        if count == 0 || index >= count {
            return bad(format!(
                "shard {index} of {count}: the index must be below the count"
            ));
        }
        Ok(())
    }

    /// The collection index of this stream's `k`-th episode.
    fn index(&self, k: usize) -> usize {
        self.shard.0 + k * self.shard.1
    }
}

/// One decision of the expert: what a policy is sent, and the expert's chunk.
#[derive(Debug, Clone)]
pub struct Sample {
    /// Control steps since the episode started.
    pub step: u64,
    pub task_index: usize,
    pub sub_task: String,
    /// The observation history, oldest first, the decision's own frame last: up to
    /// `observation_history` frames (fewer at a task's start).
    pub frames: Vec<Frame>,
    /// The expert's 16 actions.
    pub chunk: Vec<[f64; ACTION_DIM]>,
    /// The world state the expert read (what the privileged track's observation is derived
    /// from, [`crate::policy::PrivilegedObservation::from_world`]).
    pub privileged: Option<Privileged>,
}

/// One episode's samples, in decision order.
#[derive(Debug, Clone)]
pub struct EpisodeSamples {
    /// The episode's index in the collection.
    pub index: usize,
    pub instruction_id: String,
    pub config: EpisodeConfig,
    pub outcome: EpisodeOutcome,
    pub samples: Vec<Sample>,
}

#[derive(Debug, thiserror::Error)]
pub enum SampleError {
    #[error("{0}")]
    Options(String),
    #[error("episode {index}: {source}")]
    Episode { index: usize, source: SimError },
    #[error("episode {index}: {source}")]
    Run { index: usize, source: RunError },
    #[error("a simulator thread panicked")]
    Panicked,
}

/// The episodes of a collection as they finish, in order.
pub struct SampleStream {
    results: Receiver<(usize, Result<EpisodeSamples, SampleError>)>,
    pending: BTreeMap<usize, Result<EpisodeSamples, SampleError>>,
    next: usize,
    total: usize,
    window: Arc<Window>,
    threads: Vec<JoinHandle<()>>,
}

/// How far the threads may run ahead: episode `k` starts only once `k < yielded + size`.
struct Window {
    yielded: Mutex<usize>,
    moved: Condvar,
    size: usize,
    stop: AtomicBool,
}

impl Window {
    fn wait_for(&self, k: usize) -> bool {
        let mut yielded = self.yielded.lock().unwrap_or_else(PoisonError::into_inner);
        while k >= *yielded + self.size && !self.stop.load(Ordering::SeqCst) {
            yielded = self.moved.wait(yielded).unwrap_or_else(PoisonError::into_inner);
        }
        !self.stop.load(Ordering::SeqCst)
    }

    fn advance(&self, to: usize) {
        *self.yielded.lock().unwrap_or_else(PoisonError::into_inner) = to;
        self.moved.notify_all();
    }

    fn halt(&self) {
        self.stop.store(true, Ordering::SeqCst);
        let _guard = self.yielded.lock().unwrap_or_else(PoisonError::into_inner);
        self.moved.notify_all();
    }
}

impl SampleStream {
    /// Start `opts.workers` simulator threads over the episodes built from `instructions`.
    pub fn start(
        assets: Assets,
        instructions: Vec<Instruction>,
        opts: SampleOptions,
    ) -> Result<SampleStream, SampleError> {
        opts.validate()?;
        if instructions.is_empty() {
            return Err(SampleError::Options(
                "no instructions to build episodes from".into(),
            ));
        }
        let setup = |e: SimError| SampleError::Episode { index: 0, source: e };
        let params = EpisodeParams::load_default().map_err(setup)?;
        let sim_cfg = SimConfig::load_default().map_err(setup)?;
        let sensors = SensorsConfig::load_default().map_err(setup)?;
        let workers = opts.workers.min(opts.episodes.max(1));
        let window = Arc::new(Window {
            yielded: Mutex::new(0),
            moved: Condvar::new(),
            size: 2 * workers,
            stop: AtomicBool::new(false),
        });
        let (tx, rx) = sync_channel(2 * workers);
        let next = Arc::new(AtomicUsize::new(0));
        let shared = Arc::new(Shared {
            assets,
            params,
            sim_cfg,
            sensors,
            instructions,
            opts,
        });
        let threads = (0..workers)
            .map(|i| {
                let (shared, next, window, tx) = (shared.clone(), next.clone(), window.clone(), tx.clone());
                std::thread::Builder::new()
                    .name(format!("kitchen-r-samples-{i}"))
                    .spawn(move || worker(&shared, &next, &window, &tx))
                    .map_err(|_| SampleError::Panicked)
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(SampleStream {
            results: rx,
            pending: BTreeMap::new(),
            next: 0,
            total: shared.opts.episodes,
            window,
            threads,
        })
    }

    /// Episodes this stream yields in all.
    pub fn len(&self) -> usize {
        self.total
    }

    pub fn is_empty(&self) -> bool {
        self.total == 0
    }
}

impl Iterator for SampleStream {
    type Item = Result<EpisodeSamples, SampleError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.next >= self.total {
            return None;
        }
        loop {
            if let Some(r) = self.pending.remove(&self.next) {
                self.next += 1;
                self.window.advance(self.next);
                return Some(r);
            }
            match self.results.recv() {
                Ok((k, r)) => {
                    self.pending.insert(k, r);
                }
                Err(_) => {
                    // Every thread is gone and episode `next` never came: one panicked.
                    self.next = self.total;
                    return Some(Err(SampleError::Panicked));
                }
            }
        }
    }
}

impl Drop for SampleStream {
    fn drop(&mut self) {
        self.window.halt();
        // Unblock senders waiting on a full channel, then wait for the threads.
        while self.results.try_recv().is_ok() {}
        for t in self.threads.drain(..) {
            while !t.is_finished() {
                while self.results.try_recv().is_ok() {}
                std::thread::sleep(std::time::Duration::from_millis(1));
            }
            let _ = t.join();
        }
    }
}

struct Shared {
    assets: Assets,
    params: EpisodeParams,
    sim_cfg: SimConfig,
    sensors: SensorsConfig,
    instructions: Vec<Instruction>,
    opts: SampleOptions,
}

type Results = SyncSender<(usize, Result<EpisodeSamples, SampleError>)>;

fn worker(shared: &Shared, next: &AtomicUsize, window: &Window, tx: &Results) {
    let opts = &shared.opts;
    let mut sim: Option<Sim> = None;
    let mut recorder = Recorder {
        oracle: OraclePolicy::new(&shared.assets).with_grasp_mode(shared.sim_cfg.grasp.mode),
        spec: PolicySpec {
            name: "expert-samples".into(),
            horizon: HORIZON,
            observation_history: opts.observation_history,
            actions_executed_per_chunk: Some(opts.execute),
            ..PolicySpec::default()
        },
        images: opts.images,
        samples: Vec::new(),
    };
    let run = RunOptions {
        execute: opts.execute,
        privileged: true,
        wall_budget: None,
        ..opts.run.clone()
    };
    loop {
        let k = next.fetch_add(1, Ordering::SeqCst);
        if k >= opts.episodes || !window.wait_for(k) {
            return;
        }
        let r = one(shared, &mut sim, &mut recorder, &run, opts.index(k));
        if r.is_err() {
            // A simulator that failed mid-episode is rebuilt for the next one.
            sim = None;
        }
        if tx.send((k, r)).is_err() {
            return;
        }
    }
}

fn one(
    shared: &Shared,
    sim: &mut Option<Sim>,
    recorder: &mut Recorder,
    run: &RunOptions,
    index: usize,
) -> Result<EpisodeSamples, SampleError> {
    let ep = |source| SampleError::Episode { index, source };
    let opts = &shared.opts;
    let cfg = collection_episode(
        &shared.assets,
        &shared.params,
        &shared.instructions,
        opts.seed,
        index,
        opts.randomise,
    )
    .map_err(ep)?;
    let s = crate::sim_slot::load(sim, &shared.assets, &shared.sim_cfg, &shared.sensors, &cfg).map_err(ep)?;
    recorder.samples.clear();
    let outcome =
        run_episode(s, recorder, run, None, &mut ()).map_err(|source| SampleError::Run { index, source })?;
    let mut samples = std::mem::take(&mut recorder.samples);
    if opts.successful_only {
        samples.retain(|s| outcome.tasks.iter().any(|t| t.index == s.task_index && t.success));
    }
    Ok(EpisodeSamples {
        index,
        instruction_id: shared.instructions[index % shared.instructions.len()].id.clone(),
        config: cfg,
        outcome,
        samples,
    })
}

/// The oracle, keeping each decision it answers as a sample.
struct Recorder {
    oracle: OraclePolicy,
    spec: PolicySpec,
    images: bool,
    samples: Vec<Sample>,
}

impl Policy for Recorder {
    fn spec(&self) -> &PolicySpec {
        &self.spec
    }

    fn reset(&mut self, episode_id: &str, task_index: usize, sub_task: &str) -> Result<(), PolicyError> {
        self.oracle.reset(episode_id, task_index, sub_task)
    }

    fn act(&mut self, input: &PolicyInput<'_>) -> Result<Vec<[f64; ACTION_DIM]>, PolicyError> {
        let chunk = self.oracle.act(input)?;
        let mut frames = input.history.to_vec();
        frames.push(Frame {
            step: input.step,
            observation: input.observation.clone(),
            ee_pose: input.ee_pose,
            previous_action: input.previous_action,
        });
        self.samples.push(Sample {
            step: input.step,
            task_index: input.task_index,
            sub_task: input.sub_task.to_string(),
            frames,
            chunk: chunk.clone(),
            privileged: input.privileged.cloned(),
        });
        Ok(chunk)
    }

    fn wants_images(&self) -> bool {
        self.images
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn options_out_of_range_are_refused_with_the_reason() {
        let bad = [
            SampleOptions {
                execute: 0,
                ..Default::default()
            },
            SampleOptions {
                execute: 17,
                ..Default::default()
            },
            SampleOptions {
                observation_history: 9,
                ..Default::default()
            },
            SampleOptions {
                workers: 0,
                ..Default::default()
            },
            SampleOptions {
                shard: (2, 2),
                ..Default::default()
            },
        ];
        for o in bad {
            assert!(matches!(o.validate(), Err(SampleError::Options(_))), "{o:?}");
        }
        let shard = SampleOptions {
            shard: (1, 3),
            ..Default::default()
        };
        assert_eq!((0..3).map(|k| shard.index(k)).collect::<Vec<_>>(), vec![1, 4, 7]);
    }
}
