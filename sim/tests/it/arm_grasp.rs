//! The arm under the RMP controller in the world, and grasping.

use crate::common;

use common::*;

#[test]
fn arm_reaches_a_reachable_target_within_a_centimetre_and_three_degrees() {
    let a = assets();
    let ep = episode(&a, [2.0, 2.7, 0.0], Vec::new());
    let mut s = sim(&ep, blind());
    let target = [0.55, 0.1, 1.0];
    let mut info = None;
    for _ in 0..60 {
        info = Some(s.step(&hold(target, 1.0), false).unwrap().1);
    }
    let e = info.unwrap().ee_pose;
    let d = ((e[0] - target[0]).powi(2) + (e[1] - target[1]).powi(2) + (e[2] - target[2]).powi(2)).sqrt();
    assert!(d < 0.01, "position error {d}");
    let dot = (e[3] * DOWN[0] + e[4] * DOWN[1] + e[5] * DOWN[2] + e[6] * DOWN[3])
        .abs()
        .min(1.0);
    let angle = 2.0 * dot.acos();
    assert!(angle < 3f64.to_radians(), "orientation error {angle} rad");
}

#[test]
fn unreachable_target_keeps_the_arm_finite_and_within_limits() {
    let a = assets();
    let ep = episode(&a, [2.0, 2.7, 0.0], Vec::new());
    let mut s = sim(&ep, blind());
    for _ in 0..80 {
        let (_, info) = s.step(&hold([2.5, -1.0, 3.0], 1.0), false).unwrap();
        for (q, j) in info.joints.iter().zip(&a.robot.arm.joints) {
            assert!(
                q.is_finite() && *q >= j.limits[0] - 1e-9 && *q <= j.limits[1] + 1e-9,
                "{} at {q}",
                j.name
            );
        }
    }
}

#[test]
fn grasp_holds_through_a_base_rotation_and_release_drops_onto_the_counter() {
    let a = assets();
    // The blue zone's approach point, facing the counter; a cup 0.65 m ahead on the counter top.
    let ep = episode(
        &a,
        [1.5, 2.95, std::f64::consts::FRAC_PI_2],
        vec![cup_at(1.5, 3.6, 0.9)],
    );
    let mut s = sim(&ep, blind());
    let run = |s: &mut kitchen_r_sim::Sim, act: kitchen_r_sim::Action, n: usize| {
        let mut last = None;
        for _ in 0..n {
            last = Some(s.step(&act, false).unwrap().1);
        }
        last.unwrap()
    };
    run(&mut s, hold([0.65, 0.0, 1.12], 1.0), 40);
    run(&mut s, hold([0.65, 0.0, 0.97], 1.0), 30);
    let info = run(&mut s, hold([0.65, 0.0, 0.97], 0.0), 10);
    assert_eq!(info.held_object.as_deref(), Some("red cup"));
    run(&mut s, hold([0.65, 0.0, 1.12], 0.0), 20);
    let turn = kitchen_r_sim::Action::new(0.0, 0.4, [0.65, 0.0, 1.12], DOWN, 0.0);
    let info = run(&mut s, turn, 10);
    assert_eq!(
        info.held_object.as_deref(),
        Some("red cup"),
        "dropped during the rotation"
    );
    let info = run(&mut s, hold([0.65, 0.0, 1.12], 0.0), 10);
    let cup = s.object_poses()[0].1.translation.vector;
    let tcp = info.ee_world;
    assert!(
        (cup.x - tcp[0]).hypot(cup.y - tcp[1]) < 0.02,
        "cup left the gripper"
    );
    run(&mut s, hold([0.65, 0.0, 0.99], 0.0), 20);
    let info = run(&mut s, hold([0.65, 0.0, 0.99], 1.0), 30);
    assert!(info.held_object.is_none());
    let cup = s.object_poses()[0].1.translation.vector;
    assert!((cup.z - 0.95).abs() < 0.01, "cup centre at z {}", cup.z);
    assert!(cup.y > 3.4 && cup.y < 4.0, "cup is not on the counter: {cup:?}");
}

#[test]
fn fixed_furniture_stops_the_arm() {
    let a = assets();
    let ep = episode(&a, [1.5, 2.95, std::f64::consts::FRAC_PI_2], Vec::new());
    let mut s = sim(&ep, blind());
    let home = s.ee_pose().translation.vector;
    assert!(home.z > 0.9, "home TCP at {home:?} is below the counter top");
    for _ in 0..40 {
        s.step(&hold([0.65, 0.0, 1.05], 1.0), false).unwrap();
    }
    // Then a target 10 cm inside the counter top (surface at 0.9 m).
    let (mut blocked, mut touched, mut lowest) = (false, false, f64::INFINITY);
    for _ in 0..40 {
        let (_, info) = s.step(&hold([0.65, 0.0, 0.80], 1.0), false).unwrap();
        blocked |= info.arm_blocked;
        touched |= info.contacts.iter().any(|c| c.other == "scene");
        lowest = lowest.min(info.ee_world[2]);
    }
    assert!(
        blocked && touched,
        "blocked {blocked}, contact reported {touched}"
    );
    // The fingertips reach 2.5 cm below the TCP; they may only graze the top.
    assert!(lowest > 0.9 + 0.025 - 0.01, "TCP went down to {lowest}");
}

#[test]
fn the_arm_pushes_a_loose_object() {
    let a = assets();
    // A cup on the counter 0.6 m ahead, 0.15 m to the left; the palm sweeps through it sideways
    // (the fingers pass key objects by design: grasps attach them instead).
    let ep = episode(
        &a,
        [1.5, 2.95, std::f64::consts::FRAC_PI_2],
        vec![cup_at(1.35, 3.55, 0.9)],
    );
    let mut s = sim(&ep, blind());
    let before = s.object_poses()[0].1.translation.vector;
    for _ in 0..40 {
        s.step(&hold([0.6, -0.05, 1.1], 1.0), false).unwrap();
    }
    for _ in 0..20 {
        s.step(&hold([0.6, -0.05, 0.935], 1.0), false).unwrap();
    }
    let mut touched = false;
    for _ in 0..40 {
        let (_, info) = s.step(&hold([0.6, 0.3, 0.935], 1.0), false).unwrap();
        touched |= info.contacts.iter().any(|c| c.other == "red cup");
    }
    let after = s.object_poses()[0].1.translation.vector;
    assert!(touched, "no arm contact with the cup was reported");
    assert!(
        (after - before).norm() > 0.02,
        "the cup did not move: {before:?} -> {after:?}"
    );
}

#[test]
fn a_key_object_on_the_floor_trips_its_monitor() {
    let a = assets();
    let mut cup = cup_at(2.0, 1.0, 0.0);
    cup.name = "red cup".into();
    let ep = episode(&a, [1.5, 2.7, 0.0], vec![cup]);
    let mut s = sim(&ep, blind());
    let home = s.ee_pose().translation.vector;
    let (_, info) = s.step(&hold([home.x, home.y, home.z], 1.0), false).unwrap();
    assert!(info.monitors.iter().any(|m| matches!(
        m,
        kitchen_r_sim::task::MonitorTrip::ObjectOnFloor { object } if object == "red cup"
    )));
}
