use std::path::{Path, PathBuf};

use super::*;
use crate::dataset::templates::{Binding, Pattern, fill, placeholders};

fn assets() -> PathBuf {
    crate::assets::assets_dir()
}

/// A scratch directory under the system temp dir, emptied first.
fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("kitchen-r-audit-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn write_jsonl<T: serde::Serialize>(path: &Path, records: &[T]) {
    let text: String = (records.iter())
        .map(|r| serde_json::to_string(r).unwrap() + "\n")
        .collect();
    std::fs::write(path, text).unwrap();
}

/// The committed public sample is inverted entirely: proof that the attack is a real one.
#[test]
fn attack_inverts_the_public_sample() {
    let dir = assets().join("dataset");
    let report = audit(&dir, &assets()).unwrap();
    let a = report.attack.as_ref().expect("the sample ships its ground truth");
    assert_eq!(
        a.em,
        1.0,
        "{}",
        report.render(&report.checks(&Thresholds::default()))
    );
    assert_eq!(a.perfect, report.test_instructions);
    assert_eq!(report.public_phrasing, report.test_instructions);
    assert!(report.public_sample);
    let checks = report.checks(&Thresholds::default());
    assert!(checks.iter().any(|c| c.name == "attack EM" && !c.passed));
    let text = report.render(&checks);
    assert!(
        text.contains("FAILS the audit") && text.contains("public sample"),
        "{text}"
    );
}

/// The binding behind a generated instruction, read back from its plan and template (test
/// scaffolding: the attack itself never sees template ids or plans of the audited set).
fn binding_of(template: &crate::dataset::templates::Template, plan: &[String]) -> Binding {
    let mut b = Binding::new();
    for (p, step) in template.patterns().unwrap().iter().zip(plan) {
        let (var, value) = match p {
            Pattern::MoveTo(z) => (
                z,
                step.strip_prefix("move to the ")
                    .and_then(|s| s.strip_suffix(" zone")),
            ),
            Pattern::Pick(o) => (o, step.strip_prefix("pick the ")),
            Pattern::Place(o) => (o, step.strip_prefix("place the ")),
        };
        b.insert(var.clone(), value.unwrap().to_string());
    }
    b
}

/// A phrasing no public file contains: the first phrasing's mentions, objects first, in new words.
fn novel_phrasing(template: &crate::dataset::templates::Template) -> String {
    let mut objects = Vec::new();
    let mut zones = Vec::new();
    let in_plan: Vec<&str> = template.plan.iter().flat_map(|p| placeholders(p)).collect();
    for v in placeholders(&template.instructions[0]) {
        // An object the plan never handles is only a place ("next to the {b}"): say its zone.
        let zone_of_b;
        let v = if in_plan.contains(&v) {
            v
        } else {
            zone_of_b = format!("z{v}");
            zone_of_b.as_str()
        };
        let (list, text) = if v == "a" || v == "b" {
            (&mut objects, format!("the {{{v}}}"))
        } else {
            (&mut zones, format!("the {{{v}}} zone"))
        };
        if !list.contains(&text) {
            list.push(text);
        }
    }
    let mut s = String::from("Robot, a chore");
    if !objects.is_empty() {
        s += &format!(" concerning {}", objects.join(" plus "));
    }
    if !zones.is_empty() {
        s += &format!(" touching {}", zones.join(" plus "));
    }
    s + ": sort it out."
}

/// The public sample with every test instruction reworded in phrasings unknown to the attack.
fn reworded_sample(name: &str) -> PathBuf {
    let templates = crate::dataset::templates::load_templates(&assets().join("templates.toml")).unwrap();
    let gt: Vec<Instruction> = read_jsonl(&assets().join("dataset/test_ground_truth.jsonl")).unwrap();
    let reworded: Vec<Instruction> = (gt.into_iter())
        .map(|mut ins| {
            let t = templates.iter().find(|t| t.id == ins.template).unwrap();
            ins.instruction = fill(&novel_phrasing(t), &binding_of(t, &ins.plan)).unwrap();
            ins
        })
        .collect();
    let dir = scratch(name);
    write_jsonl(&dir.join("test_ground_truth.jsonl"), &reworded);
    std::fs::write(
        dir.join("manifest.json"),
        "{\"kind\": \"private\", \"seed\": 1}\n",
    )
    .unwrap();
    dir
}

/// Limits that accept what phrasings in the public mention order leave to the fallback (about
/// 0.67): the default 0.3 asks for phrasings that also reorder their mentions.
fn mention_order_thresholds() -> Thresholds {
    Thresholds {
        max_attack_em: 0.75,
        max_bag_of_mentions_em: 0.75,
        ..Thresholds::default()
    }
}

#[test]
fn unknown_phrasings_leave_the_attack_only_its_fallback() {
    let dir = reworded_sample("reworded-low");
    let report = audit(&dir, &assets()).unwrap();
    let a = report.attack.clone().unwrap();
    assert_eq!(a.inverted, 0);
    assert_eq!(report.public_phrasing, 0);
    assert!(!report.public_sample);
    // What is left is the fallback: what the mentioned objects and places give away.
    assert_eq!(a.em, a.fallback_em);
    assert!(a.em < 0.75, "{a:?}");
    // Mentions in the public order still give away too much for a contest.
    assert!(a.em > DEFAULT_MAX_ATTACK_EM, "{a:?}");
    let default_checks = report.checks(&Thresholds::default());
    let attack = default_checks.iter().find(|c| c.name == "attack EM").unwrap();
    assert!(!attack.passed);
    let checks = report.checks(&mention_order_thresholds());
    let attack = checks.iter().find(|c| c.name == "attack EM").unwrap();
    assert!(attack.passed);
    let text = report.render(&checks);
    assert!(!text.contains("note: this is a public sample"), "{text}");
    // Its answers are the public sample's, id for id (as a reused public seed would give).
    assert_eq!(report.shared_plans.unwrap().len(), report.test_instructions);
    let shared = checks
        .iter()
        .find(|c| c.name == "shared (scene, plan) pairs")
        .unwrap();
    assert!(!shared.passed);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn failed_thresholds_fail_the_audit() {
    let dir = reworded_sample("reworded-thresholds");
    let mut report = audit(&dir, &assets()).unwrap();
    let all_pass = |r: &AuditReport, t: &Thresholds| r.checks(t).iter().all(|c| c.passed);
    let loose = Thresholds {
        max_shared_plans: usize::MAX,
        ..mention_order_thresholds()
    };
    assert!(all_pass(&report, &loose));
    let strict = Thresholds {
        max_attack_em: 0.0,
        ..loose
    };
    assert!(!all_pass(&report, &strict));
    report.oracle = Some(OracleCheck {
        episodes: 1,
        failures: vec![OracleFailure {
            id: "test-0001".into(),
            scene: "kitchen_a".into(),
            reasons: vec!["pick the bowl: out of reach".into()],
        }],
    });
    assert!(!all_pass(&report, &loose));
    let text = report.render(&report.checks(&loose));
    assert!(
        text.contains("oracle failures") && text.contains("out of reach"),
        "{text}"
    );
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn a_set_without_ground_truth_reports_phrasings_only() {
    let dir = scratch("public-only");
    std::fs::copy(assets().join("dataset/test.jsonl"), dir.join("test.jsonl")).unwrap();
    let report = audit(&dir, &assets()).unwrap();
    assert!(report.attack.is_none() && report.shared_plans.is_none());
    assert!(report.public_sample, "no manifest: taken as a public sample");
    assert_eq!(report.public_phrasing, report.test_instructions);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn dev_phrasings_alone_invert_what_they_cover() {
    // Without templates the library is the dev split: test instructions phrased like a dev
    // instruction are still inverted.
    let dir = assets();
    let cat = Catalogue::load(&dir.join("objects.toml")).unwrap();
    let scenes = Scene::load_all(&dir.join("scenes"), &cat).unwrap();
    let dev: Vec<Instruction> = read_jsonl(&dir.join("dataset/dev.jsonl")).unwrap();
    let gt: Vec<Instruction> = read_jsonl(&dir.join("dataset/test_ground_truth.jsonl")).unwrap();
    let attack = Attack::from_parts(&[], &scenes, &dev);
    let (mut inverted, mut right) = (0, 0);
    for ins in &gt {
        let g = attack.predict(&ins.scene, &ins.instruction);
        if matches!(g.source, Source::Dev(_)) {
            inverted += 1;
            right += usize::from(g.plan == ins.plan);
        }
    }
    assert!(inverted > gt.len() / 2, "{inverted} of {}", gt.len());
    assert!(right * 100 >= inverted * 95, "{right} of {inverted}");
}

/// A private set made by the generator from phrasings no public file contains: nothing is
/// inverted, the manifest says `private`, and the attack is left its fallback.
#[test]
fn generated_private_set_passes_the_phrasing_checks() {
    use crate::dataset::templates::{PrivatePhrasings, Template, load_templates};
    use crate::dataset::{GenerateOptions, generate_with, write};
    let templates: Vec<Template> = load_templates(&assets().join("templates.toml")).unwrap();
    let mut file = String::new();
    for t in &templates {
        let phrasing = novel_phrasing(t);
        file += &format!("[[template]]\nid = {:?}\ninstructions = [{phrasing:?}]\n\n", t.id);
    }
    let private = PrivatePhrasings::parse(&file, &templates).unwrap();
    let options = GenerateOptions {
        seed: 77,
        private: Some(private),
        ..GenerateOptions::default()
    };
    let dir = scratch("private");
    write(&generate_with(&options, &assets()).unwrap(), &dir).unwrap();
    let report = audit(&dir, &assets()).unwrap();
    assert_eq!(report.kind.as_deref(), Some("private"));
    assert!(!report.public_sample);
    assert_eq!(report.public_phrasing, 0, "{:?}", report.leaks.first());
    let a = report.attack.clone().unwrap();
    assert_eq!(a.inverted, 0);
    assert!(a.em < 0.75, "{a:?}");
    let checks = report.checks(&mention_order_thresholds());
    let failed: Vec<_> = checks.iter().filter(|c| !c.passed).map(|c| c.name).collect();
    assert!(failed.is_empty(), "{failed:?}\n{}", report.render(&checks));
    let _ = std::fs::remove_dir_all(dir);
}
