//! Exact 2-D distances between the scene's obstacles (room walls, furniture footprints) and points,
//! segments and grid cells. The occupancy grid is built from these so that its inflation is exact
//! for every cell, not an approximation on top of an already rasterised map.

use kitchen_r_core::scene::Scene;

/// A 2-D point or vector in world metres.
pub type P2 = [f64; 2];

/// The obstacles of a scene as the navigation planner sees them: the inner room rectangle
/// `[0, size.x] × [0, size.y]` (everything outside it is wall) and furniture footprints.
#[derive(Debug, Clone, PartialEq)]
pub struct Obstacles {
    pub room: P2,
    /// Each footprint as its four corners, counter-clockwise.
    pub boxes: Vec<[P2; 4]>,
}

impl Obstacles {
    /// Footprints use the scaled size and the yaw of each furniture pose.
    pub fn from_scene(scene: &Scene) -> Obstacles {
        let boxes = scene
            .furniture
            .iter()
            .map(|f| {
                let [sx, sy, _] = f.scaled_size();
                rect_corners([f.pose[0], f.pose[1]], [sx / 2.0, sy / 2.0], f.pose[2])
            })
            .collect();
        Obstacles {
            room: scene.room.size,
            boxes,
        }
    }

    /// Distance from `p` to the nearest obstacle; 0 inside furniture or outside the room.
    pub fn point_clearance(&self, p: P2) -> f64 {
        let walls = p[0]
            .min(p[1])
            .min(self.room[0] - p[0])
            .min(self.room[1] - p[1])
            .max(0.0);
        self.boxes
            .iter()
            .map(|b| point_poly_distance(p, b))
            .fold(walls, f64::min)
    }

    /// Smallest clearance of any point of segment `a`–`b`.
    pub fn segment_clearance(&self, a: P2, b: P2) -> f64 {
        // The distance to the outside of a convex room is concave along a segment, so its
        // minimum is at an endpoint.
        let walls = |p: P2| {
            p[0].min(p[1])
                .min(self.room[0] - p[0])
                .min(self.room[1] - p[1])
                .max(0.0)
        };
        let seg = [a, b];
        self.boxes
            .iter()
            .map(|bx| poly_distance(&seg, bx))
            .fold(walls(a).min(walls(b)), f64::min)
    }

    /// Smallest clearance of any point of the axis-aligned square `[lo, hi]`.
    pub fn square_clearance(&self, lo: P2, hi: P2) -> f64 {
        let walls = lo[0]
            .min(lo[1])
            .min(self.room[0] - hi[0])
            .min(self.room[1] - hi[1])
            .max(0.0);
        let sq = [lo, [hi[0], lo[1]], hi, [lo[0], hi[1]]];
        let (c, r) = bounding_circle(&sq);
        let mut best = walls;
        for bx in &self.boxes {
            // Skip boxes whose bounding circle is already farther than the best so far: the
            // result stays exact and the grid builds several times faster.
            let (bc, br) = bounding_circle(bx);
            if dist(c, bc) - r - br < best {
                best = best.min(poly_distance(&sq, bx));
            }
        }
        best
    }
}

/// Corners of a rectangle with centre `c`, half extents `h` and rotation `yaw`, counter-clockwise.
pub fn rect_corners(c: P2, h: P2, yaw: f64) -> [P2; 4] {
    let (s, co) = yaw.sin_cos();
    [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]].map(|[u, v]| {
        let (x, y) = (u * h[0], v * h[1]);
        [c[0] + co * x - s * y, c[1] + s * x + co * y]
    })
}

fn sub(a: P2, b: P2) -> P2 {
    [a[0] - b[0], a[1] - b[1]]
}

fn dot(a: P2, b: P2) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

fn cross(a: P2, b: P2) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}

/// Euclidean distance between two points.
pub fn dist(a: P2, b: P2) -> f64 {
    let d = sub(a, b);
    d[0].hypot(d[1])
}

/// Distance from `p` to the segment `a`–`b`.
pub fn point_segment_distance(p: P2, a: P2, b: P2) -> f64 {
    let ab = sub(b, a);
    let len2 = dot(ab, ab);
    let t = if len2 > 0.0 {
        (dot(sub(p, a), ab) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    dist(p, [a[0] + t * ab[0], a[1] + t * ab[1]])
}

/// Whether `p` lies inside (or on) the convex counter-clockwise polygon `poly`.
fn inside_convex(p: P2, poly: &[P2]) -> bool {
    (0..poly.len()).all(|i| cross(sub(poly[(i + 1) % poly.len()], poly[i]), sub(p, poly[i])) >= 0.0)
}

/// Proper crossing only: touching and collinear contacts already give a zero vertex–edge
/// distance in [`poly_distance`].
fn segments_cross(a: P2, b: P2, c: P2, d: P2) -> bool {
    let o = |p: P2, q: P2, r: P2| cross(sub(q, p), sub(r, p));
    o(c, d, a) * o(c, d, b) < 0.0 && o(a, b, c) * o(a, b, d) < 0.0
}

fn point_poly_distance(p: P2, poly: &[P2; 4]) -> f64 {
    if inside_convex(p, poly) {
        return 0.0;
    }
    (0..4)
        .map(|i| point_segment_distance(p, poly[i], poly[(i + 1) % 4]))
        .fold(f64::INFINITY, f64::min)
}

/// Distance between a convex polygon or segment `a` (2 or 4 vertices, counter-clockwise) and the
/// convex quadrilateral `b`: zero when they overlap, otherwise the smallest vertex–edge distance.
fn poly_distance(a: &[P2], b: &[P2; 4]) -> f64 {
    // A segment has one edge, a polygon as many as vertices (no allocation: this runs per cell).
    let na = if a.len() == 2 { 1 } else { a.len() };
    let edge_a = |i: usize| (a[i], a[(i + 1) % a.len()]);
    let edge_b = |i: usize| (b[i], b[(i + 1) % 4]);
    let crossing = (0..na).any(|i| {
        let (p, q) = edge_a(i);
        (0..4).any(|j| {
            let (r, s) = edge_b(j);
            segments_cross(p, q, r, s)
        })
    });
    if inside_convex(a[0], b) || (a.len() > 2 && inside_convex(b[0], a)) || crossing {
        return 0.0;
    }
    let mut best = f64::INFINITY;
    for i in 0..na {
        let (p, q) = edge_a(i);
        for j in 0..4 {
            let (r, s) = edge_b(j);
            best = best
                .min(point_segment_distance(p, r, s))
                .min(point_segment_distance(q, r, s))
                .min(point_segment_distance(r, p, q))
                .min(point_segment_distance(s, p, q));
        }
    }
    best
}

/// Centre and radius of the circle through a rectangle's corners.
fn bounding_circle(b: &[P2; 4]) -> (P2, f64) {
    let c = [(b[0][0] + b[2][0]) / 2.0, (b[0][1] + b[2][1]) / 2.0];
    (c, dist(c, b[0]))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit_box() -> Obstacles {
        Obstacles {
            room: [10.0, 10.0],
            boxes: vec![rect_corners([5.0, 5.0], [1.0, 0.5], 0.0)],
        }
    }

    #[test]
    fn point_and_segment_clearances_match_hand_values() {
        let o = unit_box();
        assert!((o.point_clearance([5.0, 6.0]) - 0.5).abs() < 1e-12);
        assert_eq!(o.point_clearance([5.0, 5.0]), 0.0);
        assert!((o.point_clearance([0.2, 3.0]) - 0.2).abs() < 1e-12);
        assert!((o.segment_clearance([3.0, 6.0], [7.0, 6.0]) - 0.5).abs() < 1e-12);
        assert_eq!(o.segment_clearance([3.0, 5.0], [7.0, 5.0]), 0.0);
        assert!((o.square_clearance([6.5, 4.0], [7.0, 4.5]) - 0.5).abs() < 1e-12);
    }

    #[test]
    fn rotated_box_distance() {
        let o = Obstacles {
            room: [10.0, 10.0],
            boxes: vec![rect_corners([5.0, 5.0], [1.0, 1.0], std::f64::consts::FRAC_PI_4)],
        };
        // The corner of the diamond sits at x = 5 + sqrt(2).
        let d = o.point_clearance([7.0, 5.0]);
        assert!((d - (2.0 - 2f64.sqrt())).abs() < 1e-12, "{d}");
    }
}
