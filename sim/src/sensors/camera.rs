//! RGB-D cameras by ray casting against the physics colliders (rapier's broad-phase BVH does the
//! culling). Colour is the hit collider's material with Lambert shading from one directional light
//! plus ambient; depth is the distance along the optical axis in metres (0 = no return).

use nalgebra::{Isometry3, Vector3};
use rapier3d::prelude::*;
use serde::{Deserialize, Serialize};

use super::tiles::{Hit, TileGrid};
use crate::config::{CameraConfig, LightConfig};
use crate::convert::vec_to_glam;
use crate::material::{Material, Tag};
use rapier3d::math::Vector;

/// Colour of rays that leave the room (there is no ceiling).
const SKY: [f32; 3] = [0.80, 0.85, 0.92];

/// One rendered camera frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CameraImage {
    pub name: String,
    pub width: u32,
    pub height: u32,
    /// Row-major RGB8, top row first.
    pub rgb: Vec<u8>,
    /// Row-major depth along the optical axis (m), 0 where nothing was hit within range.
    pub depth: Vec<f32>,
}

/// A ray-generation model: perspective (`pinhole`) or orthographic (top-down view).
#[derive(Debug, Clone, Copy)]
pub enum Projection {
    /// Horizontal field of view (rad).
    Pinhole { fov: f64 },
    /// Metres per pixel.
    Ortho { scale: f64 },
}

/// Scene data the renderer needs besides the physics world.
pub struct RenderCtx<'a> {
    pub world: &'a PhysicsWorld,
    pub materials: &'a [Material],
    pub light: &'a LightConfig,
}

impl RenderCtx<'_> {
    /// Shade a hit: material albedo at the hit point under ambient plus Lambert light.
    #[inline]
    fn shade(&self, hit: &Hit, origin: Vector, dir: Vector, light: Vector) -> [f32; 3] {
        let p = origin + dir * hit.t;
        let m = &self.materials[Tag::unpack(hit.user_data).material as usize];
        let mut n = hit.normal;
        if n.dot(dir) > 0.0 {
            n = -n;
        }
        let shade = self.light.ambient as f32 + self.light.diffuse as f32 * n.dot(light).max(0.0);
        m.albedo([p.x, p.y, p.z]).map(|c| c * shade)
    }

    /// Render an image of `width`×`height` from `pose` (looking along its +x, y left, z up).
    pub fn render(
        &self,
        name: &str,
        pose: &Isometry3<f64>,
        projection: Projection,
        width: u32,
        height: u32,
        max_depth: f64,
    ) -> CameraImage {
        let grid = TileGrid::new(self.world, pose, projection, width as usize, height as usize);
        let l = Vector3::from(self.light.direction).normalize();
        let light = vec_to_glam(&l);
        let (w, h) = (width as usize, height as usize);
        let mut rgb = vec![0u8; w * h * 3];
        let mut depth = vec![0f32; w * h];
        let ax = vec_to_glam(&(pose.rotation * Vector3::x()));
        let ay = vec_to_glam(&(pose.rotation * Vector3::y()));
        let az = vec_to_glam(&(pose.rotation * Vector3::z()));
        let eye = vec_to_glam(&pose.translation.vector);
        let (cx, cy) = (w as f32 / 2.0, h as f32 / 2.0);
        let inv_f = match projection {
            Projection::Pinhole { fov } => (fov as f32 / 2.0).tan() / cx,
            Projection::Ortho { .. } => 0.0,
        };
        for v in 0..h {
            for u in 0..w {
                let (du, dv) = (cx - (u as f32 + 0.5), cy - (v as f32 + 0.5));
                let (origin, dir) = match projection {
                    Projection::Pinhole { .. } => (eye, ax + ay * (du * inv_f) + az * (dv * inv_f)),
                    Projection::Ortho { scale } => (eye + (ay * du + az * dv) * scale as f32, ax),
                };
                let i = v * w + u;
                let color = match grid.cast(u, v, origin, dir, max_depth as f32) {
                    Some(hit) => {
                        depth[i] = hit.t;
                        self.shade(&hit, origin, dir, light)
                    }
                    None => SKY,
                };
                for k in 0..3 {
                    rgb[i * 3 + k] = (color[k].clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
                }
            }
        }
        CameraImage {
            name: name.to_string(),
            width,
            height,
            rgb,
            depth,
        }
    }

    /// Render one configured camera mounted at `mount` (world pose of its mount frame).
    pub fn camera(&self, cfg: &CameraConfig, mount: &Isometry3<f64>) -> CameraImage {
        let [r, p, y] = cfg.rpy;
        let local = Isometry3::from_parts(
            nalgebra::Translation3::from(Vector3::from(cfg.position)),
            nalgebra::UnitQuaternion::from_euler_angles(r, p, y),
        );
        let fov = cfg.fov_deg.to_radians();
        self.render(
            &cfg.name,
            &(mount * local),
            Projection::Pinhole { fov },
            cfg.width,
            cfg.height,
            cfg.max_depth,
        )
    }
}
