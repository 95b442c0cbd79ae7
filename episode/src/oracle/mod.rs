//! The oracle expert as a [`Policy`]: the organisers' reference, driving any ground-truth plan
//! from privileged world state (paper, §Navigation Module and §Manipulation Module; the
//! algorithms themselves live in `kitchen_r_sim::oracle`).
//!
//! It answers each query with a chunk of 16 actions that is a coherent plan, not one action
//! repeated: the task controller (`task::TaskCtl`) is stepped along a base trajectory predicted
//! with a unicycle model under the base's speed and acceleration limits from
//! the robot description. The runner executes the first k of them; at the next query the oracle
//! adopts the controller state it predicted for exactly the steps executed and re-anchors on the
//! measured pose, so the chunks join up however many actions the runner executes.
//!
//! Queried every control step with k = 1 (see [`expert_options`]) it is the closed-loop expert
//! driver used for trajectory collection and for the expert trajectories MSE compares against.

mod arm;
mod grasp;
mod headroom;
mod task;

use std::collections::HashMap;
use std::sync::Arc;

use kitchen_r_core::GraspMode;
use kitchen_r_core::catalogue::Catalogue;
use kitchen_r_core::scene::Scene;
use kitchen_r_sim::oracle::follow::{FollowParams, PathFollower};
use kitchen_r_sim::oracle::grid::{GridParams, OccupancyGrid};
use kitchen_r_sim::oracle::manip::ManipParams;
use kitchen_r_sim::oracle::theta_star::{PlannerParams, theta_star};
use kitchen_r_sim::robot::desc::BaseDesc;
use kitchen_r_sim::task::TaskTarget;
use kitchen_r_sim::{Assets, SimConfig};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};

use crate::policy::{
    ACTION_DIM, HORIZON, Policy, PolicyError, PolicyInput, PolicySpec, Privileged, PrivilegedObject,
};
use crate::runner::RunOptions;
use arm::Prelude;
use task::{Goal, Measured, Now, TaskCtl, World};

/// Name the oracle announces and `--policy builtin:oracle` selects.
pub(crate) const ORACLE_NAME: &str = "builtin:oracle";
/// Extra clearance the planner tries first (it falls back to the plain robot radius): the
/// follower cuts corners by up to ~0.15 m, and the twin ejects a base driven into furniture.
const CLEARANCE_MARGIN: f64 = 0.2;
/// The base squares up on the last move's goal only when it stands this close to it, m.
const SETTLE_RANGE: f64 = 0.5;

/// An empty hand's fingers closer than this (a fraction of the widest gap) at a task's start are
/// still round what the last place put down ([`Prelude::open_first`]).
const OPEN_GAP: f64 = 0.95;

/// Run options for the closed-loop expert: privileged, one action per query.
pub fn expert_options() -> RunOptions {
    RunOptions {
        execute: 1,
        privileged: true,
        ..RunOptions::default()
    }
}

/// The task being driven and the controller states predicted for the last chunk.
#[derive(Debug)]
struct Active {
    ctl: TaskCtl,
    queried_at: u64,
    predicted: Vec<TaskCtl>,
    /// The chunk answered at `queried_at`.
    chunk: Vec<[f64; ACTION_DIM]>,
}

/// How close an executed action must be to the expert's own to count as the expert's: tool
/// position (m) and base velocities (m/s, rad/s).
const OWN_ACTION: (f64, f64) = (0.01, 0.02);

/// Whether `executed` is `own` to within [`OWN_ACTION`].
fn same_action(executed: &[f64; ACTION_DIM], own: &[f64; ACTION_DIM]) -> bool {
    let off = (executed[2] - own[2])
        .hypot(executed[3] - own[3])
        .hypot(executed[4] - own[4]);
    off < OWN_ACTION.0
        && (executed[0] - own[0]).abs() < OWN_ACTION.1
        && (executed[1] - own[1]).abs() < OWN_ACTION.1
}

pub struct OraclePolicy {
    spec: PolicySpec,
    scenes: Vec<Scene>,
    catalogue: Catalogue,
    base: BaseDesc,
    grids: HashMap<String, Arc<OccupancyGrid>>,
    active: Option<Active>,
    /// The approach pose of the last move, kept across the tasks of an episode.
    last_goal: Option<[f64; 3]>,
    episode: String,
    /// Whether to have the runner render for each query; the oracle itself reads only
    /// privileged state, but reference runs and the benchmark render as for any policy.
    images: bool,
    /// The twin's grasp mode: in the physical one the oracle gives the fingers time to squeeze
    /// before it lifts.
    grasp: GraspMode,
    /// How often the measured state left the plan and the oracle planned again from it.
    replans: u64,
    /// Half the fingers' length along the approach axis, m: how far the fingertips reach below
    /// the TCP (the physical grasp keeps them off the surface an object stands on).
    finger_reach: f64,
    /// The gripper's widest gap, m (the physical grasp's release opens to a fraction of it).
    max_opening: f64,
    /// How fast the finger gap may change, m/s.
    opening_speed: f64,
    /// How far the hand's own geometry stands behind the TCP, m (the physical grasp keeps a
    /// round object's top out of it, `grasp::under_palm`).
    palm_reach: f64,
    /// How high the arm's wrist stands over a top-down tool, m (`headroom::headroom` reads it:
    /// how far under a shelf board the tool stays and how it leans there).
    wrist_height: Option<f64>,
    /// The arm has a joint to spare (seven): its hand leaning sideways leans outside a board
    /// before it goes in, where a six-joint arm's only levels a held plate
    /// (`headroom::lean_outside`).
    spare_joint: bool,
}

impl OraclePolicy {
    pub fn new(assets: &Assets) -> OraclePolicy {
        OraclePolicy {
            spec: PolicySpec {
                name: ORACLE_NAME.into(),
                ..PolicySpec::default()
            },
            scenes: assets.scenes.clone(),
            catalogue: assets.catalogue.clone(),
            base: assets.robot.base.clone(),
            grids: HashMap::new(),
            active: None,
            last_goal: None,
            episode: String::new(),
            images: true,
            grasp: SimConfig::load_default().map_or(GraspMode::Abstract, |c| c.grasp.mode),
            replans: 0,
            finger_reach: assets.robot.gripper.finger_length / 2.0,
            max_opening: assets.robot.gripper.max_opening,
            opening_speed: assets.robot.gripper.opening_speed,
            palm_reach: kitchen_r_sim::robot::palm::palm_reach(&assets.robot),
            wrist_height: kitchen_r_sim::robot::wrist::wrist_height(&assets.robot),
            spare_joint: assets.robot.arm.joints.len() > 6,
        }
    }

    /// How often this oracle planned again from the measured state because it had left the
    /// plan (docs/twin/oracle.md): never in its own undisturbed episodes, at every step a learner
    /// drives differently when it labels them.
    pub fn replans(&self) -> u64 {
        self.replans
    }

    /// Drive a twin of this grasp mode (default: `configs/sim.toml`'s `[grasp] mode`).
    pub fn with_grasp_mode(mut self, mode: GraspMode) -> OraclePolicy {
        self.grasp = mode;
        self
    }

    /// The oracle as an expert nobody watches: no rendering for its queries (offline
    /// replays and teleport pre-runs, where only its actions and states matter).
    pub fn without_images(mut self) -> OraclePolicy {
        self.images = false;
        self
    }

    /// Announce `n` episodes at once (at least 1). Served over gRPC, each episode gets its own
    /// oracle instance, so a reference run can use several workers' slots.
    pub fn with_max_concurrency(mut self, n: u32) -> OraclePolicy {
        self.spec.max_concurrency = n.max(1);
        self
    }

    fn scene(&self, id: &str) -> Result<&Scene, PolicyError> {
        self.scenes
            .iter()
            .find(|s| s.id == id)
            .ok_or_else(|| PolicyError::Call(format!("oracle: unknown scene {id:?}")))
    }

    /// The scene's occupancy grid, inflated by the base's footprint radius; built once per scene.
    fn grid(&mut self, scene: &str) -> Result<Arc<OccupancyGrid>, PolicyError> {
        if let Some(g) = self.grids.get(scene) {
            return Ok(g.clone());
        }
        let s = self.scene(scene)?;
        let params = GridParams {
            robot_radius: self.base.radius,
            ..GridParams::default()
        };
        let g = Arc::new(OccupancyGrid::from_scene(s, params).map_err(|e| PolicyError::Call(e.to_string()))?);
        self.grids.insert(scene.to_string(), g.clone());
        Ok(g)
    }

    /// `gap`: the measured finger gap, a fraction of the widest.
    fn start_task(&mut self, p: &Privileged, gap: f64) -> Result<TaskCtl, PolicyError> {
        let tool = iso(&p.ee_pose);
        let holding = p.held.is_some();
        let here = [p.base_pose[0], p.base_pose[1]];
        let goal = match p.target {
            TaskTarget::Base { x, y, yaw } => {
                let grid = self.grid(&p.scene)?;
                let params = PlannerParams {
                    clearance_margin: CLEARANCE_MARGIN,
                    ..PlannerParams::default()
                };
                let path = theta_star(&grid, here, [x, y], &params)
                    .map_err(|e| PolicyError::Call(format!("oracle: no path: {e}")))?;
                self.last_goal = Some([x, y, yaw]);
                let follower = Box::new(PathFollower::new(path.waypoints, yaw, FollowParams::default()));
                Goal::Move { follower }
            }
            TaskTarget::Pick { .. } => Goal::Pick,
            TaskTarget::Place { target, .. } => Goal::Place { target },
        };
        let near = |g: &[f64; 3]| (g[0] - here[0]).hypot(g[1] - here[1]) < SETTLE_RANGE;
        let scene = self.scene(&p.scene)?;
        // An oracle that did not drive the last move (a start mid-plan, a state a learner
        // reached) squares up on the approach pose of the zone it stands at.
        let approach = self.last_goal.filter(near).or_else(|| {
            let d = |g: &[f64; 3]| (g[0] - here[0]).hypot(g[1] - here[1]);
            (scene.zones.iter().map(|z| z.approach))
                .filter(near)
                .min_by(|a, b| d(a).total_cmp(&d(b)))
        });
        let tool_world = kitchen_r_sim::oracle::manip::base_isometry(p.base_pose) * tool;
        let t = tool_world.translation;
        // The board that matters is the first one above the hand.
        let physical = self.grasp == GraspMode::Physical;
        // The physical grasp's pinches are planned top-down: only the abstract mode leans.
        let work = match p.target {
            TaskTarget::Pick { object } => p.objects.get(object).map(|o| [o.pose[0], o.pose[1], o.pose[2]]),
            TaskTarget::Place { target, .. } => Some(target),
            TaskTarget::Base { .. } => None,
        };
        let mut room = headroom::headroom(self.wrist_height, !physical);
        if let Some(w) = work {
            room = headroom::for_work(room, scene, w);
        }
        let here_max = headroom::max_tool_z(scene, [t.x, t.y], t.z, room.clear);
        let target_max = work.and_then(|w| headroom::max_tool_z(scene, [w[0], w[1]], w[2], room.clear));
        // Only work under a board leans (objects picked and placed in the open stay upright),
        // except a plate: a hand that leans over it under a board leans over it everywhere, so
        // the plate is level whenever the hand leans (picked top-down and put on a shelf
        // leaning, it was released tilted 45°, its low rim 8 cm under its centre: it struck the
        // shelf and lay 6–8 cm off its target, 3–4 dev places with each arm but the Kinova3).
        let plate = match p.target {
            TaskTarget::Pick { object } | TaskTarget::Place { object, .. } => p.objects.get(object),
            TaskTarget::Base { .. } => None,
        }
        .is_some_and(|o| self.plate_like(o));
        let tilt = room
            .tilt
            .filter(|t| target_max.is_some() || (plate && matches!(t, headroom::Lean::Closing(_))));
        // Put on a shelf, a plate picked in the open (held level by a leaning hand, then
        // straightened for the drive, so tilted in the hand) is levelled again before the hand
        // goes in under the board: tilted, it struck the shelf on the way in (the Kinova3, dev).
        let turn_to = match (self.held_plate(p), target_max, room.tilt) {
            (Some(in_hand), Some(_), Some(_)) => {
                let up = tool.rotation * in_hand.rotation * Vector3::z();
                UnitQuaternion::rotation_between(&up, &Vector3::z()).map(|turn| turn * tool.rotation)
            }
            _ => None,
        };
        let sink = match p.target {
            TaskTarget::Base { .. } if room.tilt.is_some() => {
                headroom::sink_before_pullback(scene, [t.x, t.y, t.z])
            }
            _ => 0.0,
        };
        // A physical place ends as the object touches down, the fingers still squeezing it: an
        // empty hand low over the work opens a little in place before it rises (rising at once,
        // the squeeze lifted a bowl and carried it hooked on a finger into the next pick,
        // dev-0086), and no wider than its release would (fully open, the outer finger swept a
        // neighbour off the counter).
        let low = tool.translation.z < ManipParams::default().home.translation.z - arm::LOW;
        let (open_first, start_gripper) = if physical && !holding && low && gap < OPEN_GAP {
            grasp::open_in_place(gap, self.max_opening, self.opening_speed)
        } else {
            (0.0, if holding { 0.0 } else { 1.0 })
        };
        // A leaning hand turns its lean only outside the boards (`Prelude::keep_lean`,
        // `Prelude::lean_at`); a six-joint arm's only when it leans towards the board (leaning
        // sideways so outside, the UR5e lost a plate place, dev-0030, and gained nothing). A
        // six-joint arm levels a held plate outside the board too, not at the stow position:
        // turned there, close over its shoulder, the UR5e's arm swung to another configuration
        // and its upper arm struck the board below the shelf level as it reached in (dev-0104).
        let stow = ManipParams::default().home;
        let lean_in = tilt.filter(|t| self.spare_joint || matches!(t, headroom::Lean::Reach(_)));
        let level_out = !self.spare_joint && lean_in.is_none();
        let turn_in = match (lean_in, turn_to) {
            (Some(lean), _) => Some(headroom::tilted(stow, Some(lean), false).rotation),
            (None, Some(level)) if level_out => Some(level),
            _ => None,
        };
        let turn_to = turn_to.filter(|_| !level_out);
        let (keep_lean, lean_at) = headroom::lean_outside(
            scene,
            &kitchen_r_sim::oracle::manip::base_isometry(p.base_pose),
            &tool,
            &stow,
            (here_max, target_max),
            work,
            turn_in,
        );
        let prelude = Prelude {
            here_max,
            sink,
            turn_to,
            open_first,
            keep_lean,
            lean_at,
        };
        // Opened fully, the fingers of a pinch sweep centimetres out beside a placed object and
        // can knock a neighbour off its support (the physical grasp only: the abstract mode's
        // fingers touch no key object).
        let (release, neighbours) = match p.target {
            TaskTarget::Place { object, target } if physical => (
                (self.world(p).model).map_or(1.0, |m| grasp::release_gripper(&m, self.max_opening)),
                self.neighbours(p, object, target[2]),
            ),
            // A top-down pick's fingers come down beside the object, wherever its neighbours are.
            TaskTarget::Pick { object } if physical => (
                1.0,
                p.objects
                    .get(object)
                    .map_or(Arc::from([]), |o| self.neighbours(p, object, o.pose[2])),
            ),
            _ => (1.0, Arc::from([])),
        };
        Ok(
            TaskCtl::new(goal, tool, holding, approach, prelude, target_max, physical)
                .with_tilt(tilt)
                .with_release_gripper(release)
                .with_neighbours(neighbours, self.max_opening)
                .with_start_gripper(start_gripper),
        )
    }

    /// The key objects other than `object` standing within 20 cm of height `z` (where it is
    /// picked or put down), as `(centre, footprint radius)`: what the hand keeps clear of
    /// ([`grasp::place_turn`], [`grasp::free_yaw`]).
    fn neighbours(&self, p: &Privileged, object: usize, z: f64) -> Arc<[([f64; 2], f64)]> {
        (p.objects.iter().enumerate())
            .filter(|(i, o)| *i != object && (o.pose[2] - z).abs() < 0.2)
            .filter_map(|(_, o)| {
                let m = self.catalogue.model(&o.model)?;
                Some((
                    [o.pose[0], o.pose[1]],
                    m.in_mode(self.grasp).shape.footprint_radius(),
                ))
            })
            .collect()
    }

    /// Whether key object `o` is plate-like ([`headroom::plate_like`]).
    fn plate_like(&self, o: &PrivilegedObject) -> bool {
        self.catalogue
            .model(&o.model)
            .is_some_and(|m| headroom::plate_like(&m.shape))
    }

    /// The held object's pose in the tool frame, if it is plate-like.
    fn held_plate(&self, p: &Privileged) -> Option<Isometry3<f64>> {
        let name = p.held.as_deref()?;
        let o = p.objects.iter().find(|o| o.name == name)?;
        let tool_world = kitchen_r_sim::oracle::manip::base_isometry(p.base_pose) * iso(&p.ee_pose);
        self.plate_like(o).then(|| tool_world.inverse() * iso(&o.pose))
    }

    fn world(&self, p: &Privileged) -> World {
        let object = match p.target {
            TaskTarget::Pick { object } | TaskTarget::Place { object, .. } => p.objects.get(object),
            TaskTarget::Base { .. } => None,
        };
        let pose = object.map(|o| iso(&o.pose));
        let tool_world = kitchen_r_sim::oracle::manip::base_isometry(p.base_pose) * iso(&p.ee_pose);
        let held = object.is_some_and(|o| p.held.as_deref() == Some(o.name.as_str()));
        let model = object.and_then(|o| self.catalogue.model(&o.model).map(|m| m.in_mode(self.grasp)));
        World {
            object: pose,
            held_in_tool: pose.filter(|_| held).map(|o| tool_world.inverse() * o),
            model: match self.grasp {
                GraspMode::Physical => model
                    .map(|m| grasp::under_palm(grasp::physical_grasp(m, self.finger_reach), self.palm_reach)),
                GraspMode::Abstract => model,
            },
        }
    }

    /// Unicycle prediction of one control step under the base's limits (the twin slews the
    /// commanded velocities every physics substep; 10 substeps here too).
    fn predict(&self, now: Now, v_cmd: f64, w_cmd: f64) -> Now {
        let b = &self.base;
        let [mut x, mut y, mut th] = now.base;
        let [mut v, mut w] = now.velocity;
        let h = task::DT / 10.0;
        for _ in 0..10 {
            v += (v_cmd.clamp(-b.max_v, b.max_v) - v).clamp(-b.acc_v * h, b.acc_v * h);
            w += (w_cmd.clamp(-b.max_omega, b.max_omega) - w).clamp(-b.acc_omega * h, b.acc_omega * h);
            x += v * th.cos() * h;
            y += v * th.sin() * h;
            th += w * h;
        }
        Now {
            base: [x, y, th],
            velocity: [v, w],
        }
    }
}

/// `[x, y, z, qw, qx, qy, qz]` as an isometry.
fn iso(p: &[f64; 7]) -> Isometry3<f64> {
    let q = UnitQuaternion::from_quaternion(Quaternion::new(p[3], p[4], p[5], p[6]));
    Isometry3::from_parts(Translation3::new(p[0], p[1], p[2]), q)
}

impl Policy for OraclePolicy {
    fn spec(&self) -> &PolicySpec {
        &self.spec
    }

    fn wants_images(&self) -> bool {
        self.images
    }

    fn reset(&mut self, episode_id: &str, task_index: usize, _: &str) -> Result<(), PolicyError> {
        if episode_id != self.episode || task_index == 0 {
            self.last_goal = None;
            self.episode = episode_id.to_string();
        }
        self.active = None;
        Ok(())
    }

    fn act(&mut self, input: &PolicyInput<'_>) -> Result<Vec<[f64; ACTION_DIM]>, PolicyError> {
        let p = input.privileged.ok_or(PolicyError::NeedsPrivileged)?;
        let world = self.world(p);
        // Whether the action just executed was this expert's own: then a state off its plan
        // was the world's doing, not a learner's.
        let mut own = false;
        let mut ctl = match self.active.take() {
            None => self.start_task(p, input.observation.gripper)?,
            Some(a) => {
                let done = input.step.saturating_sub(a.queried_at) as usize;
                own = match (done, input.previous_action) {
                    // Asked again before anything ran (the Python env's `expert_chunk`).
                    (0, _) => true,
                    (1..=HORIZON, Some(executed)) => same_action(&executed, &a.chunk[done - 1]),
                    _ => false,
                };
                match done {
                    0 => a.ctl,
                    n => a.predicted.into_iter().nth(n.min(HORIZON) - 1).unwrap_or(a.ctl),
                }
            }
        };
        // A pick that closed on nothing goes round again from where the tool is.
        if matches!(ctl.goal, Goal::Pick) && ctl.manipulation_finished() && p.held.is_none() {
            ctl.restart_manipulation();
        }
        // A state the plan does not expect (a policy drove, the world was pushed): plan again
        // from the state, as at a task's start.
        let measured_tool = iso(&p.ee_pose);
        let measured = Measured {
            now: &Now {
                base: p.base_pose,
                velocity: input.observation.odometry.velocity,
            },
            tool: &measured_tool,
            held: world.held_in_tool.is_some(),
            object: world.object.as_ref(),
        };
        // A learner's hand sets the plan's pace, not the plan's own clock.
        if !own {
            ctl.follow_hand(&measured_tool);
        }
        if ctl.off_plan(&measured).is_some() {
            self.replans += 1;
            // Off its plan under a learner's actions, a manipulation goes on from where the
            // hand is (the label a lagging learner needs); under its own actions the world held
            // the hand or base back (an object at the edge of reach), and the task starts
            // afresh from the state, base squared up again. A state no plan starts from (a path
            // planner boxed in by a learner's base) keeps the plan it had: a label is better
            // than an error in a DAgger round.
            let now = *measured.now;
            if (own || !ctl.resume(&measured_tool, &now, &world))
                && let Ok(fresh) = self.start_task(p, input.observation.gripper)
            {
                ctl = fresh;
            }
        }
        let mut now = Now {
            base: p.base_pose,
            velocity: input.observation.odometry.velocity,
        };
        let mut chunk = Vec::with_capacity(HORIZON);
        let mut predicted = Vec::with_capacity(HORIZON);
        let mut sim_ctl = ctl.clone();
        for _ in 0..HORIZON {
            let a = sim_ctl.step(&now, &world);
            now = self.predict(now, a[0], a[1]);
            chunk.push(a);
            predicted.push(sim_ctl.clone());
        }
        self.active = Some(Active {
            ctl,
            queried_at: input.step,
            predicted,
            chunk: chunk.clone(),
        });
        Ok(chunk)
    }
}
