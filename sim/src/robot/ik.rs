//! Numerical inverse kinematics: damped least squares on the geometric Jacobian of
//! [`ArmModel`], with a seven-joint arm's redundant direction pulled towards a rest pose through
//! the Jacobian's null space, and
//! the joint limits applied at every step. No crate fitted: `k` builds its own chain type from a
//! URDF and knows neither MJCF nor our turned joint frames, so this solves on the very model the
//! controller and the oracle use (tested against its forward kinematics below).

use nalgebra::{Isometry3, Matrix6, SMatrix, Vector6};

use super::kinematics::{ArmModel, JointVec, MAX_DOF};
use super::rmp::orientation_error;

/// Tolerances and step rules.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IkOptions {
    /// Position and orientation error at which a solution is accepted (m, rad).
    pub position_tolerance: f64,
    pub orientation_tolerance: f64,
    pub max_iterations: usize,
    /// Damping λ of `Jᵀ(JJᵀ + λ²I)⁻¹`.
    pub damping: f64,
    /// Gain of the null-space pull towards the rest pose (per iteration).
    pub rest_gain: f64,
    /// Largest joint step per iteration (rad).
    pub max_step: f64,
}

impl Default for IkOptions {
    fn default() -> Self {
        IkOptions {
            position_tolerance: 1e-5,
            orientation_tolerance: 1e-4,
            max_iterations: 300,
            damping: 0.02,
            rest_gain: 0.1,
            max_step: 0.2,
        }
    }
}

/// A target the solver did not reach: the best configuration and its errors.
#[derive(Debug, Clone, PartialEq)]
pub struct IkMiss {
    pub q: JointVec,
    pub position_error: f64,
    pub orientation_error: f64,
}

/// Joint values that put the TCP at `target` (base frame), starting from `seed`; the arm's
/// self-motion drifts towards `rest`.
pub fn solve(
    arm: &ArmModel,
    target: &Isometry3<f64>,
    seed: &JointVec,
    rest: &JointVec,
    o: &IkOptions,
) -> Result<JointVec, IkMiss> {
    let mut q = arm.clamp(seed);
    let mut best = (f64::INFINITY, q, 0.0, 0.0);
    for _ in 0..o.max_iterations {
        let fk = arm.forward(&q);
        let ep = target.translation.vector - fk.tcp.translation.vector;
        let eo = orientation_error(&target.rotation, &fk.tcp.rotation);
        let (np, no) = (ep.norm(), eo.norm());
        if np + no < best.0 {
            best = (np + no, q, np, no);
        }
        if np < o.position_tolerance && no < o.orientation_tolerance {
            return Ok(q);
        }
        let jac = arm.jacobian(&fk);
        let e = Vector6::new(ep.x, ep.y, ep.z, eo.x, eo.y, eo.z);
        let jjt: Matrix6<f64> = jac * jac.transpose() + Matrix6::identity() * (o.damping * o.damping);
        let Some(inv) = jjt.try_inverse() else { break };
        let pinv: SMatrix<f64, MAX_DOF, 6> = jac.transpose() * inv;
        let mut step = pinv * e;
        if arm.dof > 6 {
            // The self-motion towards rest, through the exact null-space projector (the damped
            // one leaks into the task and would hold the TCP off its target).
            if let Ok(exact) = jac.pseudo_inverse(1e-9) {
                let null = SMatrix::<f64, MAX_DOF, MAX_DOF>::identity() - exact * jac;
                step += null * ((rest - q) * o.rest_gain);
            }
        }
        let largest = step.amax();
        if largest > o.max_step {
            step *= o.max_step / largest;
        }
        for i in arm.dof..MAX_DOF {
            step[i] = 0.0;
        }
        q = arm.clamp(&(q + step));
    }
    Err(IkMiss {
        q: best.1,
        position_error: best.2,
        orientation_error: best.3,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::desc::RobotDesc;
    use crate::seeds::splitmix;

    /// Random configurations well inside the limits; their forward kinematics as targets; the
    /// solver started a little away from each must land on a configuration with the same TCP.
    fn round_trip(desc: &RobotDesc, trials: usize) -> usize {
        let arm = ArmModel::new(desc);
        let home = arm.vec(&desc.arm.home);
        let mut n = 0u64;
        let mut unit = || {
            n += 1;
            (splitmix(n) >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut solved = 0;
        for _ in 0..trials {
            let q = JointVec::from_fn(|i, _| {
                if i >= arm.dof {
                    return 0.0;
                }
                let (lo, hi) = (arm.lower[i].max(-3.0), arm.upper[i].min(3.0));
                let mid = (lo + hi) / 2.0;
                mid + (unit() - 0.5) * 0.8 * (hi - lo)
            });
            let target = arm.forward(&q).tcp;
            let seed = arm.clamp(&JointVec::from_fn(|i, _| {
                if i < arm.dof {
                    q[i] + (unit() - 0.5) * 0.6
                } else {
                    0.0
                }
            }));
            if let Ok(sol) = solve(&arm, &target, &seed, &home, &IkOptions::default()) {
                let fk = arm.forward(&sol).tcp;
                assert!((fk.translation.vector - target.translation.vector).norm() < 1e-4);
                assert!(orientation_error(&target.rotation, &fk.rotation).norm() < 1e-3);
                assert!(arm.within_limits(&sol));
                solved += 1;
            }
        }
        solved
    }

    #[test]
    fn reachable_targets_round_trip_through_forward_kinematics() {
        let desc = RobotDesc::load_default().unwrap();
        let solved = round_trip(&desc, 200);
        assert!(solved >= 190, "{solved}/200 solved");
    }

    /// The robosuite arms (six and seven joints, turned frames), where their wheel is unpacked
    /// (`ROBOSUITE_ASSETS`, scripts/robosuite-assets.sh).
    #[test]
    fn robosuite_arms_round_trip_through_forward_kinematics() {
        if kitchen_r_core::assets::robosuite_assets_for_tests().is_none() {
            return;
        }
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/robots/robosuite");
        for name in ["panda", "ur5e", "kinova3", "xarm7"] {
            let desc = RobotDesc::load(&dir.join(format!("{name}.toml"))).unwrap();
            let solved = round_trip(&desc, 100);
            assert!(solved >= 90, "{name}: {solved}/100 solved");
        }
    }
}
