//! The example private phrasings (`docs/examples/private-phrasings.example.toml`) against the
//! leak audit: a set generated from them with a fresh seed must keep the public-material attack
//! at or below the limit, and none of its texts may be a public phrasing's fill.

use std::path::PathBuf;

use super::phrase::{Vocab, matches, parse_template};
use super::*;
use crate::dataset::templates::{OBJECT_VARS, load_private_phrasings};
use crate::dataset::{GenerateOptions, TEMPLATE_COUNT, generate_with, write};

/// The attack EM a set in private phrasings must stay within (the acceptance limit).
const MAX_EM: f64 = 0.3;
/// A seed unlike the committed sample's (`COMMITTED_SEED`).
const SEED: u64 = 913_577;

fn example_file() -> PathBuf {
    PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../docs/examples/private-phrasings.example.toml"
    ))
}

#[test]
fn example_private_phrasings_keep_the_public_attack_under_the_limit() {
    let assets = crate::assets::assets_dir();
    let templates = load_templates(&assets.join("templates.toml")).unwrap();
    let private = load_private_phrasings(&example_file(), &templates).unwrap();
    let covered: Vec<&str> = private.template_ids().collect();
    assert_eq!(covered.len(), TEMPLATE_COUNT, "the example covers every template");
    let options = GenerateOptions {
        seed: SEED,
        private: Some(private),
        ..GenerateOptions::default()
    };
    let set = generate_with(&options, &assets).unwrap();
    let dir = std::env::temp_dir().join(format!("kitchen-r-private-example-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    write(&set, &dir).unwrap();

    // What `dataset audit` reports: the attack is built from public material only.
    let report = audit(&dir, &assets).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    assert_eq!(report.kind.as_deref(), Some("private"));
    assert_eq!(report.test_instructions, set.test.len());
    assert_eq!(report.public_phrasing, 0, "{:?}", report.leaks.first());
    let attack = report.attack.expect("the set has its ground truth");
    assert_eq!(attack.inverted, 0);
    assert!(
        attack.em <= MAX_EM,
        "attack EM {:.3} on the example private set (seed {SEED}) exceeds {MAX_EM}",
        attack.em
    );

    // No filling of any public phrasing (any objects, any places, by colour or by furniture)
    // reproduces a test text.
    let catalogue = Catalogue::load(&assets.join("objects.toml")).unwrap();
    let scenes = Scene::load_all(&assets.join("scenes"), &catalogue).unwrap();
    let vocabs: BTreeMap<String, Vocab> = scenes.iter().map(|s| (s.id.clone(), Vocab::of(s))).collect();
    let public: Vec<(&str, Vec<phrase::Token>)> = (templates.iter())
        .flat_map(|t| t.instructions.iter().map(move |p| (t.id.as_str(), p)))
        .map(|(id, p)| (id, parse_template(p, |v| OBJECT_VARS.contains(&v))))
        .collect();
    let fills_public = |scene: &str, text: &str| {
        (public.iter()).find(|(_, tokens)| matches(tokens, text, &vocabs[scene], &|_| false, &mut |_| true))
    };
    // The check sees public phrasings: the dev split, in public phrasings, is all found.
    for ins in &set.dev {
        assert!(
            fills_public(&ins.scene, &ins.instruction).is_some(),
            "{}",
            ins.instruction
        );
    }
    for ins in &set.test {
        if let Some((id, _)) = fills_public(&ins.scene, &ins.instruction) {
            panic!(
                "{}: {:?} fills a public phrasing of {id}",
                ins.id, ins.instruction
            );
        }
    }
}
