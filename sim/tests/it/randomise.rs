//! The paper's randomisation of instruction episodes: seeded, switchable, feasible, and off means
//! unchanged.

use crate::common;

use common::*;
use kitchen_r_core::dataset::symbolic::check_plan;
use kitchen_r_core::dataset::{Instruction, read_jsonl};
use kitchen_r_sim::episode::EpisodeConfig;
use kitchen_r_sim::generator::EpisodeParams;
use kitchen_r_sim::randomise::{Randomise, generate_varied, randomise};
use kitchen_r_sim::{Assets, Sim};

fn dev() -> Vec<Instruction> {
    read_jsonl(&kitchen_r_core::assets::assets_dir().join("dataset/dev.jsonl")).unwrap()
}

fn base(a: &Assets, ins: &Instruction, p: &EpisodeParams) -> EpisodeConfig {
    let scene = a.scene(&ins.scene).unwrap();
    EpisodeConfig::from_instruction(ins, scene, &a.catalogue, p, 7).unwrap()
}

fn randomised(a: &Assets, ins: &Instruction, p: &EpisodeParams, seed: u64) -> EpisodeConfig {
    let mut cfg = base(a, ins, p);
    randomise(&mut cfg, a.scene(&ins.scene).unwrap(), &a.catalogue, p, seed).unwrap();
    cfg
}

#[test]
fn the_same_seed_gives_the_same_episode_and_another_seed_another() {
    let (a, p) = (assets(), EpisodeParams::default());
    for ins in dev().iter().take(12) {
        let one = randomised(&a, ins, &p, 3);
        assert_eq!(one, randomised(&a, ins, &p, 3));
        let other = randomised(&a, ins, &p, 4);
        assert_ne!(one.style, other.style);
        assert_ne!(one.objects, other.objects);
    }
}

#[test]
fn everything_off_leaves_the_episode_as_it_was() {
    let a = assets();
    let p = EpisodeParams {
        randomise: Randomise::off(),
        ..EpisodeParams::default()
    };
    for ins in dev().iter().take(12) {
        assert_eq!(randomised(&a, ins, &p, 3), base(&a, ins, &p));
    }
}

#[test]
fn one_aspect_off_leaves_the_others_draws_unchanged() {
    let a = assets();
    let on = EpisodeParams::default();
    let mut no_lights = EpisodeParams::default();
    no_lights.randomise.lights = false;
    let ins = &dev()[0];
    let (x, y) = (randomised(&a, ins, &on, 9), randomised(&a, ins, &no_lights, 9));
    assert!(x.style.light.is_some() && y.style.light.is_none());
    assert_eq!(
        (&x.objects, x.robot_start, &x.background),
        (&y.objects, y.robot_start, &y.background)
    );
    assert_eq!(x.style.floor_pattern, y.style.floor_pattern);
}

#[test]
fn key_objects_stay_within_the_radius_and_the_episode_stays_feasible() {
    let (a, p) = (assets(), EpisodeParams::default());
    let mut moved = 0;
    for ins in dev() {
        let scene = a.scene(&ins.scene).unwrap();
        let before = base(&a, &ins, &p);
        for seed in 0..3 {
            let after = randomised(&a, &ins, &p, seed);
            after.validate(scene, &a.catalogue).unwrap();
            for (o, n) in before.objects.iter().zip(&after.objects) {
                let d = (o.position[0] - n.position[0]).hypot(o.position[1] - n.position[1]);
                assert!(d <= p.radius + 1e-9, "{}: {} moved {d} m", ins.id, o.name);
                assert_eq!((o.position[2], &o.name), (n.position[2], &n.name));
                moved += usize::from(d > 0.0);
            }
            // The dataset's feasibility rule holds for the drawn layout.
            let mut s = scene.clone();
            for (k, n) in s.key_objects.iter_mut().zip(&after.objects) {
                let z = scene.zone(&k.zone).unwrap();
                k.offset = [n.position[0] - z.center[0], n.position[1] - z.center[1]];
            }
            check_plan(&s, &a.catalogue, &ins.plan, &ins.place_targets)
                .unwrap_or_else(|e| panic!("{} seed {seed}: {e}", ins.id));
        }
    }
    assert!(moved > 0, "no key object was ever moved");
}

#[test]
fn a_randomised_episode_builds_and_renders_a_different_image() {
    let (a, p) = (assets(), EpisodeParams::default());
    let ins = &dev()[0];
    let render = |cfg: &EpisodeConfig| {
        let sensors = kitchen_r_sim::SensorsConfig::default();
        let (_, obs) = Sim::new(a.clone(), Default::default(), sensors, cfg).unwrap();
        obs.images[0].rgb.clone()
    };
    assert_ne!(render(&base(&a, ins, &p)), render(&randomised(&a, ins, &p, 1)));
}

#[test]
fn configs_written_before_randomisation_load_and_unrandomised_ones_write_no_new_fields() {
    let a = assets();
    let p = EpisodeParams {
        randomise: Randomise::off(),
        ..EpisodeParams::default()
    };
    let cfg = base(&a, &dev()[0], &p);
    let json = serde_json::to_value(&cfg).unwrap();
    let style = json["style"].as_object().unwrap();
    assert_eq!(
        style.keys().map(String::as_str).collect::<Vec<_>>(),
        ["floor_color", "floor_tile", "wall_color"]
    );
    let back: EpisodeConfig = serde_json::from_value(json).unwrap();
    assert_eq!(back, cfg);
}

#[test]
fn generated_episodes_get_looks_and_honour_the_switches() {
    let a = assets();
    let scene = a.scene("kitchen_b").unwrap();
    let p = EpisodeParams::default();
    let v = generate_varied(scene, &a.catalogue, &p, 11, 2).unwrap();
    assert!(v.style.light.is_some() && v.style.furniture_pattern.is_some());
    assert_eq!(v, generate_varied(scene, &a.catalogue, &p, 11, 2).unwrap());
    let off = EpisodeParams {
        randomise: Randomise::off(),
        ..EpisodeParams::default()
    };
    let g = generate_varied(scene, &a.catalogue, &off, 11, 2).unwrap();
    assert_eq!(g.style, kitchen_r_sim::world::Style::of(scene));
    assert!(g.background.is_empty());
    let z = scene
        .zone(
            g.plan[0]
                .trim_start_matches("move to the ")
                .trim_end_matches(" zone"),
        )
        .unwrap();
    assert_eq!([g.objects[0].position[0], g.objects[0].position[1]], z.center);
}
