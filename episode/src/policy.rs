//! The policy interface the episode runner drives, whatever the policy is: the in-process
//! oracle, or (through the gRPC client) a participant's endpoint.
//!
//! The runner never trusts a policy: every chunk is checked by [`validate_chunk`] before a
//! single action of it reaches the simulator.

use kitchen_r_sim::Observation;
use kitchen_r_sim::task::TaskTarget;
use serde::{Deserialize, Serialize};

/// Action dimension of the paper's PROBLEM FORMULATION.
pub const ACTION_DIM: usize = 10;
/// Chunk length the paper's policies predict.
pub const HORIZON: usize = 16;

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
    /// Present only in organiser reference runs.
    pub privileged: Option<&'a Privileged>,
}

/// Why a policy could not give a usable chunk; the task fails with this reason.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
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
    /// Whether the next `act` call needs camera images and LiDAR. The runner renders only when
    /// it does (rendering is most of an episode's cost); the robot state is always there.
    fn wants_images(&self) -> bool {
        true
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
                horizon: HORIZON,
                action_dim: ACTION_DIM,
                cameras: Vec::new(),
                max_concurrency: 1,
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

/// Tolerance on the quaternion norm: chunks are produced in f32 by most learned policies.
pub(crate) const QUAT_NORM_TOLERANCE: f64 = 1e-2;

/// Shape, finiteness, gripper range and unit quaternion of every action in `chunk`.
pub fn validate_chunk(chunk: &[[f64; ACTION_DIM]], horizon: usize) -> Result<(), PolicyError> {
    if chunk.len() != horizon {
        return Err(PolicyError::BadChunk(format!(
            "expected {horizon} actions of {ACTION_DIM} values, got {} actions",
            chunk.len()
        )));
    }
    for (i, a) in chunk.iter().enumerate() {
        if let Some(j) = a.iter().position(|v| !v.is_finite()) {
            return Err(PolicyError::BadChunk(format!(
                "action {i} value {j} is not finite"
            )));
        }
        if !(0.0..=1.0).contains(&a[9]) {
            return Err(PolicyError::BadChunk(format!(
                "action {i}: gripper {} outside [0, 1]",
                a[9]
            )));
        }
        let n = a[5..9].iter().map(|q| q * q).sum::<f64>().sqrt();
        if (n - 1.0).abs() > QUAT_NORM_TOLERANCE {
            return Err(PolicyError::BadChunk(format!(
                "action {i}: quaternion norm {n:.4} is not 1 (±{QUAT_NORM_TOLERANCE})"
            )));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: [f64; 10] = [0.0, 0.0, 0.4, 0.0, 0.9, 1.0, 0.0, 0.0, 0.0, 1.0];

    #[test]
    fn a_well_formed_chunk_passes() {
        validate_chunk(&[GOOD; HORIZON], HORIZON).unwrap();
    }

    #[test]
    fn each_defect_is_named() {
        let mut nan = [GOOD; HORIZON];
        nan[3][4] = f64::NAN;
        let mut grip = [GOOD; HORIZON];
        grip[0][9] = 1.5;
        let mut quat = [GOOD; HORIZON];
        quat[7][5] = 2.0;
        let cases: [(&[[f64; 10]], &str); 4] = [
            (&[GOOD; 3], "got 3 actions"),
            (&nan, "action 3 value 4 is not finite"),
            (&grip, "gripper 1.5"),
            (&quat, "quaternion norm"),
        ];
        for (chunk, needle) in cases {
            let err = validate_chunk(chunk, HORIZON).unwrap_err().to_string();
            assert!(err.contains(needle), "{err:?} lacks {needle:?}");
        }
    }
}
