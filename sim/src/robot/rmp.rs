//! RMPflow-style arm controller (paper, Manipulation Module).
//!
//! Each leaf policy is a pair (desired acceleration `a_i`, Riemannian metric `M_i`) on a task map
//! with Jacobian `J_i`: an end-effector position attractor, an orientation attractor fed by the
//! quaternion error, a joint-limit barrier, joint damping and a faint posture pull that keeps the
//! redundant directions of singular configurations defined. They are pulled back to joint space
//! and combined by the canonical resolved solve `q̈ = (Σ Jᵢᵀ Mᵢ Jᵢ)⁺ Σ Jᵢᵀ Mᵢ aᵢ`. The result is
//! integrated into joint velocity and position targets with the joint speed and position limits
//! applied, so an unreachable target is approached but never reached through a limit.
//!
//! A seven-joint arm takes the same 6-value pose target: the attractors fix six directions of
//! joint space and the posture pull towards the home pose (with joint damping) settles the
//! seventh, the arm's self-motion, so its redundancy resolves towards home. Its links are also
//! kept off fixed geometry by an obstacle leaf ([`clearance`]), which only that self-motion can
//! serve without pulling the tool off its target. Joint-space slots
//! past the arm's joints carry a unit metric and no force: they stay zero and leave the solve of
//! the arm's own joints exactly as it is without them.

use nalgebra::{Isometry3, Matrix3, SMatrix, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use super::clearance::{self, Near};
use super::kinematics::{ArmModel, JointVec, MAX_DOF};

/// Gains and weights; `configs/sim.toml` `[rmp]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RmpParams {
    /// Position attractor stiffness (1/s²) and damping (1/s).
    pub position_gain: f64,
    pub position_damping: f64,
    /// The attractor's pull saturates beyond this error (m), bounding its acceleration.
    pub position_saturation: f64,
    pub position_weight: f64,
    pub orientation_gain: f64,
    pub orientation_damping: f64,
    /// Orientation pull saturates beyond this error (rad).
    pub orientation_saturation: f64,
    pub orientation_weight: f64,
    /// The joint-limit barrier acts within this distance of a limit (rad).
    pub limit_margin: f64,
    pub limit_gain: f64,
    pub limit_weight: f64,
    pub damping_gain: f64,
    pub damping_weight: f64,
    pub posture_gain: f64,
    pub posture_weight: f64,
}

impl Default for RmpParams {
    fn default() -> Self {
        RmpParams {
            position_gain: 49.0,
            position_damping: 14.0,
            position_saturation: 0.12,
            position_weight: 1.0,
            orientation_gain: 49.0,
            orientation_damping: 14.0,
            orientation_saturation: 0.8,
            orientation_weight: 0.1,
            limit_margin: 0.2,
            limit_gain: 30.0,
            limit_weight: 1.0,
            damping_gain: 4.0,
            damping_weight: 0.002,
            posture_gain: 4.0,
            posture_weight: 1e-5,
        }
    }
}

/// Integrated joint targets: what the articulation follows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArmState {
    pub q: JointVec,
    pub qd: JointVec,
}

fn saturate(e: Vector3<f64>, limit: f64) -> Vector3<f64> {
    let n = e.norm();
    if n > limit { e * (limit / n) } else { e }
}

/// Orientation error from `current` to `goal` as a rotation vector (shortest way round).
pub fn orientation_error(goal: &UnitQuaternion<f64>, current: &UnitQuaternion<f64>) -> Vector3<f64> {
    (goal * current.inverse()).scaled_axis()
}

/// Joint acceleration from the combined RMPs towards `target` (TCP pose, base frame), a
/// seven-joint arm's links kept off the fixed geometry they are `near` ([`clearance`]).
pub fn resolve(
    arm: &ArmModel,
    p: &RmpParams,
    state: &ArmState,
    home: &JointVec,
    target: &Isometry3<f64>,
    near: &[Near],
) -> JointVec {
    let fk = arm.forward(&state.q);
    let jac = arm.jacobian(&fk);
    let jp = jac.fixed_rows::<3>(0).into_owned();
    let jo = jac.fixed_rows::<3>(3).into_owned();
    let xd = jp * state.qd;
    let wd = jo * state.qd;

    let e_p = target.translation.vector - fk.tcp.translation.vector;
    let a_p = saturate(e_p, p.position_saturation) * p.position_gain - xd * p.position_damping;
    let e_o = orientation_error(&target.rotation, &fk.tcp.rotation);
    let a_o = saturate(e_o, p.orientation_saturation) * p.orientation_gain - wd * p.orientation_damping;
    let m_p = Matrix3::identity() * p.position_weight;
    let m_o = Matrix3::identity() * p.orientation_weight;

    let mut a_mat: SMatrix<f64, MAX_DOF, MAX_DOF> = jp.transpose() * m_p * jp + jo.transpose() * m_o * jo;
    let mut b: JointVec = jp.transpose() * (m_p * a_p) + jo.transpose() * (m_o * a_o);
    for n in near {
        let (row, m, a) = clearance::leaf(arm, &fk, &state.qd, n);
        a_mat += row.transpose() * m * row;
        b += row.transpose() * (m * a);
    }
    for i in arm.dof..MAX_DOF {
        a_mat[(i, i)] = 1.0;
    }

    for i in 0..arm.dof {
        // Barrier: its metric grows as the joint nears a limit, so it overrides the attractor there.
        let (lo, hi) = (state.q[i] - arm.lower[i], arm.upper[i] - state.q[i]);
        let (d, dir) = if lo < hi { (lo, 1.0) } else { (hi, -1.0) };
        let closeness = (1.0 - d / p.limit_margin).max(0.0);
        if closeness > 0.0 {
            let m = p.limit_weight * closeness * closeness;
            let a = dir * p.limit_gain * closeness - p.position_damping * state.qd[i];
            a_mat[(i, i)] += m;
            b[i] += m * a;
        }
        let m_d = p.damping_weight + p.posture_weight;
        a_mat[(i, i)] += m_d;
        b[i] += p.damping_weight * (-p.damping_gain * state.qd[i])
            + p.posture_weight * (p.posture_gain * (home[i] - state.q[i]) - state.qd[i]);
    }
    // The damping and posture metrics put a positive diagonal under the attractor's JᵀMJ, so the
    // resolved metric is symmetric positive definite and its pseudo-inverse is its inverse: a
    // Cholesky solve gives it at a fraction of an SVD's cost. The SVD stays for configurations
    // that zero those weights.
    match a_mat.cholesky() {
        Some(c) => c.solve(&b),
        None => a_mat
            .pseudo_inverse(1e-12)
            .map(|inv| inv * b)
            .unwrap_or_else(|_| JointVec::zeros()),
    }
}

/// Integrate one controller step of length `dt`, applying speed and position limits.
pub fn integrate(arm: &ArmModel, state: &ArmState, qdd: &JointVec, dt: f64) -> ArmState {
    let mut next = *state;
    for i in 0..arm.dof {
        let v = (state.qd[i] + qdd[i] * dt).clamp(-arm.max_velocity[i], arm.max_velocity[i]);
        let q = state.q[i] + v * dt;
        let clamped = q.clamp(arm.lower[i], arm.upper[i]);
        next.q[i] = clamped;
        // Stopped at a limit: drop the velocity into it so the target never overshoots.
        next.qd[i] = if clamped != q { 0.0 } else { v };
    }
    next
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::desc::RobotDesc;

    fn run(target: Isometry3<f64>, steps: usize) -> (ArmModel, ArmState) {
        let desc = RobotDesc::load_default().unwrap();
        let arm = ArmModel::new(&desc);
        let home = arm.vec(&desc.arm.home);
        let mut s = ArmState {
            q: home,
            qd: JointVec::zeros(),
        };
        let p = RmpParams::default();
        for _ in 0..steps {
            let qdd = resolve(&arm, &p, &s, &home, &target, &[]);
            s = integrate(&arm, &s, &qdd, 0.01);
        }
        (arm, s)
    }

    #[test]
    fn reaches_a_reachable_target() {
        let rot = UnitQuaternion::from_euler_angles(0.0, std::f64::consts::FRAC_PI_2, 0.0);
        let target = Isometry3::from_parts(nalgebra::Translation3::new(0.62, 0.05, 0.97), rot);
        let (arm, s) = run(target, 500);
        let fk = arm.forward(&s.q);
        let dp = (fk.tcp.translation.vector - target.translation.vector).norm();
        let da = orientation_error(&target.rotation, &fk.tcp.rotation).norm();
        assert!(dp < 0.01, "position error {dp}");
        assert!(da < 3f64.to_radians(), "orientation error {da}");
    }

    #[test]
    fn unreachable_target_stays_finite_and_inside_limits() {
        let target = Isometry3::translation(3.0, -2.0, 2.5);
        let (arm, s) = run(target, 800);
        assert!(s.q.iter().chain(s.qd.iter()).all(|v| v.is_finite()));
        assert!(arm.within_limits(&s.q));
    }
}
