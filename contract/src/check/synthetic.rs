//! The synthetic observations the conformance checks send: no simulator is needed to probe.

use kitchen_r_sim::Observation;
use kitchen_r_sim::sensors::CameraImage;
use kitchen_r_sim::types::Odometry;

use crate::convert::CameraPlan;

/// A grey-gradient frame per camera at exactly the planned size (no resampling).
pub(crate) fn synthetic(plans: &[CameraPlan], step: u64) -> Observation {
    let images = plans
        .iter()
        .map(|p| {
            let n = (p.width * p.height) as usize;
            CameraImage {
                name: p.name.clone(),
                width: p.width,
                height: p.height,
                rgb: (0..n * 3).map(|i| (i / 3 % 251) as u8).collect(),
                depth: vec![1.5; n],
            }
        })
        .collect();
    Observation {
        time: step as f64 * 0.1,
        images,
        lidar: None,
        odometry: Odometry {
            pose: [0.0; 3],
            velocity: [0.0; 2],
        },
        joints: [0.0; 6],
        gripper: 1.0,
        task: Some("move to the blue zone".into()),
    }
}
