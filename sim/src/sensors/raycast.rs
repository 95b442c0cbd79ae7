//! The ray caster behind the cameras and the LiDAR. Casting each pixel through rapier's query
//! pipeline runs at well under a million rays per second (dynamic dispatch, filtering and a full
//! BVH descent per ray). Here every collider is flattened once per image into a primitive with
//! its world bounding box, sorted near to far, and placed on the image (`footprint`): a ray tests
//! only the boxes that cover its pixel, with an exact closed-form test per shape (parry's for any
//! other), and stops as soon as its nearest hit is closer than the next candidate's box. The hits
//! are the same as the query pipeline's, and do not depend on how the candidates were culled:
//! culling only skips boxes the ray misses, and the order of the rest is fixed.

use nalgebra::Isometry3;
use rapier3d::math::{Pose, Vec3A, Vector};
use rapier3d::prelude::*;

use super::footprint::{Coverage, Footprint, Projector};
use super::projection::Projection;
use super::ray_shapes::{EyePlanes, aligned_normal, ray_capsule, ray_convex, ray_cuboid, ray_cylinder, slab};
use crate::convert::vec_to_glam;

/// One collider, flattened.
struct Prim<'a> {
    pose: Pose,
    shape: &'a dyn Shape,
    kind: Kind<'a>,
    user_data: u128,
    /// World bounding box, SIMD-friendly.
    mins: Vec3A,
    maxs: Vec3A,
    /// Euclidean distance from the eye to the bounding box.
    near: f32,
    /// The eye in the shape's frame: every ray of a perspective camera starts there.
    local_eye: Vector,
    /// A convex hull's faces as seen from `local_eye`.
    planes: Option<EyePlanes>,
}

/// Shapes with a closed-form intersection here; anything else uses parry's generic ray cast.
#[derive(Clone, Copy)]
enum Kind<'a> {
    /// A box whose world bounding box is the box itself: the slab test is the exact hit.
    AlignedBox,
    Cuboid(Vector),
    Capsule(Vector, Vector, f32),
    /// Half height along local y, radius (parry's cylinder axis).
    Cylinder(f32, f32),
    /// A convex hull (robot link meshes): clipped against its face planes, where parry's
    /// generic cast iterates GJK on the support map and made a mesh arm ten times the image.
    Convex(&'a ConvexPolyhedron),
    Other,
}

impl<'a> Prim<'a> {
    /// `co` with its world bounding box `aabb`, seen from `eye`.
    fn of(co: &'a Collider, aabb: &Aabb, eye: Vector) -> Prim<'a> {
        let shape = co.shape();
        let r = co.position().rotation;
        let aligned = r.x.abs() < 1e-6 && r.y.abs() < 1e-6 && r.z.abs() < 1e-6;
        let kind = if let Some(c) = shape.as_cuboid() {
            if aligned {
                Kind::AlignedBox
            } else {
                Kind::Cuboid(c.half_extents)
            }
        } else if let Some(c) = shape.as_capsule() {
            Kind::Capsule(c.segment.a, c.segment.b, c.radius)
        } else if let Some(c) = shape.as_cylinder() {
            Kind::Cylinder(c.half_height, c.radius)
        } else if let Some(c) = shape.as_convex_polyhedron() {
            Kind::Convex(c)
        } else {
            Kind::Other
        };
        let local_eye = co.position().inverse_transform_point(eye);
        let planes = match kind {
            Kind::Convex(c) => Some(EyePlanes::new(c, local_eye)),
            _ => None,
        };
        Prim {
            pose: *co.position(),
            shape,
            kind,
            user_data: co.user_data,
            mins: Vec3A::from(aabb.mins),
            maxs: Vec3A::from(aabb.maxs),
            near: box_distance(eye, aabb),
            local_eye,
            planes,
        }
    }
}

/// A ray with what every box test needs: `inv` is `dir.recip()`, `len` is `dir.length()`.
#[derive(Debug, Clone, Copy)]
pub struct Ray3 {
    pub origin: Vector,
    pub dir: Vector,
    pub inv: Vector,
    pub len: f32,
}

impl Ray3 {
    #[inline]
    pub fn new(origin: Vector, dir: Vector) -> Ray3 {
        Ray3 {
            origin,
            dir,
            inv: dir.recip(),
            len: dir.length(),
        }
    }
}

/// A hit: ray parameter (units of the ray direction), world normal, collider user data.
pub struct Hit {
    pub t: f32,
    pub normal: Vector,
    pub user_data: u128,
}

impl Prim<'_> {
    /// The exact hit of a ray whose bounding-box slab test passed with entry parameter `entry`,
    /// if nearer than `best_t`: the parameter and the normal in the shape's frame (unused for
    /// aligned boxes, whose normal `hit` derives from the entry face).
    #[inline]
    fn exact(&self, ray: &Ray3, from_eye: bool, entry: f32, best_t: f32) -> Option<(f32, Vector)> {
        if let Kind::AlignedBox = self.kind {
            return (entry < best_t).then_some((entry, Vector::ZERO));
        }
        let (origin, dir) = (ray.origin, ray.dir);
        let o = if from_eye {
            self.local_eye
        } else {
            self.pose.inverse_transform_point(origin)
        };
        let d = self.pose.inverse_transform_vector(dir);
        let hit = match self.kind {
            Kind::AlignedBox => None,
            Kind::Cuboid(h) => ray_cuboid(o, d, h, best_t),
            Kind::Capsule(a, b, r) => ray_capsule(o, d, a, b, r, best_t),
            Kind::Cylinder(hh, r) => ray_cylinder(o, d, hh, r, best_t),
            Kind::Convex(c) => match &self.planes {
                Some(planes) if from_eye => planes.cast(d, best_t),
                _ => ray_convex(o, d, c, best_t),
            },
            Kind::Other => self
                .shape
                .cast_local_ray_and_get_normal(&Ray::new(o, d), best_t, true)
                .map(|h| (h.time_of_impact, h.normal)),
        };
        hit.filter(|(t, _)| *t < best_t)
    }

    /// The hit `exact` found, with its world normal: computed once per ray, for the nearest.
    fn hit(&self, origin: Vector, dir: Vector, inv_dir: Vec3A, t: f32, local_normal: Vector) -> Hit {
        let normal = match self.kind {
            Kind::AlignedBox => aligned_normal(Vec3A::from(origin), inv_dir, self.mins, self.maxs, dir),
            _ => self.pose.rotation * local_normal,
        };
        Hit {
            t,
            normal,
            user_data: self.user_data,
        }
    }
}

fn box_distance(eye: Vector, aabb: &Aabb) -> f32 {
    let d = (aabb.mins - eye).max(eye - aabb.maxs).max(Vector::ZERO);
    d.length()
}

/// The colliders of one image (or one scan), nearest to the eye first, and which of them each
/// pixel's ray may cross.
pub struct Caster<'a> {
    eye: Vector,
    prims: Vec<Prim<'a>>,
    coverage: Coverage,
}

impl<'a> Caster<'a> {
    /// Every enabled collider of `world` placed on a `w`×`h` image from `cam`.
    pub fn camera(
        world: &'a PhysicsWorld,
        cam: &Isometry3<f64>,
        projection: Projection,
        w: usize,
        h: usize,
    ) -> Self {
        let eye = vec_to_glam(&cam.translation.vector);
        let projector = Projector::new(cam, projection, w, h);
        let mut placed = Vec::new();
        for (_, co) in world.colliders.iter() {
            if !co.is_enabled() {
                continue;
            }
            let aabb = co.compute_aabb();
            let mut prim = Prim::of(co, &aabb, eye);
            let footprint;
            (prim.near, footprint) = projector.place(&aabb, prim.near);
            if footprint != Footprint::Hidden {
                placed.push((prim, footprint));
            }
        }
        // Stable: equally near colliders keep the world's order, so ties resolve the same way
        // every time.
        placed.sort_by(|a, b| a.0.near.total_cmp(&b.0.near));
        let mut coverage = Coverage::new(w, h, placed.len());
        for (k, (_, footprint)) in placed.iter().enumerate() {
            coverage.add(k, footprint);
        }
        Caster {
            eye,
            prims: placed.into_iter().map(|(p, _)| p).collect(),
            coverage,
        }
    }

    /// Every collider `keep` accepts, for scans in all directions (LiDAR): cast with pixel
    /// `(0, 0)`.
    pub fn unbinned(world: &'a PhysicsWorld, eye: Vector, keep: impl Fn(&Collider) -> bool) -> Self {
        let mut prims: Vec<Prim> = world
            .colliders
            .iter()
            .filter(|(_, co)| co.is_enabled() && keep(co))
            .map(|(_, co)| Prim::of(co, &co.compute_aabb(), eye))
            .collect();
        prims.sort_by(|a, b| a.near.total_cmp(&b.near));
        let mut coverage = Coverage::new(1, 1, prims.len());
        for k in 0..prims.len() {
            coverage.add(k, &Footprint::Everywhere);
        }
        Caster { eye, prims, coverage }
    }

    /// Nearest hit of the ray through pixel `(u, v)` within `max` (units of `dir`). Candidates
    /// are visited near to far; the walk stops once the next one's box is farther than the best
    /// hit.
    pub fn cast(&self, u: usize, v: usize, origin: Vector, dir: Vector, max: f32) -> Option<Hit> {
        self.cast_ray(u, v, &Ray3::new(origin, dir), max)
    }

    /// [`Caster::cast`] with the ray's reciprocal and length already computed (a camera does
    /// a whole row at once, which the compiler vectorises).
    #[inline]
    pub fn cast_ray(&self, u: usize, v: usize, ray: &Ray3, max: f32) -> Option<Hit> {
        let (origin, dir, len) = (ray.origin, ray.dir, ray.len);
        // Every ray of a perspective camera starts at the eye: shapes keep its local image.
        let from_eye = origin == self.eye;
        let inv_dir = Vec3A::from(ray.inv);
        let origin_a = Vec3A::from(origin);
        let mut best: Option<(usize, Vector)> = None;
        let mut best_t = max;
        'walk: for (word, &bits) in self.coverage.pixel(u, v).iter().enumerate() {
            let mut bits = bits;
            while bits != 0 {
                let k = word * 64 + bits.trailing_zeros() as usize;
                bits &= bits - 1;
                let p = &self.prims[k];
                if p.near > best_t * len {
                    break 'walk;
                }
                let Some((entry, _)) = slab(origin_a, inv_dir, p.mins, p.maxs, best_t) else {
                    continue;
                };
                if let Some((t, n)) = p.exact(ray, from_eye, entry, best_t) {
                    best_t = t;
                    best = Some((k, n));
                }
            }
        }
        best.map(|(k, n)| self.prims[k].hit(origin, dir, inv_dir, best_t, n))
    }
}
