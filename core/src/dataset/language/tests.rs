use std::collections::BTreeSet;

use super::meaning::{Act, Meaning, ObjRef, PlaceRef};
use super::*;
use crate::assets::assets_dir;
use crate::catalogue::Catalogue;
use crate::dataset::rng::SplitMix64;
use crate::dataset::symbolic::check_plan;
use crate::dataset::{GenerateOptions, generate, generate_with};
use crate::plan::parse_plan;
use crate::scene::Scene;

fn world() -> (Catalogue, Vec<Scene>, Lexicon) {
    let dir = assets_dir();
    let cat = Catalogue::load(&dir.join("objects.toml")).unwrap();
    let scenes = Scene::load_all(&dir.join("scenes"), &cat).unwrap();
    let lex = load_lexicon(&dir.join("language.toml")).unwrap();
    (cat, scenes, lex)
}

/// kitchen_a: bowl (blue), red cup and blue cup (red: "the dining table"), apple (yellow: "the
/// side counter"), plate (green), fork (purple: "the shelf").
fn kitchen_a(m: &Meaning) -> Result<Vec<String>, Rejection> {
    let (cat, scenes, _) = world();
    let scene = scenes.iter().find(|s| s.id == "kitchen_a").unwrap();
    check(m, scene, &cat)
}

fn named(model: &str, variant: Option<&str>) -> ObjRef {
    ObjRef::Named {
        model: model.into(),
        variant: variant.map(Into::into),
    }
}

fn colour(c: &str) -> PlaceRef {
    PlaceRef::Colour(c.into())
}

#[test]
fn a_plain_instruction_has_its_one_plan_with_the_moves_implied() {
    // "Pick the apple up and put it on the shelf."
    let m = Meaning {
        objects: vec![named("apple", None), ObjRef::It],
        places: vec![PlaceRef::Named("the shelf".into())],
        acts: vec![Act::Pick { obj: 0 }, Act::Place { obj: 1, place: 0 }],
        ..Meaning::default()
    };
    assert_eq!(
        kitchen_a(&m).unwrap(),
        [
            "move to the yellow zone",
            "pick the apple",
            "move to the purple zone",
            "place the apple"
        ]
    );
    // "Move the red cup to the green zone, then take the other cup to the side counter."
    let m = Meaning {
        objects: vec![
            named("cup", Some("red")),
            ObjRef::Other {
                model: "cup".into(),
                of: 0,
            },
        ],
        places: vec![colour("green"), PlaceRef::Named("the side counter".into())],
        acts: vec![Act::Put { obj: 0, place: 0 }, Act::Put { obj: 1, place: 1 }],
        ..Meaning::default()
    };
    let plan = kitchen_a(&m).unwrap();
    assert_eq!(plan[5], "pick the blue cup", "{plan:?}");
    // "I'm at the shelf. Bring me the bowl."
    let m = Meaning {
        objects: vec![named("bowl", None)],
        places: vec![PlaceRef::Named("the shelf".into()), PlaceRef::Me],
        me: Some(0),
        acts: vec![Act::Put { obj: 0, place: 1 }],
        ..Meaning::default()
    };
    assert_eq!(kitchen_a(&m).unwrap()[2], "move to the purple zone");
}

#[test]
fn planted_ambiguous_instructions_are_refused() {
    // "Put the cup on the dining table on the green zone": both cups start there.
    let m = Meaning {
        objects: vec![ObjRef::On {
            model: "cup".into(),
            variant: None,
            place: 0,
        }],
        places: vec![PlaceRef::Named("the dining table".into()), colour("green")],
        acts: vec![Act::Put { obj: 0, place: 1 }],
        ..Meaning::default()
    };
    assert_eq!(kitchen_a(&m), Err(Rejection::AmbiguousReference));
    // "Put the bowl next to the apple, then move it to the green zone": "it" may be either,
    // and both plans run.
    let m = Meaning {
        objects: vec![named("bowl", None), named("apple", None), ObjRef::It],
        places: vec![PlaceRef::By(1), colour("green")],
        acts: vec![Act::Put { obj: 0, place: 0 }, Act::Put { obj: 2, place: 1 }],
        ..Meaning::default()
    };
    assert_eq!(kitchen_a(&m), Err(Rejection::Ambiguous { plans: 2 }));
    // The same with a pick in between that only one reading can follow is unique: "it" is
    // resolved by what can be done, not by guessing.
    let m = Meaning {
        objects: vec![named("bowl", None), named("apple", None), ObjRef::It],
        places: vec![PlaceRef::By(1), colour("green")],
        acts: vec![
            Act::Pick { obj: 0 },
            Act::Place { obj: 2, place: 0 },
            Act::Go { place: 1 },
        ],
        ..Meaning::default()
    };
    assert_eq!(kitchen_a(&m).unwrap()[1], "pick the bowl");
}

#[test]
fn planted_impossible_instructions_are_refused() {
    // "Move the cup next to the fork to the green zone": the fork is alone on the shelf.
    let m = Meaning {
        objects: vec![
            ObjRef::NextTo {
                model: "cup".into(),
                variant: None,
                anchor: 1,
            },
            named("fork", None),
        ],
        places: vec![colour("green")],
        acts: vec![Act::Put { obj: 0, place: 0 }],
        ..Meaning::default()
    };
    assert_eq!(kitchen_a(&m), Err(Rejection::NoReferent));
    // "I'm at the side counter. Bring me the apple.": the apple is already there.
    let m = Meaning {
        objects: vec![named("apple", None)],
        places: vec![PlaceRef::Named("the side counter".into()), PlaceRef::Me],
        me: Some(0),
        acts: vec![Act::Put { obj: 0, place: 1 }],
        ..Meaning::default()
    };
    assert_eq!(kitchen_a(&m), Err(Rejection::NoPlan));
    // "Bring me the bowl." with nothing saying where "me" is.
    let m = Meaning {
        objects: vec![named("bowl", None)],
        places: vec![PlaceRef::Me],
        acts: vec![Act::Put { obj: 0, place: 0 }],
        ..Meaning::default()
    };
    assert_eq!(kitchen_a(&m), Err(Rejection::NoReferent));
    // "Move the bowl to the green zone. Don't touch the bowl."
    let m = Meaning {
        objects: vec![named("bowl", None), named("bowl", None)],
        places: vec![colour("green")],
        acts: vec![Act::Put { obj: 0, place: 0 }],
        untouched: vec![1],
        ..Meaning::default()
    };
    assert_eq!(kitchen_a(&m), Err(Rejection::NoPlan));
    // "Put the mango on the green zone."
    let m = Meaning {
        objects: vec![named("mango", None)],
        places: vec![colour("green")],
        acts: vec![Act::Put { obj: 0, place: 0 }],
        ..Meaning::default()
    };
    assert_eq!(kitchen_a(&m), Err(Rejection::NoReferent));
}

#[test]
fn every_kept_rendering_says_its_plan_and_only_it() {
    let (cat, scenes, lex) = world();
    let set = generate(5, &assets_dir()).unwrap();
    let all: BTreeSet<Feature> = Feature::ALL.into_iter().collect();
    let mut rng = SplitMix64::new(3);
    let (mut kept, mut refused) = (0, 0);
    for inst in &set.test {
        let scene = scenes.iter().find(|s| s.id == inst.scene).unwrap();
        let steps = parse_plan(&inst.plan).unwrap();
        let (text, m) = compose(&steps, scene, &lex, &all, &mut rng).unwrap();
        match check(&m, scene, &cat) {
            Ok(plan) => {
                // A unique reading is always the intended one.
                assert_eq!(plan, inst.plan, "{text}");
                kept += 1;
            }
            Err(_) => refused += 1,
        }
    }
    assert!(kept > 200 && refused > 20, "kept {kept}, refused {refused}");
}

#[test]
fn a_composed_set_keeps_dev_and_stays_executable() {
    let assets = assets_dir();
    let public = generate(913, &assets).unwrap();
    let options = GenerateOptions {
        seed: 913,
        language: Feature::ALL.into_iter().collect(),
        ..GenerateOptions::default()
    };
    let composed = generate_with(&options, &assets).unwrap();
    assert_eq!(composed.dev, public.dev, "the dev split never changes");
    assert_eq!(
        composed,
        generate_with(&options, &assets).unwrap(),
        "deterministic"
    );
    let summary = composed.manifest.language.clone().unwrap();
    assert_eq!(summary.composed + summary.template_phrased, composed.test.len());
    assert!(summary.composed >= 390, "{summary:?}");
    assert!(summary.rejected.values().sum::<usize>() > 0, "{summary:?}");
    assert!(public.manifest.language.is_none());
    let (cat, scenes, _) = world();
    for i in &composed.test {
        let scene = scenes.iter().find(|s| s.id == i.scene).unwrap();
        check_plan(scene, &cat, &i.plan, &i.place_targets).unwrap_or_else(|e| panic!("{}: {e}", i.id));
    }
    // Each feature on its own makes a set too.
    for f in Feature::ALL {
        let options = GenerateOptions {
            seed: 913,
            language: [f].into_iter().collect(),
            ..GenerateOptions::default()
        };
        let set = generate_with(&options, &assets).unwrap();
        assert_eq!(set.manifest.language.unwrap().features, [f]);
    }
}

#[test]
fn features_parse_and_the_phrase_book_is_checked() {
    assert_eq!(parse_features("all").unwrap().len(), 5);
    assert!(parse_features("none").unwrap().is_empty());
    assert_eq!(
        parse_features("order, pronouns").unwrap(),
        [Feature::Pronouns, Feature::Order].into_iter().collect()
    );
    assert!(parse_features("sarcasm").unwrap_err().contains("relational"));
    let (_, _, lex) = world();
    lex.validate(true).unwrap();
    let bad = |l: Lexicon| l.validate(false).unwrap_err();
    assert!(
        bad(Lexicon {
            put: vec!["put {obj} away".into()],
            ..Lexicon::default()
        })
        .contains("lacks {place}")
    );
    assert!(
        bad(Lexicon {
            before: vec!["{a} before you {b}".into()],
            ..Lexicon::default()
        })
        .contains("must say {b} before {a}")
    );
    assert!(
        bad(Lexicon {
            go: vec!["go to {place} with {obj}".into()],
            ..Lexicon::default()
        })
        .contains("holes other than")
    );
    let private = Lexicon {
        go: vec!["make your way to {place}".into()],
        ..Lexicon::default()
    };
    let merged = lex.overlay(&private);
    assert_eq!(merged.go, private.go);
    assert_eq!(merged.put, lex.put);
}
