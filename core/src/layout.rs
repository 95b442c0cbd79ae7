//! Navigability rules for scene layouts, stricter than [`Scene::validate`].
//!
//! `validate` checks that a scene file is self-consistent; this module checks the conventions the
//! simulator's oracle navigator relies on (docs/twin/oracle.md): a robot of radius
//! [`ROBOT_RADIUS`] can stop at every approach point and start anywhere on a start segment without
//! touching furniture or walls, furniture pieces either touch or leave a corridor of at least
//! [`MIN_CORRIDOR`], and every approach point is reachable from every start segment. These rules
//! are kept out of `validate` so that small hand-made test scenes elsewhere need not follow them;
//! every committed scene must (see the `committed_scenes_validate` test).

use std::collections::VecDeque;

use crate::catalogue::Catalogue;
use crate::dataset::symbolic::{OBJECT_GAP, fits_in_zone};
use crate::scene::{Furniture, Scene};

/// Base radius of the mobile ALOHA robot, metres.
pub const ROBOT_RADIUS: f64 = 0.35;
/// Clearance an approach point or start position keeps from furniture footprints and walls.
pub const MIN_CLEARANCE: f64 = 0.4;
/// Smallest free gap between two furniture pieces that do not touch.
pub const MIN_CORRIDOR: f64 = 1.0;
/// Largest zone-centre depth behind the front edge of its surface the arm is expected to reach.
pub const MAX_ZONE_DEPTH: f64 = 0.25;
/// Occupancy grid resolution of the reachability check.
const CELL: f64 = 0.05;
/// Gaps below this count as "touching" (pieces of one counter run).
const TOUCH: f64 = 0.01;

impl Furniture {
    /// Distance from world point `p` to the footprint (0 inside).
    pub fn footprint_distance(&self, p: [f64; 2]) -> f64 {
        let [cx, cy, yaw] = self.pose;
        let (dx, dy) = (p[0] - cx, p[1] - cy);
        let (s, c) = yaw.sin_cos();
        let (lx, ly) = (c * dx + s * dy, -s * dx + c * dy);
        let [sx, sy, _] = self.scaled_size();
        let ex = (lx.abs() - sx / 2.0).max(0.0);
        let ey = (ly.abs() - sy / 2.0).max(0.0);
        ex.hypot(ey)
    }

    /// World-axis bounding box of the footprint: `[min_x, min_y, max_x, max_y]`.
    pub fn footprint_aabb(&self) -> [f64; 4] {
        let [cx, cy, yaw] = self.pose;
        let [sx, sy, _] = self.scaled_size();
        let (s, c) = yaw.sin_cos();
        let hx = (c * sx).abs() / 2.0 + (s * sy).abs() / 2.0;
        let hy = (s * sx).abs() / 2.0 + (c * sy).abs() / 2.0;
        [cx - hx, cy - hy, cx + hx, cy + hy]
    }
}

impl Scene {
    /// Distance from `p` to the nearest furniture footprint or wall.
    pub fn clearance(&self, p: [f64; 2]) -> f64 {
        let [rx, ry] = self.room.size;
        let walls = p[0].min(rx - p[0]).min(p[1]).min(ry - p[1]);
        self.furniture
            .iter()
            .map(|f| f.footprint_distance(p))
            .fold(walls, f64::min)
    }

    /// Check the navigation conventions; the message says what to fix.
    pub fn check_layout(&self) -> Result<(), String> {
        self.check_zones()?;
        self.check_corridors()?;
        self.check_reachable()
    }

    fn check_reachable(&self) -> Result<(), String> {
        let starts = self.start_points();
        for p in &starts {
            if self.clearance(*p) < MIN_CLEARANCE - 1e-9 {
                return Err(format!(
                    "start position {p:?} is closer than {MIN_CLEARANCE} m to an obstacle"
                ));
            }
        }
        let grid = Grid::new(self);
        let seen = grid.flood(starts[0]);
        for p in &starts {
            if !seen[grid.index(*p)] {
                return Err(format!(
                    "start position {p:?} is not connected to the first start segment"
                ));
            }
        }
        for z in &self.zones {
            if !seen[grid.index([z.approach[0], z.approach[1]])] {
                return Err(format!(
                    "zone {:?}: approach point unreachable from the start",
                    z.color
                ));
            }
        }
        Ok(())
    }

    /// Check what stands on the surfaces: every key object's footprint lies inside its zone
    /// with the zone margin and keeps [`OBJECT_GAP`] from its neighbours (the rule place targets
    /// follow too, see [`crate::dataset::symbolic`]), and every background area lies on one
    /// surface without touching a zone, so scattered clutter never blocks a pick or a place.
    pub fn check_contents(&self, catalogue: &Catalogue) -> Result<(), String> {
        let mut placed: Vec<(String, [f64; 2], f64)> = Vec::new();
        for o in &self.key_objects {
            let m = catalogue.model(&o.model).ok_or("unknown model")?;
            let z = self.zone(&o.zone).ok_or("unknown zone")?;
            let (p, r) = (
                [z.center[0] + o.offset[0], z.center[1] + o.offset[1]],
                m.shape.footprint_radius(),
            );
            if !fits_in_zone(z, r, p) {
                return Err(format!(
                    "key object {:?} sticks out of the {} zone",
                    o.name(),
                    z.color
                ));
            }
            for (other, q, rq) in &placed {
                let (dx, dy) = (p[0] - q[0], p[1] - q[1]);
                if (dx * dx + dy * dy).sqrt() < r + rq + OBJECT_GAP - 1e-9 {
                    return Err(format!("key objects {:?} and {other:?} overlap", o.name()));
                }
            }
            placed.push((o.name(), p, r));
        }
        for a in &self.background_areas {
            let [hx, hy] = [a.size[0] / 2.0, a.size[1] / 2.0];
            let corners = [(-hx, -hy), (-hx, hy), (hx, -hy), (hx, hy)]
                .map(|(dx, dy)| [a.center[0] + dx, a.center[1] + dy]);
            let on_surface = self.furniture.iter().any(|f| {
                corners.iter().all(|c| f.covers(*c, 1e-9))
                    && f.surfaces().iter().any(|h| (h - a.height).abs() < 1e-6)
            });
            if !on_surface {
                return Err(format!(
                    "background area at {:?} does not lie on one surface",
                    a.center
                ));
            }
            let overlaps = |z: &crate::scene::Zone| {
                (0..2).all(|i| (a.center[i] - z.center[i]).abs() < (a.size[i] + z.size[i]) / 2.0)
            };
            if let Some(z) = self.zones.iter().find(|z| overlaps(z)) {
                return Err(format!(
                    "background area at {:?} overlaps the {} zone",
                    a.center, z.color
                ));
            }
        }
        Ok(())
    }

    fn check_zones(&self) -> Result<(), String> {
        for z in &self.zones {
            let a = [z.approach[0], z.approach[1]];
            if self.clearance(a) < MIN_CLEARANCE - 1e-9 {
                return Err(format!(
                    "zone {:?}: approach point {a:?} is closer than {MIN_CLEARANCE} m to an obstacle",
                    z.color
                ));
            }
            let f = self.furniture(&z.furniture).ok_or("zone on unknown furniture")?;
            // The zone must lie on its surface: all four corners over the footprint.
            let [hx, hy] = [z.size[0] / 2.0, z.size[1] / 2.0];
            for (sx, sy) in [(-1.0, -1.0), (-1.0, 1.0), (1.0, -1.0), (1.0, 1.0)] {
                if !f.covers([z.center[0] + sx * hx, z.center[1] + sy * hy], 1e-9) {
                    return Err(format!("zone {:?} overhangs furniture {:?}", z.color, f.id));
                }
            }
            // Facing: the heading must point from the approach point at the zone centre.
            let (dx, dy) = (z.center[0] - a[0], z.center[1] - a[1]);
            let (s, c) = z.approach[2].sin_cos();
            if (c * dx + s * dy) / dx.hypot(dy) < 0.95 {
                return Err(format!(
                    "zone {:?}: approach heading does not face the zone",
                    z.color
                ));
            }
            // Depth behind the front edge = distance to the centre minus the 0.45 m standoff.
            let depth = f.footprint_distance(a);
            if dx.hypot(dy) - depth > MAX_ZONE_DEPTH + 1e-9 {
                return Err(format!("zone {:?}: centre is too deep on its surface", z.color));
            }
        }
        Ok(())
    }

    fn check_corridors(&self) -> Result<(), String> {
        for (i, a) in self.furniture.iter().enumerate() {
            for b in &self.furniture[i + 1..] {
                let [a0, a1, a2, a3] = a.footprint_aabb();
                let [b0, b1, b2, b3] = b.footprint_aabb();
                let gx = (b0 - a2).max(a0 - b2).max(0.0);
                let gy = (b1 - a3).max(a1 - b3).max(0.0);
                let gap = gx.hypot(gy);
                // A gap filled by a third piece (a stove between two counters) is no corridor.
                let mid = |lo0: f64, hi0: f64, lo1: f64, hi1: f64| (lo0.max(lo1) + hi0.min(hi1)) / 2.0;
                let m = [mid(a0, a2, b0, b2), mid(a1, a3, b1, b3)];
                let filled = self.furniture.iter().any(|f| f.covers(m, 1e-9));
                // Only pieces facing each other form a corridor; diagonal gaps are corners,
                // and whether the robot gets around them is the reachability check's business.
                let facing = gx == 0.0 || gy == 0.0;
                if facing && gap > TOUCH && gap < MIN_CORRIDOR - 1e-9 && !filled {
                    return Err(format!(
                        "furniture {:?} and {:?} leave a {gap:.2} m gap (touch or leave {MIN_CORRIDOR} m)",
                        a.id, b.id
                    ));
                }
            }
        }
        Ok(())
    }

    /// Points every 5 cm along every start segment.
    pub fn start_points(&self) -> Vec<[f64; 2]> {
        let mut out = Vec::new();
        for s in &self.start_segments {
            let len = (s.to[0] - s.from[0]).hypot(s.to[1] - s.from[1]);
            let n = (len / CELL).ceil().max(1.0) as usize;
            for k in 0..=n {
                let t = k as f64 / n as f64;
                out.push([
                    s.from[0] + t * (s.to[0] - s.from[0]),
                    s.from[1] + t * (s.to[1] - s.from[1]),
                ]);
            }
        }
        out
    }
}

/// Free-space grid for a disc robot: a cell is free when its centre keeps `ROBOT_RADIUS`.
struct Grid {
    nx: usize,
    ny: usize,
    free: Vec<bool>,
}

impl Grid {
    fn new(scene: &Scene) -> Grid {
        let nx = (scene.room.size[0] / CELL).ceil() as usize;
        let ny = (scene.room.size[1] / CELL).ceil() as usize;
        let mut free = Vec::with_capacity(nx * ny);
        for j in 0..ny {
            for i in 0..nx {
                let p = [(i as f64 + 0.5) * CELL, (j as f64 + 0.5) * CELL];
                free.push(scene.clearance(p) >= ROBOT_RADIUS);
            }
        }
        Grid { nx, ny, free }
    }

    fn index(&self, p: [f64; 2]) -> usize {
        let i = ((p[0] / CELL) as usize).min(self.nx - 1);
        let j = ((p[1] / CELL) as usize).min(self.ny - 1);
        j * self.nx + i
    }

    /// Cells reachable from `start` through 4-connected free cells.
    fn flood(&self, start: [f64; 2]) -> Vec<bool> {
        let mut seen = vec![false; self.free.len()];
        let s = self.index(start);
        let mut queue = VecDeque::from([s]);
        seen[s] = true;
        while let Some(c) = queue.pop_front() {
            let (i, j) = (c % self.nx, c / self.nx);
            let mut push = |n: usize| {
                if self.free[n] && !seen[n] {
                    seen[n] = true;
                    queue.push_back(n);
                }
            };
            if i > 0 {
                push(c - 1);
            }
            if i + 1 < self.nx {
                push(c + 1);
            }
            if j > 0 {
                push(c - self.nx);
            }
            if j + 1 < self.ny {
                push(c + self.nx);
            }
        }
        seen
    }
}

#[cfg(test)]
mod tests {
    use crate::catalogue::Catalogue;
    use crate::scene::Scene;

    fn kitchen_a() -> Scene {
        let dir = crate::assets::assets_dir();
        let cat = Catalogue::load(&dir.join("objects.toml")).unwrap();
        Scene::load(&dir.join("scenes/kitchen_a.toml"), &cat).unwrap()
    }

    #[test]
    fn approach_too_close_to_furniture_is_refused() {
        let mut s = kitchen_a();
        s.zones[0].approach[1] = 3.1;
        assert!(s.check_layout().unwrap_err().contains("approach point"));
    }

    #[test]
    fn narrow_corridor_is_refused() {
        let mut s = kitchen_a();
        let table = s.furniture.iter_mut().find(|f| f.id == "table").unwrap();
        table.pose[0] = 1.3;
        assert!(s.check_layout().is_err());
    }

    #[test]
    fn crowded_objects_and_cluttered_zones_are_refused() {
        let cat = Catalogue::load(&crate::assets::assets_dir().join("objects.toml")).unwrap();
        let mut s = kitchen_a();
        s.check_contents(&cat).unwrap();
        s.key_objects[1].offset = [0.1, 0.0];
        assert!(s.check_contents(&cat).unwrap_err().contains("overlap"));
        let mut s = kitchen_a();
        s.background_areas[0].center = s.zones[0].center;
        assert!(s.check_contents(&cat).unwrap_err().contains("zone"));
    }

    #[test]
    fn walled_off_zone_is_unreachable() {
        let mut s = kitchen_a();
        // A long counter across the room cuts the north half off from the southern start segment.
        let mut wall = s.furniture[1].clone();
        wall.id = "barrier".into();
        wall.pose = [2.5, 2.85, 0.0];
        wall.size = [5.0, 0.1, 0.9];
        s.furniture.push(wall);
        s.start_segments.retain(|seg| seg.from[1] < 2.5);
        let err = s.check_reachable().unwrap_err();
        assert!(err.contains("unreachable"), "{err}");
    }
}
