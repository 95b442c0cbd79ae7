use std::f64::consts::{FRAC_PI_2, PI};

use super::*;

fn obj(name: &str, x: f64, y: f64, yaw: f64) -> PrivilegedObject {
    let (c, s) = ((yaw / 2.0).cos(), (yaw / 2.0).sin());
    PrivilegedObject {
        name: name.into(),
        model: name.rsplit(' ').next().unwrap_or(name).into(),
        pose: [x, y, 0.9, c, 0.0, 0.0, s],
    }
}

/// The robot at (1, 2) facing +y, three key objects, and `target` as the current task.
fn world(target: TaskTarget) -> Privileged {
    Privileged {
        scene: "kitchen_a".into(),
        base_pose: [1.0, 2.0, FRAC_PI_2],
        objects: vec![
            obj("red cup", 1.0, 3.0, FRAC_PI_2),
            obj("bowl", 4.0, 2.0, 0.0),
            obj("apple", -2.0, -2.0, 0.0),
        ],
        held: Some("red cup".into()),
        ee_pose: [0.3, 0.0, 0.9, 1.0, 0.0, 0.0, 0.0],
        target,
    }
}

fn close(a: &[f64], b: &[f64]) {
    assert_eq!(a.len(), b.len());
    for (x, y) in a.iter().zip(b) {
        assert!((x - y).abs() < 1e-12, "{a:?} != {b:?}");
    }
}

fn names(o: &PrivilegedObservation) -> Vec<&str> {
    o.objects.iter().map(|o| o.name.as_str()).collect()
}

#[test]
fn a_move_goal_is_the_approach_pose_in_the_robot_frame_and_shows_no_object_on_test() {
    // One metre ahead of a robot facing +y, approached facing -x: a quarter turn left.
    let w = world(TaskTarget::Base {
        x: 1.0,
        y: 3.0,
        yaw: PI,
    });
    let test = PrivilegedObservation::from_world(&w, PrivilegedScope::SubTask).unwrap();
    let Goal::Approach { x, y, yaw } = test.goal else {
        panic!("{:?}", test.goal)
    };
    close(&[x, y, yaw], &[1.0, 0.0, FRAC_PI_2]);
    assert_eq!(test.base_pose, [1.0, 2.0, FRAC_PI_2]);
    assert!(
        test.objects.is_empty(),
        "a move names no object: {:?}",
        names(&test)
    );
    let dev = PrivilegedObservation::from_world(&w, PrivilegedScope::Episode).unwrap();
    assert_eq!(names(&dev), ["red cup", "bowl", "apple"]);
    assert_eq!(dev.goal, test.goal);
}

#[test]
fn a_pick_goal_is_the_named_objects_pose_in_the_robot_frame() {
    let w = world(TaskTarget::Pick { object: 1 });
    let o = PrivilegedObservation::from_world(&w, PrivilegedScope::SubTask).unwrap();
    let Goal::Pick { object, pose } = &o.goal else {
        panic!("{:?}", o.goal)
    };
    assert_eq!(object, "bowl");
    // The bowl is 3 m along +x of the scene, which is to the robot's right (-y); its heading
    // (scene yaw 0) is a quarter turn right of the robot's.
    let h = (-FRAC_PI_2 / 2.0).sin();
    close(pose, &[0.0, -3.0, 0.9, (-FRAC_PI_2 / 2.0).cos(), 0.0, 0.0, h]);
    // Test: only the object the sub-task names, with its scene pose.
    assert_eq!(names(&o), ["bowl"]);
    assert_eq!(o.objects[0], w.objects[1]);
}

#[test]
fn a_place_goal_is_the_target_in_the_robot_frame_and_test_shows_only_the_placed_object() {
    let w = world(TaskTarget::Place {
        object: 0,
        target: [0.0, 2.5, 0.95],
    });
    let o = PrivilegedObservation::from_world(&w, PrivilegedScope::SubTask).unwrap();
    let Goal::Place { object, target } = &o.goal else {
        panic!("{:?}", o.goal)
    };
    assert_eq!(object, "red cup");
    close(target, &[0.5, 1.0, 0.95]);
    assert_eq!(names(&o), ["red cup"]);
    let dev = PrivilegedObservation::from_world(&w, PrivilegedScope::Episode).unwrap();
    assert_eq!(dev.objects, w.objects);
}

#[test]
fn the_test_scope_never_shows_another_key_object_whatever_the_task() {
    for target in [
        TaskTarget::Base {
            x: 0.0,
            y: 0.0,
            yaw: 0.0,
        },
        TaskTarget::Pick { object: 2 },
        TaskTarget::Place {
            object: 2,
            target: [0.0, 0.0, 0.0],
        },
    ] {
        let o = PrivilegedObservation::from_world(&world(target.clone()), PrivilegedScope::SubTask).unwrap();
        assert!(
            names(&o).iter().all(|n| *n == "apple"),
            "{target:?} shows {:?}",
            names(&o)
        );
        let goal_object = match &o.goal {
            Goal::Approach { .. } => None,
            Goal::Pick { object, .. } | Goal::Place { object, .. } => Some(object.as_str()),
        };
        assert!(
            goal_object.is_none_or(|n| n == "apple"),
            "{target:?}: {:?}",
            o.goal
        );
    }
}

#[test]
fn a_target_naming_a_missing_object_shows_nothing() {
    let w = world(TaskTarget::Pick { object: 7 });
    assert_eq!(
        PrivilegedObservation::from_world(&w, PrivilegedScope::Episode),
        None
    );
}

#[test]
fn angles_wrap_into_the_half_open_interval() {
    close(
        &[wrap(3.0 * PI), wrap(-PI), wrap(0.5), wrap(-3.5 * PI)],
        &[PI, PI, 0.5, FRAC_PI_2],
    );
}
