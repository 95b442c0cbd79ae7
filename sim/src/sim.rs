//! The simulator: [`Sim::reset`] builds the world from an [`EpisodeConfig`], [`Sim::step`] applies
//! one 10-value action for one control step (fixed physics substeps in between), snapshots restore
//! the whole state bit for bit.

use kitchen_r_core::catalogue::Catalogue;
use kitchen_r_core::scene::Scene;
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use rapier3d::prelude::*;

use crate::config::{Mount, SensorsConfig, SimConfig};
use crate::convert::{iso_to_pose, pose_to_iso, vec_to_glam};
use crate::episode::EpisodeConfig;
use crate::error::SimError;
use crate::material::{Materials, Owner, Tag};
use crate::robot::desc::RobotDesc;
use crate::robot::{PART_NAMES, Robot, RobotCommand, RobotState};
use crate::sensors::camera::RenderCtx;
use crate::task::{Facts, MonitorTrip, Task, TaskStatus, objects_on_floor, task_target};
use crate::types::{Action, Contact, Observation, Odometry, StepInfo};
use crate::world::{build_static, spawn_object};

/// Scenes, catalogue and robot: the content a simulator is built from.
#[derive(Debug, Clone)]
pub struct Assets {
    pub scenes: Vec<Scene>,
    pub catalogue: Catalogue,
    pub robot: RobotDesc,
}

impl Assets {
    /// Everything under the assets directory (`KITCHEN_R_ASSETS`, `./assets`, or the workspace).
    pub fn load_default() -> Result<Assets, SimError> {
        let dir = kitchen_r_core::assets::assets_dir();
        let catalogue = Catalogue::load(&dir.join("objects.toml"))?;
        let scenes = Scene::load_all(&dir.join("scenes"), &catalogue)?;
        let robot = RobotDesc::load(&dir.join("robot.toml"))?;
        Ok(Assets {
            scenes,
            catalogue,
            robot,
        })
    }

    pub fn scene(&self, id: &str) -> Result<&Scene, SimError> {
        self.scenes
            .iter()
            .find(|s| s.id == id)
            .ok_or_else(|| SimError::UnknownScene(id.into()))
    }
}

/// A key object in the world.
#[derive(Debug, Clone)]
pub struct ObjectBody {
    pub name: String,
    pub body: RigidBodyHandle,
    pub half_height: f64,
    /// Grasp point from the centre, object frame.
    pub grasp_offset: Vector3<f64>,
}

/// The gripper's hold on an object.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Held {
    pub object: usize,
    /// Finger gap when the grasp closed (m).
    pub width: f64,
    /// Object pose in the TCP frame at the grasp.
    pub offset: Isometry3<f64>,
}

/// Make `body` a carried (kinematic, robot-ignoring, furniture-reporting) object, or release it
/// back to physics.
fn set_carried(world: &mut PhysicsWorld, body: RigidBodyHandle, carried: bool) {
    let (kind, groups, types) = if carried {
        (
            RigidBodyType::KinematicPositionBased,
            Owner::KeyObject.held_groups(),
            ActiveCollisionTypes::default() | ActiveCollisionTypes::KINEMATIC_FIXED,
        )
    } else {
        (
            RigidBodyType::Dynamic,
            Owner::KeyObject.groups(false),
            ActiveCollisionTypes::default(),
        )
    };
    world.bodies[body].set_body_type(kind, true);
    let handles: Vec<ColliderHandle> = world.bodies[body].colliders().to_vec();
    for c in handles {
        if let Some(co) = world.colliders.get_mut(c) {
            co.set_collision_groups(groups);
            co.set_active_collision_types(types);
        }
    }
}

/// Everything that changes while stepping (what a snapshot holds besides the physics sets).
#[derive(Debug, Clone)]
pub(crate) struct Dynamic {
    pub robot: RobotState,
    pub held: Option<Held>,
    /// Physics substeps since reset (time = substeps × dt, exact).
    pub substeps: u64,
    pub steps: u64,
    pub task: Option<Task>,
}

/// The kitchen twin.
pub struct Sim {
    pub(crate) assets: Assets,
    pub(crate) config: SimConfig,
    pub(crate) sensors: SensorsConfig,
    pub(crate) world: PhysicsWorld,
    pub(crate) materials: Materials,
    pub(crate) robot: Robot,
    pub(crate) objects: Vec<ObjectBody>,
    pub(crate) episode: EpisodeConfig,
    pub(crate) dynamic: Dynamic,
}

impl std::fmt::Debug for Sim {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Sim")
            .field("episode", &self.episode.id)
            .field("time", &self.time())
            .finish()
    }
}

impl Sim {
    /// Build a simulator and reset it to `episode`.
    pub fn new(
        assets: Assets,
        config: SimConfig,
        sensors: SensorsConfig,
        episode: &EpisodeConfig,
    ) -> Result<(Sim, Observation), SimError> {
        config.validate()?;
        sensors.validate()?;
        let (world, materials, robot, objects, dynamic) = build(&assets, &config, episode)?;
        let sim = Sim {
            assets,
            config,
            sensors,
            world,
            materials,
            robot,
            objects,
            episode: episode.clone(),
            dynamic,
        };
        let obs = sim.observe();
        Ok((sim, obs))
    }

    /// Rebuild the world for `episode` and return the first observation.
    pub fn reset(&mut self, episode: &EpisodeConfig) -> Result<Observation, SimError> {
        let (world, materials, robot, objects, dynamic) = build(&self.assets, &self.config, episode)?;
        (self.world, self.materials, self.robot, self.objects, self.dynamic) =
            (world, materials, robot, objects, dynamic);
        self.episode = episode.clone();
        Ok(self.observe())
    }

    pub fn time(&self) -> f64 {
        self.dynamic.substeps as f64 * self.config.physics.dt()
    }

    pub fn episode(&self) -> &EpisodeConfig {
        &self.episode
    }

    pub fn scene(&self) -> &Scene {
        self.assets
            .scene(&self.episode.scene)
            .unwrap_or(&self.assets.scenes[0])
    }

    pub fn config(&self) -> &SimConfig {
        &self.config
    }

    pub fn robot(&self) -> &Robot {
        &self.robot
    }

    /// Apply `action` for one control step; render an observation only when `render` is set.
    pub fn step(
        &mut self,
        action: &Action,
        render: bool,
    ) -> Result<(Option<Observation>, StepInfo), SimError> {
        action.validate()?;
        let [qw, qx, qy, qz] = action.quaternion();
        let rot = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(qw, qx, qy, qz));
        let [x, y, z] = action.position();
        let mut cmd = RobotCommand {
            v: action.v(),
            omega: action.omega(),
            ee_target: Isometry3::from_parts(Translation3::new(x, y, z), rot),
            opening: action.gripper(),
            min_opening: 0.0,
        };
        let dt = self.config.physics.dt();
        let mut blocked = false;
        for _ in 0..self.config.physics.substeps {
            cmd.min_opening = self.dynamic.held.map_or(0.0, |h| h.width);
            let next_base = self.robot.command(
                &mut self.world,
                &mut self.dynamic.robot,
                &self.config.rmp,
                &cmd,
                dt,
            );
            self.update_grasp(action.gripper());
            self.carry(&next_base);
            self.world.step();
            let carried = self.dynamic.held.map(|h| self.objects[h.object].body);
            self.robot
                .enforce_obstacles(&self.world, &mut self.dynamic.robot, carried);
            blocked |= self.dynamic.robot.arm_blocked;
            self.dynamic.substeps += 1;
        }
        self.dynamic.steps += 1;
        let facts = self.facts();
        let task = self.update_task(&facts);
        let names: Vec<String> = self.objects.iter().map(|o| o.name.clone()).collect();
        let monitors = objects_on_floor(&self.config.monitors, &facts, &names);
        let mut info = self.info(task, monitors);
        info.arm_blocked = blocked;
        Ok((render.then(|| self.observe()), info))
    }

    /// Attach an object whose grasp point (or centre) is between the closing fingers; release on open.
    fn update_grasp(&mut self, g: f64) {
        let grip = &self.robot.desc.gripper;
        if let Some(h) = self.dynamic.held {
            if g > grip.release_threshold {
                set_carried(&mut self.world, self.objects[h.object].body, false);
                self.dynamic.held = None;
            }
            return;
        }
        let opening = self.dynamic.robot.opening;
        if g >= grip.grasp_threshold || opening < 0.01 {
            return;
        }
        let tcp = self.robot.tcp_world(&self.world, &self.dynamic.robot);
        let inside = |p: Point3<f64>| {
            let l = tcp.inverse_transform_point(&p);
            l.x.abs() <= grip.finger_length / 2.0 + 0.01
                && l.y.abs() <= opening / 2.0
                && l.z.abs() <= grip.finger_height / 2.0 + 0.015
        };
        let found = self.objects.iter().position(|o| {
            let pose = pose_to_iso(self.world.bodies[o.body].position());
            inside(pose * Point3::from(o.grasp_offset)) || inside(pose * Point3::origin())
        });
        if let Some(i) = found {
            let body = self.objects[i].body;
            let obj_pose = pose_to_iso(self.world.bodies[body].position());
            let offset = tcp.inverse() * obj_pose;
            // Rigid attachment: the object becomes a kinematic body carried at its grasp offset from
            // the TCP (a fixed joint to the ideal position-controlled wrist). rapier's islands reject
            // joints anchored on kinematic links, and a joint to the base would lag the wrist.
            set_carried(&mut self.world, body, true);
            self.dynamic.held = Some(Held {
                object: i,
                width: opening,
                offset,
            });
        }
    }

    /// Move the held object with the TCP to where the links go this substep.
    fn carry(&mut self, next_base: &Isometry3<f64>) {
        let Some(h) = self.dynamic.held else { return };
        let pose = next_base * self.robot.arm.forward(&self.dynamic.robot.arm.q).tcp * h.offset;
        let body = self.objects[h.object].body;
        self.world.bodies[body].set_next_kinematic_position(iso_to_pose(&pose));
    }

    /// Start judging plan step `index` of the episode as the current task.
    pub fn begin_task(&mut self, index: usize) -> Result<(), SimError> {
        let target = task_target(&self.episode, self.scene(), index)?;
        let facts = self.facts();
        self.dynamic.task = Some(Task::new(index, self.episode.plan[index].clone(), target, &facts));
        Ok(())
    }

    /// Stop the current task; returns its final status with the end-of-task monitor applied.
    pub fn end_task(&mut self) -> Option<TaskStatus> {
        let facts = self.facts();
        let mut task = self.dynamic.task.take()?;
        let mut status = task.update(&self.config.success, &self.config.monitors, &facts);
        if status.failure.is_none() {
            status.failure = task.end_checks(&self.config.monitors, &facts);
        }
        Some(status)
    }

    fn update_task(&mut self, facts: &Facts) -> Option<TaskStatus> {
        let (s, m) = (&self.config.success, &self.config.monitors);
        self.dynamic.task.as_mut().map(|t| t.update(s, m, facts))
    }

    /// Privileged world facts for success checks and monitors.
    pub fn facts(&self) -> Facts {
        let tcp = self.robot.tcp_world(&self.world, &self.dynamic.robot);
        let base = self.robot.base_pose(&self.world);
        let mut f = Facts {
            time: self.time(),
            base_xy: [base[0], base[1]],
            objects: Vec::new(),
            bottoms: Vec::new(),
            held: self.dynamic.held.map(|h| h.object),
            tcp_to_grasp: Vec::new(),
        };
        for o in &self.objects {
            let pose = pose_to_iso(self.world.bodies[o.body].position());
            let c = pose.translation.vector;
            f.objects.push([c.x, c.y, c.z]);
            f.bottoms.push(c.z - o.half_height);
            let g = pose * Point3::from(o.grasp_offset);
            f.tcp_to_grasp
                .push((g - Point3::from(tcp.translation.vector)).norm());
        }
        f
    }

    /// World pose `[x, y, z, yaw]`-free isometry of every key object, in episode order.
    pub fn object_poses(&self) -> Vec<(String, Isometry3<f64>)> {
        self.objects
            .iter()
            .map(|o| (o.name.clone(), pose_to_iso(self.world.bodies[o.body].position())))
            .collect()
    }

    /// The current task's target, if any.
    pub fn current_task(&self) -> Option<&Task> {
        self.dynamic.task.as_ref()
    }

    pub fn held_object(&self) -> Option<&str> {
        self.dynamic.held.map(|h| self.objects[h.object].name.as_str())
    }

    /// Arm joint targets and velocities.
    pub fn joints(&self) -> ([f64; 6], [f64; 6]) {
        let a = &self.dynamic.robot.arm;
        (std::array::from_fn(|i| a.q[i]), std::array::from_fn(|i| a.qd[i]))
    }

    /// TCP pose in the base frame.
    pub fn ee_pose(&self) -> Isometry3<f64> {
        self.robot.arm.forward(&self.dynamic.robot.arm.q).tcp
    }

    pub fn base_pose(&self) -> [f64; 3] {
        self.robot.base_pose(&self.world)
    }

    fn info(&self, task: Option<TaskStatus>, monitors: Vec<MonitorTrip>) -> StepInfo {
        let (v, w) = self.robot.base_velocity(&self.world);
        let ee = self.ee_pose();
        let ee_w = self.robot.tcp_world(&self.world, &self.dynamic.robot);
        let pack = |i: &Isometry3<f64>| {
            let (t, r) = (i.translation.vector, i.rotation);
            [t.x, t.y, t.z, r.w, r.i, r.j, r.k]
        };
        let (joints, _) = self.joints();
        StepInfo {
            time: self.time(),
            step: self.dynamic.steps,
            base_pose: self.base_pose(),
            base_velocity: [v, w],
            ee_pose: pack(&ee),
            ee_world: pack(&ee_w),
            joints,
            gripper: self.dynamic.robot.opening / self.robot.desc.gripper.max_opening,
            held_object: self.held_object().map(String::from),
            contacts: self.contacts(),
            arm_blocked: self.dynamic.robot.arm_blocked,
            task,
            monitors,
        }
    }

    /// Every touching pair between a robot collider and anything else.
    pub fn contacts(&self) -> Vec<Contact> {
        let mut out = Vec::new();
        for pair in self.world.contact_pairs() {
            let (Some(a), Some(b)) = (
                self.world.colliders.get(pair.collider1),
                self.world.colliders.get(pair.collider2),
            ) else {
                continue;
            };
            let (ta, tb) = (Tag::unpack(a.user_data), Tag::unpack(b.user_data));
            let (robot, other) = match (ta.owner, tb.owner) {
                (Owner::Robot, o) if o != Owner::Robot => (ta, tb),
                (o, Owner::Robot) if o != Owner::Robot => (tb, ta),
                _ => continue,
            };
            let Some((_, deepest)) = pair.find_deepest_contact() else {
                continue;
            };
            if deepest.dist > 0.0 {
                continue;
            }
            let other = match other.owner {
                Owner::KeyObject => self
                    .objects
                    .get(other.index as usize)
                    .map_or("object".into(), |o| o.name.clone()),
                Owner::Background => format!(
                    "background:{}",
                    self.episode
                        .background
                        .get(other.index as usize)
                        .map_or("?", |o| o.model.as_str())
                ),
                _ => "scene".into(),
            };
            out.push(Contact {
                robot_part: PART_NAMES
                    .get(robot.index as usize)
                    .copied()
                    .unwrap_or("robot")
                    .into(),
                other,
                depth: -f64::from(deepest.dist),
            });
        }
        out
    }

    /// Render the configured cameras and LiDAR and read odometry.
    pub fn observe(&self) -> Observation {
        let base = self.robot.base_iso(&self.world);
        let tcp = self.robot.tcp_world(&self.world, &self.dynamic.robot);
        let mount = |m: Mount| match m {
            Mount::Base => base,
            Mount::Gripper => tcp,
            Mount::World => Isometry3::identity(),
        };
        let ctx = RenderCtx {
            world: &self.world,
            materials: &self.materials.list,
            light: &self.sensors.light,
        };
        let images = self
            .sensors
            .cameras
            .iter()
            .map(|c| ctx.camera(c, &mount(c.mount)))
            .collect();
        let lidar = self.sensors.lidar.as_ref().map(|l| {
            let pose = mount(l.mount) * Translation3::from(Vector3::from(l.position));
            crate::sensors::lidar::scan(&self.world, l, &pose)
        });
        let s = self.episode.robot_start;
        let start = crate::convert::planar(s[0], s[1], 0.0, s[2]);
        let rel = start.inverse() * base;
        let (v, w) = self.robot.base_velocity(&self.world);
        let (joints, _) = self.joints();
        Observation {
            time: self.time(),
            images,
            lidar,
            odometry: Odometry {
                pose: [
                    rel.translation.x,
                    rel.translation.y,
                    crate::convert::yaw_of(&rel.rotation),
                ],
                velocity: [v, w],
            },
            joints,
            gripper: self.dynamic.robot.opening / self.robot.desc.gripper.max_opening,
            task: self.dynamic.task.as_ref().map(|t| t.step.clone()),
        }
    }
}

type Built = (PhysicsWorld, Materials, Robot, Vec<ObjectBody>, Dynamic);

fn build(assets: &Assets, config: &SimConfig, ep: &EpisodeConfig) -> Result<Built, SimError> {
    let scene = assets.scene(&ep.scene)?;
    ep.validate(scene, &assets.catalogue)?;
    let mut world = PhysicsWorld::new();
    world.gravity = vec_to_glam(&Vector3::new(0.0, 0.0, config.physics.gravity));
    world.integration_parameters.dt = config.physics.dt() as f32;
    world.integration_parameters.num_solver_iterations = config.physics.solver_iterations as usize;
    let mut materials = Materials::default();
    build_static(&mut world, &mut materials, scene, &ep.style);
    let mut objects = Vec::new();
    for (list, owner) in [
        (&ep.objects, Owner::KeyObject),
        (&ep.background, Owner::Background),
    ] {
        for (i, o) in list.iter().enumerate() {
            let model = assets
                .catalogue
                .model(&o.model)
                .ok_or_else(|| SimError::UnknownObject(o.model.clone()))?;
            let [x, y, z] = o.position;
            let pose = crate::convert::planar(x, y, z, o.yaw);
            let body = spawn_object(&mut world, &mut materials, model, o.color, pose, owner, i as u32);
            if owner == Owner::KeyObject {
                objects.push(ObjectBody {
                    name: o.name.clone(),
                    body,
                    half_height: model.shape.half_height(),
                    grasp_offset: Vector3::from(model.grasp_offset),
                });
            }
        }
    }
    let (robot, state) = Robot::spawn(&mut world, &mut materials, &assets.robot, ep.robot_start);
    crate::preflight::check(&world, &objects)?;
    // Fill the broad phase so sensors can see the world before the first step.
    world.detect_collisions(&(), &());
    let dynamic = Dynamic {
        robot: state,
        held: None,
        substeps: 0,
        steps: 0,
        task: None,
    };
    Ok((world, materials, robot, objects, dynamic))
}
