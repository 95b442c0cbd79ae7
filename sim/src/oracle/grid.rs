//! The navigation occupancy grid (paper, §Navigation Module): the room floor cut into square cells,
//! walls and furniture footprints occupied, obstacles inflated by the robot radius R.
//!
//! Inflation is exact per cell: a cell is *free* only if every point of its square lies at least
//! R from every wall and footprint ([`Obstacles::square_clearance`]). It is therefore conservative
//! by at most one cell width, and it is what makes the planner's promise hold: a segment all of
//! whose touched cells are free ([`OccupancyGrid::line_of_sight`]) keeps clearance R everywhere,
//! not just at sampled points.
//!
//! Cell `[ix, iy]` covers world `[ix·res, (ix+1)·res] × [iy·res, (iy+1)·res]`; the grid covers the
//! inner room rectangle (cells sticking out past a wall have zero clearance).

use kitchen_r_core::scene::Scene;

use super::geometry::{Obstacles, P2};

/// A grid cell `[ix, iy]` (column from the west wall, row from the south wall).
pub type Cell = [usize; 2];

/// Slack on cell boundaries in the line-of-sight test: a segment passing within this distance of
/// a cell counts as touching it, so grazing a corner is never treated as free.
const TOUCH_EPS: f64 = 1e-9;

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridParams {
    /// Cell edge length, metres.
    pub resolution: f64,
    /// Robot radius R used for inflation, metres.
    pub robot_radius: f64,
}

impl Default for GridParams {
    fn default() -> Self {
        GridParams {
            resolution: 0.05,
            robot_radius: 0.35,
        }
    }
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GridError {
    #[error("grid resolution must be positive and finite, got {0}")]
    BadResolution(f64),
    #[error("robot radius must be non-negative and finite, got {0}")]
    BadRadius(f64),
    #[error("room size {0:?} gives an empty or huge grid at this resolution")]
    BadSize(P2),
}

/// An RGB8 image, rows top (north) to bottom, ready for any PNG encoder.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GridImage {
    pub width: usize,
    pub height: usize,
    pub rgb: Vec<u8>,
}

#[derive(Debug, Clone)]
pub struct OccupancyGrid {
    params: GridParams,
    width: usize,
    height: usize,
    /// Per cell: the smallest distance from any point of the cell to an obstacle.
    clearance: Vec<f64>,
    obstacles: Obstacles,
}

impl OccupancyGrid {
    pub fn from_scene(scene: &Scene, params: GridParams) -> Result<OccupancyGrid, GridError> {
        Self::from_obstacles(Obstacles::from_scene(scene), params)
    }

    pub fn from_obstacles(obstacles: Obstacles, params: GridParams) -> Result<OccupancyGrid, GridError> {
        let res = params.resolution;
        if !(res.is_finite() && res > 0.0) {
            return Err(GridError::BadResolution(res));
        }
        if !(params.robot_radius.is_finite() && params.robot_radius >= 0.0) {
            return Err(GridError::BadRadius(params.robot_radius));
        }
        let n = |len: f64| (len / res - 1e-9).ceil();
        let (w, h) = (n(obstacles.room[0]), n(obstacles.room[1]));
        if !(w >= 1.0 && h >= 1.0 && w * h <= 1e8) {
            return Err(GridError::BadSize(obstacles.room));
        }
        let (width, height) = (w as usize, h as usize);
        let mut clearance = Vec::with_capacity(width * height);
        for iy in 0..height {
            for ix in 0..width {
                let lo = [ix as f64 * res, iy as f64 * res];
                clearance.push(obstacles.square_clearance(lo, [lo[0] + res, lo[1] + res]));
            }
        }
        Ok(OccupancyGrid {
            params,
            width,
            height,
            clearance,
            obstacles,
        })
    }

    pub fn params(&self) -> GridParams {
        self.params
    }

    pub fn width(&self) -> usize {
        self.width
    }

    pub fn height(&self) -> usize {
        self.height
    }

    pub fn obstacles(&self) -> &Obstacles {
        &self.obstacles
    }

    /// Row-major index of a cell (`iy · width + ix`).
    pub fn index(&self, c: Cell) -> usize {
        c[1] * self.width + c[0]
    }

    pub fn cell_at_index(&self, i: usize) -> Cell {
        [i % self.width, i / self.width]
    }

    /// The cell containing world point `p`, if it lies on the grid.
    pub fn cell_of(&self, p: P2) -> Option<Cell> {
        let res = self.params.resolution;
        let (fx, fy) = ((p[0] / res).floor(), (p[1] / res).floor());
        (fx >= 0.0 && fy >= 0.0 && fx < self.width as f64 && fy < self.height as f64)
            .then_some([fx as usize, fy as usize])
    }

    /// World coordinates of a cell's centre.
    pub fn center(&self, c: Cell) -> P2 {
        let res = self.params.resolution;
        [(c[0] as f64 + 0.5) * res, (c[1] as f64 + 0.5) * res]
    }

    /// Smallest distance from any point of the cell to a wall or footprint.
    pub fn clearance(&self, c: Cell) -> f64 {
        self.clearance[self.index(c)]
    }

    /// Free after inflation: the whole cell keeps clearance R.
    pub fn is_free(&self, c: Cell) -> bool {
        self.is_free_for(c, self.params.robot_radius)
    }

    /// Free for a robot of radius `radius` (the grid keeps exact clearances, so any radius works).
    pub fn is_free_for(&self, c: Cell, radius: f64) -> bool {
        self.clearance(c) >= radius
    }

    /// Touched by a wall or footprint before inflation.
    pub fn is_occupied(&self, c: Cell) -> bool {
        self.clearance(c) <= 0.0
    }

    /// True when every cell the segment `a`–`b` touches (corners included) is free. Segments
    /// leaving the grid are blocked.
    pub fn line_of_sight(&self, a: P2, b: P2) -> bool {
        self.line_of_sight_for(a, b, self.params.robot_radius)
    }

    /// [`OccupancyGrid::line_of_sight`] for a robot of radius `radius`.
    pub fn line_of_sight_for(&self, a: P2, b: P2, radius: f64) -> bool {
        self.for_each_touched_cell(a, b, |c| self.is_free_for(c, radius))
    }

    /// Calls `visit` on a superset of the cells the segment touches, in no particular order,
    /// stopping at the first `false`; returns whether all visits returned `true`.
    pub fn for_each_touched_cell(&self, a: P2, b: P2, mut visit: impl FnMut(Cell) -> bool) -> bool {
        let res = self.params.resolution;
        let (w, h) = (self.width as f64 * res, self.height as f64 * res);
        let (xmin, xmax) = (a[0].min(b[0]), a[0].max(b[0]));
        let (ymin, ymax) = (a[1].min(b[1]), a[1].max(b[1]));
        if !(xmin >= 0.0 && ymin >= 0.0 && xmax <= w && ymax <= h) {
            return false;
        }
        let idx = |v: f64, n: usize| ((v / res).floor().max(0.0) as usize).min(n - 1);
        let dx = b[0] - a[0];
        for ix in idx(xmin - TOUCH_EPS, self.width)..=idx(xmax + TOUCH_EPS, self.width) {
            // The part of the segment inside this column (slightly widened), as a y interval.
            let lo = xmin.max(ix as f64 * res - TOUCH_EPS);
            let hi = xmax.min((ix + 1) as f64 * res + TOUCH_EPS);
            if lo > hi {
                continue;
            }
            let (y0, y1) = if dx == 0.0 {
                (ymin, ymax)
            } else {
                let y = |x: f64| a[1] + ((x - a[0]) / dx).clamp(0.0, 1.0) * (b[1] - a[1]);
                (y(lo).min(y(hi)), y(lo).max(y(hi)))
            };
            for iy in idx(y0 - TOUCH_EPS, self.height)..=idx(y1 + TOUCH_EPS, self.height) {
                if !visit([ix, iy]) {
                    return false;
                }
            }
        }
        true
    }

    /// The grid as an image for debugging: obstacles dark, inflated margin grey, free floor white,
    /// `path` (world points, joined in order) red. North is up.
    pub fn render_rgb(&self, path: &[P2]) -> GridImage {
        let mut rgb = vec![0u8; self.width * self.height * 3];
        let mut put = |c: Cell, px: [u8; 3]| {
            let row = self.height - 1 - c[1];
            let at = (row * self.width + c[0]) * 3;
            rgb[at..at + 3].copy_from_slice(&px);
        };
        for i in 0..self.clearance.len() {
            let c = self.cell_at_index(i);
            let px = if self.is_occupied(c) {
                [40, 40, 40]
            } else if !self.is_free(c) {
                [170, 170, 170]
            } else {
                [255, 255, 255]
            };
            put(c, px);
        }
        for seg in path.windows(2) {
            self.for_each_touched_cell(seg[0], seg[1], |c| {
                put(c, [220, 30, 30]);
                true
            });
        }
        GridImage {
            width: self.width,
            height: self.height,
            rgb,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::oracle::geometry::rect_corners;

    fn grid() -> OccupancyGrid {
        let obstacles = Obstacles {
            room: [2.0, 1.0],
            boxes: vec![rect_corners([1.0, 0.5], [0.1, 0.1], 0.0)],
        };
        let params = GridParams {
            resolution: 0.1,
            robot_radius: 0.2,
        };
        OccupancyGrid::from_obstacles(obstacles, params).unwrap()
    }

    #[test]
    fn world_cell_round_trip() {
        let g = grid();
        assert_eq!((g.width(), g.height()), (20, 10));
        assert_eq!(g.cell_of([0.05, 0.95]), Some([0, 9]));
        assert_eq!(g.cell_of([2.0, 0.5]), None);
        assert_eq!(g.cell_of([-0.01, 0.5]), None);
        let c = [7, 3];
        assert_eq!(g.cell_of(g.center(c)), Some(c));
        assert_eq!(g.cell_at_index(g.index(c)), c);
    }

    #[test]
    fn obstacles_and_inflation() {
        let g = grid();
        assert!(g.is_occupied([9, 4]) && g.is_occupied([10, 5]));
        assert!(g.is_occupied([0, 3]), "cells on the wall line touch the wall");
        // Cell [12, 4] spans x 1.2..1.3: 0.1 from the box, inside R = 0.2.
        assert!(!g.is_occupied([12, 4]) && !g.is_free([12, 4]));
        // Cell [14, 4] starts 0.3 > R from the box edge at x = 1.1; column 1 is 0.1 from the wall.
        assert!(g.is_free([14, 4]));
        assert!(!g.is_free([1, 4]) && g.is_free([3, 4]));
    }

    #[test]
    fn line_of_sight_is_conservative_at_corners() {
        let g = grid();
        assert!(g.line_of_sight([0.25, 0.25], [0.65, 0.25]));
        assert!(!g.line_of_sight([0.25, 0.5], [1.75, 0.5]), "through the box");
        // Grazing the corner shared by a free and a non-free cell touches both.
        let mut touched = Vec::new();
        g.for_each_touched_cell([0.25, 0.25], [0.45, 0.45], |c| {
            touched.push(c);
            true
        });
        for c in [[2, 2], [3, 3], [2, 3], [3, 2], [4, 4]] {
            assert!(touched.contains(&c), "{c:?} not in {touched:?}");
        }
        assert!(
            !g.line_of_sight([0.1, 0.5], [1.9, 0.5]),
            "leaves free space near the walls"
        );
        assert!(!g.line_of_sight([0.5, 0.5], [2.5, 0.5]), "leaves the grid");
    }

    #[test]
    fn render_marks_cells() {
        let g = grid();
        let img = g.render_rgb(&[[0.25, 0.25], [0.65, 0.25]]);
        assert_eq!(img.rgb.len(), 20 * 10 * 3);
        let px = |ix: usize, iy: usize| {
            let at = ((9 - iy) * 20 + ix) * 3;
            [img.rgb[at], img.rgb[at + 1], img.rgb[at + 2]]
        };
        assert_eq!(px(9, 4), [40, 40, 40]);
        assert_eq!(px(4, 2), [220, 30, 30]);
        assert_eq!(px(15, 6), [255, 255, 255]);
    }
}
