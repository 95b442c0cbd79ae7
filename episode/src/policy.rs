//! The policy interface the episode runner drives, whatever the policy is: the in-process
//! oracle, or (through the gRPC client) a participant's endpoint.
//!
//! The runner never trusts a policy: every chunk goes through [`check_chunk`] before a single
//! action of it reaches the simulator. Small numeric slips that learned models make routinely
//! (a quaternion norm a little off 1, a gripper value a hair outside [0, 1]) are corrected and
//! counted ([`Corrections`], reported with the task as a warning); anything beyond the
//! organiser's [`ChunkTolerance`] fails the task with the reason.

use kitchen_r_sim::Observation;
use kitchen_r_sim::task::TaskTarget;
use serde::{Deserialize, Serialize};

/// Action dimension of the paper's PROBLEM FORMULATION.
pub const ACTION_DIM: usize = 10;
/// Chunk length the paper's policies predict.
pub const HORIZON: usize = 16;
/// Most consecutive frames a policy may ask to see with each decision (contract v1.1).
pub const MAX_OBSERVATION_HISTORY: usize = 8;

/// What a policy announces about itself (the GetSpec handshake).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PolicySpec {
    pub name: String,
    /// Actions per chunk (16).
    pub horizon: usize,
    /// Values per action (10).
    pub action_dim: usize,
    /// Cameras the policy wants, by configured name; empty = every configured camera.
    pub cameras: Vec<String>,
    /// Parallel episodes the endpoint accepts.
    pub max_concurrency: u32,
    /// Consecutive control steps each decision sees, the newest included (1..=8; 1 = v1).
    #[serde(default = "one")]
    pub observation_history: usize,
    /// Actions of each chunk executed before asking again, when the policy chose (v1.1);
    /// `None` = the organiser's [`RunOptions::execute`](crate::runner::RunOptions::execute).
    #[serde(default)]
    pub actions_executed_per_chunk: Option<usize>,
    /// The policy asks for privileged observations (the privileged track; [`privileged`]).
    /// Whether it gets them is the run's decision
    /// ([`RunOptions::privileged_observations`](crate::runner::RunOptions::privileged_observations)).
    #[serde(default)]
    pub privileged_observations: bool,
}

fn one() -> usize {
    1
}

impl Default for PolicySpec {
    /// A v1 policy: 16×10 chunks, default cameras, one frame, the organiser's execution count.
    fn default() -> Self {
        PolicySpec {
            name: String::new(),
            horizon: HORIZON,
            action_dim: ACTION_DIM,
            cameras: Vec::new(),
            max_concurrency: 1,
            observation_history: 1,
            actions_executed_per_chunk: None,
            privileged_observations: false,
        }
    }
}

/// World state only organiser-run reference policies (the oracle) may see.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Privileged {
    pub scene: String,
    /// World `[x, y, yaw]` of the base centre.
    pub base_pose: [f64; 3],
    /// Key objects: name, catalogue model and world pose `[x, y, z, qw, qx, qy, qz]`.
    pub objects: Vec<PrivilegedObject>,
    pub held: Option<String>,
    /// Tool centre point pose in the base frame `[x, y, z, qw, qx, qy, qz]`.
    pub ee_pose: [f64; 7],
    /// What the current task must achieve.
    pub target: TaskTarget,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PrivilegedObject {
    pub name: String,
    pub model: String,
    pub pose: [f64; 7],
}

/// One control step as a policy sees it (an element of an observation history).
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// Control steps since the episode started.
    pub step: u64,
    /// Images only where the runner rendered (the policy wants images); robot state always.
    pub observation: Observation,
    /// Hand (tool centre point) pose in the base frame `[x, y, z, qw, qx, qy, qz]`.
    pub ee_pose: [f64; 7],
    /// The action executed in the step that led here (after corrections); `None` at the start
    /// of the episode and after the robot was moved to the expert's state (teleport).
    pub previous_action: Option<[f64; ACTION_DIM]>,
}

/// One decision point.
#[derive(Debug, Clone, Copy)]
pub struct PolicyInput<'a> {
    pub episode_id: &'a str,
    /// Control steps since the episode started.
    pub step: u64,
    pub task_index: usize,
    /// The sub-task sentence, a canonical plan step (`pick the bowl`).
    pub sub_task: &'a str,
    pub observation: &'a Observation,
    /// Hand pose in the base frame `[x, y, z, qw, qx, qy, qz]`, in every run.
    pub ee_pose: [f64; 7],
    /// The action executed in the last control step; `None` before the first one of the
    /// episode and right after a teleport.
    pub previous_action: Option<[f64; ACTION_DIM]>,
    /// The frames before this one, oldest first, consecutive control steps of the current task:
    /// at most `observation_history - 1`, fewer at the start of a task (the wire pads them).
    pub history: &'a [Frame],
    /// Present only in organiser reference runs.
    pub privileged: Option<&'a Privileged>,
    /// Present only in runs on the privileged track, as their scope allows ([`privileged`]).
    pub privileged_observation: Option<&'a PrivilegedObservation>,
}

/// Why a policy could not give a usable chunk; the task fails with this reason. Serde-able
/// because a trace records it ([`crate::trace`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error, Serialize, Deserialize)]
pub enum PolicyError {
    #[error("policy call failed: {0}")]
    Call(String),
    #[error("policy did not answer within {0:.1} s")]
    Timeout(f64),
    #[error("invalid action chunk: {0}")]
    BadChunk(String),
    #[error("policy needs privileged state, which only organiser reference runs provide")]
    NeedsPrivileged,
}

pub trait Policy: Send {
    fn spec(&self) -> &PolicySpec;
    /// Called when a task (plan step) starts.
    fn reset(&mut self, episode_id: &str, task_index: usize, sub_task: &str) -> Result<(), PolicyError>;
    /// The next chunk of `horizon` actions.
    fn act(&mut self, input: &PolicyInput<'_>) -> Result<Vec<[f64; ACTION_DIM]>, PolicyError>;
    /// Whether the frame the runner is about to capture needs camera images and LiDAR. The
    /// runner renders only the frames a decision will show and only when this says so
    /// (rendering is most of an episode's cost); the robot state is always there.
    fn wants_images(&self) -> bool {
        true
    }
}

/// A borrowed policy drives an episode as the policy itself, so wrappers such as
/// [`crate::trace::TracingPolicy`] take either.
impl<P: Policy + ?Sized> Policy for &mut P {
    fn spec(&self) -> &PolicySpec {
        (**self).spec()
    }
    fn reset(&mut self, episode_id: &str, task_index: usize, sub_task: &str) -> Result<(), PolicyError> {
        (**self).reset(episode_id, task_index, sub_task)
    }
    fn act(&mut self, input: &PolicyInput<'_>) -> Result<Vec<[f64; ACTION_DIM]>, PolicyError> {
        (**self).act(input)
    }
    fn wants_images(&self) -> bool {
        (**self).wants_images()
    }
}

/// Stands in for an endpoint that could not be reached or refused the handshake: every call
/// fails with the same reason. Offline episodes run it so that such a policy is charged a failed
/// prediction at every decision point, exactly as a bad chunk is: dodging the MSE episodes never
/// improves MSE or P.
#[derive(Debug, Clone)]
pub struct Unreachable {
    spec: PolicySpec,
    reason: String,
}

impl Unreachable {
    pub fn new(reason: impl Into<String>) -> Unreachable {
        Unreachable {
            spec: PolicySpec {
                name: "unreachable".into(),
                ..PolicySpec::default()
            },
            reason: reason.into(),
        }
    }
}

impl Policy for Unreachable {
    fn spec(&self) -> &PolicySpec {
        &self.spec
    }
    fn reset(&mut self, _: &str, _: usize, _: &str) -> Result<(), PolicyError> {
        Ok(())
    }
    fn act(&mut self, _: &PolicyInput<'_>) -> Result<Vec<[f64; ACTION_DIM]>, PolicyError> {
        Err(PolicyError::Call(self.reason.clone()))
    }
    fn wants_images(&self) -> bool {
        false
    }
}

mod chunk;
pub mod privileged;
mod state;
pub use chunk::{ChunkTolerance, Corrections, check_chunk};
pub use privileged::{Goal, PrivilegedObservation, PrivilegedScope};
pub use state::{STATE_FIELDS, state_vector};
