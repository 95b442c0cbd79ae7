//! Forward kinematics and the geometric Jacobian of the arm, in the robot base frame (nalgebra,
//! f64). The physics engine never computes these: the arm's links are placed from this model.

use nalgebra::{Isometry3, Matrix6, Translation3, UnitQuaternion, Vector3};

use super::desc::RobotDesc;

/// Number of arm joints.
pub const DOF: usize = 6;

/// Joint-space vector.
pub type JointVec = nalgebra::SVector<f64, DOF>;

/// Result of forward kinematics at one configuration.
#[derive(Debug, Clone)]
pub struct ArmFk {
    /// Frame of each joint (after its rotation), base frame.
    pub joints: [Isometry3<f64>; DOF],
    /// Tool centre point frame, base frame.
    pub tcp: Isometry3<f64>,
}

/// The arm's kinematic model, extracted once from the description.
#[derive(Debug, Clone)]
pub struct ArmModel {
    pub mount: Vector3<f64>,
    pub origins: [Vector3<f64>; DOF],
    pub axes: [Vector3<f64>; DOF],
    pub lower: JointVec,
    pub upper: JointVec,
    pub max_velocity: JointVec,
    pub tcp_offset: f64,
}

impl ArmModel {
    pub fn new(desc: &RobotDesc) -> ArmModel {
        let j = &desc.arm.joints;
        ArmModel {
            mount: Vector3::from(desc.arm.mount),
            origins: std::array::from_fn(|i| Vector3::from(j[i].origin)),
            axes: std::array::from_fn(|i| Vector3::from(j[i].axis.unit())),
            lower: JointVec::from_fn(|i, _| j[i].limits[0]),
            upper: JointVec::from_fn(|i, _| j[i].limits[1]),
            max_velocity: JointVec::from_fn(|i, _| j[i].max_velocity),
            tcp_offset: desc.gripper.tcp_offset,
        }
    }

    pub fn forward(&self, q: &JointVec) -> ArmFk {
        let mut frame = Isometry3::from_parts(Translation3::from(self.mount), UnitQuaternion::identity());
        let joints = std::array::from_fn(|i| {
            let rot = UnitQuaternion::from_scaled_axis(self.axes[i] * q[i]);
            frame *= Isometry3::from_parts(Translation3::from(self.origins[i]), rot);
            frame
        });
        let tcp = frame * Translation3::new(self.tcp_offset, 0.0, 0.0);
        ArmFk { joints, tcp }
    }

    /// Geometric Jacobian of the TCP: rows 0..3 linear, 3..6 angular, base frame.
    pub fn jacobian(&self, fk: &ArmFk) -> Matrix6<f64> {
        let p = fk.tcp.translation.vector;
        let mut jac = Matrix6::zeros();
        for i in 0..DOF {
            let a = fk.joints[i].rotation * self.axes[i];
            let o = fk.joints[i].translation.vector;
            let lin = a.cross(&(p - o));
            jac.fixed_view_mut::<3, 1>(0, i).copy_from(&lin);
            jac.fixed_view_mut::<3, 1>(3, i).copy_from(&a);
        }
        jac
    }

    /// Clamp a configuration into the joint limits.
    pub fn clamp(&self, q: &JointVec) -> JointVec {
        JointVec::from_fn(|i, _| q[i].clamp(self.lower[i], self.upper[i]))
    }

    pub fn within_limits(&self, q: &JointVec) -> bool {
        (0..DOF).all(|i| q[i] >= self.lower[i] - 1e-9 && q[i] <= self.upper[i] + 1e-9)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jacobian_matches_finite_differences() {
        let desc = RobotDesc::load_default().unwrap();
        let arm = ArmModel::new(&desc);
        let q = JointVec::from_column_slice(&[0.3, -0.2, 0.8, 0.4, 0.6, -0.5]);
        let fk = arm.forward(&q);
        let jac = arm.jacobian(&fk);
        let h = 1e-6;
        for i in 0..DOF {
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
