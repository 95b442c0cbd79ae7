//! Tests of the generated dataset against the paper's numbers and the executability rule.

use std::collections::BTreeSet;
use std::path::PathBuf;

use super::symbolic::{check_plan, fits_in_zone};
use super::*;
use crate::catalogue::Catalogue;
use crate::plan::Step;
use crate::scene::Scene;

fn assets() -> PathBuf {
    crate::assets::assets_dir()
}

fn generated() -> Dataset {
    generate(COMMITTED_SEED, &assets()).unwrap()
}

#[test]
fn counts_follow_the_paper() {
    let d = generated();
    assert_eq!(d.dev.len(), DEV_INSTRUCTIONS);
    assert_eq!(d.dev.len() + d.test.len(), TOTAL_INSTRUCTIONS);
    assert_eq!(d.manifest.templates, TEMPLATE_COUNT);
    let all: Vec<&Instruction> = d.dev.iter().chain(&d.test).collect();
    let templates: BTreeSet<&str> = all.iter().map(|i| i.template.as_str()).collect();
    assert_eq!(templates.len(), TEMPLATE_COUNT);
    let dev_templates: BTreeSet<&str> = d.dev.iter().map(|i| i.template.as_str()).collect();
    assert_eq!(
        dev_templates.len(),
        TEMPLATE_COUNT,
        "the dev split shows every template"
    );
    let lens: BTreeSet<usize> = all.iter().map(|i| i.plan.len()).collect();
    assert_eq!(lens, (4..=8).collect());
    assert_eq!(d.dev[0].id, "dev-0001");
    assert_eq!(
        d.test.last().unwrap().id,
        format!("test-{:04}", TOTAL_INSTRUCTIONS - DEV_INSTRUCTIONS)
    );
}

#[test]
fn every_plan_is_executable_in_its_scene() {
    let cat = Catalogue::load(&assets().join("objects.toml")).unwrap();
    let scenes = Scene::load_all(&assets().join("scenes"), &cat).unwrap();
    let d = generated();
    let mut texts = BTreeSet::new();
    for i in d.dev.iter().chain(&d.test) {
        let scene = scenes.iter().find(|s| s.id == i.scene).unwrap();
        for s in &i.plan {
            assert_eq!(s.parse::<Step>().unwrap().to_string(), *s);
        }
        check_plan(scene, &cat, &i.plan, &i.place_targets).unwrap_or_else(|e| panic!("{}: {e}", i.id));
        assert!(
            texts.insert((&i.scene, &i.instruction)),
            "{}: duplicate text",
            i.id
        );
    }
}

#[test]
fn place_targets_lie_inside_their_zone() {
    let cat = Catalogue::load(&assets().join("objects.toml")).unwrap();
    let scenes = Scene::load_all(&assets().join("scenes"), &cat).unwrap();
    for i in generated().dev.iter().chain(&generated().test) {
        let scene = scenes.iter().find(|s| s.id == i.scene).unwrap();
        let mut at = None;
        let mut targets = i.place_targets.iter();
        for s in i.plan.iter().map(|s| s.parse::<Step>().unwrap()) {
            match s {
                Step::MoveTo { zone } => at = scene.zone(&zone),
                Step::Pick { .. } => {}
                Step::Place { object } => {
                    let (z, t) = (at.unwrap(), targets.next().unwrap());
                    let model = &scene.key_object(&object).unwrap().model;
                    let shape = &cat.model(model).unwrap().shape;
                    assert!(
                        fits_in_zone(z, shape.footprint_radius(), [t[0], t[1]]),
                        "{}",
                        i.id
                    );
                    assert!((t[2] - z.height - shape.half_height()).abs() < 1e-3, "{}", i.id);
                }
            }
        }
        assert!(targets.next().is_none());
    }
}

#[test]
fn same_seed_same_dataset_other_seed_other_dataset() {
    assert_eq!(generated(), generated());
    assert_ne!(generate(1, &assets()).unwrap().dev, generated().dev);
}

/// The committed files are exactly what the generator writes for the committed seed, so they
/// cannot drift from the code. Regenerate with
/// `cargo run -- dataset generate --seed 20241 --out assets/dataset` when this fails on purpose.
#[test]
fn committed_dataset_is_reproducible_byte_for_byte() {
    let out = std::env::temp_dir().join(format!("kitchen-r-dataset-{}", std::process::id()));
    write(&generated(), &out).unwrap();
    for name in [
        "dev.jsonl",
        "test.jsonl",
        "test_ground_truth.jsonl",
        "manifest.json",
    ] {
        let fresh = std::fs::read(out.join(name)).unwrap();
        let committed = std::fs::read(assets().join("dataset").join(name)).unwrap();
        assert!(
            fresh == committed,
            "assets/dataset/{name} differs from a fresh generation"
        );
    }
    std::fs::remove_dir_all(&out).unwrap();
    let loaded = Dataset::load(&assets().join("dataset")).unwrap();
    assert_eq!(loaded, generated());
}

#[test]
fn check_plan_rejects_broken_plans() {
    let cat = Catalogue::load(&assets().join("objects.toml")).unwrap();
    let scene = Scene::load(&assets().join("scenes/kitchen_a.toml"), &cat).unwrap();
    let plan = |s: &[&str]| s.iter().map(|s| s.to_string()).collect::<Vec<_>>();
    let ok = plan(&[
        "move to the red zone",
        "pick the red cup",
        "move to the green zone",
        "place the red cup",
    ]);
    // The plate sits in the middle of the green zone; the cup goes beside it.
    let good_target = [3.18, 3.6, 0.95];
    check_plan(&scene, &cat, &ok, &[good_target]).unwrap();
    // Picking where the object is not, placing nothing held, moving in place, placing back where
    // it was picked up, off-zone, crowded or misplaced targets.
    for (bad, targets) in [
        (
            plan(&[
                "move to the blue zone",
                "pick the red cup",
                "move to the green zone",
                "place the bowl",
            ]),
            vec![good_target],
        ),
        (
            plan(&[
                "move to the blue zone",
                "move to the green zone",
                "place the bowl",
                "move to the red zone",
            ]),
            vec![good_target],
        ),
        (
            plan(&[
                "move to the blue zone",
                "move to the blue zone",
                "pick the bowl",
                "move to the green zone",
            ]),
            vec![],
        ),
        (
            plan(&[
                "move to the red zone",
                "pick the red cup",
                "move to the green zone",
                "move to the red zone",
                "place the red cup",
            ]),
            vec![[2.38, 1.8, 0.8]],
        ),
        (ok.clone(), vec![[3.5, 3.6, 0.95]]),
        (ok.clone(), vec![[3.0, 3.6, 0.95]]),
        (ok.clone(), vec![[3.18, 3.6, 0.9]]),
        (ok.clone(), vec![]),
    ] {
        assert!(
            check_plan(&scene, &cat, &bad, &targets).is_err(),
            "{bad:?} {targets:?}"
        );
    }
}

#[test]
fn every_template_has_at_least_four_phrasings() {
    let ts = templates::load_templates(&assets().join("templates.toml")).unwrap();
    for t in &ts {
        assert!(
            t.instructions.len() >= 4,
            "{}: {} phrasings",
            t.id,
            t.instructions.len()
        );
    }
}

#[test]
fn places_are_named_by_colour_or_furniture_and_plans_use_colours() {
    let cat = Catalogue::load(&assets().join("objects.toml")).unwrap();
    let scenes = Scene::load_all(&assets().join("scenes"), &cat).unwrap();
    let d = generated();
    let (mut by_name, mut by_colour) = (0, 0);
    for i in d.dev.iter().chain(&d.test) {
        let scene = scenes.iter().find(|s| s.id == i.scene).unwrap();
        assert!(!i.instruction.contains(['{', '}']), "{}: {}", i.id, i.instruction);
        let text = i.instruction.to_lowercase();
        let names = scene.zones.iter().flat_map(|z| &z.names);
        by_name += usize::from(names.into_iter().any(|n| text.contains(n.as_str())));
        by_colour += usize::from(text.contains(" zone"));
        for step in &i.plan {
            if let Step::MoveTo { zone } = step.parse::<Step>().unwrap() {
                assert!(scene.zone(&zone).is_some(), "{}: {step}", i.id);
            }
        }
    }
    let total = d.dev.len() + d.test.len();
    assert!(
        by_name > total / 4,
        "{by_name} of {total} name a place by furniture"
    );
    assert!(
        by_colour > total / 4,
        "{by_colour} of {total} name a place by colour"
    );
}

const PRIVATE: &str = r#"
[[template]]
id = "t01_move"
instructions = ["Kindly relocate the {a} onto the {x} zone.", "The {x} zone wants the {a}."]

[[template]]
id = "t36_swap"
instructions = ["Have the {a} and the {b} change places, the {a} going first."]
"#;

fn public_templates() -> Vec<templates::Template> {
    templates::load_templates(&assets().join("templates.toml")).unwrap()
}

fn private_options(seed: u64) -> GenerateOptions {
    let private = templates::PrivatePhrasings::parse(PRIVATE, &public_templates()).unwrap();
    GenerateOptions {
        seed,
        private: Some(private),
        ..GenerateOptions::default()
    }
}

#[test]
fn private_phrasings_replace_test_phrasings_only() {
    let public = generated();
    let private = generate_with(&private_options(COMMITTED_SEED), &assets()).unwrap();
    assert_eq!(
        private.dev, public.dev,
        "the dev split does not depend on private phrasings"
    );
    let is_private = |text: &str| {
        ["Kindly relocate", "wants the", "change places, the"]
            .iter()
            .any(|p| text.contains(p))
    };
    assert!(private.dev.iter().all(|i| !is_private(&i.instruction)));
    let mut seen = 0;
    for i in &private.test {
        let covered = ["t01_move", "t36_swap"].contains(&i.template.as_str());
        assert_eq!(covered, is_private(&i.instruction), "{}: {}", i.id, i.instruction);
        seen += usize::from(covered);
    }
    assert!(seen >= 10, "{seen} private test instructions");
    // Plans do not depend on the phrasing: the same template still gives colour plans.
    let swap = private.test.iter().find(|i| i.template == "t36_swap").unwrap();
    assert!(swap.plan[0].starts_with("move to the ") && swap.plan[0].ends_with(" zone"));
}

#[test]
fn private_manifest_has_digest_and_no_seed() {
    let d = generate_with(&private_options(987_654_321), &assets()).unwrap();
    let m = &d.manifest;
    assert!(m.is_private() && !m.is_public_sample());
    assert_eq!(m.seed, None);
    let p = m.private_phrasings.as_ref().unwrap();
    assert_eq!((p.templates, p.phrasings), (2, 3));
    assert_eq!(p.sha256, sha256_hex(PRIVATE.as_bytes()));
    let debug = format!("{:?}", private_options(1));
    assert!(!debug.contains("Kindly") && debug.contains(&p.sha256), "{debug}");
    assert!(
        m.tag()
            .starts_with(&format!("dataset-private-{}", &p.sha256[..12]))
    );
    let out = std::env::temp_dir().join(format!("kitchen-r-private-{}", std::process::id()));
    write(&d, &out).unwrap();
    let json = std::fs::read_to_string(out.join("manifest.json")).unwrap();
    assert!(!json.contains("seed") && !json.contains("987654321"), "{json}");
    assert!(
        json.contains("\"kind\": \"private\"") && json.contains(&p.sha256),
        "{json}"
    );
    for name in ["manifest.json", "dev.jsonl"] {
        let text = std::fs::read_to_string(out.join(name)).unwrap();
        assert!(
            !text.contains("Kindly relocate"),
            "{name} leaks a private phrasing"
        );
    }
    assert_eq!(Dataset::load(&out).unwrap(), d);
    std::fs::remove_dir_all(&out).unwrap();
}

#[test]
fn generation_is_deterministic_with_private_phrasings() {
    let a = generate_with(&private_options(5), &assets()).unwrap();
    let b = generate_with(&private_options(5), &assets()).unwrap();
    assert_eq!(a, b);
    assert_ne!(
        a.test,
        generate_with(&private_options(6), &assets()).unwrap().test
    );
}

#[test]
fn bad_private_phrasings_are_refused() {
    let ts = public_templates();
    let parse = |text: &str| templates::PrivatePhrasings::parse(text, &ts).unwrap_err();
    let entry =
        |id: &str, phrasing: &str| format!("[[template]]\nid = {id:?}\ninstructions = [{phrasing:?}]\n");
    let cases = [
        (
            entry("t99_nope", "Move the {a} to the {x} zone."),
            "unknown template id \"t99_nope\"",
        ),
        (
            entry("t01_move", "Move the {a} somewhere."),
            "does not mention {x}",
        ),
        (
            entry("t01_move", "Move the {a} to the {x} zone."),
            "also a public phrasing",
        ),
        (
            entry("t01_move", "Move the {a} to the {x} zone near the {b}."),
            "uses {b}",
        ),
        (entry("t01_move", "Move the {a} to the {q} zone."), "uses {q}"),
        (
            entry("t01_move", "Shove the {a} to the {x} zone.")
                + &entry("t01_move", "Shove the {a} at the {x} zone."),
            "appears twice",
        ),
        (
            entry("t01_move", "Shove the {a} to the {x} zone.") + "plan = [\"move to the {za} zone\"]\n",
            "unknown field `plan`",
        ),
        (String::new(), "no [[template]]"),
    ];
    for (text, want) in cases {
        let err = parse(&text);
        assert!(err.contains(want), "{text}: {err}");
    }
    let missing = entry("t01_move", "Move the {a} somewhere.");
    assert!(parse(&missing).contains("t01_move"));
}

#[test]
fn old_manifests_read_as_public_samples_and_kinds_are_checked() {
    let old = r#"{"seed": 20241, "generator_version": 2, "templates": 58, "dev": 163, "test": 400}"#;
    let m: Manifest = serde_json::from_str(old).unwrap();
    assert!(m.is_public_sample() && m.check().is_ok());
    assert_eq!(
        (m.seed, m.tag().as_str()),
        (Some(20241), "dataset-seed-20241-gen-2")
    );
    let mut private = generate_with(&private_options(1), &assets()).unwrap().manifest;
    private.check().unwrap();
    private.seed = Some(1);
    assert!(private.check().unwrap_err().contains("seed"));
    private.seed = None;
    private.kind = DatasetKind::PublicSample;
    assert!(private.check().is_err());
}

/// Not a check: `cargo test -p kitchen-r-core -- --ignored write_committed_dataset` rewrites
/// `assets/dataset/` from the committed seed (the CLI's `dataset generate` does the same).
#[test]
#[ignore]
fn write_committed_dataset() {
    write(&generated(), &assets().join("dataset")).unwrap();
}
