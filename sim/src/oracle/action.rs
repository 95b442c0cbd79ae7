//! Packing the oracle's outputs into the paper's 10-value action
//! `(v, ω, x, y, z, qw, qx, qy, qz, g)` (§PROBLEM FORMULATION).
//!
//! `q` and `−q` are the same rotation, but the MSE metric compares the numbers, so expert
//! trajectories must not flip sign from one step to the next: the quaternion is written with
//! `qw ≥ 0` (and, when `qw = 0`, the first non-zero of `qx, qy, qz` positive).

use nalgebra::Isometry3;

/// The action for base command `(v, ω)`, end-effector target `ee_in_base` and gripper `g`.
pub fn action(v: f64, omega: f64, ee_in_base: &Isometry3<f64>, gripper: f64) -> [f64; 10] {
    let t = ee_in_base.translation.vector;
    let q = ee_in_base.rotation.quaternion();
    let (w, x, y, z) = (q.w, q.i, q.j, q.k);
    let first = [w, x, y, z].into_iter().find(|c| *c != 0.0).unwrap_or(1.0);
    let s = if first < 0.0 { -1.0 } else { 1.0 };
    [v, omega, t.x, t.y, t.z, s * w, s * x, s * y, s * z, gripper]
}

#[cfg(test)]
mod tests {
    use nalgebra::{Quaternion, Translation3, UnitQuaternion, Vector3};

    use super::*;

    #[test]
    fn packs_in_order_with_a_canonical_quaternion_sign() {
        let rot = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), std::f64::consts::FRAC_PI_2);
        let ee = Isometry3::from_parts(Translation3::new(0.5, -0.1, 0.9), rot);
        let a = action(0.18, -0.3, &ee, 1.0);
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let want = [0.18, -0.3, 0.5, -0.1, 0.9, h, 0.0, h, 0.0, 1.0];
        assert!(a.iter().zip(want).all(|(x, y)| (x - y).abs() < 1e-12), "{a:?}");
        // The same rotation stored as −q packs to the same numbers.
        let neg = UnitQuaternion::new_unchecked(-rot.into_inner());
        assert_eq!(
            action(0.18, -0.3, &Isometry3::from_parts(ee.translation, neg), 1.0),
            a
        );
        let half_turn = UnitQuaternion::new_unchecked(Quaternion::new(0.0, 0.0, -1.0, 0.0));
        let b = action(0.0, 0.0, &Isometry3::from_parts(ee.translation, half_turn), 0.0);
        assert_eq!(&b[5..9], &[0.0, 0.0, 1.0, 0.0]);
    }
}
