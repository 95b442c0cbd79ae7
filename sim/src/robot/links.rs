//! The colliders of an arm link and of the palm: the shipped arm's capsules from each joint to
//! the next, or a description's own shapes (meshes as their convex hulls, which the ray caster
//! draws like any other collider, and primitives), each in its joint's frame.

use nalgebra::{Translation3, UnitQuaternion, Vector3};
use rapier3d::prelude::*;

use super::desc::{Geometry, LinkShape, RobotDesc};
use super::kinematics::{ArmModel, pose_iso};
use super::{PALM, collider};
use crate::convert::{iso_to_pose, vec_to_glam};
use crate::material::{Material, Materials};

/// The collider tag index of arm link `i` (0-based): 1..=6, and the seventh after the gripper's.
pub(crate) fn part(i: usize) -> u32 {
    if i < 6 { i as u32 + 1 } else { 10 }
}

/// The colliders of arm link `i` in its joint's frame.
pub(crate) fn link_colliders(
    desc: &RobotDesc,
    arm: &ArmModel,
    i: usize,
    arm_mat: u32,
    mats: &mut Materials,
) -> Vec<ColliderBuilder> {
    let j = &desc.arm.joints[i];
    let mut out: Vec<ColliderBuilder> = j
        .shapes
        .iter()
        .filter_map(|s| shape_collider(s, part(i), mats))
        .collect();
    if j.shapes.is_empty() && j.link_radius > 0.0 {
        let end = if i + 1 < arm.dof {
            arm.origins[i + 1]
        } else {
            hand_point(arm, desc.gripper.tcp_offset - desc.gripper.palm_back)
        };
        let r = j.link_radius as f32;
        let shape = SharedShape::capsule(vec_to_glam(&Vector3::zeros()), vec_to_glam(&end), r);
        out.push(collider(shape, part(i), arm_mat, false));
    }
    if i + 1 == arm.dof {
        out.extend(
            desc.arm
                .hand_shapes
                .iter()
                .filter_map(|s| shape_collider(s, PALM, mats)),
        );
    }
    out
}

/// The point `x` along the hand frame's x axis, in the last joint's frame.
fn hand_point(arm: &ArmModel, x: f64) -> Vector3<f64> {
    match &arm.flange {
        Some(f) => (f * Translation3::new(x, 0.0, 0.0)).translation.vector,
        None => Vector3::x() * x,
    }
}

/// The palm box, in the last joint's frame.
pub(crate) fn palm(desc: &RobotDesc, arm: &ArmModel, grip_mat: u32) -> ColliderBuilder {
    let g = &desc.gripper;
    let ps = g.palm_size.map(|v| v as f32 / 2.0);
    let co = collider(SharedShape::cuboid(ps[0], ps[1], ps[2]), PALM, grip_mat, false);
    match &arm.flange {
        None => co.translation(vec_to_glam(&Vector3::new(g.tcp_offset - g.palm_back, 0.0, 0.0))),
        Some(f) => co.position(iso_to_pose(
            &(f * Translation3::new(g.tcp_offset - g.palm_back, 0.0, 0.0)),
        )),
    }
}

/// One description shape as a collider (`None`: a mesh the assets did not load).
fn shape_collider(s: &LinkShape, part: u32, mats: &mut Materials) -> Option<ColliderBuilder> {
    let mut pose = pose_iso(&s.pose);
    let shape = match &s.geometry {
        Geometry::Mesh { file, scale } => {
            let name = file.to_string_lossy();
            let mesh = crate::mesh::cached(&name, scale[0])?;
            // The cached mesh is centred on its bounding box: put the centre back.
            pose *= Translation3::from(Vector3::from(mesh.center));
            crate::mesh::robot_hull(&name, scale[0])?
        }
        Geometry::Box { size } => {
            SharedShape::cuboid(size[0] as f32 / 2.0, size[1] as f32 / 2.0, size[2] as f32 / 2.0)
        }
        Geometry::Cylinder { radius, length } => {
            // parry's cylinders stand along y, the descriptions' along z.
            pose *= UnitQuaternion::from_euler_angles(std::f64::consts::FRAC_PI_2, 0.0, 0.0);
            SharedShape::cylinder(*length as f32 / 2.0, *radius as f32)
        }
        Geometry::Capsule { radius, length } => {
            let h = Vector3::z() * (length / 2.0);
            SharedShape::capsule(vec_to_glam(&-h), vec_to_glam(&h), *radius as f32)
        }
        Geometry::Sphere { radius } => SharedShape::ball(*radius as f32),
    };
    let mat = mats.add(Material::plain(s.color));
    Some(collider(shape, part, mat, false).position(iso_to_pose(&pose)))
}
