//! One test per rule of the paper's path follower, on constructed poses, plus closed-loop runs
//! with an ideal unicycle through planned paths in every committed scene.

use super::follow::{FollowParams, FollowStatus, PathFollower, Pose2, wrap};
use super::geometry::dist;
use super::grid::{GridParams, OccupancyGrid};
use super::nav_tests::{scenes, start_poses};
use super::theta_star::{PlannerParams, theta_star};

const EPS: f64 = 1e-12;

/// A follower whose only waypoint lies 5 m away at bearing `phi` from the origin, heading 0.
fn aimed(phi: f64) -> (PathFollower, Pose2) {
    let f = PathFollower::new(
        vec![[5.0 * phi.cos(), 5.0 * phi.sin()]],
        0.0,
        FollowParams::default(),
    );
    (f, [0.0, 0.0, 0.0])
}

#[test]
fn waypoint_advances_only_inside_0_35_m() {
    let path = vec![[1.0, 0.0], [2.0, 0.0], [3.0, 0.0]];
    let mut f = PathFollower::new(path.clone(), 0.0, FollowParams::default());
    f.step([0.64, 0.0, 0.0]);
    assert_eq!(f.waypoint_index(), 0, "0.36 m away: not reached");
    f.step([0.66, 0.0, 0.0]);
    assert_eq!(f.waypoint_index(), 1, "0.34 m away: reached");
    // Two waypoints inside the radius at once are both passed; the goal never is.
    let mut f = PathFollower::new(
        vec![[0.1, 0.0], [0.2, 0.0], [0.3, 0.0]],
        0.0,
        FollowParams::default(),
    );
    f.step([0.0, 0.0, 0.0]);
    assert_eq!(f.waypoint_index(), 2);
}

#[test]
fn heading_error_is_wrapped_to_pi() {
    // Waypoint almost straight behind along -x, robot heading almost -π: α − θ ≈ 2π − 0.03.
    let mut f = PathFollower::new(vec![[-5.0, 0.05]], 0.0, FollowParams::default());
    let theta = -std::f64::consts::PI + 0.02;
    let (v, w, s) = f.step([0.0, 0.0, theta]);
    let alpha = 0.05f64.atan2(-5.0);
    assert!((w - wrap(alpha - theta)).abs() < EPS && w.abs() < 0.1, "ω = {w}");
    assert!(v > 0.0 && s == FollowStatus::Driving);
    assert!((wrap(3.0 * std::f64::consts::PI) - std::f64::consts::PI).abs() < 1e-9);
}

#[test]
fn aligned_ramps_v_by_acc_dt_to_max_v_with_omega_equal_theta_e() {
    let p = FollowParams::default();
    let (mut f, pose) = aimed(0.05);
    for k in 1..=60 {
        let (v, w, s) = f.step(pose);
        let want = (k as f64 * p.acc_v * p.dt).min(p.max_v);
        assert!((v - want).abs() < 1e-9, "step {k}: v = {v}, want {want}");
        assert!((w - 0.05).abs() < 1e-9 && s == FollowStatus::Driving);
    }
    assert!((f.step(pose).0 - 0.18).abs() < EPS);
}

#[test]
fn gain_table_by_angular_error_band() {
    for (theta_e, gain) in [
        (0.1 + 1e-6, 0.9),
        (0.2, 0.9),
        (0.38 - 1e-6, 0.9),
        (0.38 + 1e-6, 0.85),
        (0.6, 0.85),
        (0.7 + 1e-6, 0.8),
        (0.9, 0.8),
        (1.0 + 1e-6, 0.75),
        (1.25 - 1e-6, 0.75),
    ] {
        for sign in [1.0, -1.0] {
            let (mut f, pose) = aimed(sign * theta_e);
            let (v, w, s) = f.step(pose);
            assert!((w - gain * sign * theta_e).abs() < 1e-9, "θe {theta_e}: ω = {w}");
            assert!(v > 0.0 && s == FollowStatus::Driving);
        }
    }
}

#[test]
fn linear_speed_limit_is_reduced_band_by_band() {
    let p = FollowParams::default();
    for (theta_e, scale) in [(0.05, 1.0), (0.2, 0.75), (0.5, 0.5), (0.8, 0.3), (1.1, 0.15)] {
        let (mut f, pose) = aimed(theta_e);
        let v = (0..100).map(|_| f.step(pose).0).fold(0.0, f64::max);
        assert!((v - p.max_v * scale).abs() < 1e-9, "θe {theta_e}: top speed {v}");
    }
    // Entering a slower band drops v to that band's limit at once.
    let (mut f, pose) = aimed(0.0);
    (0..60).for_each(|_| {
        f.step(pose);
    });
    assert!((f.step([0.0, 0.0, -0.8]).0 - 0.3 * p.max_v).abs() < 1e-9);
}

#[test]
fn turns_in_place_from_1_25_rad_with_omega_clamped() {
    for (theta_e, w_want) in [(1.25 + 1e-6, 0.7), (2.0, 0.7), (-1.3, -0.7), (3.0, 0.7)] {
        let (mut f, pose) = aimed(theta_e);
        let (v, w, s) = f.step(pose);
        assert_eq!((v, s), (0.0, FollowStatus::Turning), "θe {theta_e}");
        assert!((w - w_want).abs() < EPS, "θe {theta_e}: ω = {w}");
    }
    // Moving fast, then a large error: forward motion stops at once.
    let (mut f, pose) = aimed(0.0);
    (0..60).for_each(|_| {
        f.step(pose);
    });
    assert_eq!(f.step([0.0, 0.0, 2.0]).0, 0.0);
}

/// The follower's speed after driving aligned at full speed, then one step at `d` from a goal.
fn speed_at(path: Vec<[f64; 2]>, d_goal_x: f64) -> f64 {
    let mut f = PathFollower::new(path, 0.0, FollowParams::default());
    (0..60).for_each(|_| {
        f.step([0.0, 0.0, 0.0]);
    });
    f.step([d_goal_x, 0.0, 0.0]).0
}

#[test]
fn decelerates_near_the_goal_on_the_final_segment_only() {
    let p = FollowParams::default();
    // Final segment, goal at x = 10.
    assert!(
        (speed_at(vec![[10.0, 0.0]], 8.6) - p.max_v).abs() < EPS,
        "1.4 m: the cap is above max_v"
    );
    let mut last = p.max_v;
    for d in [0.4, 0.3, 0.2, 0.15, 0.1, 0.095] {
        let v = speed_at(vec![[10.0, 0.0]], 10.0 - d);
        let cap = (2.0 * p.acc_v * (d - p.arrive)).sqrt().max(p.min_v);
        assert!((v - cap.min(p.max_v)).abs() < 1e-9, "{d} m: v = {v}, cap {cap}");
        assert!(v <= last && v >= p.min_v);
        last = v;
    }
    // Same distance to the active waypoint but more path after it: no deceleration.
    assert!((speed_at(vec![[10.0, 0.0], [10.0, 5.0]], 9.64) - p.max_v).abs() < EPS);
    // One step at the slowest speed cannot jump across the arrival circle.
    assert!(p.min_v * p.dt < 2.0 * p.arrive);
}

#[test]
fn arrival_at_0_09_m_then_final_heading_at_0_15_rad_per_s() {
    let goal = [2.0, 1.0];
    let mut f = PathFollower::new(vec![goal], 1.0, FollowParams::default());
    let (v, _, s) = f.step([2.0 - 0.091, 1.0, 0.0]);
    assert!(v > 0.0 && s == FollowStatus::Driving, "0.091 m: not yet arrived");
    assert_eq!(
        f.step([2.0 - 0.089, 1.0, 0.5]),
        (0.0, 0.15, FollowStatus::FinalHeading)
    );
    assert_eq!(f.step([2.0, 1.0, 1.5]), (0.0, -0.15, FollowStatus::FinalHeading));
    // Once arrived, drifting back out of the circle does not restart driving.
    assert_eq!(f.step([1.8, 1.0, 1.5]), (0.0, -0.15, FollowStatus::FinalHeading));
    assert_eq!(f.step([2.0, 1.0, 1.0 + 0.099]), (0.0, 0.0, FollowStatus::Done));
    assert_eq!(f.step([2.0, 1.0, 0.0]), (0.0, 0.0, FollowStatus::Done));
}

/// Exact integration of a unicycle under constant `(v, ω)` for `dt`.
pub(crate) fn unicycle(p: Pose2, v: f64, w: f64, dt: f64) -> Pose2 {
    if w.abs() < 1e-12 {
        return [p[0] + v * dt * p[2].cos(), p[1] + v * dt * p[2].sin(), p[2]];
    }
    let th = p[2] + w * dt;
    [
        p[0] + v / w * (th.sin() - p[2].sin()),
        p[1] - v / w * (th.cos() - p[2].cos()),
        wrap(th),
    ]
}

/// A robot's response to one control step: the pose after `dt` under the commands `(v, ω)`.
pub(crate) type Plant<'a> = &'a mut dyn FnMut(Pose2, f64, f64) -> Pose2;

/// Plans from `start` to `goal` and drives the path through `plant`, then lets the robot settle
/// for 0.5 s of zero commands; returns the final pose, the steps taken and the smallest clearance
/// of the base centre from any obstacle along the way.
pub(crate) fn drive(
    grid: &OccupancyGrid,
    start: Pose2,
    goal: Pose2,
    params: FollowParams,
    plant: Plant,
) -> (Pose2, usize, f64) {
    let planner = PlannerParams::default();
    let path = theta_star(grid, [start[0], start[1]], [goal[0], goal[1]], &planner).unwrap();
    let mut f = PathFollower::new(path.waypoints, goal[2], params);
    let (mut pose, mut steps, mut clearance) = (start, 0, f64::INFINITY);
    let mut done = 0;
    // 1200 steps = the 120 s a task may take (paper, METRICS).
    while steps < 1200 && done < 5 {
        let (v, w, s) = f.step(pose);
        assert!((0.0..=params.max_v + EPS).contains(&v));
        if s == FollowStatus::Done {
            done += 1;
        }
        pose = plant(pose, v, w);
        clearance = clearance.min(grid.obstacles().point_clearance([pose[0], pose[1]]));
        steps += 1;
    }
    (pose, steps - done, clearance)
}

/// The checks every closed-loop run must pass: done within 120 s, within 0.10 m of the approach
/// point, heading within 0.1 rad, and the base (body radius 0.30 m in the shipped robot) never
/// touching a footprint or wall although the follower cuts corners.
pub(crate) fn check_arrival(what: &str, goal: Pose2, (pose, steps, clearance): (Pose2, usize, f64)) {
    assert!(steps < 1200, "{what}: not done in 120 s");
    let d = dist([pose[0], pose[1]], [goal[0], goal[1]]);
    assert!(d <= 0.10, "{what}: ended {d} m from the approach point");
    assert!(wrap(goal[2] - pose[2]).abs() < 0.1, "{what}: heading {}", pose[2]);
    assert!(
        clearance >= 0.30,
        "{what}: base centre came within {clearance} m of an obstacle"
    );
}

#[test]
fn closed_loop_reaches_every_approach_point_with_an_ideal_unicycle() {
    let params = FollowParams::default();
    for scene in scenes() {
        let grid = OccupancyGrid::from_scene(&scene, GridParams::default()).unwrap();
        for start in start_poses(&scene) {
            for zone in &scene.zones {
                if dist([start[0], start[1]], [zone.approach[0], zone.approach[1]]) == 0.0 {
                    continue;
                }
                let mut plant = |p: Pose2, v: f64, w: f64| unicycle(p, v, w, params.dt);
                let run = drive(&grid, start, zone.approach, params, &mut plant);
                check_arrival(
                    &format!("{} zone {} from {start:?}", scene.id, zone.color),
                    zone.approach,
                    run,
                );
            }
        }
    }
}
