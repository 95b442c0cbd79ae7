//! The dataset generator: seed + `assets/` → 563 instructions, and writing them to disk.
//!
//! Process (paper, Language Instructions): for each instruction a template is taken from a
//! seeded round-robin over all 58 (so every template is used 9 or 10 times, and the dev split,
//! being the first 163, holds every template), a scene is drawn, then objects and zones of that
//! scene are substituted. A substitution is kept only if its plan runs symbolically from the
//! scene's initial placement ([`super::symbolic`]) and its text is new in that scene; otherwise
//! another scene and substitution are drawn. Each `the {Z} zone` of the drawn phrasing is
//! rendered by colour or, about half the time when the zone has `names`, by one of its
//! furniture names; plans always use the colour. With private phrasings
//! ([`GenerateOptions::private`]) the test split draws its phrasings from them for the templates
//! they cover; the dev split, generated first, is the same as without them.
//! Scenes that break the navigation conventions
//! ([`crate::layout`]) are refused up front, so a new scene is a data change the generator
//! vets. Only vectors and `BTreeMap`s are iterated and all randomness comes from one
//! [`SplitMix64`], so the same seed gives the same bytes.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use super::language::{self, Feature, Lexicon};
use super::rng::SplitMix64;
use super::symbolic::plan_targets_with;
use super::templates::{Binding, PrivatePhrasings, Template, fill_places, load_templates, start_zone_var};
use super::{
    DEV_INSTRUCTIONS, Dataset, DatasetKind, Instruction, LanguageSummary, Manifest, PublicInstruction,
    TOTAL_INSTRUCTIONS,
};
use crate::ContentError;
use crate::audit::{Attack, Source};
use crate::catalogue::Catalogue;
use crate::plan::parse_plan;
use crate::reach::ArmReach;
use crate::scene::Scene;

/// Bumped whenever the same seed would give different files.
pub const GENERATOR_VERSION: u32 = 3;
/// The seed of the committed `assets/dataset/`.
pub const COMMITTED_SEED: u64 = 20241;
/// Substitutions tried per instruction before the template is declared unusable.
const ATTEMPTS: usize = 600;
/// Substitutions tried in the drawn scene before the next scene is tried.
const SCENE_ATTEMPTS: usize = 100;

/// What to generate: the seed, for a private set the phrasings its test split uses, and the
/// language features its test split is composed with.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct GenerateOptions {
    pub seed: u64,
    /// Private phrasings ([`super::templates::load_private_phrasings`]); `Some` makes a
    /// [`DatasetKind::Private`] set whose manifest omits the seed.
    pub private: Option<PrivatePhrasings>,
    /// Language features of the test split ([`super::language`]); empty: template phrasings
    /// only (what every public sample has). The CLI turns them all on for private sets.
    pub language: BTreeSet<Feature>,
}

impl GenerateOptions {
    /// A public sample from `seed`.
    pub fn public(seed: u64) -> GenerateOptions {
        GenerateOptions {
            seed,
            ..GenerateOptions::default()
        }
    }
}

/// Generate a public sample from the scenes, catalogue and templates under `assets`
/// (`generate_with(&GenerateOptions::public(seed), assets)`).
pub fn generate(seed: u64, assets: &Path) -> Result<Dataset, ContentError> {
    generate_with(&GenerateOptions::public(seed), assets)
}

/// Generate the whole dataset from the scenes, catalogue and templates under `assets`, with the
/// private phrasings of `options` (if any) in the test split.
pub fn generate_with(options: &GenerateOptions, assets: &Path) -> Result<Dataset, ContentError> {
    let seed = options.seed;
    let catalogue = Catalogue::load(&assets.join("objects.toml"))?;
    let scenes = Scene::load_all(&assets.join("scenes"), &catalogue)?;
    let templates_path = assets.join("templates.toml");
    let templates = load_templates(&templates_path)?;
    // Place targets must be reachable by this robot's arm from the zone's approach pose.
    let arm = ArmReach::load(&assets.join(crate::robot::SHIPPED))?;
    if let Some(private) = &options.private
        && let Some(id) = private
            .template_ids()
            .find(|id| !templates.iter().any(|t| t.id == *id))
    {
        return Err(ContentError::Invalid {
            path: templates_path,
            message: format!("private phrasings name template {id:?}, which is not in this file"),
        });
    }
    if scenes.is_empty() {
        return Err(ContentError::Invalid {
            path: assets.join("scenes"),
            message: "no scenes".into(),
        });
    }
    // Instructions must be executable by the oracle too, not only symbolically.
    for s in &scenes {
        s.check_layout()
            .and_then(|()| s.check_contents(&catalogue))
            .map_err(|message| ContentError::Invalid {
                path: assets.join("scenes").join(format!("{}.toml", s.id)),
                message,
            })?;
    }
    let mut rng = SplitMix64::new(seed);
    let mut order = Vec::with_capacity(TOTAL_INSTRUCTIONS + templates.len());
    while order.len() < TOTAL_INSTRUCTIONS {
        let mut round: Vec<usize> = (0..templates.len()).collect();
        rng.shuffle(&mut round);
        order.extend(round);
    }
    // The phrase book is read only when features are on, so public samples need no such file.
    let lexicon = match (
        options.language.is_empty(),
        options.private.as_ref().and_then(PrivatePhrasings::lexicon),
    ) {
        (true, _) => None,
        (false, private) => {
            let public = language::load_lexicon(&assets.join("language.toml"))?;
            Some(private.map_or_else(|| public.clone(), |p| public.overlay(p)))
        }
    };
    // A composed sentence that a public phrasing reproduces would leak its plan: refused.
    let public_phrasings = lexicon
        .is_some()
        .then(|| crate::audit::Attack::from_parts(&templates, &scenes, &[]));
    let mut tally = Tally::default();
    let mut used_texts: BTreeSet<(String, String)> = BTreeSet::new();
    let mut all = Vec::with_capacity(TOTAL_INSTRUCTIONS);
    for (k, &t) in order.iter().take(TOTAL_INSTRUCTIONS).enumerate() {
        let template = &templates[t];
        let private = (k >= DEV_INSTRUCTIONS)
            .then(|| options.private.as_ref()?.for_template(&template.id))
            .flatten();
        let phrasings = private.unwrap_or(&template.instructions);
        // The scene is drawn first and kept for a while, so that scenes whose zones are
        // crowded are not under-represented; a template that cannot run there moves on.
        let first = rng.below(scenes.len());
        let found = (0..ATTEMPTS).find_map(|n| {
            let scene = &scenes[(first + n / SCENE_ATTEMPTS) % scenes.len()];
            let mut inst = instantiate(template, phrasings, scene, &catalogue, &arm, &mut rng)?;
            let mut composed = false;
            if k >= DEV_INSTRUCTIONS
                && let Some(lexicon) = &lexicon
                && let Some(text) = compose_checked(
                    &inst,
                    scene,
                    &catalogue,
                    (lexicon, &options.language, public_phrasings.as_ref()),
                    &mut rng,
                    &mut tally,
                )
            {
                inst.instruction = text;
                composed = true;
            }
            used_texts
                .insert((scene.id.clone(), inst.instruction.clone()))
                .then_some((inst, composed))
        });
        let (mut inst, composed) = found.ok_or_else(|| ContentError::Invalid {
            path: templates_path.clone(),
            message: format!(
                "template {:?} found no new executable substitution in {ATTEMPTS} tries",
                template.id
            ),
        })?;
        if k >= DEV_INSTRUCTIONS && lexicon.is_some() {
            *(if composed {
                &mut tally.composed
            } else {
                &mut tally.template_phrased
            }) += 1;
        }
        inst.id = if k < DEV_INSTRUCTIONS {
            format!("dev-{:04}", k + 1)
        } else {
            format!("test-{:04}", k + 1 - DEV_INSTRUCTIONS)
        };
        all.push(inst);
    }
    let test = all.split_off(DEV_INSTRUCTIONS);
    let private = options.private.as_ref().map(PrivatePhrasings::summary);
    Ok(Dataset {
        manifest: Manifest {
            kind: match private {
                Some(_) => DatasetKind::Private,
                None => DatasetKind::PublicSample,
            },
            seed: private.is_none().then_some(seed),
            generator_version: GENERATOR_VERSION,
            templates: templates.len(),
            dev: all.len(),
            test: test.len(),
            private_phrasings: private,
            language: lexicon.is_some().then(|| tally.summary(&options.language)),
        },
        dev: all,
        test,
    })
}

/// One random substitution of `template` in `scene`, phrased with one of `phrasings`, or `None`
/// if it does not execute.
fn instantiate(
    template: &Template,
    phrasings: &[String],
    scene: &Scene,
    catalogue: &Catalogue,
    arm: &ArmReach,
    rng: &mut SplitMix64,
) -> Option<Instruction> {
    let mut binding = Binding::new();
    let mut objects: Vec<usize> = (0..scene.key_objects.len()).collect();
    rng.shuffle(&mut objects);
    let object_vars = template.object_vars();
    if object_vars.len() > objects.len() {
        return None;
    }
    for (var, &i) in object_vars.iter().zip(&objects) {
        let o = &scene.key_objects[i];
        binding.insert(var.to_string(), o.name());
        binding.insert(start_zone_var(var), o.zone.clone());
    }
    let mut zones: Vec<&str> = scene.zones.iter().map(|z| z.color.as_str()).collect();
    rng.shuffle(&mut zones);
    let zone_vars = template.free_zone_vars();
    if zone_vars.len() > zones.len() {
        return None;
    }
    for (var, zone) in zone_vars.iter().zip(&zones) {
        binding.insert(var.to_string(), zone.to_string());
    }
    let steps = (template.patterns().ok()?.iter())
        .map(|p| p.instantiate(&binding))
        .collect::<Option<Vec<_>>>()?;
    let place_targets = plan_targets_with(scene, catalogue, arm, &steps, rng).ok()?;
    let phrasing = rng.choose(phrasings)?;
    let instruction = fill_places(phrasing, &binding, |color| {
        let names = scene.zone(color).map_or(&[][..], |z| z.names.as_slice());
        match names {
            [] => format!("the {color} zone"),
            _ if rng.below(2) == 0 => format!("the {color} zone"),
            _ => rng.choose(names).cloned().unwrap_or_default(),
        }
    })?;
    Some(Instruction {
        id: String::new(),
        scene: scene.id.clone(),
        instruction,
        plan: steps.iter().map(ToString::to_string).collect(),
        template: template.id.clone(),
        place_targets,
    })
}

/// What the composer did over the test split, for the manifest and the audit.
#[derive(Debug, Default)]
struct Tally {
    rejected: BTreeMap<String, usize>,
    composed: usize,
    template_phrased: usize,
}

impl Tally {
    fn summary(&self, features: &BTreeSet<Feature>) -> LanguageSummary {
        LanguageSummary {
            features: features.iter().copied().collect(),
            composed: self.composed,
            template_phrased: self.template_phrased,
            rejected: self.rejected.clone(),
        }
    }
}

/// The instruction said by the composer, drawing renderings until the checker finds exactly
/// the instruction's plan (refusals counted by reason); `None` after [`language::ATTEMPTS`].
fn compose_checked(
    inst: &Instruction,
    scene: &Scene,
    catalogue: &Catalogue,
    (lexicon, features, public): (&Lexicon, &BTreeSet<Feature>, Option<&Attack>),
    rng: &mut SplitMix64,
    tally: &mut Tally,
) -> Option<String> {
    let steps = parse_plan(&inst.plan).ok()?;
    for _ in 0..language::ATTEMPTS {
        let (text, meaning) = language::compose(&steps, scene, lexicon, features, rng)?;
        let is_public = |text: &str| {
            public.is_some_and(|a| matches!(a.predict(&scene.id, text).source, Source::Template(_)))
        };
        let reason = match language::check(&meaning, scene, catalogue) {
            Ok(_) if is_public(&text) => "a public template phrasing",
            Ok(plan) if plan == inst.plan => return Some(text),
            Ok(_) => "another plan than the template's",
            Err(r) => r.reason(),
        };
        *tally.rejected.entry(reason.to_string()).or_default() += 1;
    }
    None
}

/// Write `dev.jsonl`, `test.jsonl`, `test_ground_truth.jsonl` and `manifest.json` into `out_dir`
/// (created if missing), in the layout [`Dataset::load`] reads.
pub fn write(dataset: &Dataset, out_dir: &Path) -> Result<(), ContentError> {
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| ContentError::Io { path, source }
    };
    std::fs::create_dir_all(out_dir).map_err(io(out_dir))?;
    let public: Vec<PublicInstruction> = dataset.test.iter().map(PublicInstruction::from).collect();
    let files = [
        ("dev.jsonl", jsonl(&dataset.dev)),
        ("test.jsonl", jsonl(&public)),
        ("test_ground_truth.jsonl", jsonl(&dataset.test)),
        ("manifest.json", manifest_json(&dataset.manifest)),
    ];
    for (name, text) in files {
        let path = out_dir.join(name);
        std::fs::write(&path, text).map_err(io(&path))?;
    }
    Ok(())
}

/// One compact JSON record per line, `\n`-terminated.
fn jsonl<T: serde::Serialize>(records: &[T]) -> String {
    let mut out = String::new();
    for r in records {
        out.push_str(&serde_json::to_string(r).expect("dataset records serialise"));
        out.push('\n');
    }
    out
}

fn manifest_json(m: &Manifest) -> String {
    serde_json::to_string_pretty(m).expect("manifest serialises") + "\n"
}
