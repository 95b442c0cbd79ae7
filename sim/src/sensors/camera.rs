//! RGB-D cameras by ray casting against the physics colliders (`raycast` and `footprint` do the
//! culling). Colour is the hit collider's material with Lambert shading from one directional light
//! plus ambient; depth is the distance along the optical axis in metres (0 = no return).

use nalgebra::{Isometry3, Vector3};
use rapier3d::prelude::*;
use serde::{Deserialize, Serialize};

pub use super::projection::Projection;
use super::raycast::{Caster, Hit, Ray3};
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
        let grid = Caster::camera(self.world, pose, projection, width as usize, height as usize);
        let max = max_depth as f32;
        self.render_with(name, pose, projection, width, height, |u, v, ray| {
            grid.cast_ray(u, v, ray, max)
        })
    }

    /// The image `render` makes, with `cast` finding each pixel's hit.
    fn render_with(
        &self,
        name: &str,
        pose: &Isometry3<f64>,
        projection: Projection,
        width: u32,
        height: u32,
        cast: impl Fn(usize, usize, &Ray3) -> Option<Hit>,
    ) -> CameraImage {
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
        let mut rays = vec![Ray3::new(eye, ax); w];
        for v in 0..h {
            // Ray set-up for the whole row first: independent divisions and square roots
            // pipeline (and vectorise) instead of stalling each ray's walk.
            for (u, ray) in rays.iter_mut().enumerate() {
                let (du, dv) = (cx - (u as f32 + 0.5), cy - (v as f32 + 0.5));
                let (origin, dir) = match projection {
                    Projection::Pinhole { .. } => (eye, ax + ay * (du * inv_f) + az * (dv * inv_f)),
                    Projection::Ortho { scale } => (eye + (ay * du + az * dv) * scale as f32, ax),
                };
                ray.origin = origin;
                ray.dir = dir;
            }
            for ray in rays.iter_mut() {
                ray.inv = ray.dir.recip();
                ray.len = ray.dir.length();
            }
            for (u, ray) in rays.iter().enumerate() {
                let i = v * w + u;
                let color = match cast(u, v, ray) {
                    Some(hit) => {
                        depth[i] = hit.t;
                        self.shade(&hit, ray.origin, ray.dir, light)
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::{Owner, Tag};
    use nalgebra::{Translation3, UnitQuaternion};
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// A camera pose: the eye within `half` of the origin sideways and at a height in `z`,
    /// looking anywhere, mostly level or down.
    fn random_view(rng: &mut ChaCha8Rng, half: f64, z: std::ops::Range<f64>) -> Isometry3<f64> {
        let eye = Translation3::new(
            rng.random_range(-half..half),
            rng.random_range(-half..half),
            rng.random_range(z),
        );
        let rot = UnitQuaternion::from_euler_angles(
            rng.random_range(-0.5..0.5),
            rng.random_range(-0.3..1.5),
            rng.random_range(-3.1..3.1),
        );
        Isometry3::from_parts(eye, rot)
    }

    /// The materials the test worlds' tags name (`material: k % 3`).
    fn three_materials() -> [Material; 3] {
        [
            Material::plain([0.8, 0.2, 0.2]),
            Material::plain([0.2, 0.8, 0.2]),
            Material::plain([0.2, 0.2, 0.8]),
        ]
    }

    /// 70 colliders of every kind the renderer knows (two words of coverage bits), some aligned,
    /// most turned, one big floor, scattered around the origin.
    fn clutter(rng: &mut ChaCha8Rng) -> PhysicsWorld {
        let mut world = PhysicsWorld::new();
        let body = world.insert_body(RigidBodyBuilder::fixed());
        let floor = ColliderBuilder::cuboid(5.0, 5.0, 0.05).translation(Vector::new(0.0, 0.0, -0.05));
        world.insert_collider(floor, Some(body));
        for k in 0..69u32 {
            let mut r = |lo: f64, hi: f64| rng.random_range(lo..hi);
            let builder = match k % 5 {
                0 | 1 => {
                    ColliderBuilder::cuboid(r(0.02, 0.6) as f32, r(0.02, 0.6) as f32, r(0.02, 0.6) as f32)
                }
                2 => ColliderBuilder::capsule_y(r(0.02, 0.3) as f32, r(0.02, 0.2) as f32),
                3 => ColliderBuilder::cylinder(r(0.02, 0.3) as f32, r(0.02, 0.2) as f32),
                _ => ColliderBuilder::ball(r(0.02, 0.2) as f32),
            };
            let at = Translation3::new(r(-2.0, 2.0), r(-2.0, 2.0), r(0.0, 1.5));
            let rot = if k % 7 != 0 {
                UnitQuaternion::from_euler_angles(r(-3.0, 3.0), r(-3.0, 3.0), r(-3.0, 3.0))
            } else {
                UnitQuaternion::identity()
            };
            let tag = Tag {
                material: k % 3,
                owner: Owner::Static,
                index: 0,
            };
            let co = builder
                .position(crate::convert::iso_to_pose(&Isometry3::from_parts(at, rot)))
                .user_data(tag.pack());
            world.insert_collider(co, Some(body));
        }
        world
    }

    /// Twenty lumpy convex hulls (robot link meshes render as such) on a floor, seen from eyes
    /// around and among them, some inside one: the bytes the face-by-face clipping drew before
    /// the ray caster kept per-image face planes. A change to how hulls are tested must not
    /// move a pixel.
    #[test]
    fn convex_hulls_render_the_same_bytes() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let mut world = PhysicsWorld::new();
        let body = world.insert_body(RigidBodyBuilder::fixed());
        let floor = ColliderBuilder::cuboid(3.0, 3.0, 0.05).translation(Vector::new(0.0, 0.0, -0.05));
        world.insert_collider(floor, Some(body));
        for k in 0..20u32 {
            let size = Vector::new(
                rng.random_range(0.03..0.3),
                rng.random_range(0.03..0.3),
                rng.random_range(0.03..0.3),
            );
            let points: Vec<Vector> = (0..32)
                .map(|_| {
                    let mut r = || rng.random_range(-1.0f32..1.0);
                    Vector::new(r(), r(), r()) * size
                })
                .collect();
            let at = Translation3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(0.1..1.2),
            );
            let rot = UnitQuaternion::from_euler_angles(
                rng.random_range(-3.0..3.0),
                rng.random_range(-3.0..3.0),
                rng.random_range(-3.0..3.0),
            );
            let tag = Tag {
                material: k % 3,
                owner: Owner::Static,
                index: 0,
            };
            let co = ColliderBuilder::convex_hull(&points)
                .unwrap()
                .position(crate::convert::iso_to_pose(&Isometry3::from_parts(at, rot)))
                .user_data(tag.pack());
            world.insert_collider(co, Some(body));
        }
        let materials = three_materials();
        let light = LightConfig::default();
        let ctx = RenderCtx {
            world: &world,
            materials: &materials,
            light: &light,
        };
        let mut images = Vec::new();
        for shot in 0..12 {
            let pose = random_view(&mut rng, 1.2, 0.1..1.5);
            let projection = if shot % 6 == 5 {
                Projection::Ortho { scale: 0.02 }
            } else {
                Projection::Pinhole { fov: 1.2 }
            };
            images.push(ctx.render("c", &pose, projection, 64, 64, 20.0));
        }
        assert_eq!(crate::test_support::image_hash(&images), 13142985655491809533);
    }

    #[test]
    fn culling_never_changes_a_pixel() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let world = clutter(&mut rng);
        let materials = three_materials();
        let light = LightConfig::default();
        let ctx = RenderCtx {
            world: &world,
            materials: &materials,
            light: &light,
        };
        let (mut hits, mut pixels) = (0, 0);
        for shot in 0..24 {
            // Eyes anywhere in the clutter, some inside or touching a collider, looking anywhere.
            let pose = random_view(&mut rng, 2.5, 0.05..2.0);
            let projection = if shot % 6 == 5 {
                Projection::Ortho { scale: 0.03 }
            } else {
                Projection::Pinhole {
                    fov: rng.random_range(0.6..2.4),
                }
            };
            let (w, h) = (rng.random_range(9..48), rng.random_range(9..48));
            let culled = ctx.render("c", &pose, projection, w, h, 20.0);
            // Every collider for every ray, nearest to that ray's own origin first.
            let reference = ctx.render_with("c", &pose, projection, w, h, |_, _, ray| {
                Caster::unbinned(&world, ray.origin, |_| true).cast_ray(0, 0, ray, 20.0)
            });
            assert_eq!(culled, reference, "shot {shot}: {projection:?} {w}x{h}");
            hits += culled.depth.iter().filter(|d| **d > 0.0).count();
            pixels += culled.depth.len();
        }
        assert!(
            hits > pixels / 4,
            "the shots must see the clutter: {hits} of {pixels}"
        );
    }
}
