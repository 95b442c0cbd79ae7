//! Wire ↔ domain: the simulator's observation as the policy contract's `Observation` (images
//! cut to what the policy asked for in GetSpec) and back, privileged state both ways, and
//! action chunks both ways.

use std::io::Cursor;

use image::{ExtendedColorType, ImageBuffer, Rgb, imageops};
use kitchen_r_proto::policy::v1 as pb;
use kitchen_r_sim::Observation;
use kitchen_r_sim::sensors::CameraImage;
use kitchen_r_sim::task::TaskTarget;
use kitchen_r_sim::types::Odometry;

use crate::SimCamera;
use kitchen_r_episode::policy::{ACTION_DIM, PolicyError, PolicyInput, Privileged, PrivilegedObject};

/// JPEG quality promised in `policy.proto`.
const JPEG_QUALITY: u8 = 90;
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

/// The observation the policy receives for `input`.
pub(crate) fn observation(
    input: &PolicyInput<'_>,
    cameras: &[CameraPlan],
) -> Result<pb::Observation, PolicyError> {
    let o = input.observation;
    let mut images = Vec::with_capacity(cameras.len());
    let mut depth = Vec::new();
    for plan in cameras {
        let img = o.images.iter().find(|i| i.name == plan.name).ok_or_else(|| {
            PolicyError::Call(format!(
                "the simulator rendered no image for camera {:?}",
                plan.name
            ))
        })?;
        images.push(encode_rgb(img, plan)?);
        if plan.depth {
            depth.push(encode_depth(img, plan));
        }
    }
    let [x, y, yaw] = o.odometry.pose;
    let [v, w] = o.odometry.velocity;
    Ok(pb::Observation {
        episode_id: input.episode_id.to_string(),
        step: input.step,
        task_index: input.task_index as u32,
        sub_task: input.sub_task.to_string(),
        images,
        depth,
        robot: Some(pb::RobotState {
            base_x: x,
            base_y: y,
            base_yaw: yaw,
            base_v: v,
            base_omega: w,
            arm_joints: o.joints.to_vec(),
            ee_pose: input.privileged.map(|p| p.ee_pose.to_vec()).unwrap_or_default(),
            gripper: o.gripper,
        }),
        sim_time: o.time,
        privileged: input.privileged.map(privileged_to_wire),
    })
}

fn encode_rgb(img: &CameraImage, plan: &CameraPlan) -> Result<pb::Image, PolicyError> {
    let resized;
    let rgb: &[u8] = if (img.width, img.height) == (plan.width, plan.height) {
        &img.rgb
    } else {
        let src: ImageBuffer<Rgb<u8>, &[u8]> = ImageBuffer::from_raw(img.width, img.height, &img.rgb[..])
            .ok_or_else(|| PolicyError::Call(format!("camera {:?}: malformed frame", img.name)))?;
        resized = imageops::resize(&src, plan.width, plan.height, imageops::FilterType::Triangle).into_raw();
        &resized
    };
    let data = match plan.encoding {
        pb::ImageEncoding::Jpeg => {
            let mut buf = Cursor::new(Vec::with_capacity(rgb.len() / 8));
            image::codecs::jpeg::JpegEncoder::new_with_quality(&mut buf, JPEG_QUALITY)
                .encode(rgb, plan.width, plan.height, ExtendedColorType::Rgb8)
                .map_err(|e| PolicyError::Call(format!("camera {:?}: JPEG encoding: {e}", plan.name)))?;
            buf.into_inner()
        }
        _ => rgb.to_vec(),
    };
    Ok(pb::Image {
        camera: plan.name.clone(),
        width: plan.width,
        height: plan.height,
        encoding: plan.encoding as i32,
        data,
    })
}

/// Depth as little-endian f32, nearest-neighbour resampled; the simulator's 0 (no return)
/// becomes +inf as the contract says.
fn encode_depth(img: &CameraImage, plan: &CameraPlan) -> pb::DepthImage {
    let (w, h) = (plan.width as usize, plan.height as usize);
    let (sw, sh) = (img.width as usize, img.height as usize);
    let mut data = Vec::with_capacity(w * h * 4);
    for r in 0..h {
        let sr = r * sh / h;
        for c in 0..w {
            let d = img.depth.get(sr * sw + c * sw / w).copied().unwrap_or(0.0);
            let d = if d > 0.0 { d } else { f32::INFINITY };
            data.extend_from_slice(&d.to_le_bytes());
        }
    }
    pb::DepthImage {
        camera: plan.name.clone(),
        width: plan.width,
        height: plan.height,
        data,
    }
}

/// The observation a served in-process policy sees: the wire message back in the
/// simulator's types (RAW and JPEG images decoded, +inf depth back to 0).
pub(crate) fn observation_from_wire(o: &pb::Observation) -> Result<Observation, String> {
    let mut images = Vec::with_capacity(o.images.len());
    for i in &o.images {
        let rgb = match pb::ImageEncoding::try_from(i.encoding) {
            Ok(pb::ImageEncoding::Jpeg) => {
                image::load_from_memory_with_format(&i.data, image::ImageFormat::Jpeg)
                    .map_err(|e| format!("camera {:?}: bad JPEG: {e}", i.camera))?
                    .to_rgb8()
                    .into_raw()
            }
            _ => i.data.clone(),
        };
        if rgb.len() != (i.width * i.height * 3) as usize {
            return Err(format!(
                "camera {:?}: {} bytes for {}x{} RGB8",
                i.camera,
                rgb.len(),
                i.width,
                i.height
            ));
        }
        let depth = o
            .depth
            .iter()
            .find(|d| d.camera == i.camera)
            .map_or_else(Vec::new, |d| {
                d.data
                    .chunks_exact(4)
                    .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                    .map(|v| if v.is_finite() { v } else { 0.0 })
                    .collect()
            });
        images.push(CameraImage {
            name: i.camera.clone(),
            width: i.width,
            height: i.height,
            rgb,
            depth,
        });
    }
    let r = o.robot.clone().unwrap_or_default();
    let mut joints = [0.0; 6];
    for (j, v) in joints.iter_mut().zip(&r.arm_joints) {
        *j = *v;
    }
    Ok(Observation {
        time: o.sim_time,
        images,
        lidar: None,
        odometry: Odometry {
            pose: [r.base_x, r.base_y, r.base_yaw],
            velocity: [r.base_v, r.base_omega],
        },
        joints,
        gripper: r.gripper,
        task: Some(o.sub_task.clone()),
    })
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

    fn frame() -> Observation {
        let img = CameraImage {
            name: "base".into(),
            width: 128,
            height: 128,
            rgb: (0..128 * 128 * 3).map(|i| (i % 256) as u8).collect(),
            depth: (0..128 * 128)
                .map(|i| if i % 2 == 0 { 0.0 } else { 2.0 })
                .collect(),
        };
        Observation {
            time: 1.5,
            images: vec![img],
            lidar: None,
            odometry: Odometry {
                pose: [1.0, 2.0, 0.5],
                velocity: [0.1, 0.2],
            },
            joints: [0.1; 6],
            gripper: 0.7,
            task: None,
        }
    }

    #[test]
    fn jpeg_resized_with_depth_round_trips() {
        let obs = frame();
        let plan = CameraPlan {
            name: "base".into(),
            width: 64,
            height: 32,
            encoding: pb::ImageEncoding::Jpeg,
            depth: true,
        };
        let input = PolicyInput {
            episode_id: "e",
            step: 3,
            task_index: 1,
            sub_task: "pick the bowl",
            observation: &obs,
            privileged: None,
        };
        let wire = observation(&input, std::slice::from_ref(&plan)).unwrap();
        assert_eq!(&wire.images[0].data[..2], &[0xFF, 0xD8], "a JPEG file");
        let d = &wire.depth[0].data;
        assert_eq!(d.len(), 64 * 32 * 4);
        assert_eq!(
            f32::from_le_bytes([d[0], d[1], d[2], d[3]]),
            f32::INFINITY,
            "no return is +inf"
        );
        assert!(wire.privileged.is_none() && wire.robot.as_ref().unwrap().ee_pose.is_empty());
        let back = observation_from_wire(&wire).unwrap();
        assert_eq!(
            (back.images[0].width, back.images[0].rgb.len()),
            (64, 64 * 32 * 3)
        );
        assert_eq!(back.images[0].depth[0], 0.0);
        assert_eq!(back.odometry, obs.odometry);
    }

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
