//! One plan step under the oracle: a small state machine stepped once per 10 Hz control step.
//!
//! - move: clear the tool off the work surface and stow it, then the paper's Theta* path and
//!   rule-based follower (`kitchen_r_sim::oracle::follow`) to the zone's approach point.
//! - pick / place: clear the tool, square the base up on the approach pose the last move aimed
//!   for (the follower arrives anywhere inside its 0.09 m circle and the task ends at 0.10 m, so
//!   the base can stand 10 cm short of the pose the arm's reach was checked from), then the
//!   10-phase pick-and-place machine (`kitchen_r_sim::oracle::manip`).
//!
//! The controller reads only a [`Now`] (base pose, measured velocity) and the [`World`] facts
//! taken at the last query, so the oracle can step clones of it along a predicted base
//! trajectory to fill a whole chunk.

use std::f64::consts::{FRAC_PI_2, PI};
use std::sync::Arc;

use kitchen_r_core::catalogue::ObjectModel;
use kitchen_r_sim::oracle::action::action;
use kitchen_r_sim::oracle::follow::{PathFollower, wrap};
use kitchen_r_sim::oracle::manip::{ManipParams, Phase, PhasePlan, PickPlan, PlacePlan, base_isometry};
use nalgebra::{Isometry3, Vector3};

use super::arm::{ArmPath, Prelude};
use super::grasp::{free_yaw, place_turn};
use super::headroom::{Lean, tilted};

/// Physical grasp mode: the grasp and lift phases' durations, s (abstract: 1 and 2).
const PHYSICAL_GRASP_S: f64 = 2.0;
const PHYSICAL_LIFT_S: f64 = 3.0;

/// The least lift of a hand leaning over flat work under a board, m ([`TaskCtl::plan`]).
const FLAT_LIFT: f64 = 0.06;

/// A hand leaning under a board that can lift a picked object less than this pulls it out
/// from under the board before lifting it further, m ([`TaskCtl::step`]): the least lift a pick
/// needs (`configs/sim.toml`'s `lift_clearance`, 3 cm) and a margin.
const LIFT_IN_ROOM: f64 = 0.05;

/// How far a plan's lift raises the grasp, m (unbounded for a plan without its grasp, one
/// resumed from its lift: it pulls nothing out).
fn lift_of(plan: &PhasePlan) -> f64 {
    let z = |phase| {
        plan.targets()
            .iter()
            .find(|p| p.phase == phase)
            .map(|p| p.ee_in_base.translation.z)
    };
    match (z(Phase::Grasp), z(Phase::Lift)) {
        (Some(g), Some(l)) => l - g,
        _ => f64::INFINITY,
    }
}

/// Control period, s (the paper's 10 Hz).
pub(super) const DT: f64 = 0.1;

/// The robot as the controller sees it at one control step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Now {
    /// World `[x, y, yaw]`.
    pub base: [f64; 3],
    /// Measured `[v, ω]`.
    pub velocity: [f64; 2],
}

/// World facts read from privileged state at a query; constant over one chunk.
#[derive(Debug, Clone)]
pub(super) struct World {
    /// World pose of the task's object (pick, place).
    pub object: Option<Isometry3<f64>>,
    /// Object pose in the tool frame while held (rigid, so exact for the whole carry).
    pub held_in_tool: Option<Isometry3<f64>>,
    pub model: Option<ObjectModel>,
}

#[derive(Debug, Clone)]
pub(super) enum Goal {
    Move { follower: Box<PathFollower> },
    Pick,
    Place { target: [f64; 3] },
}

/// Where the arm is in its sequence.
#[derive(Debug, Clone)]
enum Stage {
    /// Prelude motion, with the time spent on it.
    Arm(ArmPath, f64),
    /// Square the base up on the approach pose (manipulation only).
    Settle {
        positioned: bool,
    },
    /// Driving (moves only).
    Drive,
    /// The pick-and-place machine and the time into it, with the base pose and the object pose
    /// (world) it was planned from: its targets hold only while those stay put.
    Manip(PhasePlan, f64, Anchor),
    Done,
}

impl Stage {
    /// The commanded tool pose (base frame) `t` seconds into a timed stage (the arm's prelude,
    /// the pick-and-place machine); `Isometry3::identity()` for the others, which have no clock.
    fn pose_at(&self, t: f64, tilt: Option<Lean>) -> Isometry3<f64> {
        match self {
            Stage::Arm(path, _) => path.at(t),
            Stage::Manip(plan, _, _) => tilted(plan.target_at(t).0, tilt, false),
            _ => Isometry3::identity(),
        }
    }
}

/// What a pick-and-place plan was made from.
#[derive(Debug, Clone, Copy)]
struct Anchor {
    base: [f64; 3],
    object: Option<Isometry3<f64>>,
}

/// How far the measured state may stray from what the controller commanded before the oracle
/// re-plans from the state (docs/twin/oracle.md). Its own runs stay inside these: the arm lags its
/// blended target by up to about 6 cm (a transport), the base stands still while it manipulates;
/// the dev and test splits run to the bit as they did before the check.
pub(super) mod tolerance {
    /// Tool position against the commanded pose, m: outside the slow phases at the object.
    pub(in crate::oracle) const TOOL: f64 = 0.10;
    /// The same while the hand works at the object (descend, grasp, lift, release), where its
    /// own lag stays under 3.1 cm: a hand further off would close or open in the wrong place.
    pub(in crate::oracle) const TOOL_AT_OBJECT: f64 = 0.05;
    /// Tool orientation against the commanded pose, rad.
    pub(in crate::oracle) const TOOL_TURN: f64 = 0.4;
    /// Base position and heading against the pose a manipulation was planned from, m and rad.
    pub(in crate::oracle) const BASE: f64 = 0.03;
    pub(in crate::oracle) const BASE_TURN: f64 = 0.05;
    /// The object against where a pick found it, before the fingers reach it, m.
    pub(in crate::oracle) const OBJECT: f64 = 0.04;
}

/// The measured state a controller step is checked against ([`TaskCtl::off_plan`]).
#[derive(Debug, Clone, Copy)]
pub(super) struct Measured<'a> {
    pub now: &'a Now,
    /// The tool pose (base frame).
    pub tool: &'a Isometry3<f64>,
    /// The task's object is in the hand.
    pub held: bool,
    /// The task's object pose (world).
    pub object: Option<&'a Isometry3<f64>>,
}

#[derive(Debug, Clone)]
pub(super) struct TaskCtl {
    pub goal: Goal,
    stage: Stage,
    /// The approach pose the base squares up on before manipulating.
    approach: Option<[f64; 3]>,
    /// The last commanded tool pose (base frame) and gripper: held while the base moves.
    tool: Isometry3<f64>,
    gripper: f64,
    params: ManipParams,
    /// Highest tool height over the work (under a shelf board).
    ceiling: Option<f64>,
    /// The physical grasp mode: no re-planning from the state (see [`TaskCtl::off_plan`]).
    physical: bool,
    /// The most a place's release and retreat open the gripper (1 fully open; the physical
    /// grasp's [`grasp::release_gripper`](super::grasp::release_gripper)).
    release_gripper: f64,
    /// The other key objects a place's hand keeps clear of, `(centre, footprint radius)`
    /// (world; the physical grasp's [`grasp::place_turn`](super::grasp::place_turn)). Shared:
    /// the controller is cloned for every step of every chunk it predicts.
    neighbours: Arc<[([f64; 2], f64)]>,
    /// The gripper's widest finger gap, m (the physical grasp's
    /// [`grasp::free_yaw`](super::grasp::free_yaw)).
    max_opening: f64,
    /// A lean (about the tool centre point, see [`tilted`]) applied to every pose of the
    /// pick-and-place machine: an arm whose wrist stands high over a top-down tool leans its
    /// fingers away from the base so the wrist stands back and lower (`OraclePolicy`'s tilt).
    tilt: Option<Lean>,
    /// A pick whose lift under a board was too short has pulled its object out to the carry
    /// pose: the task's motions are over.
    pulled_out: bool,
}

impl TaskCtl {
    /// `tool`: the current tool pose (base frame); `holding`: an object is in the gripper;
    /// `prelude`: where the motion before the task may go and how it departs from the plain
    /// one; `target_max`: the highest the tool may be where the task works (under a shelf
    /// board, see [`super::headroom`]).
    pub(super) fn new(
        goal: Goal,
        tool: Isometry3<f64>,
        holding: bool,
        approach: Option<[f64; 3]>,
        prelude: Prelude,
        target_max: Option<f64>,
        physical: bool,
    ) -> TaskCtl {
        let mut params = ManipParams::default();
        if physical {
            // Friction holds the object: the fingers close fully and build up their squeeze
            // before the lift, and the lift starts gently.
            params.durations[Phase::Grasp as usize] = PHYSICAL_GRASP_S;
            params.durations[Phase::Lift as usize] = PHYSICAL_LIFT_S;
        }
        let stow = if holding { params.carry } else { params.home };
        let is_move = matches!(goal, Goal::Move { .. });
        let arm = ArmPath::prelude(tool, stow, target_max, is_move, prelude);
        TaskCtl {
            goal,
            stage: Stage::Arm(arm, 0.0),
            approach,
            tool,
            gripper: if holding { 0.0 } else { 1.0 },
            params,
            ceiling: target_max,
            physical,
            release_gripper: 1.0,
            neighbours: Arc::from([]),
            max_opening: 0.0,
            tilt: None,
            pulled_out: false,
        }
    }

    /// Command `gripper` (0 closed, 1 open) until the manipulation's plan starts.
    pub(super) fn with_start_gripper(mut self, gripper: f64) -> TaskCtl {
        self.gripper = gripper;
        self
    }

    /// Open at most to `gripper` (0 closed, 1 open) while releasing and retreating from a place.
    pub(super) fn with_release_gripper(mut self, gripper: f64) -> TaskCtl {
        self.release_gripper = gripper;
        self
    }

    /// Keep the hand clear of `neighbours`: turn the held object on the way to a place, and
    /// turn the tool over an object with no closing direction of its own; `max_opening`: the
    /// gripper's widest finger gap, m.
    pub(super) fn with_neighbours(mut self, neighbours: Arc<[([f64; 2], f64)]>, max_opening: f64) -> TaskCtl {
        self.neighbours = neighbours;
        self.max_opening = max_opening;
        self
    }

    /// Work with the machine's poses turned by `tilt` (see [`TaskCtl::tilt`]).
    pub(super) fn with_tilt(mut self, tilt: Option<Lean>) -> TaskCtl {
        self.tilt = tilt;
        self
    }

    /// Whether the pick-and-place machine ran to its end.
    pub(super) fn manipulation_finished(&self) -> bool {
        let capped = self.ceiling.is_some();
        matches!(&self.stage, Stage::Manip(p, t, _)
            if *t >= p.duration() - if capped { p.targets().last().map_or(0.0, |l| l.duration) } else { 0.0 } - 1e-9)
    }

    /// Start the machine over from the current tool pose (a pick that closed on nothing).
    pub(super) fn restart_manipulation(&mut self) {
        self.stage = Stage::Settle { positioned: true };
    }

    /// Why the measured state is not the one this controller's plan expects, if it is not: the
    /// tool away from its commanded pose (a lagging or pushed arm), the base moved off the pose
    /// a manipulation was planned from, the object moved before the grasp, the object not in
    /// the hand when the plan carries it, or the machine ended with the task undone. The oracle
    /// then plans again from the state: its action depends on where the robot and
    /// the object are, not on how long ago the task started.
    pub(super) fn off_plan(&self, m: &Measured<'_>) -> Option<&'static str> {
        use tolerance as tol;
        // The physical grasp keeps its timed plan: its "held" flickers with the finger contacts
        // (and its arm, a motor-driven multibody until 2026-11-30, lagged a blend by more than
        // the tolerances; the physical grasp, docs/twin/robot.md).
        if self.physical {
            return None;
        }
        let tool_error = (m.tool.translation.vector - self.tool.translation.vector).norm();
        let tool_off =
            tool_error > tol::TOOL || m.tool.rotation.angle_to(&self.tool.rotation) > tol::TOOL_TURN;
        match &self.stage {
            Stage::Arm(..) if tool_off => Some("the tool left its path"),
            Stage::Manip(plan, t, anchor) => {
                let (_, _, phase) = plan.target_at(*t);
                let [bx, by, byaw] = m.now.base;
                let [ax, ay, ayaw] = anchor.base;
                let moved = |a: &Isometry3<f64>, b: &Isometry3<f64>| {
                    (a.translation.vector - b.translation.vector).norm() > tol::OBJECT
                };
                let before_grasp = matches!(phase, Phase::PreGrasp | Phase::Descend);
                let at_object = matches!(
                    phase,
                    Phase::Descend | Phase::Grasp | Phase::Lift | Phase::Release
                );
                if tool_off || (at_object && tool_error > tol::TOOL_AT_OBJECT) {
                    Some("the tool left its commanded pose")
                } else if (bx - ax).hypot(by - ay) > tol::BASE || wrap(byaw - ayaw).abs() > tol::BASE_TURN {
                    Some("the base moved off the pose the manipulation was planned from")
                } else if before_grasp
                    && matches!((anchor.object, m.object), (Some(a), Some(b)) if moved(&a, b))
                {
                    Some("the object moved before the grasp")
                } else if matches!(phase, Phase::Carry | Phase::Transport) && !m.held {
                    Some("the object is not in the hand")
                } else if self.manipulation_finished() && self.task_undone(m.held) {
                    Some("the machine ended with the task undone")
                } else {
                    None
                }
            }
            _ => None,
        }
    }

    /// Hold the plan's clock back to the hand a learner drove: the arm's prelude and
    /// the pick-and-place machine run on their own clocks, which a lagging learner's hand does
    /// not keep up with; left running, the label at a state would be the plan's pose and gripper
    /// of some seconds later (fingers closing above an object the hand has not reached). The
    /// clock goes back to the latest time, not after where it stands, whose commanded pose is
    /// nearest the measured hand (within [`SYNC_SLACK`]), so the label is the way on from where
    /// the hand is. A hand that keeps up changes nothing.
    pub(super) fn follow_hand(&mut self, tool: &Isometry3<f64>) {
        let hand = tool.translation.vector;
        let (Stage::Arm(_, t) | Stage::Manip(_, t, _)) = &self.stage else {
            return;
        };
        let now = *t;
        // (time, distance to the hand), latest first.
        let back_in_time: Vec<(f64, f64)> = (0..=(now / SYNC_STEP).floor() as usize)
            .map(|k| now - k as f64 * SYNC_STEP)
            .map(|x| {
                (
                    x,
                    (self.stage.pose_at(x, self.tilt).translation.vector - hand).norm(),
                )
            })
            .collect();
        let best = back_in_time.iter().map(|&(_, d)| d).fold(f64::INFINITY, f64::min);
        let Some(&(back, _)) = back_in_time.iter().find(|&&(_, d)| d <= best + SYNC_SLACK) else {
            return;
        };
        if back < now {
            self.tool = self.stage.pose_at(back, self.tilt);
            if let Stage::Arm(_, t) | Stage::Manip(_, t, _) = &mut self.stage {
                *t = back;
            }
        }
    }

    /// Plan again from the measured state without going back to the task's start:
    /// the hand is not sent home and the base not squared up again unless it strayed far, and a
    /// hand already in the column over the work goes on down rather than back up. A learner
    /// that lags its expert by a few centimetres is then labelled with the way on from where it
    /// is, not with the task's beginning. `false` where only a fresh start will do: a move, the
    /// physical grasp, a task whose manipulation had not begun.
    pub(super) fn resume(&mut self, tool: &Isometry3<f64>, now: &Now, world: &World) -> bool {
        if self.physical || matches!(self.goal, Goal::Move { .. }) {
            return false;
        }
        let Stage::Manip(_, _, anchor) = &self.stage else {
            return false;
        };
        let [bx, by, byaw] = now.base;
        let [ax, ay, ayaw] = anchor.base;
        self.tool = *tool;
        if (bx - ax).hypot(by - ay) > RESETTLE || wrap(byaw - ayaw).abs() > RESETTLE_TURN {
            self.stage = Stage::Settle { positioned: false };
            return true;
        }
        let Some(plan) = self.plan(now, world) else {
            return false;
        };
        let anchor = Anchor {
            base: now.base,
            object: world.object,
        };
        self.stage = Stage::Manip(skip_reached(plan, tool), 0.0, anchor);
        true
    }

    /// A finished machine left its task undone: a pick holds nothing, or a place (which picked
    /// its object up again first) still holds it.
    fn task_undone(&self, held: bool) -> bool {
        match self.goal {
            Goal::Pick => !held,
            Goal::Place { .. } => held,
            Goal::Move { .. } => false,
        }
    }

    /// One control step: the action to apply.
    pub(super) fn step(&mut self, now: &Now, world: &World) -> [f64; 10] {
        let (mut v, mut w) = (0.0, 0.0);
        loop {
            match &mut self.stage {
                Stage::Arm(path, t) => {
                    *t += DT;
                    self.tool = path.at(*t);
                    if *t < path.duration() {
                        break;
                    }
                    self.stage = match self.goal {
                        Goal::Move { .. } => Stage::Drive,
                        _ if self.pulled_out => Stage::Done,
                        _ => Stage::Settle { positioned: false },
                    };
                    break;
                }
                Stage::Drive => {
                    let Goal::Move { follower, .. } = &mut self.goal else {
                        unreachable!()
                    };
                    let (fv, fw, _) = follower.step(now.base);
                    (v, w) = (fv, fw);
                    break;
                }
                Stage::Settle { positioned } => {
                    if let Some(goal) = self.approach
                        && let Some(cmd) = settle(goal, now.base, positioned)
                    {
                        (v, w) = cmd;
                        break;
                    }
                    let anchor = Anchor {
                        base: now.base,
                        object: world.object,
                    };
                    match self.plan(now, world) {
                        Some(plan) => self.stage = Stage::Manip(plan, 0.0, anchor),
                        None => self.stage = Stage::Done,
                    }
                }
                Stage::Manip(plan, t, _) => {
                    *t += DT;
                    if self.ceiling.is_some() {
                        // The last phase (carry or home) heads for the stow pose on a slant that
                        // would catch the board; the next task's prelude pulls back level.
                        let last = plan.targets().last().map_or(0.0, |p| p.duration);
                        let end = plan.duration() - last;
                        // A leaning hand whose room under the board lifts the object less than a
                        // pick needs (the Kinova3's wrist leaves a cup on the 0.85 m shelf 5 mm,
                        // dev) pulls it out level first, as the next task's prelude would, and
                        // lifts it to the carry pose in the open; a hand that holds nothing stays
                        // (the machine ended with the task undone: the oracle plans again).
                        let short = || {
                            matches!(self.goal, Goal::Pick)
                                && world.held_in_tool.is_some()
                                && matches!(self.tilt, Some(Lean::Reach(_)))
                                && lift_of(plan) < LIFT_IN_ROOM
                        };
                        if *t >= end && short() {
                            let out = Prelude {
                                here_max: self.ceiling,
                                ..Prelude::default()
                            };
                            let path = ArmPath::prelude(self.tool, self.params.carry, None, true, out);
                            self.stage = Stage::Arm(path, 0.0);
                            self.pulled_out = true;
                            continue;
                        }
                        *t = t.min(end);
                    }
                    let (tool, g, phase) = plan.target_at(*t);
                    let g = match phase {
                        Phase::Release | Phase::Retreat => g.min(self.release_gripper),
                        _ => g,
                    };
                    (self.tool, self.gripper) = (tilted(tool, self.tilt, false), g);
                    break;
                }
                Stage::Done => break,
            }
        }
        action(v, w, &self.tool, self.gripper)
    }

    fn plan(&self, now: &Now, world: &World) -> Option<PhasePlan> {
        let model = world.model.as_ref()?;
        let mut params = self.params.clone();
        let open_lift = params.lift_height;
        if let Some(m) = self.ceiling {
            let surface_grasp = match self.goal {
                Goal::Place { target } => target[2] + model.grasp_offset[2],
                _ => world.object?.translation.z + model.grasp_offset[2],
            };
            let room = (m - surface_grasp).max(0.0);
            params.approach_height = params.approach_height.min(room);
            params.lift_height = params.lift_height.min(room);
            params.retreat_height = params.retreat_height.min(room);
            if let Some(Lean::Closing(_)) = self.tilt {
                // A hand leaning over flat work closes on it up to 2 cm over the grasp point:
                // the Kinova3's room under the board above (4.4 cm over a fork) lifted forks 2.7
                // cm of the 3 a pick needs. Leaning, its wrist stands lower than the room allows.
                params.lift_height = params.lift_height.max(FLAT_LIFT.min(open_lift));
            }
        }
        if let Some(object) = world.object.as_ref().filter(|_| !self.neighbours.is_empty()) {
            // Fingers opened fully round an object to pick, or a little wider than it to let go.
            let (centre, gap) = match self.goal {
                Goal::Place { target } => ([target[0], target[1]], self.release_gripper * self.max_opening),
                _ => ([object.translation.x, object.translation.y], self.max_opening),
            };
            params.free_yaw = free_yaw(model, now.base[2], centre, gap, &self.neighbours);
        }
        let p = &params;
        // The machine plans top-down; its start is the commanded pose with the tilt taken off,
        // so the turned poses it commands begin exactly where the hand was told to be.
        let start = tilted(self.tool, self.tilt, true);
        match self.goal {
            Goal::Move { .. } => None,
            Goal::Pick => {
                let pick = PickPlan::new(world.object.as_ref()?, model, now.base, p).plan;
                // Already in the hand (a plan resumed from the state): lift and stow it.
                let pick = match world.held_in_tool {
                    Some(_) if !self.physical => pick.from_phase(Phase::Lift),
                    _ => pick,
                };
                Some(pick.starting_from(start, self.gripper))
            }
            // Not in the hand (dropped, or a start that never held it): pick it up first; the
            // place is planned once it is held.
            Goal::Place { .. } if world.held_in_tool.is_none() && !self.physical => {
                let pick = PickPlan::new(world.object.as_ref()?, model, now.base, p);
                Some(pick.plan.starting_from(start, self.gripper))
            }
            Goal::Place { target } => {
                let object = world.object?;
                let base = base_isometry(now.base);
                let yaw_in_base = yaw(&(base.inverse() * object).rotation);
                let yaw_in_base =
                    yaw_in_base + place_turn(model, yaw_in_base, now.base[2], target, &self.neighbours);
                let plan_for = |c: [f64; 3]| {
                    let pose = PlacePlan::target_keeping_grip(c, yaw_in_base, now.base);
                    PlacePlan::new(&pose, model, now.base, p)
                };
                let mut centre = target;
                // Where the centre would be let go with the nominal grasp; the difference to the
                // real grip shifts the target once (the correction is exact: the tool
                // orientation does not depend on the target position).
                if let Some(held) = world.held_in_tool {
                    let lower = tilted(plan_for(centre).plan.targets()[1].ee_in_base, self.tilt, false);
                    let released = (base * lower * held).translation.vector;
                    let want = Vector3::from(target) + Vector3::z() * p.release_height;
                    let err = released - want;
                    centre = [target[0] - err.x, target[1] - err.y, target[2] - err.z];
                }
                Some(plan_for(centre).plan.starting_from(start, self.gripper))
            }
        }
    }
}

/// The step the plan clock is searched back in when it follows a learner's hand, s.
const SYNC_STEP: f64 = 0.05;
/// A commanded pose this much further from the hand than the nearest still counts as where the
/// hand is, m: the clock goes back no further than it must.
const SYNC_SLACK: f64 = 0.005;

/// A resumed manipulation squares the base up again first when it stands further than this from
/// where the manipulation was planned, m and rad (closer, the arm makes up the difference).
const RESETTLE: f64 = 0.15;
const RESETTLE_TURN: f64 = 0.2;
/// Horizontally this close to the approach pose over the work (and between its height and the
/// work's), the hand is in the column and a resumed plan goes on down, m.
const IN_COLUMN: f64 = 0.03;
/// Slack on the column's top and bottom, m.
const COLUMN_SLACK: f64 = 0.02;

/// `plan` from the first phase the tool has not reached: a hand in the column over the object
/// (pick) or the target (place) starts at the way down instead of the approach above it.
fn skip_reached(plan: PhasePlan, tool: &Isometry3<f64>) -> PhasePlan {
    let (above, down) = match plan.targets() {
        [a, b, ..]
            if matches!(
                (a.phase, b.phase),
                (Phase::PreGrasp, Phase::Descend) | (Phase::Transport, Phase::Lower)
            ) =>
        {
            (
                a.ee_in_base.translation.vector,
                (b.phase, b.ee_in_base.translation.z),
            )
        }
        _ => return plan,
    };
    let p = tool.translation.vector;
    let in_column = (p.x - above.x).hypot(p.y - above.y) < IN_COLUMN
        && p.z <= above.z + COLUMN_SLACK
        && p.z >= down.1 - COLUMN_SLACK;
    if in_column { plan.from_phase(down.0) } else { plan }
}

fn yaw(q: &nalgebra::UnitQuaternion<f64>) -> f64 {
    let x = q * Vector3::x();
    x.y.atan2(x.x)
}

/// Closer than this to the approach point, the base is positioned, m.
const POSITIONED: f64 = 0.03;
/// A sideways offset below this is not worth turning for, m.
const SIDEWAYS_OK: f64 = 0.06;
/// Heading tolerance before manipulating, rad.
const HEADING_OK: f64 = 0.015;

/// A slow go-to-pose for the last centimetres before manipulating (not the paper's follower,
/// whose arrival circle is 9 cm): drive straight (forwards or backwards) onto the point, then
/// turn onto its heading. `None` once both are good.
fn settle(goal: [f64; 3], pose: [f64; 3], positioned: &mut bool) -> Option<(f64, f64)> {
    let (dx, dy) = (goal[0] - pose[0], goal[1] - pose[1]);
    let d = dx.hypot(dy);
    if !*positioned && d > POSITIONED {
        let mut e = wrap(dy.atan2(dx) - pose[2]);
        let mut dir = 1.0;
        if e.abs() > FRAC_PI_2 {
            e = wrap(e - PI);
            dir = -1.0;
        }
        if e.abs() > 0.5 && d < SIDEWAYS_OK {
            *positioned = true;
        } else if e.abs() > 0.25 {
            return Some((0.0, (1.2 * e).clamp(-0.5, 0.5)));
        } else {
            return Some((dir * (0.6 * d).clamp(0.02, 0.12), e));
        }
    }
    *positioned = true;
    let e = wrap(goal[2] - pose[2]);
    if e.abs() > HEADING_OK {
        let w = (1.5 * e).clamp(-0.4, 0.4);
        return Some((0.0, if w.abs() < 0.04 { 0.04f64.copysign(e) } else { w }));
    }
    None
}
