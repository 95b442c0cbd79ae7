//! What the simulator reports: tasks and their checks, privileged state for the oracle and
//! success checks, contacts, step info and rendered observations.

use nalgebra::{Isometry3, Point3, Translation3, Vector3};

use crate::config::Mount;
use crate::convert::pose_to_iso;
use crate::error::SimError;
use crate::material::{Owner, Tag};
use crate::robot::PART_NAMES;
use crate::sensors::camera::RenderCtx;
use crate::sim::Sim;
use crate::task::{Facts, MonitorTrip, Task, TaskStatus, task_target};
use crate::types::{Contact, Observation, Odometry, StepInfo};

impl Sim {
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

    pub(crate) fn update_task(&mut self, facts: &Facts) -> Option<TaskStatus> {
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

    /// How far the current task is from success, in words (see [`Task::shortfall`]).
    pub fn task_shortfall(&self) -> Option<String> {
        let task = self.dynamic.task.as_ref()?;
        let name = |i: usize| {
            self.objects
                .get(i)
                .map_or_else(|| format!("object {i}"), |o| o.name.clone())
        };
        Some(task.shortfall(&self.config.success, &self.facts(), &name))
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

    pub(crate) fn info(&self, task: Option<TaskStatus>, monitors: Vec<MonitorTrip>) -> StepInfo {
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
        let mut out: Vec<Contact> = self
            .dynamic
            .static_touches
            .iter()
            .map(|(part, depth)| Contact {
                robot_part: PART_NAMES.get(*part as usize).copied().unwrap_or("robot").into(),
                other: "scene".into(),
                depth: *depth,
            })
            .collect();
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
        let mut obs = self.observe_state();
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
            light: self.light(),
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
        obs.images = images;
        obs.lidar = lidar;
        obs
    }

    /// Odometry, joints, gripper and task without rendering anything (`images` empty, no
    /// LiDAR): for steps where nobody looks at the sensors.
    pub fn observe_state(&self) -> Observation {
        let base = self.robot.base_iso(&self.world);
        let s = self.episode.robot_start;
        let start = crate::convert::planar(s[0], s[1], 0.0, s[2]);
        let rel = start.inverse() * base;
        let (v, w) = self.robot.base_velocity(&self.world);
        let (joints, _) = self.joints();
        Observation {
            time: self.time(),
            images: Vec::new(),
            lidar: None,
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
