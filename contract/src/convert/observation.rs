//! The policy's observation on the wire and back: images cut to what the policy asked for in
//! GetSpec, robot state with the hand pose, the previous action, and (contract v1.1) the
//! observation history padded to the frames asked for.

use std::io::Cursor;

use image::{ExtendedColorType, ImageBuffer, Rgb, imageops};
use kitchen_r_proto::policy::v1 as pb;
use kitchen_r_sim::Observation;
use kitchen_r_sim::sensors::CameraImage;
use kitchen_r_sim::types::Odometry;

use super::{CameraPlan, privileged_to_wire};
use kitchen_r_episode::policy::{ACTION_DIM, Frame, PolicyError, PolicyInput};

/// JPEG quality promised in `policy.proto`.
const JPEG_QUALITY: u8 = 90;

/// The observation the policy receives for `input`, with the `history - 1` frames before it
/// (contract v1.1), padded at the front with the task's first frame where the task is younger.
pub(crate) fn observation(
    input: &PolicyInput<'_>,
    cameras: &[CameraPlan],
    history: usize,
) -> Result<pb::Observation, PolicyError> {
    let o = input.observation;
    let (images, depth) = encode_images(o, cameras)?;
    let robot = robot_state(o, &input.ee_pose);
    let previous_action = input.previous_action.map_or_else(Vec::new, |a| a.to_vec());
    let want = history.saturating_sub(1);
    let shown = &input.history[input.history.len().saturating_sub(want)..];
    let mut frames = Vec::with_capacity(want);
    for f in shown {
        frames.push(frame_to_wire(f, cameras)?);
    }
    if frames.len() < want {
        let pad = match frames.first() {
            Some(f) => f.clone(),
            None => pb::Frame {
                step: input.step,
                sim_time: o.time,
                images: images.clone(),
                depth: depth.clone(),
                robot: Some(robot.clone()),
                previous_action: previous_action.clone(),
            },
        };
        frames.splice(0..0, std::iter::repeat_n(pad, want - frames.len()));
    }
    Ok(pb::Observation {
        episode_id: input.episode_id.to_string(),
        step: input.step,
        task_index: input.task_index as u32,
        sub_task: input.sub_task.to_string(),
        images,
        depth,
        robot: Some(robot),
        sim_time: o.time,
        privileged: input.privileged.map(privileged_to_wire),
        privileged_observation: input.privileged_observation.map(super::privileged::to_wire),
        previous_action,
        history: frames,
    })
}

/// Colour (and, where asked, depth) images of the planned cameras.
fn encode_images(
    o: &Observation,
    cameras: &[CameraPlan],
) -> Result<(Vec<pb::Image>, Vec<pb::DepthImage>), PolicyError> {
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
    Ok((images, depth))
}

/// Odometry, joints, gripper opening and the hand pose (in every run since v1.1).
fn robot_state(o: &Observation, ee_pose: &[f64; 7]) -> pb::RobotState {
    let [x, y, yaw] = o.odometry.pose;
    let [v, w] = o.odometry.velocity;
    pb::RobotState {
        base_x: x,
        base_y: y,
        base_yaw: yaw,
        base_v: v,
        base_omega: w,
        arm_joints: o.joints.to_vec(),
        ee_pose: ee_pose.to_vec(),
        gripper: o.gripper,
    }
}

fn frame_to_wire(f: &Frame, cameras: &[CameraPlan]) -> Result<pb::Frame, PolicyError> {
    let (images, depth) = encode_images(&f.observation, cameras)?;
    Ok(pb::Frame {
        step: f.step,
        sim_time: f.observation.time,
        images,
        depth,
        robot: Some(robot_state(&f.observation, &f.ee_pose)),
        previous_action: f.previous_action.map_or_else(Vec::new, |a| a.to_vec()),
    })
}

/// One camera's colour image at the plan's size and encoding (resized with a triangle filter).
pub(crate) fn encode_rgb(img: &CameraImage, plan: &CameraPlan) -> Result<pb::Image, PolicyError> {
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
    let r = o.robot.clone().unwrap_or_default();
    let mut obs = observation_parts(&o.images, &o.depth, &r, o.sim_time)?;
    obs.task = Some(o.sub_task.clone());
    Ok(obs)
}

/// A wire frame of an observation history back in the runner's types.
pub(crate) fn frame_from_wire(f: &pb::Frame) -> Result<Frame, String> {
    let r = f.robot.clone().unwrap_or_default();
    Ok(Frame {
        step: f.step,
        observation: observation_parts(&f.images, &f.depth, &r, f.sim_time)?,
        ee_pose: ee_pose_from_wire(&r.ee_pose)?,
        previous_action: action_from_wire(&f.previous_action)?,
    })
}

/// The 7-value hand pose; an empty one (a v1.0 worker) reads as zeros.
pub(crate) fn ee_pose_from_wire(v: &[f64]) -> Result<[f64; 7], String> {
    if v.is_empty() {
        return Ok([0.0; 7]);
    }
    v.try_into()
        .map_err(|_| format!("robot.ee_pose has {} values, not 7", v.len()))
}

/// A previous action: empty for none, else 10 values.
pub(crate) fn action_from_wire(v: &[f64]) -> Result<Option<[f64; ACTION_DIM]>, String> {
    if v.is_empty() {
        return Ok(None);
    }
    v.try_into()
        .map(Some)
        .map_err(|_| format!("previous_action has {} values, not {ACTION_DIM}", v.len()))
}

fn observation_parts(
    wire_images: &[pb::Image],
    wire_depth: &[pb::DepthImage],
    r: &pb::RobotState,
    sim_time: f64,
) -> Result<Observation, String> {
    let mut images = Vec::with_capacity(wire_images.len());
    for i in wire_images {
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
        let depth = wire_depth
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
    let mut joints = [0.0; 6];
    for (j, v) in joints.iter_mut().zip(&r.arm_joints) {
        *j = *v;
    }
    Ok(Observation {
        time: sim_time,
        images,
        lidar: None,
        odometry: Odometry {
            pose: [r.base_x, r.base_y, r.base_yaw],
            velocity: [r.base_v, r.base_omega],
        },
        joints,
        gripper: r.gripper,
        task: None,
    })
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
            ee_pose: [0.4, 0.0, 0.9, 1.0, 0.0, 0.0, 0.0],
            previous_action: None,
            history: &[],
            privileged: None,
            privileged_observation: None,
        };
        let wire = observation(&input, std::slice::from_ref(&plan), 1).unwrap();
        assert_eq!(&wire.images[0].data[..2], &[0xFF, 0xD8], "a JPEG file");
        let d = &wire.depth[0].data;
        assert_eq!(d.len(), 64 * 32 * 4);
        assert_eq!(
            f32::from_le_bytes([d[0], d[1], d[2], d[3]]),
            f32::INFINITY,
            "no return is +inf"
        );
        assert!(wire.privileged.is_none() && wire.history.is_empty() && wire.previous_action.is_empty());
        assert_eq!(
            wire.robot.as_ref().unwrap().ee_pose,
            input.ee_pose,
            "in every run"
        );
        let back = observation_from_wire(&wire).unwrap();
        assert_eq!(
            (back.images[0].width, back.images[0].rgb.len()),
            (64, 64 * 32 * 3)
        );
        assert_eq!(back.images[0].depth[0], 0.0);
        assert_eq!(back.odometry, obs.odometry);
    }

    #[test]
    fn history_is_padded_with_the_tasks_first_frame_and_round_trips() {
        let plan = CameraPlan {
            name: "base".into(),
            width: 8,
            height: 8,
            encoding: pb::ImageEncoding::RawRgb8,
            depth: false,
        };
        let frame = |step: u64| Frame {
            step,
            observation: Observation {
                time: step as f64 * 0.1,
                ..frame()
            },
            ee_pose: [step as f64; 7],
            previous_action: (step > 0).then_some([step as f64; ACTION_DIM]),
        };
        let (f4, f5, f6) = (frame(4), frame(5), frame(6));
        let earlier = [f4.clone(), f5.clone()];
        let input = |history: &'static str, h: &[Frame]| {
            let wire = observation(
                &PolicyInput {
                    episode_id: "e",
                    step: 6,
                    task_index: 0,
                    sub_task: history,
                    observation: &f6.observation,
                    ee_pose: f6.ee_pose,
                    previous_action: f6.previous_action,
                    history: h,
                    privileged: None,
                    privileged_observation: None,
                },
                std::slice::from_ref(&plan),
                4,
            )
            .unwrap();
            wire.history.iter().map(|f| f.step).collect::<Vec<_>>()
        };
        assert_eq!(
            input("two earlier", &earlier),
            [4, 4, 5],
            "padded with the oldest"
        );
        assert_eq!(
            input("none earlier", &[]),
            [6, 6, 6],
            "the first frame of the task"
        );
        let wire = frame_to_wire(&f5, std::slice::from_ref(&plan)).unwrap();
        let back = frame_from_wire(&wire).unwrap();
        assert_eq!(
            (back.step, back.ee_pose, back.previous_action),
            (5, f5.ee_pose, f5.previous_action)
        );
        assert_eq!(action_from_wire(&[]).unwrap(), None);
        assert!(ee_pose_from_wire(&[1.0; 3]).is_err());
    }
}
