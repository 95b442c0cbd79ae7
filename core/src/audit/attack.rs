//! The template-inversion attack: a planner built only from public material (the template
//! file, the scene files and the public dev split) that guesses the plan of any instruction.
//!
//! Its library holds one entry per phrasing: each public template phrasing with its plan
//! patterns, and each dev instruction abstracted back into a phrasing (objects and places
//! replaced by slots, see [`abstract_text`]) paired with its dev plan, where every zone of the
//! plan is traced to a slot or to the start zone of a mentioned object. A test instruction is
//! matched against every entry ([`fn@matches`]); the first entry that reproduces the text exactly
//! gives the plan, its object slots bound by name, its zone slots by colour or by a referring
//! expression, and start zones read from the scene's key objects. When no entry matches, the
//! fallback abstracts the instruction the same way and fills the most common plan shape of the
//! library that uses exactly the mentioned objects and zones (or, failing that, the most common
//! one it can fill). Nothing about the set being audited is used except its instruction texts
//! and scenes: its ground truth only scores the guesses.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use serde::Serialize;

use super::phrase::{Abstracted, Token, Vocab, abstract_text, matches, parse_template};
use crate::ContentError;
use crate::catalogue::Catalogue;
use crate::dataset::templates::{Binding, OBJECT_VARS, Pattern, Template, load_templates};
use crate::dataset::{Instruction, read_jsonl};
use crate::plan::Step;
use crate::scene::Scene;

/// A plan step over slots: a zone slot, or `z<object slot>` for that object's start zone.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
enum Slot {
    Move(String),
    Pick(String),
    Place(String),
}

/// Where a guess came from.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case", tag = "kind", content = "id")]
pub enum Source {
    /// A public template phrasing (template id).
    Template(String),
    /// A phrasing abstracted from a public dev instruction (its id).
    Dev(String),
    /// Nothing matched: the most common plan shape over the mentioned objects and zones.
    Fallback,
}

/// A predicted plan and how it was found.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Guess {
    pub plan: Vec<String>,
    pub source: Source,
}

/// For one abstract dev phrasing: where it was first seen, and per plan its count and first id.
type DevVotes = (usize, BTreeMap<Vec<Slot>, (usize, String)>);

#[derive(Debug, Clone)]
struct Entry {
    tokens: Vec<Token>,
    plan: Vec<Slot>,
    source: Source,
    /// Object slot names (a zone slot `z<o>` is o's start zone).
    objects: BTreeSet<String>,
}

/// The attack, ready to guess.
#[derive(Debug, Clone)]
pub struct Attack {
    entries: Vec<Entry>,
    vocabs: BTreeMap<String, Vocab>,
    /// Canonical plan shapes (over `o1`, `q1`, `zo1`, …), most common first.
    shapes: Vec<Vec<Slot>>,
}

impl Attack {
    /// Build from a public assets directory: `templates.toml`, `objects.toml`, `scenes/`,
    /// and `dataset/dev.jsonl` (if present).
    pub fn from_public(assets: &Path) -> Result<Attack, ContentError> {
        let catalogue = Catalogue::load(&assets.join("objects.toml"))?;
        let scenes = Scene::load_all(&assets.join("scenes"), &catalogue)?;
        let templates = load_templates(&assets.join("templates.toml"))?;
        let dev_path = assets.join("dataset/dev.jsonl");
        let dev: Vec<Instruction> = if dev_path.is_file() {
            read_jsonl(&dev_path)?
        } else {
            Vec::new()
        };
        Ok(Attack::from_parts(&templates, &scenes, &dev))
    }

    pub fn from_parts(templates: &[Template], scenes: &[Scene], dev: &[Instruction]) -> Attack {
        let vocabs: BTreeMap<String, Vocab> = scenes.iter().map(|s| (s.id.clone(), Vocab::of(s))).collect();
        let mut entries = Vec::new();
        let mut shape_count: BTreeMap<Vec<Slot>, usize> = BTreeMap::new();
        for t in templates {
            let Ok(patterns) = t.patterns() else { continue };
            let plan: Vec<Slot> = patterns.iter().map(slot_of).collect();
            for phrasing in &t.instructions {
                let e = Entry {
                    tokens: parse_template(phrasing, |v| OBJECT_VARS.contains(&v)),
                    plan: plan.clone(),
                    source: Source::Template(t.id.clone()),
                    objects: OBJECT_VARS.iter().map(|o| o.to_string()).collect(),
                };
                if let Some(s) = canonical_shape(&e) {
                    *shape_count.entry(s).or_default() += 1;
                }
                entries.push(e);
            }
        }
        // Dev phrasings: the most frequent plan per abstract phrasing, first seen first.
        let mut dev_votes: BTreeMap<Vec<Token>, DevVotes> = BTreeMap::new();
        for (k, ins) in dev.iter().enumerate() {
            let Some(vocab) = vocabs.get(&ins.scene) else {
                continue;
            };
            let Some(e) = dev_entry(ins, vocab) else { continue };
            if let Some(s) = canonical_shape(&e) {
                *shape_count.entry(s).or_default() += 1;
            }
            let slot = dev_votes.entry(e.tokens).or_insert((k, BTreeMap::new()));
            slot.1.entry(e.plan).or_insert((0, ins.id.clone())).0 += 1;
        }
        let mut dev_entries: Vec<(usize, Entry)> = (dev_votes.into_iter())
            .filter_map(|(tokens, (first, plans))| {
                let (plan, (_, id)) = plans.into_iter().max_by_key(|(_, (n, _))| *n)?;
                let objects = object_slots(&tokens);
                let source = Source::Dev(id);
                Some((
                    first,
                    Entry {
                        tokens,
                        plan,
                        source,
                        objects,
                    },
                ))
            })
            .collect();
        dev_entries.sort_by_key(|(first, _)| *first);
        entries.extend(dev_entries.into_iter().map(|(_, e)| e));
        let mut shapes: Vec<(Vec<Slot>, usize)> = shape_count.into_iter().collect();
        // Most common first; equal counts in shape order, so the choice is deterministic.
        shapes.sort_by(|a, b| b.1.cmp(&a.1).then_with(|| a.0.cmp(&b.0)));
        Attack {
            entries,
            vocabs,
            shapes: shapes.into_iter().map(|(s, _)| s).collect(),
        }
    }

    /// Phrasings in the library (template phrasings, then dev-derived ones).
    pub fn library_size(&self) -> (usize, usize) {
        let templates = (self.entries.iter())
            .filter(|e| matches!(e.source, Source::Template(_)))
            .count();
        (templates, self.entries.len() - templates)
    }

    /// The attack's plan for `text` in `scene`.
    pub fn predict(&self, scene: &str, text: &str) -> Guess {
        let Some(vocab) = self.vocabs.get(scene) else {
            return Guess {
                plan: Vec::new(),
                source: Source::Fallback,
            };
        };
        for e in &self.entries {
            if let Some(plan) = try_entry(e, text, vocab) {
                return Guess {
                    plan,
                    source: e.source.clone(),
                };
            }
        }
        Guess {
            plan: self.fallback(text, vocab),
            source: Source::Fallback,
        }
    }

    /// The fallback alone (what the mentioned objects and zones give without any phrasing).
    pub fn fallback_only(&self, scene: &str, text: &str) -> Vec<String> {
        self.vocabs
            .get(scene)
            .map_or_else(Vec::new, |v| self.fallback(text, v))
    }

    fn fallback(&self, text: &str, vocab: &Vocab) -> Vec<String> {
        let Abstracted { binding, .. } = abstract_text(text, vocab);
        let mentioned: BTreeSet<&str> = binding.keys().map(String::as_str).collect();
        let exact = |s: &&Vec<Slot>| shape_vars(s) == mentioned;
        let fits = |s: &&Vec<Slot>| shape_vars(s).is_subset(&mentioned);
        let shape = (self.shapes.iter().find(exact)).or_else(|| self.shapes.iter().find(fits));
        shape
            .and_then(|s| instantiate(s, &binding, vocab))
            .unwrap_or_default()
    }
}

fn slot_of(p: &Pattern) -> Slot {
    match p {
        Pattern::MoveTo(z) => Slot::Move(z.clone()),
        Pattern::Pick(o) => Slot::Pick(o.clone()),
        Pattern::Place(o) => Slot::Place(o.clone()),
    }
}

fn object_slots(tokens: &[Token]) -> BTreeSet<String> {
    (tokens.iter())
        .filter_map(|t| match t {
            Token::Obj(v) => Some(v.clone()),
            _ => None,
        })
        .collect()
}

/// The plan of `e` if its phrasing reproduces `text` in a scene with `vocab`.
fn try_entry(e: &Entry, text: &str, vocab: &Vocab) -> Option<Vec<String>> {
    let start_of = |v: &str| {
        v.strip_prefix('z')
            .filter(|o| e.objects.contains(*o))
            .map(str::to_string)
    };
    let mut plan = None;
    let mut accept = |b: &Binding| {
        // A start zone the text names must be where the named object starts.
        let consistent = b.iter().all(|(v, zone)| {
            let object = start_of(v).and_then(|o| b.get(&o));
            object.is_none_or(|o| vocab.start_zone(o) == Some(zone.as_str()))
        });
        plan = consistent.then(|| instantiate(&e.plan, b, vocab)).flatten();
        plan.is_some()
    };
    matches(&e.tokens, text, vocab, &|v| start_of(v).is_none(), &mut accept);
    plan
}

fn instantiate(plan: &[Slot], b: &Binding, vocab: &Vocab) -> Option<Vec<String>> {
    let zone = |v: &str| {
        b.get(v).cloned().or_else(|| {
            let object = b.get(v.strip_prefix('z')?)?;
            vocab.start_zone(object).map(str::to_string)
        })
    };
    (plan.iter())
        .map(|s| {
            let step = match s {
                Slot::Move(z) => Step::MoveTo { zone: zone(z)? },
                Slot::Pick(o) => Step::Pick {
                    object: b.get(o)?.clone(),
                },
                Slot::Place(o) => Step::Place {
                    object: b.get(o)?.clone(),
                },
            };
            Some(step.to_string())
        })
        .collect()
}

/// A dev instruction as a library entry, or `None` if its plan names something the text does
/// not pin down.
fn dev_entry(ins: &Instruction, vocab: &Vocab) -> Option<Entry> {
    let a = abstract_text(&ins.instruction, vocab);
    let var_of = |value: &str, prefix: char| {
        (a.binding.iter())
            .find(|(v, val)| *val == value && v.starts_with(prefix))
            .map(|(v, _)| v.clone())
    };
    let steps: Vec<Step> = ins.plan.iter().map(|s| s.parse().ok()).collect::<Option<_>>()?;
    let mut plan = Vec::with_capacity(steps.len());
    for (i, step) in steps.iter().enumerate() {
        plan.push(match step {
            Step::Pick { object } => Slot::Pick(var_of(object, 'o')?),
            Step::Place { object } => Slot::Place(var_of(object, 'o')?),
            Step::MoveTo { zone } => {
                let starts_here = |o: &String| vocab.start_zone(o) == Some(zone.as_str());
                // Going to pick an object where it starts: its start zone.
                let to_pick = match steps.get(i + 1) {
                    Some(Step::Pick { object }) if starts_here(object) => var_of(object, 'o'),
                    _ => None,
                };
                let start_of_mentioned = || {
                    (a.binding.iter())
                        .find(|(v, o)| v.starts_with('o') && starts_here(o))
                        .map(|(v, _)| v.clone())
                };
                match to_pick.map(|o| format!("z{o}")).or_else(|| var_of(zone, 'q')) {
                    Some(v) => Slot::Move(v),
                    None => Slot::Move(format!("z{}", start_of_mentioned()?)),
                }
            }
        });
    }
    Some(Entry {
        objects: object_slots(&a.tokens),
        tokens: a.tokens,
        plan,
        source: Source::Dev(ins.id.clone()),
    })
}

/// The entry's plan over slots renamed in order of first mention (`o1`, `q1`, `zo1`), as the
/// fallback's abstraction names them; `None` if the plan uses a slot the phrasing never says.
fn canonical_shape(e: &Entry) -> Option<Vec<Slot>> {
    let mut names: BTreeMap<&str, String> = BTreeMap::new();
    let (mut objects, mut zones) = (0, 0);
    for t in &e.tokens {
        match t {
            Token::Obj(v) if !names.contains_key(v.as_str()) => {
                objects += 1;
                names.insert(v, format!("o{objects}"));
            }
            Token::Zone(v) | Token::ZoneRef(v) if !names.contains_key(v.as_str()) => {
                zones += 1;
                names.insert(v, format!("q{zones}"));
            }
            _ => {}
        }
    }
    let rename = |v: &str| -> Option<String> {
        if let Some(n) = names.get(v) {
            return Some(n.clone());
        }
        let object = v.strip_prefix('z').filter(|o| e.objects.contains(*o))?;
        Some(format!("z{}", names.get(object)?))
    };
    (e.plan.iter())
        .map(|s| {
            Some(match s {
                Slot::Move(z) => Slot::Move(rename(z)?),
                Slot::Pick(o) => Slot::Pick(rename(o)?),
                Slot::Place(o) => Slot::Place(rename(o)?),
            })
        })
        .collect()
}

/// The mentioned slots a canonical shape needs (`zo1` needs `o1`).
fn shape_vars(shape: &[Slot]) -> BTreeSet<&str> {
    (shape.iter())
        .map(|s| match s {
            Slot::Move(v) | Slot::Pick(v) | Slot::Place(v) => v.strip_prefix('z').unwrap_or(v),
        })
        .collect()
}
