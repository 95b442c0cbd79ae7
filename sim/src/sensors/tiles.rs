//! The fast path of the ray-cast cameras. Casting each pixel through rapier's query pipeline
//! runs at well under a million rays per second (dynamic dispatch, filtering and a full BVH descent
//! per ray). Here every collider is flattened once per image into a primitive with its world
//! bounding box, the box is projected into the image, and each 8×8-pixel tile keeps the list of
//! primitives that can appear in it, sorted near to far. A pixel then tests only its tile's
//! candidates with parry's exact per-shape ray cast and stops as soon as the nearest hit is closer
//! than the next candidate's box. The hits are the same as the query pipeline's.

use nalgebra::{Isometry3, Vector3};
use rapier3d::math::{Pose, Vec3A, Vector};
use rapier3d::prelude::*;

use super::camera::Projection;
use crate::convert::{vec_from_glam, vec_to_glam};

const TILE: usize = 8;

/// One collider, flattened.
struct Prim<'a> {
    pose: Pose,
    shape: &'a dyn Shape,
    kind: Kind,
    user_data: u128,
    /// World bounding box, SIMD-friendly.
    mins: Vec3A,
    maxs: Vec3A,
    /// Euclidean distance from the eye to the bounding box.
    near: f32,
}

/// Shapes with a closed-form intersection here; anything else uses parry's generic ray cast.
#[derive(Clone, Copy)]
enum Kind {
    /// A box whose world bounding box is the box itself: the slab test is the exact hit.
    AlignedBox,
    Cuboid(Vector),
    Capsule(Vector, Vector, f32),
    /// Half height along local y, radius (parry's cylinder axis).
    Cylinder(f32, f32),
    Other,
}

/// Entry and exit parameters of a ray through an axis-aligned box, if it crosses `[0, max]`.
#[inline]
fn slab(origin: Vec3A, inv_dir: Vec3A, mins: Vec3A, maxs: Vec3A, max: f32) -> Option<(f32, f32)> {
    let t1 = (mins - origin) * inv_dir;
    let t2 = (maxs - origin) * inv_dir;
    let near = t1.min(t2).max_element().max(0.0);
    let far = t1.max(t2).min_element().min(max);
    (near <= far).then_some((near, far))
}

/// Outward normal of the face an axis-aligned box is entered through.
#[inline]
fn aligned_normal(origin: Vec3A, inv_dir: Vec3A, mins: Vec3A, maxs: Vec3A, dir: Vector) -> Vector {
    let tmin = ((mins - origin) * inv_dir).min((maxs - origin) * inv_dir);
    if tmin.x >= tmin.y && tmin.x >= tmin.z {
        Vector::X * -dir.x.signum()
    } else if tmin.y >= tmin.z {
        Vector::Y * -dir.y.signum()
    } else {
        Vector::Z * -dir.z.signum()
    }
}

/// Ray against a box of half extents `h` centred at the origin: parameter and outward normal.
#[inline]
fn ray_cuboid(o: Vector, d: Vector, h: Vector, max: f32) -> Option<(f32, Vector)> {
    let inv = d.recip();
    let t1 = (-h - o) * inv;
    let t2 = (h - o) * inv;
    let tmin = t1.min(t2);
    let near = tmin.max_element();
    let far = t1.max(t2).min_element();
    if near > far || far < 0.0 || near > max {
        return None;
    }
    if near < 0.0 {
        // Inside the box (solid): a hit at the origin.
        return Some((0.0, -d.normalize_or_zero()));
    }
    let axis = if tmin.x >= tmin.y && tmin.x >= tmin.z {
        Vector::X * -d.x.signum()
    } else if tmin.y >= tmin.z {
        Vector::Y * -d.y.signum()
    } else {
        Vector::Z * -d.z.signum()
    };
    Some((near, axis))
}

/// Ray against a solid cylinder about local y (half height `hh`, radius `r`): side, then caps.
#[inline]
fn ray_cylinder(o: Vector, d: Vector, hh: f32, r: f32, max: f32) -> Option<(f32, Vector)> {
    let (a, b, c) = (
        d.x * d.x + d.z * d.z,
        o.x * d.x + o.z * d.z,
        o.x * o.x + o.z * o.z - r * r,
    );
    if c <= 0.0 && o.y.abs() <= hh {
        return Some((0.0, -d.normalize_or_zero()));
    }
    let mut best: Option<(f32, Vector)> = None;
    let mut offer = |t: f32, n: Vector| {
        if t >= 0.0 && t <= max && best.is_none_or(|b| t < b.0) {
            best = Some((t, n));
        }
    };
    if a > 1e-12 {
        let disc = b * b - a * c;
        if disc >= 0.0 {
            let t = (-b - disc.sqrt()) / a;
            let p = o + d * t;
            if p.y.abs() <= hh {
                offer(t, Vector::new(p.x, 0.0, p.z).normalize_or_zero());
            }
        }
    }
    if d.y.abs() > 1e-12 {
        for s in [-1.0f32, 1.0] {
            let t = (s * hh - o.y) / d.y;
            let p = o + d * t;
            if p.x * p.x + p.z * p.z <= r * r {
                offer(t, Vector::Y * s);
            }
        }
    }
    best
}

/// Ray against the capsule of segment `a`–`b` and radius `r` (closed form, after I. Quilez).
#[inline]
fn ray_capsule(ro: Vector, rd: Vector, a: Vector, b: Vector, r: f32, max: f32) -> Option<(f32, Vector)> {
    let ba = b - a;
    let oa = ro - a;
    let baba = ba.dot(ba);
    let bard = ba.dot(rd);
    let baoa = ba.dot(oa);
    let rdoa = rd.dot(oa);
    let oaoa = oa.dot(oa);
    let rdrd = rd.dot(rd);
    let qa = baba * rdrd - bard * bard;
    let qb = baba * rdoa - baoa * bard;
    let qc = baba * oaoa - baoa * baoa - r * r * baba;
    let hit = |t: f32| {
        (t >= 0.0 && t <= max).then(|| {
            let p = ro + rd * t;
            let k = ((p - a).dot(ba) / baba).clamp(0.0, 1.0);
            (t, (p - (a + ba * k)).normalize_or_zero())
        })
    };
    if qa.abs() > 1e-12 {
        let disc = qb * qb - qa * qc;
        if disc < 0.0 {
            return None;
        }
        let t = (-qb - disc.sqrt()) / qa;
        let y = baoa + t * bard;
        if y > 0.0 && y < baba {
            return hit(t);
        }
    }
    // The caps: the sphere at whichever end the infinite cylinder hit lies beyond.
    let mut best: Option<(f32, Vector)> = None;
    for c in [a, b] {
        let oc = ro - c;
        let (qb, qc) = (rd.dot(oc), oc.dot(oc) - r * r);
        let disc = qb * qb - rdrd * qc;
        if disc >= 0.0 {
            let t = (-qb - disc.sqrt()) / rdrd;
            if let Some(h) = hit(t)
                && best.is_none_or(|b| h.0 < b.0)
            {
                best = Some(h);
            }
        }
    }
    best
}

impl<'a> Prim<'a> {
    fn of(co: &'a Collider, eye: Vector) -> Prim<'a> {
        let aabb = co.compute_aabb();
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
        } else {
            Kind::Other
        };
        Prim {
            pose: *co.position(),
            shape,
            kind,
            user_data: co.user_data,
            mins: Vec3A::from(aabb.mins),
            maxs: Vec3A::from(aabb.maxs),
            near: box_distance(eye, &aabb),
        }
    }
}

/// A hit: ray parameter (units of the ray direction), world normal, collider user data.
pub struct Hit {
    pub t: f32,
    pub normal: Vector,
    pub user_data: u128,
}

/// Per-image acceleration structure.
pub struct TileGrid<'a> {
    prims: Vec<Prim<'a>>,
    lists: Vec<Vec<u32>>,
    tiles_x: usize,
}

fn box_distance(eye: Vector, aabb: &Aabb) -> f32 {
    let d = (aabb.mins - eye).max(eye - aabb.maxs).max(Vector::ZERO);
    d.length()
}

impl<'a> TileGrid<'a> {
    /// Bin every collider of `world` for an image of `w`×`h` from `cam` with `projection`.
    pub fn new(
        world: &'a PhysicsWorld,
        cam: &Isometry3<f64>,
        projection: Projection,
        w: usize,
        h: usize,
    ) -> Self {
        let eye = vec_to_glam(&cam.translation.vector);
        let inv = cam.inverse();
        let (tiles_x, tiles_y) = (w.div_ceil(TILE), h.div_ceil(TILE));
        let mut lists = vec![Vec::new(); tiles_x * tiles_y];
        let mut prims = Vec::new();
        let (cx, cy) = (w as f64 / 2.0, h as f64 / 2.0);
        for (_, co) in world.colliders.iter() {
            if !co.is_enabled() {
                continue;
            }
            let aabb = co.compute_aabb();
            let Some([u0, u1, v0, v1]) = project(&aabb, &inv, projection, cx, cy) else {
                continue;
            };
            let idx = prims.len() as u32;
            prims.push(Prim::of(co, eye));
            let clamp_x = |u: f64| (u.max(0.0) as usize / TILE).min(tiles_x - 1);
            let clamp_y = |v: f64| (v.max(0.0) as usize / TILE).min(tiles_y - 1);
            if u1 < 0.0 || v1 < 0.0 || u0 > w as f64 || v0 > h as f64 {
                continue;
            }
            for ty in clamp_y(v0)..=clamp_y(v1) {
                for tx in clamp_x(u0)..=clamp_x(u1) {
                    lists[ty * tiles_x + tx].push(idx);
                }
            }
        }
        for l in &mut lists {
            l.sort_by(|a, b| prims[*a as usize].near.total_cmp(&prims[*b as usize].near));
        }
        TileGrid {
            prims,
            lists,
            tiles_x,
        }
    }

    /// One list of every collider `keep` accepts, nearest to `eye` first: for scans in all
    /// directions (LiDAR), cast with pixel `(0, 0)`.
    pub fn unbinned(world: &'a PhysicsWorld, eye: Vector, keep: impl Fn(&Collider) -> bool) -> Self {
        let mut prims = Vec::new();
        for (_, co) in world.colliders.iter() {
            if co.is_enabled() && keep(co) {
                prims.push(Prim::of(co, eye));
            }
        }
        let mut list: Vec<u32> = (0..prims.len() as u32).collect();
        list.sort_by(|a, b| prims[*a as usize].near.total_cmp(&prims[*b as usize].near));
        TileGrid {
            prims,
            lists: vec![list],
            tiles_x: 1,
        }
    }

    /// Nearest hit of the ray through pixel `(u, v)` within `max` (units of `dir`).
    pub fn cast(&self, u: usize, v: usize, origin: Vector, dir: Vector, max: f32) -> Option<Hit> {
        let list = &self.lists[(v / TILE) * self.tiles_x + u / TILE];
        let len = dir.length();
        let inv_dir = Vec3A::from(dir.recip());
        let origin_a = Vec3A::from(origin);
        let mut best: Option<Hit> = None;
        let mut best_t = max;
        for &i in list {
            let p = &self.prims[i as usize];
            if p.near > best_t * len {
                break;
            }
            let Some((entry, _)) = slab(origin_a, inv_dir, p.mins, p.maxs, best_t) else {
                continue;
            };
            if let Kind::AlignedBox = p.kind {
                if entry < best_t {
                    best_t = entry;
                    let n = aligned_normal(origin_a, inv_dir, p.mins, p.maxs, dir);
                    best = Some(Hit {
                        t: entry,
                        normal: n,
                        user_data: p.user_data,
                    });
                }
                continue;
            }
            let (o, d) = (
                p.pose.inverse_transform_point(origin),
                p.pose.inverse_transform_vector(dir),
            );
            let hit = match p.kind {
                Kind::AlignedBox => None,
                Kind::Cuboid(h) => ray_cuboid(o, d, h, best_t),
                Kind::Capsule(a, b, r) => ray_capsule(o, d, a, b, r, best_t),
                Kind::Cylinder(hh, r) => ray_cylinder(o, d, hh, r, best_t),
                Kind::Other => p
                    .shape
                    .cast_local_ray_and_get_normal(&Ray::new(o, d), best_t, true)
                    .map(|h| (h.time_of_impact, h.normal)),
            };
            if let Some((t, n)) = hit
                && t < best_t
            {
                best_t = t;
                best = Some(Hit {
                    t,
                    normal: p.pose.rotation * n,
                    user_data: p.user_data,
                });
            }
        }
        best
    }
}

/// Pixel rectangle `[u0, u1, v0, v1]` covering `aabb`, or `None` when it is entirely behind.
fn project(aabb: &Aabb, inv: &Isometry3<f64>, projection: Projection, cx: f64, cy: f64) -> Option<[f64; 4]> {
    let (lo, hi) = (vec_from_glam(aabb.mins), vec_from_glam(aabb.maxs));
    let mut r = [f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY];
    let mut behind = 0;
    for k in 0..8 {
        let c = Vector3::new(
            if k & 1 == 0 { lo.x } else { hi.x },
            if k & 2 == 0 { lo.y } else { hi.y },
            if k & 4 == 0 { lo.z } else { hi.z },
        );
        let p = inv * nalgebra::Point3::from(c);
        let (u, v) = match projection {
            Projection::Pinhole { fov } => {
                if p.x <= 1e-3 {
                    behind += 1;
                    continue;
                }
                let f = cx / (fov / 2.0).tan();
                (cx - p.y / p.x * f, cy - p.z / p.x * f)
            }
            Projection::Ortho { scale } => (cx - p.y / scale, cy - p.z / scale),
        };
        r = [r[0].min(u), r[1].max(u), r[2].min(v), r[3].max(v)];
    }
    match behind {
        8 => None,
        // Straddles the eye plane: its projection is unbounded, so it may cover any pixel.
        0 => Some([r[0] - 1.0, r[1] + 1.0, r[2] - 1.0, r[3] + 1.0]),
        _ => Some([f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY]),
    }
}
