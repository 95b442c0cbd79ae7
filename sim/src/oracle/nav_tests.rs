//! Planner tests over every committed scene (`assets/scenes/*.toml`, loaded at test time so new
//! scenes are covered as soon as they land).

use kitchen_r_core::assets::assets_dir;
use kitchen_r_core::catalogue::Catalogue;
use kitchen_r_core::scene::Scene;

use super::geometry::{Obstacles, P2, dist, rect_corners};
use super::grid::{GridParams, OccupancyGrid};
use super::theta_star::{PlanError, PlannedPath, PlannerParams, astar8, theta_star};

pub(crate) fn scenes() -> Vec<Scene> {
    let dir = assets_dir();
    let cat = Catalogue::load(&dir.join("objects.toml")).unwrap();
    let scenes = Scene::load_all(&dir.join("scenes"), &cat).unwrap();
    assert!(!scenes.is_empty());
    scenes
}

/// Where a navigation task may begin: five points along each start segment (with its heading)
/// and every zone's approach pose (the robot moves on from one zone to the next).
pub(crate) fn start_poses(scene: &Scene) -> Vec<[f64; 3]> {
    let mut out = Vec::new();
    for s in &scene.start_segments {
        for k in 0..=4 {
            let t = k as f64 / 4.0;
            let p = [
                s.from[0] + t * (s.to[0] - s.from[0]),
                s.from[1] + t * (s.to[1] - s.from[1]),
            ];
            out.push([p[0], p[1], s.heading]);
        }
    }
    out.extend(scene.zones.iter().map(|z| z.approach));
    out
}

/// Clearance computed independently of `geometry`: distance to each footprint in its own frame.
fn naive_clearance(scene: &Scene, p: P2) -> f64 {
    let [rx, ry] = scene.room.size;
    let mut best = p[0].min(p[1]).min(rx - p[0]).min(ry - p[1]);
    for f in &scene.furniture {
        let [cx, cy, yaw] = f.pose;
        let (s, c) = yaw.sin_cos();
        let (dx, dy) = (p[0] - cx, p[1] - cy);
        let (lx, ly) = (c * dx + s * dy, -s * dx + c * dy);
        let [sx, sy, _] = f.scaled_size();
        let (ox, oy) = ((lx.abs() - sx / 2.0).max(0.0), (ly.abs() - sy / 2.0).max(0.0));
        best = best.min(ox.hypot(oy));
    }
    best
}

/// Samples every segment (start included) every 5 mm and returns the smallest clearance.
fn path_clearance(scene: &Scene, path: &PlannedPath) -> f64 {
    let mut prev = path.start;
    let mut best = f64::INFINITY;
    for &w in &path.waypoints {
        let n = (dist(prev, w) / 0.005).ceil().max(1.0) as usize;
        for k in 0..=n {
            let t = k as f64 / n as f64;
            best = best.min(naive_clearance(
                scene,
                [prev[0] + t * (w[0] - prev[0]), prev[1] + t * (w[1] - prev[1])],
            ));
        }
        prev = w;
    }
    best
}

/// splitmix64: a tiny deterministic generator so the test needs no extra dependency.
struct Rng(u64);

impl Rng {
    fn unit(&mut self) -> f64 {
        let z = crate::seeds::splitmix(self.0);
        self.0 = self.0.wrapping_add(crate::seeds::GOLDEN_GAMMA);
        z as f64 / u64::MAX as f64
    }

    fn free_point(&mut self, grid: &OccupancyGrid, room: P2) -> P2 {
        loop {
            let p = [self.unit() * room[0], self.unit() * room[1]];
            if grid.cell_of(p).is_some_and(|c| grid.is_free(c)) {
                return p;
            }
        }
    }
}

#[test]
fn theta_star_keeps_clearance_and_is_no_longer_than_grid_astar() {
    // The length bound holds for the plain planner (no extra margin) against A* on the same grid.
    let params = PlannerParams {
        clearance_margin: 0.0,
        ..PlannerParams::default()
    };
    for scene in scenes() {
        let grid = OccupancyGrid::from_scene(&scene, GridParams::default()).unwrap();
        let r = grid.params().robot_radius;
        let mut rng = Rng(0x5eed ^ scene.id.len() as u64);
        let mut planned = 0;
        for _ in 0..60 {
            let (a, b) = (
                rng.free_point(&grid, scene.room.size),
                rng.free_point(&grid, scene.room.size),
            );
            let (theta, grid_path) = match (theta_star(&grid, a, b, &params), astar8(&grid, a, b, &params)) {
                (Ok(t), Ok(g)) => (t, g),
                (Err(PlanError::Unreachable { .. }), Err(PlanError::Unreachable { .. })) => continue,
                other => panic!("{}: {a:?} -> {b:?}: planners disagree: {other:?}", scene.id),
            };
            planned += 1;
            assert_eq!(theta.waypoints.last(), Some(&b));
            assert!(theta.waypoints.len() <= params.max_waypoints);
            let c = path_clearance(&scene, &theta);
            assert!(c >= r - 1e-9, "{}: {a:?} -> {b:?}: clearance {c} < R", scene.id);
            assert!(path_clearance(&scene, &grid_path) >= r - 1e-9);
            let (lt, lg) = (theta.length(), grid_path.length());
            assert!(lt <= lg + 1e-9, "{}: theta* {lt} longer than A* {lg}", scene.id);
            assert_eq!(
                theta_star(&grid, a, b, &params).unwrap(),
                theta,
                "not deterministic"
            );
        }
        assert!(
            planned >= 30,
            "{}: only {planned} of 60 random pairs connected",
            scene.id
        );
    }
}

#[test]
fn every_zone_is_reachable_from_every_start_segment_and_every_other_zone() {
    let params = PlannerParams::default();
    for scene in scenes() {
        // The default resolution and a coarse one (the resolution is a config value).
        for resolution in [0.05, 0.1] {
            let grid = OccupancyGrid::from_scene(
                &scene,
                GridParams {
                    resolution,
                    ..GridParams::default()
                },
            )
            .unwrap();
            for a in start_poses(&scene).iter().map(|p| [p[0], p[1]]) {
                for z in &scene.zones {
                    let goal = [z.approach[0], z.approach[1]];
                    if dist(a, goal) == 0.0 {
                        continue;
                    }
                    let what = format!("{} at {resolution} m: {a:?} to zone {}", scene.id, z.color);
                    let path = theta_star(&grid, a, goal, &params).unwrap_or_else(|e| panic!("{what}: {e}"));
                    assert_eq!(path.waypoints.last(), Some(&goal), "{what}");
                    assert!(!path.start_snapped && !path.goal_snapped, "{what}");
                    assert!(
                        path_clearance(&scene, &path) >= grid.params().robot_radius - 1e-9,
                        "{what}"
                    );
                }
            }
        }
    }
}

fn corridor(wall: bool) -> OccupancyGrid {
    let mut boxes = vec![rect_corners([2.0, 0.4], [0.1, 0.4], 0.0)];
    if wall {
        boxes.push(rect_corners([2.0, 1.6], [0.1, 0.4], 0.0));
    }
    OccupancyGrid::from_obstacles(
        Obstacles {
            room: [4.0, 2.0],
            boxes,
        },
        GridParams::default(),
    )
    .unwrap()
}

#[test]
fn straight_line_when_in_sight_and_detour_otherwise() {
    let g = corridor(false);
    let p = theta_star(&g, [0.5, 1.5], [3.5, 1.5], &PlannerParams::default()).unwrap();
    assert_eq!(p.waypoints, vec![[3.5, 1.5]]);
    assert_eq!(p.start, [0.5, 1.5]);
    let p = theta_star(&g, [0.5, 0.5], [3.5, 0.5], &PlannerParams::default()).unwrap();
    assert!(
        p.waypoints.len() >= 3 && p.waypoints.iter().any(|w| w[1] > 1.1),
        "{p:?}"
    );
}

#[test]
fn blocked_and_unreachable_endpoints_are_reported() {
    let g = corridor(true);
    let params = PlannerParams::default();
    assert_eq!(
        theta_star(&g, [2.0, 0.3], [3.5, 1.0], &params),
        Err(PlanError::StartBlocked([2.0, 0.3]))
    );
    assert_eq!(
        theta_star(&g, [0.5, 1.0], [5.0, 1.0], &params),
        Err(PlanError::GoalBlocked([5.0, 1.0]))
    );
    assert!(matches!(
        theta_star(&g, [0.5, 1.0], [3.5, 1.0], &params),
        Err(PlanError::Unreachable { .. })
    ));
    let tight = PlannerParams {
        max_waypoints: 0,
        ..params
    };
    assert_eq!(
        theta_star(&corridor(false), [0.5, 1.5], [3.5, 1.5], &tight),
        Err(PlanError::TooManyWaypoints(1))
    );
}

#[test]
fn endpoints_near_obstacles_snap_to_the_nearest_free_cell() {
    let g = corridor(false);
    // 0.3 m from the west wall: inside the inflated margin but a free cell lies 0.075 m away.
    let p = theta_star(&g, [0.3, 1.5], [3.7, 1.5], &PlannerParams::default()).unwrap();
    assert!(p.start_snapped && p.goal_snapped);
    assert!(dist(p.start, [0.3, 1.5]) <= 0.1 && g.is_free(g.cell_of(p.start).unwrap()));
    assert!(dist(*p.waypoints.last().unwrap(), [3.7, 1.5]) <= 0.1);
}
