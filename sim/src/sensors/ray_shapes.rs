//! Exact ray tests against the primitive shapes the scenes use, in closed form: an axis-aligned
//! box (slab test), an oriented box, a solid cylinder and a capsule. Parameters are in units of
//! the ray direction; a ray starting inside a solid reports a hit at 0.

use rapier3d::math::{Vec3A, Vector};

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
