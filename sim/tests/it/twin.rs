//! Physics, determinism, snapshots, sensors and base limits of the kitchen twin.

use crate::common;

use common::*;
use kitchen_r_sim::bench::wobble_action;
use kitchen_r_sim::config::{CameraConfig, Mount};
use kitchen_r_sim::generator::{EpisodeParams, generate};

fn generated() -> kitchen_r_sim::EpisodeConfig {
    let a = assets();
    let scene = a.scene("kitchen_a").unwrap().clone();
    generate(&scene, &a.catalogue, &EpisodeParams::default(), 11, 3).unwrap()
}

#[test]
fn same_config_and_actions_give_identical_state_hashes() {
    let ep = generated();
    let run = || {
        let mut s = sim(&ep, blind());
        for k in 0..2000 {
            s.step(&wobble_action(k), false).unwrap();
        }
        s.state_hash()
    };
    assert_eq!(run(), run());
}

#[test]
fn restore_replays_bit_for_bit() {
    let ep = generated();
    let mut s = sim(&ep, blind());
    for k in 0..150 {
        s.step(&wobble_action(k), false).unwrap();
    }
    let snap = s.snapshot();
    let at = s.state_hash();
    for k in 150..400 {
        s.step(&wobble_action(k), false).unwrap();
    }
    let first = s.state_hash();
    s.restore(&snap).unwrap();
    assert_eq!(s.state_hash(), at);
    for k in 150..400 {
        s.step(&wobble_action(k), false).unwrap();
    }
    assert_eq!(s.state_hash(), first);
}

#[test]
fn objects_left_alone_drift_less_than_a_millimetre_in_ten_seconds() {
    let a = assets();
    let scene = a.scene("kitchen_a").unwrap().clone();
    let objects = scene
        .key_objects
        .iter()
        .map(|o| kitchen_r_sim::episode::key_object_placement(&scene, &a.catalogue, o).unwrap())
        .collect();
    let ep = episode(&a, [2.0, 2.7, 0.0], objects);
    let mut s = sim(&ep, blind());
    let home = s.ee_pose().translation.vector;
    let idle = hold([home.x, home.y, home.z], 1.0);
    s.step(&idle, false).unwrap();
    let before = s.object_poses();
    for _ in 0..100 {
        s.step(&idle, false).unwrap();
    }
    for ((name, a), (_, b)) in before.iter().zip(s.object_poses()) {
        let d = (a.translation.vector - b.translation.vector).norm();
        assert!(d < 1e-3, "{name} drifted {d} m");
    }
}

#[test]
fn depth_camera_reads_the_wall_distance() {
    let a = assets();
    let ep = episode(&a, [2.0, 2.7, 0.0], Vec::new());
    // A fixed camera 1.5 m north of the south wall's inner face, above all furniture, facing south.
    let cam = CameraConfig {
        name: "probe".into(),
        mount: Mount::World,
        position: [2.5, 1.5, 2.2],
        rpy: [0.0, 0.0, -std::f64::consts::FRAC_PI_2],
        width: 32,
        height: 32,
        fov_deg: 40.0,
        max_depth: 10.0,
    };
    let sensors = kitchen_r_sim::SensorsConfig {
        cameras: vec![cam],
        lidar: None,
        ..Default::default()
    };
    let s = sim(&ep, sensors);
    let obs = s.observe();
    let img = &obs.images[0];
    for v in 12..20 {
        for u in 12..20 {
            let d = img.depth[v * 32 + u];
            assert!((d - 1.5).abs() < 0.01, "pixel ({u}, {v}) reads {d} m");
        }
    }
}

#[test]
fn default_cameras_and_lidar_produce_full_observations() {
    let ep = generated();
    let s = sim(&ep, kitchen_r_sim::SensorsConfig::default());
    let obs = s.observe();
    assert_eq!(obs.images.len(), 2);
    for img in &obs.images {
        assert_eq!(img.rgb.len(), 128 * 128 * 3);
        let hits = img.depth.iter().filter(|d| **d > 0.0).count();
        assert!(hits > 128 * 100, "camera {} sees too little", img.name);
    }
    let cloud = obs.lidar.unwrap();
    assert!(
        cloud.points.len() > 300,
        "lidar returned {} points",
        cloud.points.len()
    );
}

#[test]
fn base_velocities_respect_their_limits() {
    let a = assets();
    // Facing east along the free corridor between the table and the north counter.
    let ep = episode(&a, [1.5, 2.7, 0.0], Vec::new());
    let mut s = sim(&ep, blind());
    let b = a.robot.base.clone();
    let home = s.ee_pose().translation.vector;
    let mut prev = [0.0, 0.0];
    // Full speed ahead, then spin in place the other way: both far beyond the limits.
    for (v, w, n) in [(5.0, 0.0, 15), (0.0, -5.0, 20)] {
        for _ in 0..n {
            let act = kitchen_r_sim::Action::new(v, w, [home.x, home.y, home.z], DOWN, 1.0);
            let (_, info) = s.step(&act, false).unwrap();
            let [mv, mw] = info.base_velocity;
            assert!(
                info.contacts.is_empty(),
                "the test path must be free: {:?}",
                info.contacts
            );
            assert!(
                mv.abs() <= b.max_v + 1e-3 && mw.abs() <= b.max_omega + 1e-3,
                "v {mv} w {mw}"
            );
            assert!(
                (mv - prev[0]).abs() <= b.acc_v * 0.1 + 1e-3,
                "linear acceleration {mv} after {}",
                prev[0]
            );
            assert!(
                (mw - prev[1]).abs() <= b.acc_omega * 0.1 + 1e-3,
                "angular acceleration {mw} after {}",
                prev[1]
            );
            prev = [mv, mw];
        }
    }
    assert!(prev[1] < -b.max_omega + 0.05, "the spin reached its limit");
}

#[test]
fn the_base_is_stopped_by_the_counter() {
    let a = assets();
    // Facing north towards counter_north, whose front face is at y = 3.4.
    let ep = episode(&a, [2.0, 2.7, std::f64::consts::FRAC_PI_2], Vec::new());
    let mut s = sim(&ep, blind());
    let home = s.ee_pose().translation.vector;
    let mut touched = false;
    for _ in 0..60 {
        let act = kitchen_r_sim::Action::new(0.5, 0.0, [home.x, home.y, home.z], DOWN, 1.0);
        let (_, info) = s.step(&act, false).unwrap();
        assert!(
            info.base_pose[1] <= 3.4 - a.robot.base.body_radius + 0.01,
            "base at {:?}",
            info.base_pose
        );
        touched |= info.contacts.iter().any(|c| c.other == "scene");
    }
    assert!(touched, "contact with the counter was not reported");
}
