//! The simulator: [`Sim::reset`] builds the world from an [`EpisodeConfig`], [`Sim::step`] applies
//! one 10-value action for one control step (fixed physics substeps in between), snapshots restore
//! the whole state bit for bit.

use kitchen_r_core::GraspMode;
use kitchen_r_core::catalogue::Catalogue;
use kitchen_r_core::scene::Scene;
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use rapier3d::prelude::*;

use crate::config::{RobotConfig, SensorsConfig, SimConfig};
use crate::convert::vec_to_glam;
use crate::episode::EpisodeConfig;
use crate::error::SimError;
use crate::material::{Materials, Owner};
use crate::robot::desc::RobotDesc;
use crate::robot::{Robot, RobotCommand, RobotState};
use crate::task::{Task, objects_on_floor};
use crate::types::{Action, Observation, StepInfo};
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
        Assets::load(&kitchen_r_core::assets::assets_dir())
    }

    /// Everything under `dir`: `objects.toml`, `scenes/`, and the robot that `[robot] file` of
    /// `configs/sim.toml` names (the shipped `robots/kitchen_r_aloha.urdf` by default).
    pub fn load(dir: &std::path::Path) -> Result<Assets, SimError> {
        Assets::load_with_robot(dir, &SimConfig::load_default()?.robot)
    }

    /// Everything under `dir`, with the robot `robot` names.
    pub fn load_with_robot(dir: &std::path::Path, robot: &RobotConfig) -> Result<Assets, SimError> {
        let catalogue = Catalogue::load(&dir.join("objects.toml"))?;
        crate::mesh::load_catalogue(&catalogue)?;
        let scenes = Scene::load_all(&dir.join("scenes"), &catalogue)?;
        crate::mesh::load_scenes(&scenes)?;
        let robot = RobotDesc::load(&robot.path(dir))?;
        crate::mesh::load_robot(&robot)?;
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

pub use crate::bodies::{Held, ObjectBody};

/// Everything that changes while stepping (what a snapshot holds besides the physics sets).
#[derive(Debug, Clone)]
pub(crate) struct Dynamic {
    pub robot: RobotState,
    pub held: Option<Held>,
    /// Physics substeps since reset (time = substeps × dt, exact).
    pub substeps: u64,
    pub steps: u64,
    pub task: Option<Task>,
    /// Robot parts touching fixed geometry after the last substep: `(part, depth)`.
    pub static_touches: Vec<(u32, f64)>,
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

    /// The light images are shaded with: the episode's own, else the sensors'.
    pub fn light(&self) -> &crate::config::LightConfig {
        self.episode.style.light.as_ref().unwrap_or(&self.sensors.light)
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
        let physical = self.robot.bodies.articulation.is_some();
        for _ in 0..self.config.physics.substeps {
            if physical {
                // Fingers close until the object stops them; friction alone holds it.
                self.robot.command(
                    &mut self.world,
                    &mut self.dynamic.robot,
                    &self.config.rmp,
                    &cmd,
                    dt,
                );
                self.world.step();
                self.update_physical_hold();
                self.dynamic.static_touches =
                    self.robot.enforce_obstacles(&self.world, &mut self.dynamic.robot);
                blocked |= self.dynamic.robot.arm_blocked;
                self.dynamic.substeps += 1;
                continue;
            }
            cmd.min_opening = self.dynamic.held.map_or(0.0, |h| h.width);
            let next_base = self.robot.command(
                &mut self.world,
                &mut self.dynamic.robot,
                &self.config.rmp,
                &cmd,
                dt,
            );
            self.update_grasp(action.gripper());
            self.carry(&next_base, dt);
            self.world.step();
            self.dynamic.static_touches = self.robot.enforce_obstacles(&self.world, &mut self.dynamic.robot);
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
            let model = &assets
                .catalogue
                .model(&o.model)
                .ok_or_else(|| SimError::UnknownObject(o.model.clone()))?
                .in_mode(config.grasp.mode);
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
    let (robot, state) = match config.grasp.mode {
        GraspMode::Abstract => Robot::spawn(&mut world, &mut materials, &assets.robot, ep.robot_start),
        GraspMode::Physical => {
            for o in &objects {
                crate::bodies::set_groups(&mut world, o.body, Owner::KeyObject.physical_key_groups());
            }
            let a = &config.articulation;
            Robot::spawn_articulated(&mut world, &mut materials, &assets.robot, ep.robot_start, a)
        }
    };
    crate::preflight::check(&world, &objects)?;
    let dynamic = Dynamic {
        robot: state,
        held: None,
        substeps: 0,
        steps: 0,
        task: None,
        static_touches: Vec::new(),
    };
    Ok((world, materials, robot, objects, dynamic))
}
