//! Exact ray tests against the primitive shapes the scenes use, in closed form: an axis-aligned
//! box (slab test), an oriented box, a solid cylinder, a capsule and a convex hull. Parameters are in units of
//! the ray direction; a ray starting inside a solid reports a hit at 0.

use rapier3d::math::{Vec3A, Vector};
use rapier3d::parry::shape::ConvexPolyhedron;

/// Entry and exit parameters of a ray through an axis-aligned box, if it crosses `[0, max]`.
#[inline]
pub(super) fn slab(origin: Vec3A, inv_dir: Vec3A, mins: Vec3A, maxs: Vec3A, max: f32) -> Option<(f32, f32)> {
    let t1 = (mins - origin) * inv_dir;
    let t2 = (maxs - origin) * inv_dir;
    let near = t1.min(t2).max_element().max(0.0);
    let far = t1.max(t2).min_element().min(max);
    (near <= far).then_some((near, far))
}

/// Outward normal of the face an axis-aligned box is entered through.
#[inline]
pub(super) fn aligned_normal(origin: Vec3A, inv_dir: Vec3A, mins: Vec3A, maxs: Vec3A, dir: Vector) -> Vector {
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
pub(super) fn ray_cuboid(o: Vector, d: Vector, h: Vector, max: f32) -> Option<(f32, Vector)> {
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
pub(super) fn ray_cylinder(o: Vector, d: Vector, hh: f32, r: f32, max: f32) -> Option<(f32, Vector)> {
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
pub(super) fn ray_capsule(
    ro: Vector,
    rd: Vector,
    a: Vector,
    b: Vector,
    r: f32,
    max: f32,
) -> Option<(f32, Vector)> {
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

/// Ray against a solid convex polyhedron: the ray clipped by every face's half-space (enter
/// through the last face it crosses inwards, leave through the first outwards).
#[inline]
pub(super) fn ray_convex(o: Vector, d: Vector, c: &ConvexPolyhedron, max: f32) -> Option<(f32, Vector)> {
    clip(d, max, face_planes(c, o))
}

/// Each face of `c`: its outward normal and `o`'s signed distance from its plane.
#[inline]
fn face_planes(c: &ConvexPolyhedron, o: Vector) -> impl Iterator<Item = (Vector, f32)> + '_ {
    let (points, ring) = (c.points(), c.vertices_adj_to_face());
    c.faces().iter().map(move |f| {
        let p = points[ring[f.first_vertex_or_edge as usize] as usize];
        (f.normal, f.normal.dot(o - p))
    })
}

/// The ray along `d` (up to `max`) clipped by half-spaces, each a face's outward normal and the
/// ray origin's signed distance from the face's plane.
#[inline]
fn clip(d: Vector, max: f32, planes: impl Iterator<Item = (Vector, f32)>) -> Option<(f32, Vector)> {
    let (mut near, mut far, mut normal) = (f32::NEG_INFINITY, max, Vector::ZERO);
    for (n, dist) in planes {
        let along = n.dot(d);
        if along == 0.0 {
            if dist > 0.0 {
                return None;
            }
            continue;
        }
        let t = -dist / along;
        if along < 0.0 {
            if t > near {
                (near, normal) = (t, n);
            }
        } else if t < far {
            far = t;
        }
        if near > far {
            return None;
        }
    }
    if far < 0.0 {
        return None;
    }
    if near < 0.0 {
        // Inside the solid: a hit at the origin.
        return Some((0.0, -d.normalize_or_zero()));
    }
    Some((near, normal))
}

/// A convex hull's face planes for rays that all start at one point (a camera's eye, in the
/// hull's frame). A mesh arm's rays spend their time in [`ray_convex`], most of it on rays that
/// pass the link's world box, which a turned link fills loosely, and miss the hull. Here each
/// face's distance from the eye is computed once per image ([`face_planes`], as `ray_convex` does),
/// and a ray must first cross the hull's own box, grown by `BOX_SLACK`; the clipping after that is
/// `ray_convex`'s own ([`clip`]), so the bits are its bits (the
/// `ray_convex_from_the_eye_gives_the_same_bits` test).
pub(super) struct EyePlanes {
    /// Per face: normal and the eye's signed distance from the face's plane.
    planes: Vec<(Vector, f32)>,
    mins: Vec3A,
    maxs: Vec3A,
    eye: Vec3A,
}

/// Growth of a hull's box (m, plus this fraction of its largest coordinate): far above the
/// round-off that lets `ray_convex` accept a ray grazing the hull, so the box never drops one.
const BOX_SLACK: f32 = 1e-4;

impl EyePlanes {
    pub(super) fn new(hull: &ConvexPolyhedron, eye: Vector) -> EyePlanes {
        let planes = face_planes(hull, eye).collect();
        let (mut mins, mut maxs) = (Vec3A::splat(f32::INFINITY), Vec3A::splat(f32::NEG_INFINITY));
        for p in hull.points() {
            (mins, maxs) = (mins.min(Vec3A::from(*p)), maxs.max(Vec3A::from(*p)));
        }
        let slack = BOX_SLACK * (1.0 + mins.abs().max(maxs.abs()).max_element());
        EyePlanes {
            planes,
            mins: mins - slack,
            maxs: maxs + slack,
            eye: Vec3A::from(eye),
        }
    }

    /// [`ray_convex`] for the ray from the eye along `d`.
    #[inline]
    pub(super) fn cast(&self, d: Vector, max: f32) -> Option<(f32, Vector)> {
        slab(self.eye, Vec3A::from(d.recip()), self.mins, self.maxs, max)?;
        clip(d, max, self.planes.iter().copied())
    }
}

#[cfg(test)]
mod tests {
    use rapier3d::parry::query::{Ray, RayCast};
    use rapier3d::parry::shape::TriMesh;

    use super::*;

    /// Rays from eyes outside, on and inside lumpy hulls, aimed near them and anywhere: the
    /// per-image planes give exactly the face-by-face clipping's bits, up to the ray's `max`.
    #[test]
    fn ray_convex_from_the_eye_gives_the_same_bits() {
        let mut seed = 3u64;
        let mut unit = move || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
        };
        let mut hits = 0;
        for h in 0..40 {
            // Some hulls with few faces (one partial chunk), most with many.
            let n = if h % 4 == 0 { 5 } else { 32 };
            let points: Vec<Vector> = (0..n)
                .map(|_| Vector::new(0.05 * unit(), 0.03 * unit(), 0.08 * unit()))
                .collect();
            let hull = ConvexPolyhedron::from_convex_hull(&points).unwrap();
            for e in 0..20 {
                let eye = match e % 4 {
                    0 => Vector::ZERO,
                    1 => hull.points()[e % hull.points().len()],
                    _ => Vector::new(unit(), unit(), unit()) * 0.3,
                };
                let planes = EyePlanes::new(&hull, eye);
                for r in 0..200 {
                    let aim = Vector::new(0.05 * unit(), 0.03 * unit(), 0.08 * unit());
                    let d = match r % 5 {
                        0 => Vector::new(unit(), unit(), unit()),
                        // Along a coordinate axis: faces parallel to the ray.
                        1 => Vector::X * unit(),
                        _ => aim - eye,
                    };
                    let max = if r % 7 == 0 { 0.5 * unit().abs() } else { 10.0 };
                    let ours = planes.cast(d, max);
                    let theirs = ray_convex(eye, d, &hull, max);
                    let bits = |x: Option<(f32, Vector)>| {
                        x.map(|(t, n)| [t.to_bits(), n.x.to_bits(), n.y.to_bits(), n.z.to_bits()])
                    };
                    assert_eq!(bits(ours), bits(theirs), "hull {h} eye {e} ray {r}");
                    hits += usize::from(theirs.is_some());
                }
            }
        }
        assert!(hits > 40 * 20 * 200 / 4, "{hits} rays hit");
    }

    /// Rays from all around a lumpy hull: the face clipping finds the hits that casting against
    /// the hull's own triangles finds, at the same distance, entering through an outward face.
    /// (parry's generic cast on the hull, GJK on its support map, lands up to 2 mm off.)
    #[test]
    fn a_convex_hull_is_hit_where_its_triangles_are_hit() {
        let mut seed = 7u64;
        let mut unit = move || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
        };
        let points: Vec<Vector> = (0..32)
            .map(|_| Vector::new(0.05 * unit(), 0.03 * unit(), 0.08 * unit()))
            .collect();
        let hull = ConvexPolyhedron::from_convex_hull(&points).unwrap();
        let (v, i) = hull.to_trimesh();
        let triangles = TriMesh::new(v, i).unwrap();
        let (mut hits, mut agree) = (0, 0);
        for _ in 0..2000 {
            let o = Vector::new(unit(), unit(), unit()).normalize_or(Vector::X) * 0.3;
            let aim = Vector::new(0.04 * unit(), 0.02 * unit(), 0.06 * unit());
            let d = (aim - o).normalize();
            let ours = ray_convex(o, d, &hull, 10.0);
            let theirs = triangles.cast_local_ray(&Ray::new(o, d), 10.0, false);
            match (ours, theirs) {
                (Some((t, n)), Some(t_ref)) => {
                    hits += 1;
                    assert!((t - t_ref).abs() < 1e-5, "{t} vs {t_ref}");
                    assert!(n.dot(d) < 0.0, "entered through a face it leaves by");
                    agree += 1;
                }
                (None, None) => agree += 1,
                // A ray grazing an edge may fall either way by rounding.
                _ => {}
            }
        }
        assert!(hits > 500, "{hits} rays hit");
        assert!(agree >= 1995, "{agree}/2000 agree");
    }
}
