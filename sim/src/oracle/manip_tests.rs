//! Tests of the pick-and-place state machine: the blend, continuity, the object-frame targets,
//! the finger axis, unit quaternions, and that a place undoes the pick's grip.

use std::f64::consts::{FRAC_PI_2, PI};

use kitchen_r_core::assets::assets_dir;
use kitchen_r_core::catalogue::{Catalogue, ObjectModel};
use nalgebra::{Isometry3, Vector3};

use super::manip::{ManipParams, Phase, PhasePlan, PickPlan, PlacePlan, alpha, base_isometry};
use super::nav_tests::scenes;

fn catalogue() -> Catalogue {
    Catalogue::load(&assets_dir().join("objects.toml")).unwrap()
}

fn object_at(x: f64, y: f64, z: f64, yaw: f64) -> Isometry3<f64> {
    Isometry3::new(Vector3::new(x, y, z), Vector3::z() * yaw)
}

/// A robot at the kitchen_a blue-zone approach point, facing north, and an object on the counter
/// 0.65 m ahead of it (a bit to the left), for each yaw tried.
const BASE: [f64; 3] = [1.5, 2.95, FRAC_PI_2];
const YAWS: [f64; 5] = [0.0, 0.4, FRAC_PI_2, 2.5, -2.0];

fn plans(model: &ObjectModel) -> Vec<(PickPlan, PlacePlan, Isometry3<f64>, Isometry3<f64>)> {
    let p = ManipParams::default();
    let z = 0.9 + model.shape.half_height();
    YAWS.iter()
        .map(|&yaw| {
            let obj = object_at(1.45, 3.6, z, yaw);
            let pick = PickPlan::new(&obj, model, BASE, &p);
            let target = PlacePlan::target_keeping_grip(
                [2.1, 2.9, 0.75 + model.shape.half_height()],
                pick.object_yaw_in_base(),
                [2.0, 2.3, 0.7],
            );
            let place = PlacePlan::new(&target, model, [2.0, 2.3, 0.7], &p);
            (pick, place, obj, target)
        })
        .collect()
}

#[test]
fn raised_cosine_blend_endpoints_midpoint_and_flat_ends() {
    assert_eq!(alpha(0.0), 0.0);
    assert!((alpha(1.0) - 1.0).abs() < 1e-15);
    assert!((alpha(0.5) - 0.5).abs() < 1e-15);
    let h = 1e-6;
    assert!(((alpha(h) - alpha(0.0)) / h).abs() < 1e-5, "α'(0) ≈ 0");
    assert!(((alpha(1.0) - alpha(1.0 - h)) / h).abs() < 1e-5, "α'(1) ≈ 0");
    assert!(
        ((alpha(0.5 + h) - alpha(0.5 - h)) / (2.0 * h) - PI / 2.0).abs() < 1e-6,
        "α'(½) = π/2"
    );
    assert!((0..100).all(|i| alpha(i as f64 / 100.0) <= alpha((i + 1) as f64 / 100.0)));
    assert_eq!((alpha(-1.0), alpha(2.0)), (0.0, 1.0));
}

#[test]
fn ten_distinct_phases_pick_then_place() {
    let cat = catalogue();
    let (pick, place, ..) = plans(cat.model("cup").unwrap()).remove(0);
    let phases: Vec<Phase> = pick
        .plan
        .targets()
        .iter()
        .chain(place.plan.targets())
        .map(|t| t.phase)
        .collect();
    assert_eq!(phases, Phase::ALL.to_vec());
    let names: std::collections::BTreeSet<_> = Phase::ALL.iter().map(|p| p.name()).collect();
    assert_eq!(names.len(), 10);
    let total: f64 = ManipParams::default().durations.iter().sum();
    assert!((pick.duration() + place.duration() - total).abs() < 1e-12);
}

/// Samples every 0.1 s (the control period) and checks for jumps and unit quaternions. Within a
/// phase of duration `T` moving by `Δ`, the blend's speed peaks at `(π/2)·Δ/T`, so no 0.1 s step
/// may exceed the largest such peak times 0.1 s.
fn check_continuous(plan: &PhasePlan, what: &str) {
    let (mut bound_p, mut bound_r, mut bound_g) = (0.0f64, 0.0f64, 0.0f64);
    let (mut prev, mut g_prev, _) = plan.target_at(0.0);
    for t in plan.targets() {
        let k = PI / 2.0 * 0.1 / t.duration;
        bound_p = bound_p.max(k * (t.ee_in_base.translation.vector - prev.translation.vector).norm());
        bound_r = bound_r.max(k * t.ee_in_base.rotation.angle_to(&prev.rotation));
        bound_g = bound_g.max(k * (t.gripper - g_prev).abs());
        (prev, g_prev) = (t.ee_in_base, t.gripper);
    }
    // With the default durations the tool never moves faster than 0.4 m/s or 1 rad/s.
    assert!(
        bound_p <= 0.04 && bound_r <= 0.1,
        "{what}: {bound_p} m, {bound_r} rad per step"
    );
    let n = (plan.duration() / 0.1).round() as usize;
    let (mut prev, mut g_prev, _) = plan.target_at(0.0);
    for k in 1..=n + 2 {
        let (pose, g, _) = plan.target_at(k as f64 * 0.1);
        assert!(
            (pose.rotation.coords.norm() - 1.0).abs() < 1e-9,
            "{what}: non-unit quaternion"
        );
        let step = (pose.translation.vector - prev.translation.vector).norm();
        assert!(step <= bound_p + 1e-9, "{what}: jump of {step} m at {k}");
        assert!(
            pose.rotation.angle_to(&prev.rotation) <= bound_r + 1e-9,
            "{what}: rotation jump at {k}"
        );
        assert!(
            (g - g_prev).abs() <= bound_g + 1e-9,
            "{what}: gripper jump at {k}"
        );
        assert!((0.0..=1.0).contains(&g));
        (prev, g_prev) = (pose, g);
    }
}

#[test]
fn blended_targets_are_continuous_with_unit_quaternions() {
    let cat = catalogue();
    for model in cat.key_models() {
        for (pick, place, ..) in plans(model) {
            check_continuous(&pick.plan, &format!("pick {}", model.id));
            check_continuous(&place.plan, &format!("place {}", model.id));
        }
    }
}

#[test]
fn each_phase_starts_where_the_previous_ended_and_ends_on_its_target() {
    let cat = catalogue();
    let (pick, ..) = plans(cat.model("fork").unwrap()).remove(1);
    let p = ManipParams::default();
    let (start, g0, _) = pick.target_at(0.0);
    assert_eq!((start, g0), (p.home, 1.0));
    let mut t = 0.0;
    for target in pick.plan.targets() {
        t += target.duration;
        let (pose, g, phase) = pick.target_at(t - 1e-9);
        assert_eq!(phase, target.phase);
        assert!((pose.translation.vector - target.ee_in_base.translation.vector).norm() < 1e-6);
        assert!(pose.rotation.angle_to(&target.ee_in_base.rotation) < 1e-6);
        assert!((g - target.gripper).abs() < 1e-6, "{:?}", target.phase);
    }
    assert_eq!(pick.target_at(1e9).0, p.carry);
}

#[test]
fn phase_targets_are_the_grasp_offset_in_the_object_frame() {
    let cat = catalogue();
    let p = ManipParams::default();
    for model in cat.key_models() {
        let g = Vector3::from(model.grasp_offset);
        for (pick, place, obj, target) in plans(model) {
            let base = base_isometry(BASE);
            for t in pick.plan.targets().iter().filter(|t| t.phase != Phase::Carry) {
                let in_obj = obj.inverse() * base * t.ee_in_base;
                let h = match t.phase {
                    Phase::PreGrasp => p.approach_height,
                    Phase::Lift => p.lift_height,
                    _ => 0.0,
                };
                let want = g + Vector3::z() * h;
                assert!(
                    (in_obj.translation.vector - want).norm() < 1e-9,
                    "{} {:?}",
                    model.id,
                    t.phase
                );
                // Top-down: the approach axis points straight down in the world.
                let approach = base.rotation * t.ee_in_base.rotation * Vector3::x();
                assert!((approach + Vector3::z()).norm() < 1e-9);
            }
            let base = base_isometry([2.0, 2.3, 0.7]);
            let lower = &place.plan.targets()[1];
            let in_target = target.inverse() * base * lower.ee_in_base;
            assert!((in_target.translation.vector - (g + Vector3::z() * p.release_height)).norm() < 1e-9);
        }
    }
}

#[test]
fn fingers_close_across_the_narrow_axis() {
    let cat = catalogue();
    // (model, closing axis in the object frame): the fork across its width, plate and bowl
    // radially at the rim.
    for (id, axis) in [
        ("fork", Vector3::y()),
        ("plate", Vector3::x()),
        ("bowl", Vector3::x()),
    ] {
        for (pick, _, obj, _) in plans(cat.model(id).unwrap()) {
            let descend = &pick.plan.targets()[1];
            let closing = obj.inverse() * base_isometry(BASE) * descend.ee_in_base.rotation * Vector3::y();
            assert!(
                (closing.dot(&axis).abs() - 1.0).abs() < 1e-9,
                "{id}: closing along {closing:?}"
            );
            // Of the two tool yaws, the one within a quarter turn of the base's forward one.
            let tool_z = descend.ee_in_base.rotation * Vector3::z();
            assert!(tool_z.x > -1e-9, "{id}: wrist turned past a quarter turn");
        }
    }
    // Round objects: no wrist turn at all.
    for (pick, ..) in plans(cat.model("cup").unwrap()) {
        assert!(
            pick.plan.targets()[1]
                .ee_in_base
                .rotation
                .angle_to(&ManipParams::default().home.rotation)
                < 1e-9
        );
    }
}

#[test]
fn placing_with_the_grip_kept_puts_the_centre_on_the_target() {
    let cat = catalogue();
    let p = ManipParams::default();
    for model in cat.key_models() {
        for (pick, place, obj, target) in plans(model) {
            // Object pose relative to the tool at the grasp, carried unchanged to the release.
            let tool_at_grasp = base_isometry(BASE) * pick.plan.targets()[2].ee_in_base;
            let held = tool_at_grasp.inverse() * obj;
            let tool_at_release = base_isometry([2.0, 2.3, 0.7]) * place.plan.targets()[2].ee_in_base;
            let released = tool_at_release * held;
            let want = target.translation.vector + Vector3::z() * p.release_height;
            let err = (released.translation.vector - want).norm();
            assert!(err < 1e-9, "{}: centre lands {err} m off", model.id);
        }
    }
}

/// Lowest point of the held object while the tool is at `tool` (world), for a grip `held`.
fn bottom(tool: &Isometry3<f64>, held: &Isometry3<f64>, model: &ObjectModel) -> (Isometry3<f64>, f64) {
    let obj = tool * held;
    (obj, obj.translation.vector.z - model.shape.half_height())
}

#[test]
fn neither_the_hand_nor_a_held_object_dips_below_the_surface_it_crosses() {
    let cat = catalogue();
    let p = ManipParams::default();
    for scene in scenes() {
        for obj in &scene.key_objects {
            let model = cat.model(&obj.model).unwrap();
            let zone = scene.zone(&obj.zone).unwrap();
            let c = scene.key_object_start(obj, model.shape.half_height()).unwrap();
            let pose = Isometry3::new(Vector3::from(c), Vector3::z() * obj.yaw);
            let pick = PickPlan::new(&pose, model, zone.approach, &p);
            let base = base_isometry(zone.approach);
            let held = (base * pick.plan.targets()[2].ee_in_base).inverse() * pose;
            // (what, plan, base pose, zone of the surface, from when to check)
            let mut checks = Vec::new();
            let from_lift = pick.plan.targets()[..3].iter().map(|t| t.duration).sum::<f64>();
            checks.push((format!("pick {}", obj.name()), pick.plan.clone(), zone, from_lift));
            for other in &scene.zones {
                let centre = [
                    other.center[0],
                    other.center[1],
                    other.height + model.shape.half_height(),
                ];
                let target =
                    PlacePlan::target_keeping_grip(centre, pick.object_yaw_in_base(), other.approach);
                let place = PlacePlan::new(&target, model, other.approach, &p);
                let what = format!("place {} at {}", obj.name(), other.color);
                checks.push((what, place.plan, other, 0.0));
            }
            for (what, plan, z, from) in checks {
                let (f, surface) = (scene.furniture(&z.furniture).unwrap(), z.height);
                let base = base_isometry(z.approach);
                // Until the object is let go: the lift and carry of a pick, the transport and
                // lowering of a place.
                let until = if from > 0.0 {
                    plan.duration()
                } else {
                    plan.targets()[..2].iter().map(|t| t.duration).sum()
                };
                let mut t = 0.0;
                while t <= plan.duration() {
                    let tool = base * plan.target_at(t).0;
                    if (from..=until).contains(&t) {
                        let (object, low) = bottom(&tool, &held, model);
                        let xy = [object.translation.vector.x, object.translation.vector.y];
                        let over = f.covers(xy, model.shape.footprint_radius());
                        assert!(
                            !over || low >= surface - 1e-6,
                            "{} {what}: object at {low:.3} < {surface}",
                            scene.id
                        );
                    } else {
                        // Empty-handed moves (to the pre-grasp, back home): the fingertips, at
                        // the tool centre point, stay above the surface too.
                        let xy = [tool.translation.vector.x, tool.translation.vector.y];
                        let low = tool.translation.vector.z;
                        let over = f.covers(xy, 0.05);
                        assert!(
                            !over || low >= surface - 1e-6,
                            "{} {what}: tool at {low:.3} < {surface}",
                            scene.id
                        );
                    }
                    t += 0.05;
                }
            }
        }
    }
}
