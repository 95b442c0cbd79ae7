//! The composer: a template's plan said in richer English, with the [`Meaning`] the checker
//! reads.
//!
//! The plan (already instantiated and executable) is read back into acts: a move followed by a
//! pick or a place is implied by it, every other move is a visit. The acts become clauses; with
//! the features on, a pick and its place become one verb ("put the mug in the sink") or "bring
//! me …" with a sentence saying where "me" is; clauses are reordered by order words at a point
//! where the robot holds nothing; objects are named by colour and kind, by kind alone, by where
//! they are, by what is next to them, as "the other …" or as "it"; places by colour, by
//! furniture or by an object there; and sentences that add no step are mixed in. Every choice is
//! drawn from the seeded generator and checked afterwards, never filtered in advance, so the
//! checker's refusals are real ([`super::unique`]).

use std::collections::BTreeSet;

use super::lexicon::{Feature, Lexicon};
use super::meaning::{Act, Meaning, ObjRef, PlaceRef};
use crate::dataset::rng::SplitMix64;
use crate::plan::Step;
use crate::scene::Scene;

/// A plan act over the scene's things (key object indices) and zone colours.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Did {
    Go(String),
    Pick(usize),
    Place(usize, String),
    Put(usize, String),
}

impl Did {
    fn object(&self) -> Option<usize> {
        match self {
            Did::Go(_) => None,
            Did::Pick(t) | Did::Place(t, _) | Did::Put(t, _) => Some(*t),
        }
    }
}

/// One drawn rendering of `plan` in `scene`: the text and its meaning (not yet checked).
pub fn compose(
    plan: &[Step],
    scene: &Scene,
    lexicon: &Lexicon,
    features: &BTreeSet<Feature>,
    rng: &mut SplitMix64,
) -> Option<(String, Meaning)> {
    let names: Vec<String> = scene.key_objects.iter().map(|o| o.name()).collect();
    let thing = |n: &str| names.iter().position(|m| m == n);
    // Plan steps → acts: moves implied by the next pick or place are dropped.
    let mut dids = Vec::new();
    let mut robot = String::new();
    for (i, s) in plan.iter().enumerate() {
        match s {
            Step::MoveTo { zone } => {
                robot.clone_from(zone);
                if !matches!(plan.get(i + 1), Some(Step::Pick { .. } | Step::Place { .. })) {
                    dids.push(Did::Go(zone.clone()));
                }
            }
            Step::Pick { object } => dids.push(Did::Pick(thing(object)?)),
            Step::Place { object } => dids.push(Did::Place(thing(object)?, robot.clone())),
        }
    }
    let on = |f| features.contains(&f);
    if on(Feature::Implicit) {
        let mut merged: Vec<Did> = Vec::new();
        for d in dids {
            match (merged.last(), &d) {
                (Some(Did::Pick(a)), Did::Place(b, z)) if a == b && rng.below(4) > 0 => {
                    let t = *b;
                    let z = z.clone();
                    merged.pop();
                    merged.push(Did::Put(t, z));
                }
                _ => merged.push(d),
            }
        }
        dids = merged;
    }
    // Where "me" is: the target of some one-verb delivery, half the time.
    let me_zone = (on(Feature::Implicit) && rng.below(2) == 0)
        .then(|| {
            let targets: Vec<&String> = (dids.iter())
                .filter_map(|d| match d {
                    Did::Put(_, z) => Some(z),
                    _ => None,
                })
                .collect();
            rng.choose(&targets).map(|z| (*z).clone())
        })
        .flatten();
    // Order words: split where nothing is held.
    let mut held = false;
    let splits: Vec<usize> = (dids.iter().enumerate())
        .filter_map(|(i, d)| {
            match d {
                Did::Pick(_) => held = true,
                Did::Place(..) => held = false,
                _ => {}
            }
            (!held && i + 1 < dids.len()).then_some(i + 1)
        })
        .collect();
    let order = (on(Feature::Order) && !splits.is_empty() && rng.below(3) > 0)
        .then(|| {
            let k = *rng.choose(&splits)?;
            let reverse = rng.below(3) > 0;
            Some((k, reverse))
        })
        .flatten();
    let plan_things: BTreeSet<usize> = dids.iter().filter_map(Did::object).collect();
    let mut w = Writer {
        scene,
        lex: lexicon,
        features,
        rng,
        meaning: Meaning::default(),
        denotes: Vec::new(),
        acts: Vec::new(),
        current: 0,
        moved: BTreeSet::new(),
        prev_obj: None,
        plan_things,
        me_zone: me_zone.clone(),
    };
    let mut pre = Vec::new();
    let mut post = Vec::new();
    // The sentences around the main one are said first or last; mentions follow the text.
    let me_first = w.rng.below(2) == 0;
    let leave = on(Feature::Distractors) && w.rng.below(3) > 0;
    let leave_first = w.rng.below(2) == 0;
    if let Some(z) = &me_zone
        && me_first
    {
        pre.push(w.me_sentence(z)?);
    }
    if leave && leave_first {
        pre.extend(w.leave_sentence());
    }
    // Plan-order bookkeeping for relational references: what has been handled before each act
    // (picked, carried or placed: no longer where it started).
    let moved_before: Vec<BTreeSet<usize>> = {
        let mut moved = BTreeSet::new();
        (dids.iter())
            .map(|d| {
                let before = moved.clone();
                moved.extend(d.object());
                before
            })
            .collect()
    };
    let all: Vec<usize> = (0..dids.len()).collect();
    let main = match order {
        None => w.run(&all, &dids, &moved_before)?,
        Some((k, reverse)) => {
            let (a, b) = all.split_at(k);
            let (pattern, first, second) = if reverse {
                (w.pick(&w.lex.before)?, b, a)
            } else {
                (w.pick(&w.lex.after)?, a, b)
            };
            let first_text = w.run(first, &dids, &moved_before)?;
            let second_text = w.run(second, &dids, &moved_before)?;
            let (ta, tb) = if reverse {
                (second_text, first_text)
            } else {
                (first_text, second_text)
            };
            pattern.replace("{a}", &ta).replace("{b}", &tb)
        }
    };
    if leave && !leave_first {
        post.extend(w.leave_sentence());
    }
    if let Some(z) = &me_zone
        && !me_first
    {
        post.push(w.me_sentence(z)?);
    }
    let text = (pre.iter().chain(std::iter::once(&main)).chain(&post))
        .map(|s| sentence(s))
        .collect::<Vec<_>>()
        .join(" ");
    w.acts.sort_by_key(|(i, _)| *i);
    let mut meaning = w.meaning;
    meaning.acts = w.acts.into_iter().map(|(_, a)| a).collect();
    Some((text, meaning))
}

/// Capitalised, with a full stop.
fn sentence(s: &str) -> String {
    let s = s.trim();
    let mut chars = s.chars();
    let mut out: String = chars
        .next()
        .map(|c| c.to_uppercase().collect())
        .unwrap_or_default();
    out.push_str(chars.as_str());
    if !out.ends_with(['.', '!', '?']) {
        out.push('.');
    }
    out
}

/// Builds a clause's act from the object and place mentions its holes made.
type MakeAct = fn(&[usize], &[usize]) -> Act;

/// A hole of a clause pattern.
#[derive(Debug, Clone)]
enum Hole {
    Obj(usize),
    Place(String),
}

struct Writer<'a, 'r> {
    scene: &'a Scene,
    lex: &'a Lexicon,
    features: &'a BTreeSet<Feature>,
    rng: &'r mut SplitMix64,
    meaning: Meaning,
    /// What each object mention means (the composer's intent; the checker never sees it).
    denotes: Vec<usize>,
    /// Objects moved before the act being said (plan order).
    moved: BTreeSet<usize>,
    /// Acts with their index in plan order, as said (sorted into plan order at the end).
    acts: Vec<(usize, Act)>,
    /// The plan index of the act being said.
    current: usize,
    /// The object of the clause said just before in the same run, for "it".
    prev_obj: Option<usize>,
    /// Objects the plan handles (distractors pick others).
    plan_things: BTreeSet<usize>,
    me_zone: Option<String>,
}

impl Writer<'_, '_> {
    fn on(&self, f: Feature) -> bool {
        self.features.contains(&f)
    }

    fn pick(&mut self, list: &[String]) -> Option<String> {
        self.rng.choose(list).cloned()
    }

    /// A run of acts said one after another, joined by `then` words.
    fn run(&mut self, acts: &[usize], dids: &[Did], moved_before: &[BTreeSet<usize>]) -> Option<String> {
        self.prev_obj = None;
        let mut out = String::new();
        for (n, &i) in acts.iter().enumerate() {
            if n > 0 {
                out.push_str(&self.pick(&self.lex.then)?);
            }
            self.moved.clone_from(&moved_before[i]);
            self.current = i;
            let carrying = dids[..i].iter().rev().find_map(holding).flatten();
            out.push_str(&self.clause(&dids[i], carrying)?);
            self.prev_obj = dids[i].object();
        }
        Some(out)
    }

    /// One act as a clause; `carrying` is what the robot holds when a visit is said.
    fn clause(&mut self, did: &Did, carrying: Option<usize>) -> Option<String> {
        let me = |z: &String| self.me_zone.as_ref() == Some(z);
        let (pattern, holes, act): (String, Vec<(&str, Hole)>, MakeAct) = match did {
            Did::Go(z) if me(z) && self.rng.below(2) == 0 => {
                let p = self.pick(&self.lex.go_me)?;
                let place = self.push_place(PlaceRef::Me);
                self.acts.push((self.current, Act::Go { place }));
                return Some(p);
            }
            Did::Go(z) => match carrying {
                Some(t) if self.rng.below(2) == 0 => (
                    self.pick(&self.lex.go_holding)?,
                    vec![("{obj}", Hole::Obj(t)), ("{place}", Hole::Place(z.clone()))],
                    |_, p| Act::Go { place: p[0] },
                ),
                _ => (
                    self.pick(&self.lex.go)?,
                    vec![("{place}", Hole::Place(z.clone()))],
                    |_, p| Act::Go { place: p[0] },
                ),
            },
            Did::Pick(t) => (
                self.pick(&self.lex.pick)?,
                vec![("{obj}", Hole::Obj(*t))],
                |o, _| Act::Pick { obj: o[0] },
            ),
            Did::Place(t, z) => (
                self.pick(&self.lex.place)?,
                vec![("{obj}", Hole::Obj(*t)), ("{place}", Hole::Place(z.clone()))],
                |o, p| Act::Place {
                    obj: o[0],
                    place: p[0],
                },
            ),
            Did::Put(t, z) if me(z) => {
                let p = self.pick(&self.lex.bring_me)?;
                let (text, objs, _) = self.fill_holes(&p, &[("{obj}", Hole::Obj(*t))])?;
                let place = self.push_place(PlaceRef::Me);
                self.acts.push((self.current, Act::Put { obj: objs[0], place }));
                return Some(text);
            }
            Did::Put(t, z) => (
                self.pick(&self.lex.put)?,
                vec![("{obj}", Hole::Obj(*t)), ("{place}", Hole::Place(z.clone()))],
                |o, p| Act::Put {
                    obj: o[0],
                    place: p[0],
                },
            ),
        };
        let (text, objs, places) = self.fill_holes(&pattern, &holes)?;
        self.acts.push((self.current, act(&objs, &places)));
        Some(text)
    }
}

/// How an object is named.
#[derive(Debug, Clone, Copy)]
enum Form {
    /// "the red cup".
    Full,
    /// "the cup" (its colour left out).
    Bare,
    /// "the other cup", looking back to that object mention.
    Other(usize),
    /// "the cup on the dining table".
    On,
    /// "the cup next to the bowl" (that thing).
    NextTo(usize),
    /// "the red cup, not the blue one" (that thing).
    Contrast(usize),
}

impl Writer<'_, '_> {
    /// Fill a clause pattern's holes in the order the pattern says them; the object and place
    /// mentions it made, in hole order.
    fn fill_holes(
        &mut self,
        pattern: &str,
        holes: &[(&str, Hole)],
    ) -> Option<(String, Vec<usize>, Vec<usize>)> {
        let mut order: Vec<&(&str, Hole)> = holes.iter().collect();
        order.sort_by_key(|(name, _)| pattern.find(name));
        let (mut objs, mut places) = (Vec::new(), Vec::new());
        let mut text = pattern.to_string();
        for (name, hole) in order {
            let said = match hole {
                Hole::Obj(t) => {
                    let (said, id) = self.obj_ref(*t)?;
                    objs.push(id);
                    said
                }
                Hole::Place(z) => {
                    let (said, id) = self.place_ref(z)?;
                    places.push(id);
                    said
                }
            };
            text = text.replacen(name, &said, 1);
        }
        Some((text, objs, places))
    }

    fn push_obj(&mut self, r: ObjRef, t: usize) -> usize {
        self.meaning.objects.push(r);
        self.denotes.push(t);
        self.meaning.objects.len() - 1
    }

    fn push_place(&mut self, r: PlaceRef) -> usize {
        self.meaning.places.push(r);
        self.meaning.places.len() - 1
    }

    /// A reference to thing `t`: its text and its mention number.
    fn obj_ref(&mut self, t: usize) -> Option<(String, usize)> {
        let o = &self.scene.key_objects[t];
        let (model, variant) = (o.model.clone(), o.variant.clone());
        if self.on(Feature::Pronouns) && self.prev_obj == Some(t) && self.rng.below(5) > 0 {
            let it = self.pick(&self.lex.it)?;
            return Some((it, self.push_obj(ObjRef::It, t)));
        }
        let objects = &self.scene.key_objects;
        let same_model = |u: usize| u != t && objects[u].model == model;
        let mut forms = vec![Form::Full];
        if self.on(Feature::Relational) {
            if variant.is_some() {
                forms.push(Form::Bare);
            }
            // "The other cup" only when every cup said so far (distractors aside) is one other cup.
            let said: Vec<usize> = (0..self.denotes.len())
                .filter(|j| !self.meaning.untouched.contains(j) && objects[self.denotes[*j]].model == model)
                .collect();
            if let Some(&j) = said.last()
                && said
                    .iter()
                    .all(|&k| self.denotes[k] == self.denotes[j] && self.denotes[k] != t)
            {
                forms.extend([Form::Other(j), Form::Other(j)]);
            }
            if !self.moved.contains(&t) {
                forms.push(Form::On);
                let near: Vec<usize> = (0..objects.len())
                    .filter(|&u| u != t && objects[u].zone == o.zone && !self.moved.contains(&u))
                    .collect();
                if let Some(&u) = self.rng.choose(&near) {
                    forms.push(Form::NextTo(u));
                }
            }
        }
        if self.on(Feature::Distractors) && variant.is_some() {
            let others: Vec<usize> = (0..objects.len())
                .filter(|&u| same_model(u) && objects[u].variant.is_some() && !self.plan_things.contains(&u))
                .collect();
            if let Some(&u) = self.rng.choose(&others) {
                forms.push(Form::Contrast(u));
            }
        }
        let form = *self.rng.choose(&forms)?;
        let full = format!("the {}", o.name());
        let bare = format!("the {model}");
        Some(match form {
            Form::Full => (full, self.push_obj(ObjRef::Named { model, variant }, t)),
            Form::Bare => (bare, self.push_obj(ObjRef::Named { model, variant: None }, t)),
            Form::Other(j) => {
                let said = self.pick(&self.lex.other)?.replace("{noun}", &model);
                (said, self.push_obj(ObjRef::Other { model, of: j }, t))
            }
            Form::On => {
                let pattern = self.pick(&self.lex.on)?;
                let zone = o.zone.clone();
                let (place_said, place) = self.plain_place(&zone);
                let id = self.push_obj(
                    ObjRef::On {
                        model,
                        variant: None,
                        place,
                    },
                    t,
                );
                (
                    pattern.replace("{obj}", &bare).replace("{place}", &place_said),
                    id,
                )
            }
            Form::NextTo(u) => {
                let pattern = self.pick(&self.lex.next_to)?;
                let id = self.push_obj(
                    ObjRef::NextTo {
                        model,
                        variant: None,
                        anchor: usize::MAX,
                    },
                    t,
                );
                let (other_said, anchor) = self.named(u);
                if let Some(ObjRef::NextTo { anchor: a, .. }) = self.meaning.objects.get_mut(id) {
                    *a = anchor;
                }
                (
                    pattern.replace("{obj}", &bare).replace("{other}", &other_said),
                    id,
                )
            }
            Form::Contrast(u) => {
                let pattern = self.pick(&self.lex.contrast)?;
                let id = self.push_obj(ObjRef::Named { model, variant }, t);
                let other = &self.scene.key_objects[u];
                let (m, v) = (other.model.clone(), other.variant.clone());
                let said_variant = v.clone().unwrap_or_default();
                let distractor = self.push_obj(ObjRef::Named { model: m, variant: v }, u);
                self.meaning.untouched.push(distractor);
                (
                    pattern
                        .replace("{obj}", &full)
                        .replace("{variant}", &said_variant),
                    id,
                )
            }
        })
    }

    /// Thing `u` by its full name.
    fn named(&mut self, u: usize) -> (String, usize) {
        let o = &self.scene.key_objects[u];
        let r = ObjRef::Named {
            model: o.model.clone(),
            variant: o.variant.clone(),
        };
        (format!("the {}", o.name()), self.push_obj(r, u))
    }

    /// A zone by colour or, half the time when it has them, by a furniture name.
    fn plain_place(&mut self, zone: &str) -> (String, usize) {
        let names = self.scene.zone(zone).map_or(&[][..], |z| z.names.as_slice());
        match self.rng.choose(names) {
            Some(n) if self.rng.below(2) == 0 => {
                let n = n.clone();
                (n.clone(), self.push_place(PlaceRef::Named(n)))
            }
            _ => (
                format!("the {zone} zone"),
                self.push_place(PlaceRef::Colour(zone.to_string())),
            ),
        }
    }

    /// A place: plainly, or (relational) by an unmoved object there.
    fn place_ref(&mut self, zone: &str) -> Option<(String, usize)> {
        if self.on(Feature::Relational) && self.rng.below(2) == 0 {
            let objects = &self.scene.key_objects;
            let there: Vec<usize> = (0..objects.len())
                .filter(|&u| objects[u].zone == zone && !self.moved.contains(&u))
                .collect();
            if let Some(&u) = self.rng.choose(&there) {
                let pattern = self.pick(&self.lex.by)?;
                let (said, obj) = self.named(u);
                return Some((
                    pattern.replace("{obj}", &said),
                    self.push_place(PlaceRef::By(obj)),
                ));
            }
        }
        Some(self.plain_place(zone))
    }

    /// "I'm at the dining table."
    fn me_sentence(&mut self, zone: &str) -> Option<String> {
        let pattern = self.pick(&self.lex.me_at)?;
        let (said, place) = self.plain_place(zone);
        self.meaning.me = Some(place);
        Some(pattern.replace("{place}", &said))
    }

    /// "Leave the plate where it is." about a thing the plan does not handle, if there is one.
    fn leave_sentence(&mut self) -> Option<String> {
        let idle: Vec<usize> = (0..self.scene.key_objects.len())
            .filter(|u| !self.plan_things.contains(u))
            .collect();
        let &u = self.rng.choose(&idle)?;
        let pattern = self.pick(&self.lex.leave)?;
        // Only untouched things may anchor it, so it reads the same before and after the work.
        let (saved_moved, saved_prev) = (self.moved.clone(), self.prev_obj.take());
        self.moved.clone_from(&self.plan_things);
        let said = self.obj_ref(u);
        (self.moved, self.prev_obj) = (saved_moved, saved_prev);
        let (said, id) = said?;
        self.meaning.untouched.push(id);
        Some(pattern.replace("{obj}", &said))
    }
}

/// The object a pick leaves in the hand, looking back from an act (`None` once placed).
fn holding(d: &Did) -> Option<Option<usize>> {
    match d {
        Did::Pick(t) => Some(Some(*t)),
        Did::Place(..) | Did::Put(..) => Some(None),
        Did::Go(_) => None,
    }
}
