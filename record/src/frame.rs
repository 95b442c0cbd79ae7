//! One recorded control step as every writer (MCAP, HDF5, LeRobot) takes it, and the sensor
//! mounts they publish: shared by `collect` and by recording a replay (`crate::replay`), so a
//! replayed episode's MCAP has the same topics, frames and values as a collected one.

use kitchen_r_sim::SensorsConfig;
use kitchen_r_sim::{Action, Observation, Sim, StepInfo};

use crate::{CameraFrame, Frame, StaticTransform};

/// Keep only the cameras `names` of `sensors`, in their configured order (the order of the
/// recorded topics and datasets); an unknown name is an error listing the configured ones.
pub fn keep_cameras(sensors: &mut SensorsConfig, names: &[String]) -> Result<(), String> {
    let known: Vec<&str> = sensors.cameras.iter().map(|c| c.name.as_str()).collect();
    if let Some(bad) = names.iter().find(|n| !known.contains(&n.as_str())) {
        return Err(format!("no camera {bad:?} (configured: {})", known.join(", ")));
    }
    sensors.cameras.retain(|c| names.contains(&c.name));
    Ok(())
}

/// The [`Frame`] of one control step from its rendered observation (`depth`: keep depth images).
pub(crate) fn frame_of(
    sim: &Sim,
    obs: Observation,
    action: &Action,
    info: &StepInfo,
    task: usize,
    depth: bool,
) -> Frame {
    // Odometry as the policy contract gives it (relative to the episode's start pose), not
    // the world pose in `info`: a policy trained on recordings must see what it is sent.
    let base_pose = obs.odometry.pose;
    let (_, qd) = sim.joints();
    let mut qpos = info.joints.to_vec();
    qpos.push(info.gripper);
    let mut qvel = qd.to_vec();
    qvel.push(0.0);
    Frame {
        time: info.time,
        cameras: obs
            .images
            .into_iter()
            .map(|c| CameraFrame {
                name: c.name,
                width: c.width,
                height: c.height,
                rgb: c.rgb,
                depth: if depth { c.depth } else { Vec::new() },
            })
            .collect(),
        lidar: obs.lidar.map(|l| l.points),
        base_pose,
        base_twist: info.base_velocity,
        action: action.0,
        qpos,
        qvel,
        ee_pose: info.ee_pose,
        task,
    }
}

/// Static transforms of the sensor mounts (`/tf_static`).
pub(crate) fn mounts(sensors: &SensorsConfig) -> Vec<StaticTransform> {
    use kitchen_r_sim::config::Mount;
    let parent = |m: Mount| match m {
        Mount::Base => "base_link",
        Mount::Gripper => "ee_link",
        Mount::World => "odom",
    };
    let mut out: Vec<StaticTransform> = sensors
        .cameras
        .iter()
        .map(|c| {
            let q = nalgebra::UnitQuaternion::from_euler_angles(c.rpy[0], c.rpy[1], c.rpy[2]);
            StaticTransform {
                parent: parent(c.mount).into(),
                child: format!("{}_optical_frame", c.name),
                translation: c.position,
                rotation: [q.w, q.i, q.j, q.k],
            }
        })
        .collect();
    if let Some(l) = &sensors.lidar {
        out.push(StaticTransform {
            parent: parent(l.mount).into(),
            child: "lidar".into(),
            translation: l.position,
            rotation: [1.0, 0.0, 0.0, 0.0],
        });
    }
    out
}
