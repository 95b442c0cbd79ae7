//! The oracle against the robot description (`assets/robots/kitchen_r_aloha.urdf`): every pick and place it plans
//! in the committed scenes (stow poses included) lies within the arm's reach from the zone's
//! approach pose, and the path follower still arrives when the base only follows its commands
//! within the description's speed and acceleration limits.

use kitchen_r_core::assets::assets_dir;
use kitchen_r_core::catalogue::Catalogue;
use nalgebra::{Isometry3, Vector3};

use super::follow::{FollowParams, Pose2};
use super::follow_tests::{check_arrival, drive, unicycle};
use super::geometry::dist;
use super::grid::{GridParams, OccupancyGrid};
use super::manip::{ManipParams, Phase, PhaseTarget, PickPlan, PlacePlan};
use super::nav_tests::{scenes, start_poses};
use crate::robot::desc::RobotDesc;
use crate::robot::kinematics::ArmModel;

/// Contact phases must be reachable; hover phases (approach heights above the grasp point) may
/// overreach a little, the arm then stretching toward them as far as it can.
const HOVER_OVERREACH: f64 = 0.05;

#[test]
fn every_pick_and_place_target_is_within_the_arms_reach() {
    let desc = RobotDesc::load_default().unwrap();
    let arm = ArmModel::new(&desc);
    let shoulder = arm.mount + arm.origins[1];
    // Shoulder to wrist-angle joint with the elbow straightened (within its limits for this arm);
    // the wrist joint sits `wrist_back` behind the TCP along the approach axis.
    let reach = arm.origins[2].norm() + (arm.origins[3] + arm.origins[4]).norm();
    let wrist_back = arm.origins[5].norm() + arm.tcp_offset;
    let cat = Catalogue::load(&assets_dir().join("objects.toml")).unwrap();
    let params = ManipParams::default();
    let mut failures = Vec::new();
    let mut check = |what: String, targets: &[PhaseTarget]| {
        for t in targets {
            let approach = t.ee_in_base.rotation * Vector3::x();
            let need = (t.ee_in_base.translation.vector - approach * wrist_back - shoulder).norm();
            let hover = matches!(
                t.phase,
                Phase::PreGrasp | Phase::Lift | Phase::Transport | Phase::Retreat
            );
            if need > reach + if hover { HOVER_OVERREACH } else { 0.0 } {
                failures.push(format!("{what}: {:?} needs {need:.3} m > {reach:.3} m", t.phase));
            }
        }
    };
    for scene in scenes() {
        for obj in &scene.key_objects {
            let model = cat.model(&obj.model).unwrap();
            let zone = scene.zone(&obj.zone).unwrap();
            let c = scene.key_object_start(obj, model.shape.half_height()).unwrap();
            let pose = Isometry3::new(Vector3::from(c), Vector3::z() * obj.yaw);
            let pick = PickPlan::new(&pose, model, zone.approach, &params);
            check(format!("{} pick {}", scene.id, obj.name()), pick.plan.targets());
            for other in &scene.zones {
                let centre = [
                    other.center[0],
                    other.center[1],
                    other.height + model.shape.half_height(),
                ];
                let target =
                    PlacePlan::target_keeping_grip(centre, pick.object_yaw_in_base(), other.approach);
                let place = PlacePlan::new(&target, model, other.approach, &params);
                check(
                    format!("{} place {} at {}", scene.id, obj.name(), other.color),
                    place.plan.targets(),
                );
            }
        }
    }
    assert!(failures.is_empty(), "out of reach:\n{}", failures.join("\n"));
}

#[test]
fn follower_arrives_under_the_base_speed_and_acceleration_limits() {
    let base = RobotDesc::load_default().unwrap().base;
    let params = FollowParams::default();
    let dt = params.dt;
    let slew = |actual: f64, cmd: f64, max: f64, acc: f64| {
        actual + (cmd.clamp(-max, max) - actual).clamp(-acc * dt, acc * dt)
    };
    for scene in scenes() {
        let grid = OccupancyGrid::from_scene(&scene, GridParams::default()).unwrap();
        for start in start_poses(&scene) {
            for zone in &scene.zones {
                if dist([start[0], start[1]], [zone.approach[0], zone.approach[1]]) == 0.0 {
                    continue;
                }
                // The base reaches the commanded speeds only as fast as its limits allow.
                let (mut v_now, mut w_now) = (0.0, 0.0);
                let mut plant = |p: Pose2, v: f64, w: f64| {
                    v_now = slew(v_now, v, base.max_v, base.acc_v);
                    w_now = slew(w_now, w, base.max_omega, base.acc_omega);
                    unicycle(p, v_now, w_now, dt)
                };
                let run = drive(&grid, start, zone.approach, params, &mut plant);
                check_arrival(
                    &format!("{} zone {} from {start:?}", scene.id, zone.color),
                    zone.approach,
                    run,
                );
            }
        }
    }
}
