//! Episode configurations, dataset instructions and task checks.

use crate::common;

use common::*;
use kitchen_r_core::dataset::Instruction;
use kitchen_r_sim::episode::{EpisodeConfig, load_batch, save_batch};
use kitchen_r_sim::generator::{EpisodeParams, batch};
use kitchen_r_sim::{TaskTarget, task_target};

#[test]
fn a_saved_batch_reloads_equal_and_the_generator_is_seeded() {
    let a = assets();
    let p = EpisodeParams::load_default().unwrap();
    let b1 = batch(&a.scenes, &a.catalogue, &p, 42, 12).unwrap();
    let b2 = batch(&a.scenes, &a.catalogue, &p, 42, 12).unwrap();
    let b3 = batch(&a.scenes, &a.catalogue, &p, 43, 12).unwrap();
    assert_eq!(b1, b2);
    assert_ne!(b1, b3);
    let dir = std::env::temp_dir().join(format!("kitchen-r-sim-batch-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("batch.json");
    save_batch(&b1, &path).unwrap();
    assert_eq!(load_batch(&path).unwrap(), b1);
    std::fs::remove_dir_all(&dir).unwrap();
    // Balanced objects: the first five episodes use five different models.
    let models: std::collections::BTreeSet<_> = b1[..5].iter().map(|e| e.objects[0].model.clone()).collect();
    assert_eq!(models.len(), 5);
}

#[test]
fn fixed_values_override_draws() {
    let a = assets();
    let mut p = EpisodeParams::default();
    p.fixed.object = Some("bowl".into());
    p.fixed.start = Some("red".into());
    p.fixed.goal = Some("blue".into());
    p.fixed.robot_start = Some([2.0, 2.7, 0.5]);
    let scene = a.scene("kitchen_a").unwrap();
    for i in 0..4 {
        let e = kitchen_r_sim::generator::generate(scene, &a.catalogue, &p, 5, i).unwrap();
        assert_eq!(e.objects[0].model, "bowl");
        assert_eq!(e.robot_start, [2.0, 2.7, 0.5]);
        assert_eq!(e.plan[0], "move to the red zone");
        assert_eq!(e.plan[2], "move to the blue zone");
    }
}

#[test]
fn instruction_episodes_resolve_their_tasks() {
    let a = assets();
    let scene = a.scene("kitchen_a").unwrap();
    let ins = Instruction {
        id: "dev-0000".into(),
        scene: "kitchen_a".into(),
        instruction: "Put the bowl on the table.".into(),
        plan: [
            "move to the blue zone",
            "pick the bowl",
            "move to the red zone",
            "place the bowl",
        ]
        .map(String::from)
        .to_vec(),
        template: "t00".into(),
        place_targets: vec![[2.5, 1.8, 0.78]],
    };
    let ep =
        EpisodeConfig::from_instruction(&ins, scene, &a.catalogue, &EpisodeParams::default(), 1).unwrap();
    assert_eq!(ep.objects.len(), scene.key_objects.len());
    let z = scene.zone("blue").unwrap();
    assert_eq!(
        task_target(&ep, scene, 0).unwrap(),
        TaskTarget::Base {
            x: z.approach[0],
            y: z.approach[1],
            yaw: z.approach[2]
        }
    );
    let bowl = ep.objects.iter().position(|o| o.name == "bowl").unwrap();
    assert_eq!(
        task_target(&ep, scene, 1).unwrap(),
        TaskTarget::Pick { object: bowl }
    );
    assert_eq!(
        task_target(&ep, scene, 3).unwrap(),
        TaskTarget::Place {
            object: bowl,
            target: [2.5, 1.8, 0.78]
        }
    );
}

#[test]
fn a_move_task_succeeds_at_the_approach_point_and_monitors_report() {
    let a = assets();
    let scene = a.scene("kitchen_a").unwrap();
    let z = scene.zone("green").unwrap();
    let mut ep = episode(&a, z.approach, vec![cup_at(3.0, 3.6, 0.9)]);
    ep.plan = vec!["move to the green zone".into(), "pick the red cup".into()];
    let mut s = sim(&ep, blind());
    s.begin_task(0).unwrap();
    let home = s.ee_pose().translation.vector;
    let (_, info) = s.step(&hold([home.x, home.y, home.z], 1.0), false).unwrap();
    assert!(info.task.unwrap().success);
    assert!(s.end_task().unwrap().failure.is_none());
    // A pick that never happens: the gripper stays far from the cup.
    s.begin_task(1).unwrap();
    let (_, info) = s.step(&hold([home.x, home.y, home.z], 1.0), false).unwrap();
    assert!(!info.task.unwrap().success);
    let end = s.end_task().unwrap();
    assert!(matches!(
        end.failure,
        Some(kitchen_r_sim::task::MonitorTrip::GripperFarFromObject { .. })
    ));
}
