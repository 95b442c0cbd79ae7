//! Conversions between our nalgebra f64 kinematics and rapier's glam f32 API. Only this module
//! crosses that boundary, so precision loss happens in one known place.

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use rapier3d::math::{Pose, Rotation, Vector};

pub fn vec_to_glam(v: &Vector3<f64>) -> Vector {
    Vector::new(v.x as f32, v.y as f32, v.z as f32)
}

pub fn vec_from_glam(v: Vector) -> Vector3<f64> {
    Vector3::new(f64::from(v.x), f64::from(v.y), f64::from(v.z))
}

pub fn quat_to_glam(q: &UnitQuaternion<f64>) -> Rotation {
    Rotation::from_xyzw(q.i as f32, q.j as f32, q.k as f32, q.w as f32).normalize()
}

pub fn quat_from_glam(q: Rotation) -> UnitQuaternion<f64> {
    UnitQuaternion::from_quaternion(Quaternion::new(
        f64::from(q.w),
        f64::from(q.x),
        f64::from(q.y),
        f64::from(q.z),
    ))
}

pub fn iso_to_pose(iso: &Isometry3<f64>) -> Pose {
    Pose::from_parts(vec_to_glam(&iso.translation.vector), quat_to_glam(&iso.rotation))
}

pub fn pose_to_iso(pose: &Pose) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::from(vec_from_glam(pose.translation)),
        quat_from_glam(pose.rotation),
    )
}

/// Planar pose `[x, y, yaw]` plus height as an isometry.
pub fn planar(x: f64, y: f64, z: f64, yaw: f64) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(x, y, z),
        UnitQuaternion::from_euler_angles(0.0, 0.0, yaw),
    )
}

/// Yaw of a rotation (heading of its x axis in the xy plane).
pub fn yaw_of(q: &UnitQuaternion<f64>) -> f64 {
    let x = q * Vector3::x();
    x.y.atan2(x.x)
}
