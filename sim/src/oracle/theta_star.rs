//! Any-angle path planning on the inflated occupancy grid (paper, §Navigation Module): Theta*
//! (Daniel et al., 2010), plus an 8-connected A* used as a reference in tests.
//!
//! Both searches run over cell centres with 8-connected moves; a diagonal move needs both cells
//! it cuts past to be free, so every grid move passes [`OccupancyGrid::line_of_sight`]. Theta*
//! additionally links a cell straight to its grandparent whenever that segment has line of sight,
//! and by the triangle inequality never returns a longer path than A* over the same grid.
//!
//! The returned polyline **excludes the start** and ends at the goal: it is the list of
//! waypoints the follower drives to. The search runs between the cells of the start and goal; a
//! start or goal whose cell is not free is first moved to the nearest free cell centre within
//! [`PlannerParams::snap_radius`] ([`PlanError::StartBlocked`] / [`PlanError::GoalBlocked`] when
//! there is none). The exact start and goal are then joined to their cell centres whenever that
//! short segment keeps clearance R (always so on a free cell, whose whole square keeps R), so a
//! robot gets a path that keeps clearance R from where it actually stands to exactly where it is
//! sent; when they cannot be joined the path starts or ends at the cell centre and
//! [`PlannedPath`] says so.
//!
//! With [`PlannerParams::clearance_margin`] > 0 the planner first plans as if the robot were that
//! much wider (the exact endpoints must then be joinable at R) and falls back to plain R. The
//! paper's follower cuts corners, so this margin is what keeps the *driven* path clear.
//!
//! Everything is indexed by cell (vectors, a binary heap keyed by `(f, −g, index)`), so ties break
//! the same way on every run and platform.

use std::cmp::{Ordering, Reverse};
use std::collections::BinaryHeap;

use super::geometry::{P2, dist};
use super::grid::{Cell, OccupancyGrid};

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlannerParams {
    /// How far (metres, to the cell centre) a blocked start or goal may be moved to a free cell.
    pub snap_radius: f64,
    /// Most waypoints a path may have (paper: the controller stores up to 100).
    pub max_waypoints: usize,
    /// Extra clearance tried first: plan as if the robot were this much wider, falling back to
    /// plain R when that finds no path or cannot join the exact endpoints. The paper's follower
    /// switches waypoints 0.35 m early and so cuts corners by up to ~0.15 m; this margin keeps the
    /// driven (not just the planned) path clear of the furniture: with 0.1 m the robot's centre
    /// stays ≥ 0.31 m from every footprint in all committed scenes (the body radius is 0.30 m),
    /// against 0.20 m without. 0 = the paper's planner alone.
    pub clearance_margin: f64,
}

impl Default for PlannerParams {
    fn default() -> Self {
        PlannerParams {
            snap_radius: 0.3,
            max_waypoints: 100,
            clearance_margin: 0.1,
        }
    }
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlanError {
    #[error("start {0:?} is off the map or has no free cell within the snap radius")]
    StartBlocked(P2),
    #[error("goal {0:?} is off the map or has no free cell within the snap radius")]
    GoalBlocked(P2),
    #[error("no collision-free path from {start:?} to {goal:?}")]
    Unreachable { start: P2, goal: P2 },
    #[error("the path needs {0} waypoints, more than the limit")]
    TooManyWaypoints(usize),
}

#[derive(Debug, Clone, PartialEq)]
pub struct PlannedPath {
    /// Waypoints in world metres, start excluded, last = goal (or the snapped goal).
    pub waypoints: Vec<P2>,
    /// The point the path starts from: the requested start, or its snapped cell centre.
    pub start: P2,
    pub start_snapped: bool,
    pub goal_snapped: bool,
}

impl PlannedPath {
    /// Length of the polyline from [`PlannedPath::start`] through every waypoint.
    pub fn length(&self) -> f64 {
        let mut prev = self.start;
        let mut total = 0.0;
        for &w in &self.waypoints {
            total += dist(prev, w);
            prev = w;
        }
        total
    }
}

/// Theta*: an any-angle path from `start` to `goal`.
pub fn theta_star(
    grid: &OccupancyGrid,
    start: P2,
    goal: P2,
    params: &PlannerParams,
) -> Result<PlannedPath, PlanError> {
    plan(grid, start, goal, params, true)
}

/// 8-connected A* over cell centres, for comparison: the same endpoints handling as
/// [`theta_star`] but no shortcuts, and no waypoint limit.
pub fn astar8(
    grid: &OccupancyGrid,
    start: P2,
    goal: P2,
    params: &PlannerParams,
) -> Result<PlannedPath, PlanError> {
    let params = PlannerParams {
        max_waypoints: usize::MAX,
        ..*params
    };
    plan(grid, start, goal, &params, false)
}

fn plan(
    grid: &OccupancyGrid,
    start: P2,
    goal: P2,
    params: &PlannerParams,
    any_angle: bool,
) -> Result<PlannedPath, PlanError> {
    let r = grid.params().robot_radius;
    if params.clearance_margin > 0.0
        && let Ok(path) = plan_for(grid, start, goal, params, any_angle, r + params.clearance_margin)
    {
        return Ok(path);
    }
    plan_for(grid, start, goal, params, any_angle, r)
}

/// Plans for a robot of radius `rho` ≥ R. With `rho` > R, both exact endpoints must be joined
/// (at clearance R) to the wider corridor, otherwise the caller falls back to R.
fn plan_for(
    grid: &OccupancyGrid,
    start: P2,
    goal: P2,
    params: &PlannerParams,
    any_angle: bool,
    rho: f64,
) -> Result<PlannedPath, PlanError> {
    let r = grid.params().robot_radius;
    let reach = params.snap_radius + (rho - r);
    let s = snap(grid, start, reach, rho).ok_or(PlanError::StartBlocked(start))?;
    let g = snap(grid, goal, reach, rho).ok_or(PlanError::GoalBlocked(goal))?;
    let cells = search(grid, s, g, any_angle, rho).ok_or(PlanError::Unreachable { start, goal })?;
    let mut pts: Vec<P2> = cells.iter().map(|&c| grid.center(c)).collect();
    // Join the exact endpoints when the short segment to their cell centre keeps clearance R
    // (always so when they lie on a free cell, since the segment stays inside it).
    let joins = |p: P2, c: P2| grid.obstacles().segment_clearance(p, c) >= r;
    let (start_joined, goal_joined) = (joins(start, pts[0]), joins(goal, pts[pts.len() - 1]));
    if rho > r && !(start_joined && goal_joined) {
        return Err(PlanError::Unreachable { start, goal });
    }
    if start_joined {
        pts.insert(0, start);
    }
    if goal_joined {
        pts.push(goal);
    }
    if any_angle {
        pts = shortcut(grid, &pts, rho);
    } else {
        pts.dedup();
    }
    let waypoints = pts[1..].to_vec();
    if waypoints.len() > params.max_waypoints {
        return Err(PlanError::TooManyWaypoints(waypoints.len()));
    }
    Ok(PlannedPath {
        waypoints,
        start: pts[0],
        start_snapped: !start_joined,
        goal_snapped: !goal_joined,
    })
}

/// The point's own cell when free for `rho`, else the free cell whose centre is nearest within
/// `reach` (ties to the lower index).
fn snap(grid: &OccupancyGrid, p: P2, reach: f64, rho: f64) -> Option<Cell> {
    let c = grid.cell_of(p)?;
    if grid.is_free_for(c, rho) {
        return Some(c);
    }
    let n = (reach / grid.params().resolution).ceil() as isize + 1;
    let mut best: Option<(f64, usize)> = None;
    for dy in -n..=n {
        for dx in -n..=n {
            let (x, y) = (c[0] as isize + dx, c[1] as isize + dy);
            if x < 0 || y < 0 || x as usize >= grid.width() || y as usize >= grid.height() {
                continue;
            }
            let cell = [x as usize, y as usize];
            let (d, i) = (dist(grid.center(cell), p), grid.index(cell));
            let better = best.is_none_or(|(bd, bi)| d < bd || (d == bd && i < bi));
            if d <= reach && grid.is_free_for(cell, rho) && better {
                best = Some((d, i));
            }
        }
    }
    best.map(|(_, i)| grid.cell_at_index(i))
}

/// Greedy string pulling: from each kept point jump to the farthest later point in sight. Never
/// lengthens the path (triangle inequality) and keeps every segment in line of sight.
fn shortcut(grid: &OccupancyGrid, pts: &[P2], rho: f64) -> Vec<P2> {
    let mut out = vec![pts[0]];
    let mut i = 0;
    while i + 1 < pts.len() {
        let mut j = pts.len() - 1;
        while j > i + 1 && !grid.line_of_sight_for(pts[i], pts[j], rho) {
            j -= 1;
        }
        if dist(pts[j], pts[i]) > 0.0 {
            out.push(pts[j]);
        }
        i = j;
    }
    out
}

/// Heap entry ordered so that `BinaryHeap` pops the smallest `f`, then the largest `g`, then the
/// smallest index: a total order that does not depend on insertion order.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Entry {
    f: f64,
    g: f64,
    index: usize,
}

impl Eq for Entry {}

impl Ord for Entry {
    fn cmp(&self, other: &Self) -> Ordering {
        (Reverse(self.f.to_bits()), self.g.to_bits(), Reverse(self.index)).cmp(&(
            Reverse(other.f.to_bits()),
            other.g.to_bits(),
            Reverse(other.index),
        ))
    }
}

impl PartialOrd for Entry {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

const MOVES: [(isize, isize); 8] = [
    (1, 0),
    (0, 1),
    (-1, 0),
    (0, -1),
    (1, 1),
    (-1, 1),
    (-1, -1),
    (1, -1),
];

/// Cells from `s` to `g` inclusive, or `None` when `g` is unreachable. Costs and the Euclidean
/// heuristic are measured between cell centres (non-negative floats, so their bit patterns order
/// like their values).
fn search(grid: &OccupancyGrid, s: Cell, g: Cell, any_angle: bool, rho: f64) -> Option<Vec<Cell>> {
    let n = grid.width() * grid.height();
    let mut cost = vec![f64::INFINITY; n];
    let mut parent = vec![usize::MAX; n];
    let mut closed = vec![false; n];
    let mut open = BinaryHeap::new();
    let (si, gi) = (grid.index(s), grid.index(g));
    let goal_pt = grid.center(g);
    cost[si] = 0.0;
    parent[si] = si;
    open.push(Entry {
        f: dist(grid.center(s), goal_pt),
        g: 0.0,
        index: si,
    });
    while let Some(Entry { g: gcost, index, .. }) = open.pop() {
        if closed[index] || gcost > cost[index] {
            continue;
        }
        if index == gi {
            return Some(trace(grid, &parent, si, gi));
        }
        closed[index] = true;
        let c = grid.cell_at_index(index);
        for (dx, dy) in MOVES {
            let Some(nb) = neighbour(grid, c, dx, dy, rho) else {
                continue;
            };
            let ni = grid.index(nb);
            if closed[ni] {
                continue;
            }
            let npt = grid.center(nb);
            let p = parent[index];
            let pp = grid.center(grid.cell_at_index(p));
            let (from, base) = if any_angle && p != index && grid.line_of_sight_for(pp, npt, rho) {
                (p, cost[p] + dist(pp, npt))
            } else {
                (index, cost[index] + dist(grid.center(c), npt))
            };
            if base < cost[ni] {
                cost[ni] = base;
                parent[ni] = from;
                open.push(Entry {
                    f: base + dist(npt, goal_pt),
                    g: base,
                    index: ni,
                });
            }
        }
    }
    None
}

/// The free neighbour in direction `(dx, dy)`; diagonal moves may not cut a corner.
fn neighbour(grid: &OccupancyGrid, c: Cell, dx: isize, dy: isize, rho: f64) -> Option<Cell> {
    let at = |dx: isize, dy: isize| -> Option<Cell> {
        let (x, y) = (c[0] as isize + dx, c[1] as isize + dy);
        let inside = x >= 0 && y >= 0 && (x as usize) < grid.width() && (y as usize) < grid.height();
        inside
            .then_some([x as usize, y as usize])
            .filter(|&n| grid.is_free_for(n, rho))
    };
    if dx != 0 && dy != 0 {
        at(dx, 0)?;
        at(0, dy)?;
    }
    at(dx, dy)
}

fn trace(grid: &OccupancyGrid, parent: &[usize], si: usize, gi: usize) -> Vec<Cell> {
    let mut out = vec![grid.cell_at_index(gi)];
    let mut i = gi;
    while i != si {
        i = parent[i];
        out.push(grid.cell_at_index(i));
    }
    out.reverse();
    out
}
