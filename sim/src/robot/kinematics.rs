//! Forward kinematics and the geometric Jacobian of the arm, in the robot base frame (nalgebra,
//! f64). The physics engine never computes these: the arm's links are placed from this model.
//!
//! Six or seven joints: joint-space vectors hold [`MAX_DOF`] values, of which the arm's
//! [`ArmModel::dof`] are its joints; the rest stay zero and every loop stops at `dof`. A joint
//! frame is its parent's moved by the joint's origin, turned by its fixed rotation where the
//! description gives one (the shipped arm's joints have none, and compute exactly as before
//! rotations were read), then turned about its axis by the joint value.

use nalgebra::{Isometry3, Quaternion, SMatrix, Translation3, UnitQuaternion, Vector3};

use super::desc::{PoseDesc, RobotDesc};

/// The most arm joints (a redundant arm's seven).
pub const MAX_DOF: usize = kitchen_r_core::robot::MAX_ARM_JOINTS;

/// Joint-space vector: the arm's joints first, zeros after them.
pub type JointVec = nalgebra::SVector<f64, MAX_DOF>;

/// The TCP's geometric Jacobian: rows 0..3 linear, 3..6 angular; columns past the arm's joints
/// are zero.
pub type Jacobian = SMatrix<f64, 6, MAX_DOF>;

/// Result of forward kinematics at one configuration.
#[derive(Debug, Clone)]
pub struct ArmFk {
    /// Frame of each joint (after its rotation), base frame; past the arm's joints, the last
    /// joint's frame again.
    pub joints: [Isometry3<f64>; MAX_DOF],
    /// The hand frame (palm and fingers hang from it), base frame.
    pub hand: Isometry3<f64>,
    /// Tool centre point frame, base frame.
    pub tcp: Isometry3<f64>,
}

/// The arm's kinematic model, extracted once from the description.
#[derive(Debug, Clone)]
pub struct ArmModel {
    /// Number of joints (6 or 7).
    pub dof: usize,
    pub mount: Vector3<f64>,
    pub mount_rotation: Option<UnitQuaternion<f64>>,
    pub origins: [Vector3<f64>; MAX_DOF],
    pub rotations: [Option<UnitQuaternion<f64>>; MAX_DOF],
    pub axes: [Vector3<f64>; MAX_DOF],
    pub lower: JointVec,
    pub upper: JointVec,
    pub max_velocity: JointVec,
    pub tcp_offset: f64,
    /// The hand frame in the last joint's frame (`None`: that frame itself).
    pub flange: Option<Isometry3<f64>>,
}

/// A unit quaternion from `w, x, y, z`.
pub fn unit_quat(q: [f64; 4]) -> UnitQuaternion<f64> {
    UnitQuaternion::from_quaternion(Quaternion::new(q[0], q[1], q[2], q[3]))
}

/// A description's pose as an isometry.
pub fn pose_iso(p: &PoseDesc) -> Isometry3<f64> {
    Isometry3::from_parts(Translation3::from(Vector3::from(p.xyz)), unit_quat(p.quat))
}

impl ArmModel {
    pub fn new(desc: &RobotDesc) -> ArmModel {
        let j = &desc.arm.joints;
        let dof = j.len();
        let each = |f: &dyn Fn(usize) -> f64| JointVec::from_fn(|i, _| if i < dof { f(i) } else { 0.0 });
        ArmModel {
            dof,
            mount: Vector3::from(desc.arm.mount),
            mount_rotation: desc.arm.mount_rotation.map(unit_quat),
            origins: std::array::from_fn(|i| j.get(i).map_or(Vector3::zeros(), |j| Vector3::from(j.origin))),
            rotations: std::array::from_fn(|i| j.get(i).and_then(|j| j.rotation).map(unit_quat)),
            axes: std::array::from_fn(|i| {
                j.get(i)
                    .map_or(Vector3::zeros(), |j| Vector3::from(j.axis.unit()))
            }),
            lower: each(&|i| j[i].limits[0]),
            upper: each(&|i| j[i].limits[1]),
            max_velocity: each(&|i| j[i].max_velocity),
            tcp_offset: desc.gripper.tcp_offset,
            flange: desc.arm.flange.as_ref().map(pose_iso),
        }
    }

    /// A joint-space vector from one value per arm joint (zeros past them).
    pub fn vec(&self, values: &[f64]) -> JointVec {
        JointVec::from_fn(|i, _| if i < self.dof { values[i] } else { 0.0 })
    }

    pub fn forward(&self, q: &JointVec) -> ArmFk {
        let mount = self.mount_rotation.unwrap_or_else(UnitQuaternion::identity);
        let mut frame = Isometry3::from_parts(Translation3::from(self.mount), mount);
        let joints = std::array::from_fn(|i| {
            if i < self.dof {
                let rot = UnitQuaternion::from_scaled_axis(self.axes[i] * q[i]);
                let rot = match self.rotations[i] {
                    Some(fixed) => fixed * rot,
                    None => rot,
                };
                frame *= Isometry3::from_parts(Translation3::from(self.origins[i]), rot);
            }
            frame
        });
        let hand = match &self.flange {
            Some(f) => frame * f,
            None => frame,
        };
        let tcp = hand * Translation3::new(self.tcp_offset, 0.0, 0.0);
        ArmFk { joints, hand, tcp }
    }

    /// Geometric Jacobian of the TCP: rows 0..3 linear, 3..6 angular, base frame.
    pub fn jacobian(&self, fk: &ArmFk) -> Jacobian {
        let mut jac = Jacobian::zeros();
        let lin = self.point_jacobian(fk, self.dof - 1, &fk.tcp.translation.vector);
        jac.fixed_view_mut::<3, MAX_DOF>(0, 0).copy_from(&lin);
        for i in 0..self.dof {
            jac.fixed_view_mut::<3, 1>(3, i)
                .copy_from(&(fk.joints[i].rotation * self.axes[i]));
        }
        jac
    }

    /// Linear velocity Jacobian of `point` (base frame) carried by joint `link`'s frame: the
    /// joints up to that one move it, the rest do not.
    pub fn point_jacobian(&self, fk: &ArmFk, link: usize, point: &Vector3<f64>) -> SMatrix<f64, 3, MAX_DOF> {
        let mut jac = SMatrix::<f64, 3, MAX_DOF>::zeros();
        for i in 0..=link.min(self.dof - 1) {
            let a = fk.joints[i].rotation * self.axes[i];
            let o = fk.joints[i].translation.vector;
            jac.fixed_view_mut::<3, 1>(0, i).copy_from(&a.cross(&(point - o)));
        }
        jac
    }

    /// Clamp a configuration into the joint limits.
    pub fn clamp(&self, q: &JointVec) -> JointVec {
        JointVec::from_fn(|i, _| q[i].clamp(self.lower[i], self.upper[i]))
    }

    pub fn within_limits(&self, q: &JointVec) -> bool {
        (0..self.dof).all(|i| q[i] >= self.lower[i] - 1e-9 && q[i] <= self.upper[i] + 1e-9)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jacobian_matches_finite_differences() {
        let desc = RobotDesc::load_default().unwrap();
        let arm = ArmModel::new(&desc);
        let q = arm.vec(&[0.3, -0.2, 0.8, 0.4, 0.6, -0.5]);
        let fk = arm.forward(&q);
        let jac = arm.jacobian(&fk);
        let h = 1e-6;
        for i in 0..arm.dof {
            let mut q2 = q;
            q2[i] += h;
            let fk2 = arm.forward(&q2);
            let dp = (fk2.tcp.translation.vector - fk.tcp.translation.vector) / h;
            let dr = (fk2.tcp.rotation * fk.tcp.rotation.inverse()).scaled_axis() / h;
            assert!(
                (dp - jac.fixed_view::<3, 1>(0, i)).norm() < 1e-4,
                "linear column {i}"
            );
            assert!(
                (dr - jac.fixed_view::<3, 1>(3, i)).norm() < 1e-4,
                "angular column {i}"
            );
        }
    }
}
