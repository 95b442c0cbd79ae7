//! Wire ↔ domain: the cameras a GetSpec asks for, the observation (in [`mod@observation`]: the
//! simulator's frames as the policy contract's `Observation` and back), privileged state both
//! ways, and action chunks both ways.

mod observation;
pub(crate) mod privileged;

use kitchen_r_proto::policy::v1 as pb;
use kitchen_r_sim::task::TaskTarget;

use crate::SimCamera;
use kitchen_r_episode::policy::{ACTION_DIM, PolicyError, Privileged, PrivilegedObject};

pub(crate) use observation::{
    action_from_wire, ee_pose_from_wire, encode_rgb, frame_from_wire, observation, observation_from_wire,
};

/// Largest side a policy may ask for (`policy.proto`).
pub(crate) const MAX_SIDE: u32 = 1024;

/// One camera as the policy asked for it in GetSpec, checked against the simulator's cameras.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct CameraPlan {
    pub(crate) name: String,
    pub(crate) width: u32,
    pub(crate) height: u32,
    pub(crate) encoding: pb::ImageEncoding,
    pub(crate) depth: bool,
}

/// The cameras to send: the spec's requests, or `base` and `gripper` at 128×128 RAW_RGB8
/// without depth when it names none; every name must be a simulator camera.
pub(crate) fn plan_cameras(spec: &pb::PolicySpec, sim: &[SimCamera]) -> Result<Vec<CameraPlan>, String> {
    let defaults = || {
        ["base", "gripper"].map(|n| pb::CameraRequest {
            name: n.into(),
            width: 128,
            height: 128,
            encoding: pb::ImageEncoding::RawRgb8 as i32,
            depth: false,
        })
    };
    let requests = if spec.cameras.is_empty() {
        defaults().to_vec()
    } else {
        spec.cameras.clone()
    };
    let names: Vec<&str> = sim.iter().map(|c| c.name.as_str()).collect();
    let mut out: Vec<CameraPlan> = Vec::new();
    for r in requests {
        if !names.contains(&r.name.as_str()) {
            return Err(format!(
                "camera {:?} is not one of the simulator's cameras {names:?}",
                r.name
            ));
        }
        if out.iter().any(|c| c.name == r.name) {
            return Err(format!("camera {:?} is requested twice", r.name));
        }
        if !(1..=MAX_SIDE).contains(&r.width) || !(1..=MAX_SIDE).contains(&r.height) {
            return Err(format!(
                "camera {:?}: resolution {}x{} is outside 1..={MAX_SIDE}",
                r.name, r.width, r.height
            ));
        }
        let encoding = match pb::ImageEncoding::try_from(r.encoding) {
            Ok(pb::ImageEncoding::Unspecified) => pb::ImageEncoding::RawRgb8,
            Ok(e) => e,
            Err(_) => {
                return Err(format!(
                    "camera {:?}: unknown image encoding {}",
                    r.name, r.encoding
                ));
            }
        };
        out.push(CameraPlan {
            name: r.name,
            width: r.width,
            height: r.height,
            encoding,
            depth: r.depth,
        });
    }
    Ok(out)
}

pub(crate) fn privileged_to_wire(p: &Privileged) -> pb::Privileged {
    let target = match p.target {
        TaskTarget::Base { x, y, yaw } => pb::task_target::Target::Base(pb::BaseTarget { x, y, yaw }),
        TaskTarget::Pick { object } => pb::task_target::Target::PickObject(object as u32),
        TaskTarget::Place { object, target } => pb::task_target::Target::Place(pb::PlaceTarget {
            object: object as u32,
            target: target.to_vec(),
        }),
    };
    pb::Privileged {
        scene: p.scene.clone(),
        base_x: p.base_pose[0],
        base_y: p.base_pose[1],
        base_yaw: p.base_pose[2],
        objects: p
            .objects
            .iter()
            .map(|o| pb::PrivilegedObject {
                name: o.name.clone(),
                model: o.model.clone(),
                pose: o.pose.to_vec(),
            })
            .collect(),
        held: p.held.clone().unwrap_or_default(),
        ee_pose: p.ee_pose.to_vec(),
        target: Some(pb::TaskTarget { target: Some(target) }),
    }
}

pub(crate) fn privileged_from_wire(p: &pb::Privileged) -> Result<Privileged, String> {
    let arr7 = |v: &[f64], what: &str| -> Result<[f64; 7], String> {
        v.try_into()
            .map_err(|_| format!("{what} has {} values, not 7", v.len()))
    };
    let target = match p.target.as_ref().and_then(|t| t.target.as_ref()) {
        Some(pb::task_target::Target::Base(b)) => TaskTarget::Base {
            x: b.x,
            y: b.y,
            yaw: b.yaw,
        },
        Some(pb::task_target::Target::PickObject(o)) => TaskTarget::Pick { object: *o as usize },
        Some(pb::task_target::Target::Place(pl)) => TaskTarget::Place {
            object: pl.object as usize,
            target: pl
                .target
                .as_slice()
                .try_into()
                .map_err(|_| "place target needs 3 values".to_string())?,
        },
        None => return Err("privileged.target is missing".into()),
    };
    Ok(Privileged {
        scene: p.scene.clone(),
        base_pose: [p.base_x, p.base_y, p.base_yaw],
        objects: p
            .objects
            .iter()
            .map(|o| {
                Ok(PrivilegedObject {
                    name: o.name.clone(),
                    model: o.model.clone(),
                    pose: arr7(&o.pose, "object pose")?,
                })
            })
            .collect::<Result<_, String>>()?,
        held: (!p.held.is_empty()).then(|| p.held.clone()),
        ee_pose: arr7(&p.ee_pose, "ee_pose")?,
        target,
    })
}

/// The actions of a chunk: `values_f64` when given, else `values`; exactly `horizon` × 10.
pub(crate) fn chunk_from_wire(
    c: &pb::ActionChunk,
    horizon: usize,
) -> Result<Vec<[f64; ACTION_DIM]>, PolicyError> {
    let values: Vec<f64> = if c.values_f64.is_empty() {
        c.values.iter().map(|&v| f64::from(v)).collect()
    } else {
        c.values_f64.clone()
    };
    let want = horizon * ACTION_DIM;
    if values.len() != want {
        return Err(PolicyError::BadChunk(format!(
            "expected {want} values ({horizon} actions of {ACTION_DIM}), got {}",
            values.len()
        )));
    }
    Ok(values
        .chunks_exact(ACTION_DIM)
        .map(|a| a.try_into().unwrap_or([f64::NAN; ACTION_DIM]))
        .collect())
}

/// A chunk on the wire, in both precisions so a reference policy reaches the sim bit for bit.
pub(crate) fn chunk_to_wire(chunk: &[[f64; ACTION_DIM]]) -> pb::ActionChunk {
    let flat: Vec<f64> = chunk.iter().flatten().copied().collect();
    pb::ActionChunk {
        values: flat.iter().map(|&v| v as f32).collect(),
        values_f64: flat,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unknown_cameras_and_sizes_are_refused() {
        let sim = [SimCamera {
            name: "base".into(),
            width: 128,
            height: 128,
        }];
        let spec = |name: &str, w: u32| pb::PolicySpec {
            cameras: vec![pb::CameraRequest {
                name: name.into(),
                width: w,
                height: 8,
                encoding: 0,
                depth: false,
            }],
            ..pb::PolicySpec::default()
        };
        assert_eq!(
            plan_cameras(&spec("base", 8), &sim).unwrap()[0].encoding,
            pb::ImageEncoding::RawRgb8
        );
        assert!(
            plan_cameras(&spec("thermal", 8), &sim)
                .unwrap_err()
                .contains("\"thermal\"")
        );
        assert!(
            plan_cameras(&spec("base", 2048), &sim)
                .unwrap_err()
                .contains("outside 1..=1024")
        );
        assert!(
            plan_cameras(&pb::PolicySpec::default(), &sim)
                .unwrap_err()
                .contains("\"gripper\"")
        );
    }
}
