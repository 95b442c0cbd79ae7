//! Key-object glyphs for the top-down image: one silhouette per model type, filled with the
//! object's colour, drawn at least [`MIN_RADIUS`] across so a 4 cm cup is legible, and ringed
//! by a dark outline and a light halo so it stands out on any zone, including one of its own
//! colour.
//!
//! A glyph is a union of primitives given by signed distance (negative inside) in the object's
//! frame (x along its yaw), so outline and halo are the distance bands around the silhouette.
//! Silhouettes: apple = round with a stem and a leaf, bowl = round with a thick inner wall ring,
//! cup = round with a handle, plate = wide round with a thin rim ring, fork = a handle and a
//! head with two tines. A model without a glyph gets its footprint (disc or box).

use crate::catalogue::Shape;

/// Smallest glyph radius, metres.
pub(super) const MIN_RADIUS: f64 = 0.07;
/// Outline colour: dark enough to separate any fill from a light halo.
pub(super) const OUTLINE: [u8; 3] = [20, 20, 24];
/// Halo colour, outside the outline.
pub(super) const HALO: [u8; 3] = [250, 250, 250];

#[derive(Debug, Clone, Copy, PartialEq)]
enum Prim {
    Circle {
        c: [f64; 2],
        r: f64,
    },
    /// A segment from `a` to `b` thickened by `r`.
    Capsule {
        a: [f64; 2],
        b: [f64; 2],
        r: f64,
    },
    /// An axis-aligned box.
    Rect {
        c: [f64; 2],
        half: [f64; 2],
    },
    /// A band of half width `w` around the circle of radius `r`.
    Ring {
        r: f64,
        w: f64,
    },
}

impl Prim {
    fn sdf(&self, p: [f64; 2]) -> f64 {
        match *self {
            Prim::Circle { c, r } => (p[0] - c[0]).hypot(p[1] - c[1]) - r,
            Prim::Capsule { a, b, r } => {
                let (ab, ap) = ([b[0] - a[0], b[1] - a[1]], [p[0] - a[0], p[1] - a[1]]);
                let len2 = ab[0] * ab[0] + ab[1] * ab[1];
                let t = if len2 > 0.0 {
                    ((ap[0] * ab[0] + ap[1] * ab[1]) / len2).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                (ap[0] - t * ab[0]).hypot(ap[1] - t * ab[1]) - r
            }
            Prim::Rect { c, half } => {
                let q = [(p[0] - c[0]).abs() - half[0], (p[1] - c[1]).abs() - half[1]];
                q[0].max(0.0).hypot(q[1].max(0.0)) + q[0].max(q[1]).min(0.0)
            }
            Prim::Ring { r, w } => (p[0].hypot(p[1]) - r).abs() - w,
        }
    }
}

/// A model's glyph: the silhouette, and details painted in a shade of the fill inside it.
#[derive(Debug, Clone, PartialEq)]
pub struct Glyph {
    body: Vec<Prim>,
    details: Vec<(Prim, f32)>,
    /// Radius that bounds the silhouette.
    pub reach: f64,
}

/// What a point of the glyph's neighbourhood shows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Paint {
    Fill,
    /// The fill darkened by this factor.
    Shade(f32),
    Outline,
    Halo,
}

impl Glyph {
    /// The glyph of catalogue model `model` with shape `shape`.
    pub fn of(model: &str, shape: &Shape) -> Glyph {
        let fp = shape.footprint_radius();
        let circle = |x: f64, y: f64, r: f64| Prim::Circle { c: [x, y], r };
        let capsule = |a: [f64; 2], b: [f64; 2], r: f64| Prim::Capsule { a, b, r };
        let (r, body, details) = match model {
            "apple" => {
                let r = fp.max(MIN_RADIUS);
                let stem = capsule([0.0, 0.7 * r], [0.15 * r, 1.05 * r], 0.1 * r);
                let leaf = circle(0.38 * r, 0.92 * r, 0.17 * r);
                (r, vec![circle(0.0, 0.0, 0.8 * r), stem, leaf], vec![])
            }
            "bowl" => {
                let r = fp.max(MIN_RADIUS * 1.15);
                let wall = (
                    Prim::Ring {
                        r: 0.55 * r,
                        w: 0.13 * r,
                    },
                    0.62,
                );
                (r, vec![circle(0.0, 0.0, r)], vec![wall])
            }
            "cup" => {
                let r = fp.max(MIN_RADIUS);
                let handle = capsule([0.5 * r, 0.0], [r, 0.0], 0.2 * r);
                let inside = (circle(-0.1 * r, 0.0, 0.4 * r), 0.8);
                (r, vec![circle(-0.1 * r, 0.0, 0.7 * r), handle], vec![inside])
            }
            "plate" => {
                let r = fp.max(MIN_RADIUS * 1.4);
                let rim = (
                    Prim::Ring {
                        r: 0.8 * r,
                        w: 0.04 * r,
                    },
                    0.7,
                );
                (r, vec![circle(0.0, 0.0, r)], vec![rim])
            }
            "fork" => {
                let r = fp.max(MIN_RADIUS * 1.6);
                let handle = capsule([-r, 0.0], [0.1 * r, 0.0], 0.09 * r);
                let head = Prim::Rect {
                    c: [0.3 * r, 0.0],
                    half: [0.2 * r, 0.28 * r],
                };
                let tine = |y: f64| capsule([0.45 * r, y], [r, y], 0.08 * r);
                (r, vec![handle, head, tine(-0.19 * r), tine(0.19 * r)], vec![])
            }
            _ => match shape {
                Shape::Cuboid { size } => {
                    let half = [size[0] / 2.0, size[1] / 2.0].map(|h| h.max(MIN_RADIUS / 3.0));
                    let r = half[0].hypot(half[1]);
                    (r, vec![Prim::Rect { c: [0.0, 0.0], half }], vec![])
                }
                _ => {
                    let r = fp.max(MIN_RADIUS);
                    (r, vec![circle(0.0, 0.0, r)], vec![])
                }
            },
        };
        Glyph {
            body,
            details,
            reach: r * 1.1,
        }
    }

    /// What the point `p` (object frame, metres) shows, with outline and halo `line` wide each.
    pub fn paint(&self, p: [f64; 2], line: f64) -> Option<Paint> {
        let d = (self.body.iter()).map(|b| b.sdf(p)).fold(f64::INFINITY, f64::min);
        if d <= 0.0 {
            let shade = (self.details.iter()).find(|(prim, _)| prim.sdf(p) <= 0.0);
            Some(shade.map_or(Paint::Fill, |(_, s)| Paint::Shade(*s)))
        } else if d <= line {
            Some(Paint::Outline)
        } else if d <= 2.0 * line {
            Some(Paint::Halo)
        } else {
            None
        }
    }
}
