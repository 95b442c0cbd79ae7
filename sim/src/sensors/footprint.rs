//! Which pixels a bounding box can appear in. A ray from the eye crosses a box only if its pixel
//! centre lies inside the box's projection, the convex hull of its projected corners (for a box
//! partly behind the eye: of the part in front of it). Each box's hull is scan-converted into one
//! bit per pixel, so a camera ray tests only the boxes whose bit is set at its pixel instead of
//! every box near its part of the image. Hulls are dilated by a hundredth of a pixel, far above
//! the round-off of the f32 rays, so the bits never drop a box the ray crosses.

use nalgebra::{Isometry3, Point3, Vector3};
use rapier3d::prelude::Aabb;

use super::projection::Projection;
use crate::convert::vec_from_glam;

/// Distance (camera frame, along the optical axis) in front of the eye below which a corner
/// counts as behind it.
const EYE_PLANE: f64 = 1e-3;
/// Dilation of every hull (pixels).
const SLACK: f64 = 0.01;

/// Where a box lands on the image.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum Footprint {
    /// Entirely behind the eye: never seen.
    Hidden,
    /// So close to the eye that any pixel may see it.
    Everywhere,
    /// Convex polygon in pixel coordinates (x right, y down; pixel `(u, v)` has its centre at
    /// `(u + 0.5, v + 0.5)`).
    Hull(Vec<[f64; 2]>),
}

/// The projection model of one image, to place boxes on it.
pub(super) struct Projector {
    inv: Isometry3<f64>,
    projection: Projection,
    cx: f64,
    cy: f64,
    /// Focal length (pixels), for pinholes.
    f: f64,
    /// A box whose nearest point is closer to the eye than this may hold a ray's only crossing
    /// within `EYE_PLANE` of it: such boxes are `Everywhere`.
    close: f64,
}

impl Projector {
    pub(super) fn new(cam: &Isometry3<f64>, projection: Projection, w: usize, h: usize) -> Projector {
        let (cx, cy) = (w as f64 / 2.0, h as f64 / 2.0);
        let (f, close) = match projection {
            Projection::Pinhole { fov } => {
                let f = cx / (fov / 2.0).tan();
                // The longest ray direction (per unit of depth) is the image corner's.
                let k = (1.0 + (cx * cx + cy * cy) / (f * f)).sqrt();
                (f, EYE_PLANE * k * 1.01 + 1e-6)
            }
            Projection::Ortho { .. } => (1.0, 0.0),
        };
        Projector {
            inv: cam.inverse(),
            projection,
            cx,
            cy,
            f,
            close,
        }
    }

    /// Where `aabb` lands, and the distance that bounds every hit on it: `near` (from the eye)
    /// for a pinhole; for parallel rays, which start across the image plane rather than at the
    /// eye, how far in front of that plane the box starts (0 if it reaches behind it), a little
    /// short so that round-off never puts it beyond a hit on it.
    pub(super) fn place(&self, aabb: &Aabb, near: f32) -> (f32, Footprint) {
        let corners = self.corners(aabb);
        match self.projection {
            Projection::Ortho { .. } => {
                let d = corners.iter().map(|p| p.x).fold(f64::INFINITY, f64::min);
                let depth = (d - 1e-4 * (1.0 + d.abs())).max(0.0) as f32;
                (depth, self.footprint(&corners, depth))
            }
            Projection::Pinhole { .. } => (near, self.footprint(&corners, near)),
        }
    }

    fn corners(&self, aabb: &Aabb) -> Vec<Vector3<f64>> {
        let (lo, hi) = (vec_from_glam(aabb.mins), vec_from_glam(aabb.maxs));
        (0..8)
            .map(|k| {
                let c = Vector3::new(
                    if k & 1 == 0 { lo.x } else { hi.x },
                    if k & 2 == 0 { lo.y } else { hi.y },
                    if k & 4 == 0 { lo.z } else { hi.z },
                );
                (self.inv * Point3::from(c)).coords
            })
            .collect()
    }

    /// The footprint of a box with camera-frame `corners`, whose distance from the eye is `near`.
    fn footprint(&self, corners: &[Vector3<f64>], near: f32) -> Footprint {
        let points = match self.projection {
            Projection::Ortho { scale } => corners
                .iter()
                .map(|p| [self.cx - p.y / scale, self.cy - p.z / scale])
                .collect(),
            Projection::Pinhole { .. } => {
                let behind = corners.iter().filter(|p| p.x <= EYE_PLANE).count();
                if behind == 8 {
                    return Footprint::Hidden;
                }
                if behind > 0 && f64::from(near) <= self.close {
                    return Footprint::Everywhere;
                }
                self.clipped(corners)
            }
        };
        Footprint::Hull(hull(points))
    }

    /// Projected vertices of the part of a box (camera-frame `corners`) in front of the eye
    /// plane: the corners in front, and where the box's edges cross the plane.
    fn clipped(&self, corners: &[Vector3<f64>]) -> Vec<[f64; 2]> {
        let project = |p: &Vector3<f64>| [self.cx - p.y / p.x * self.f, self.cy - p.z / p.x * self.f];
        let mut points: Vec<[f64; 2]> = corners.iter().filter(|p| p.x > EYE_PLANE).map(project).collect();
        for a in 0..8usize {
            for bit in [1, 2, 4] {
                let b = a | bit;
                if b == a {
                    continue;
                }
                let (p, q) = (&corners[a], &corners[b]);
                if (p.x > EYE_PLANE) != (q.x > EYE_PLANE) {
                    let s = (EYE_PLANE - p.x) / (q.x - p.x);
                    let mut c = p + (q - p) * s;
                    c.x = EYE_PLANE;
                    points.push(project(&c));
                }
            }
        }
        points
    }
}

/// Convex hull (Andrew's monotone chain), counter-clockwise; one or two points stay as they are.
fn hull(mut points: Vec<[f64; 2]>) -> Vec<[f64; 2]> {
    points.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    points.dedup();
    if points.len() < 3 {
        return points;
    }
    let cross =
        |o: [f64; 2], a: [f64; 2], b: [f64; 2]| (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]);
    let mut out: Vec<[f64; 2]> = Vec::with_capacity(points.len() * 2);
    for pass in 0..2 {
        let start = out.len();
        let iter: Box<dyn Iterator<Item = &[f64; 2]>> = if pass == 0 {
            Box::new(points.iter())
        } else {
            Box::new(points.iter().rev())
        };
        for &p in iter {
            while out.len() >= start + 2 && cross(out[out.len() - 2], out[out.len() - 1], p) <= 0.0 {
                out.pop();
            }
            out.push(p);
        }
        out.pop();
    }
    out
}

/// One bit per pixel and box: bit `k` of pixel `(u, v)` is set when box `k` may appear there.
/// Memory: pixels × ⌈boxes / 64⌉ × 8 bytes per image (256 KiB for 128×128 and 66 colliders).
pub(super) struct Coverage {
    width: usize,
    height: usize,
    /// Words of bits per pixel.
    words: usize,
    bits: Vec<u64>,
}

impl Coverage {
    /// No box anywhere on a `width`×`height` image, room for `boxes` boxes.
    pub(super) fn new(width: usize, height: usize, boxes: usize) -> Coverage {
        let words = boxes.div_ceil(64).max(1);
        Coverage {
            width,
            height,
            words,
            bits: vec![0; width * height * words],
        }
    }

    /// The words of pixel `(u, v)`; bit `k % 64` of word `k / 64` is box `k`.
    #[inline]
    pub(super) fn pixel(&self, u: usize, v: usize) -> &[u64] {
        let at = (v * self.width + u) * self.words;
        &self.bits[at..at + self.words]
    }

    /// Mark box `k` on the pixels of `footprint`.
    pub(super) fn add(&mut self, k: usize, footprint: &Footprint) {
        match footprint {
            Footprint::Hidden => {}
            Footprint::Everywhere => {
                for v in 0..self.height {
                    self.set_span(k, v, 0, self.width - 1);
                }
            }
            Footprint::Hull(poly) => self.add_hull(k, poly),
        }
    }

    fn set_span(&mut self, k: usize, v: usize, u0: usize, u1: usize) {
        let (word, bit) = (k / 64, 1u64 << (k % 64));
        let at = |u: usize| (v * self.width + u) * self.words + word;
        for w in self.bits[at(u0)..=at(u1)].iter_mut().step_by(self.words) {
            *w |= bit;
        }
    }

    /// Scan-convert a convex polygon: on each pixel row, the pixels whose centres lie within
    /// `SLACK` of the polygon.
    fn add_hull(&mut self, k: usize, poly: &[[f64; 2]]) {
        if poly.is_empty() {
            return;
        }
        let (ymin, ymax) = poly.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
            (a.min(p[1]), b.max(p[1]))
        });
        let rows = |y: f64| (y - 0.5).clamp(-1.0, self.height as f64);
        let (v0, v1) = (rows(ymin - SLACK).ceil(), rows(ymax + SLACK).floor());
        if v1 < 0.0 || v0 >= self.height as f64 {
            return;
        }
        for v in (v0.max(0.0) as usize)..=(v1 as usize).min(self.height - 1) {
            let yc = v as f64 + 0.5;
            let Some((x0, x1)) = row_extent(poly, yc - SLACK, yc + SLACK) else {
                continue;
            };
            let u0 = (x0 - SLACK - 0.5).ceil().max(0.0);
            let u1 = (x1 + SLACK - 0.5).floor().min(self.width as f64 - 1.0);
            if u1 >= u0 {
                self.set_span(k, v, u0 as usize, u1 as usize);
            }
        }
    }
}

/// The x extent of a convex polygon within the band `y0 ≤ y ≤ y1`: the extreme points of the
/// polygon there lie on its edges.
fn row_extent(poly: &[[f64; 2]], y0: f64, y1: f64) -> Option<(f64, f64)> {
    let mut ext: Option<(f64, f64)> = None;
    let mut take = |x: f64| {
        ext = Some(ext.map_or((x, x), |(a, b)| (a.min(x), b.max(x))));
    };
    for (i, p) in poly.iter().enumerate() {
        let q = poly[(i + 1) % poly.len()];
        let (lo, hi) = (p[1].min(q[1]), p[1].max(q[1]));
        if hi < y0 || lo > y1 {
            continue;
        }
        if hi - lo < 1e-12 {
            take(p[0]);
            take(q[0]);
            continue;
        }
        for y in [lo.max(y0), hi.min(y1)] {
            take(p[0] + (q[0] - p[0]) * (y - p[1]) / (q[1] - p[1]));
        }
    }
    ext
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bits(c: &Coverage, k: usize) -> Vec<(usize, usize)> {
        let mut out = Vec::new();
        for v in 0..c.height {
            for u in 0..c.width {
                if c.pixel(u, v)[k / 64] & (1 << (k % 64)) != 0 {
                    out.push((u, v));
                }
            }
        }
        out
    }

    #[test]
    fn a_triangle_covers_the_pixel_centres_inside_it() {
        let mut c = Coverage::new(8, 8, 70);
        // Right triangle with legs along the top and left edges, hypotenuse x + y = 4.
        c.add(
            65,
            &Footprint::Hull(hull(vec![[0.0, 0.0], [4.0, 0.0], [0.0, 4.0]])),
        );
        let expect: Vec<_> = (0..8)
            .flat_map(|v| (0..8).map(move |u| (u, v)))
            .filter(|&(u, v)| u as f64 + 0.5 + v as f64 + 0.5 <= 4.0 + 1e-9)
            .collect();
        assert_eq!(bits(&c, 65), expect);
        assert!(bits(&c, 0).is_empty());
    }

    #[test]
    fn everywhere_and_hidden_cover_all_and_nothing() {
        let mut c = Coverage::new(4, 3, 2);
        c.add(0, &Footprint::Everywhere);
        c.add(1, &Footprint::Hidden);
        assert_eq!(bits(&c, 0).len(), 12);
        assert!(bits(&c, 1).is_empty());
    }

    #[test]
    fn a_box_behind_the_eye_is_hidden_and_one_across_it_is_clipped() {
        let cam = Isometry3::identity();
        let p = Projector::new(&cam, Projection::Pinhole { fov: 1.4 }, 16, 16);
        let behind = Aabb::new([-3.0, -1.0, -1.0].into(), [-2.0, 1.0, 1.0].into());
        assert_eq!(p.place(&behind, 2.0).1, Footprint::Hidden);
        // A slab from behind the eye to 2 m in front, off to the left: its footprint is finite.
        let across = Aabb::new([-1.0, 0.5, -0.2].into(), [2.0, 1.5, 0.2].into());
        let Footprint::Hull(h) = p.place(&across, 0.5).1 else {
            panic!("expected a hull");
        };
        assert!(h.iter().all(|q| q[0].is_finite() && q[1].is_finite()));
        let close = Aabb::new([-1.0, -0.0005, -0.1].into(), [1.0, 0.1, 0.1].into());
        assert_eq!(p.place(&close, 0.0).1, Footprint::Everywhere);
    }
}
