//! The physical grasp mode (docs/twin/robot.md): the hand follows the controller, friction
//! between force-limited fingers lifts an object and holds it while the base drives and the arm
//! swings, opening the gripper drops it, and two runs of the same commands give the same bits.

use kitchen_r_core::GraspMode;
use kitchen_r_sim::config::SimConfig;
use kitchen_r_sim::episode::EpisodeConfig;
use kitchen_r_sim::{Action, Sim, StepInfo};

use crate::common::*;

fn physical(ep: &EpisodeConfig) -> Sim {
    let mut cfg = SimConfig::load_default().unwrap();
    cfg.grasp.mode = GraspMode::Physical;
    Sim::new(assets(), cfg, blind(), ep).unwrap().0
}

fn run(s: &mut Sim, act: Action, n: usize) -> StepInfo {
    let mut last = None;
    for _ in 0..n {
        last = Some(s.step(&act, false).unwrap().1);
    }
    last.unwrap()
}

/// The blue zone's approach point facing the counter, a cup 0.65 m ahead on the counter top.
fn cup_on_the_counter() -> EpisodeConfig {
    episode(
        &assets(),
        [1.5, 2.95, std::f64::consts::FRAC_PI_2],
        vec![cup_at(1.5, 3.6, 0.9)],
    )
}

fn dist(a: [f64; 3], b: &[f64]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

#[test]
fn the_physical_hand_follows_the_controller_within_a_centimetre() {
    let a = assets();
    let mut s = physical(&episode(&a, [2.0, 2.7, 0.0], Vec::new()));
    let target = [0.55, 0.1, 1.0];
    let info = run(&mut s, hold(target, 1.0), 60);
    // The measured TCP (world) against the targets' forward kinematics (base frame).
    let base = s.base_pose();
    let (c, sn) = (base[2].cos(), base[2].sin());
    let e = info.ee_world;
    let local = [
        c * (e[0] - base[0]) + sn * (e[1] - base[1]),
        -sn * (e[0] - base[0]) + c * (e[1] - base[1]),
        e[2],
    ];
    assert!(dist(target, &local) < 0.01, "measured TCP {local:?}");
    assert!(
        dist(target, &info.ee_pose) < 0.01,
        "target TCP {:?}",
        info.ee_pose
    );
}

#[test]
fn friction_lifts_a_cup_and_opening_the_gripper_drops_it() {
    let mut s = physical(&cup_on_the_counter());
    run(&mut s, hold([0.65, 0.0, 1.12], 1.0), 40);
    run(&mut s, hold([0.65, 0.0, 0.97], 1.0), 30);
    let info = run(&mut s, hold([0.65, 0.0, 0.97], 0.0), 15);
    assert!(info.held_object.is_none(), "held while still on the counter");
    // Nothing attaches it: only the fingers' friction lifts it off the counter.
    let info = run(&mut s, hold([0.65, 0.0, 1.05], 0.0), 4);
    assert_eq!(info.held_object.as_deref(), Some("red cup"), "not lifted");
    let cup = s.object_poses()[0].1.translation.vector;
    assert!(cup.z > 0.95 + 0.03, "cup centre at z {}", cup.z);
    let info = run(&mut s, hold([0.65, 0.0, 1.05], 1.0), 20);
    assert!(info.held_object.is_none(), "still held with the gripper open");
    let cup = s.object_poses()[0].1.translation.vector;
    assert!(cup.z < 0.95 + 0.02, "the cup did not fall: centre at z {}", cup.z);
}

/// The distance from the measured TCP to the first object's centre.
fn grip_offset(s: &Sim, info: &StepInfo) -> f64 {
    let cup = s.object_poses()[0].1.translation.vector;
    let tcp = &info.ee_world;
    dist([cup.x, cup.y, cup.z], &tcp[..3])
}

#[test]
fn a_held_cup_stays_put_in_the_fingers_while_the_base_drives_and_the_arm_swings() {
    let mut s = physical(&cup_on_the_counter());
    run(&mut s, hold([0.65, 0.0, 1.12], 1.0), 40);
    run(&mut s, hold([0.65, 0.0, 0.97], 1.0), 30);
    run(&mut s, hold([0.65, 0.0, 0.97], 0.0), 15);
    let info = run(&mut s, hold([0.65, 0.0, 1.12], 0.0), 20);
    assert_eq!(info.held_object.as_deref(), Some("red cup"), "not lifted");
    let before = grip_offset(&s, &info);
    // Back away from the counter, turn on the spot, then swing the hand sideways and up.
    let moves = [
        (-0.3, 0.0, [0.65, 0.0, 1.12], 20),
        (0.0, 1.0, [0.65, 0.0, 1.12], 20),
        (0.3, -0.5, [0.65, 0.0, 1.12], 20),
        (0.0, 0.0, [0.45, 0.3, 1.25], 30),
    ];
    for (v, omega, target, n) in moves {
        let info = run(&mut s, Action::new(v, omega, target, DOWN, 0.0), n);
        assert_eq!(info.held_object.as_deref(), Some("red cup"), "dropped");
        let slip = (grip_offset(&s, &info) - before).abs();
        assert!(slip < 0.005, "the cup moved {slip} m in the fingers");
    }
}

#[test]
fn physical_mode_is_bit_identical_across_runs() {
    let go = || {
        let mut s = physical(&cup_on_the_counter());
        let mut hashes = Vec::new();
        for (target, g, n) in [
            ([0.65, 0.0, 1.12], 1.0, 30),
            ([0.65, 0.0, 0.97], 1.0, 25),
            ([0.65, 0.0, 0.97], 0.0, 15),
            ([0.65, 0.0, 1.12], 0.0, 20),
        ] {
            run(&mut s, hold(target, g), n);
            hashes.push(s.state_hash());
        }
        run(&mut s, Action::new(0.3, 0.3, [0.65, 0.0, 1.12], DOWN, 0.0), 10);
        hashes.push(s.state_hash());
        hashes
    };
    assert_eq!(go(), go());
}
