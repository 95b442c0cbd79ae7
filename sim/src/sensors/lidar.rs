//! LiDAR: a planar or multi-channel scanner by ray casting (the cameras' exact per-shape casts,
//! on one near-to-far list), ignoring the robot's own parts.

use nalgebra::{Isometry3, Vector3};
use rapier3d::prelude::*;
use serde::{Deserialize, Serialize};

use super::raycast::Caster;
use crate::config::LidarConfig;
use crate::convert::vec_to_glam;
use crate::material::{Owner, Tag};

/// Points in the sensor frame (x forward, y left, z up), metres.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PointCloud {
    pub points: Vec<[f32; 3]>,
}

/// Scan from `sensor` (world pose of the sensor frame).
pub fn scan(world: &PhysicsWorld, cfg: &LidarConfig, sensor: &Isometry3<f64>) -> PointCloud {
    let origin = vec_to_glam(&sensor.translation.vector);
    let grid = Caster::unbinned(world, origin, |c| {
        let owner = Tag::unpack(c.user_data).owner;
        owner != Owner::Robot && owner != Owner::Decoration
    });
    let mut points = Vec::with_capacity(cfg.beams as usize * cfg.channels_deg.len());
    for elev in &cfg.channels_deg {
        let (se, ce) = elev.to_radians().sin_cos();
        for b in 0..cfg.beams {
            let az = std::f64::consts::TAU * f64::from(b) / f64::from(cfg.beams);
            let local = Vector3::new(ce * az.cos(), ce * az.sin(), se);
            let dir = vec_to_glam(&(sensor.rotation * local));
            if let Some(hit) = grid.cast(0, 0, origin, dir, cfg.max_range as f32)
                && f64::from(hit.t) >= cfg.min_range
            {
                let p = local * f64::from(hit.t);
                points.push([p.x as f32, p.y as f32, p.z as f32]);
            }
        }
    }
    PointCloud { points }
}
