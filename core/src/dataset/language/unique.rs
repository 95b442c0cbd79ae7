//! The uniqueness checker: every plan a scene and an instruction's [`Meaning`] allow.
//!
//! Each object mention may denote any key object its description fits; "it" any object an
//! earlier mention denotes; "the other cup" a cup other than the one its mention points back to.
//! Every combination of readings that fits the scene as the robot finds it is acted out: the
//! moves a pick or a place needs are added (no move to where the robot already is), and the plan
//! must run by the benchmark's symbolic rules ([`crate::dataset::symbolic`]: empty gripper to
//! pick, no place back where it was picked, …) and leave untouched what the sentence says to
//! leave. An instruction is kept only when exactly one distinct plan remains.

use std::collections::BTreeSet;

use super::meaning::{Act, Meaning, ObjRef, PlaceRef};
use crate::catalogue::Catalogue;
use crate::dataset::symbolic::{Footprint, Placed, SymbolicWorld};
use crate::plan::Step;
use crate::scene::{Scene, Zone};

/// Why an instruction is refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Rejection {
    /// Some reference fits nothing in the scene (alone or together with the others).
    NoReferent,
    /// The references fit, but no reading gives a plan that runs and obeys the sentence.
    NoPlan,
    /// A description (not a pronoun) fits more than one thing in the readings that fit the
    /// scene, even if the plans agree or only one of them runs: "the cup" among two cups.
    AmbiguousReference,
    /// More than one plan: `plans` distinct ones.
    Ambiguous { plans: usize },
}

impl Rejection {
    /// The reason as the audit counts it.
    pub fn reason(self) -> &'static str {
        match self {
            Rejection::NoReferent => "no referent",
            Rejection::NoPlan => "no executable plan",
            Rejection::AmbiguousReference => "ambiguous reference",
            Rejection::Ambiguous { .. } => "ambiguous (several plans)",
        }
    }
}

/// A key object as descriptions see it.
struct Thing {
    name: String,
    model: String,
    variant: Option<String>,
    zone: String,
}

/// The one plan the meaning allows in `scene`, or why there is not exactly one.
pub fn check(meaning: &Meaning, scene: &Scene, catalogue: &Catalogue) -> Result<Vec<String>, Rejection> {
    let (plans, denoted) = search(meaning, scene, catalogue)?;
    let vague = (meaning.objects.iter().zip(&denoted)).any(|(r, d)| *r != ObjRef::It && d.len() > 1);
    if vague {
        return Err(Rejection::AmbiguousReference);
    }
    match plans.len() {
        0 => Err(Rejection::NoPlan),
        1 => Ok(plans.into_iter().next().unwrap_or_default()),
        n => Err(Rejection::Ambiguous { plans: n }),
    }
}

/// Every distinct plan the meaning allows; `Err(NoReferent)` when no reading fits the scene.
pub fn readings(
    meaning: &Meaning,
    scene: &Scene,
    catalogue: &Catalogue,
) -> Result<BTreeSet<Vec<String>>, Rejection> {
    search(meaning, scene, catalogue).map(|(plans, _)| plans)
}

/// The plans, and per object mention the things it denotes in the readings that fit the scene.
type Found = (BTreeSet<Vec<String>>, Vec<BTreeSet<usize>>);

fn search(meaning: &Meaning, scene: &Scene, catalogue: &Catalogue) -> Result<Found, Rejection> {
    let things: Vec<Thing> = (scene.key_objects.iter())
        .map(|o| Thing {
            name: o.name(),
            model: o.model.clone(),
            variant: o.variant.clone(),
            zone: o.zone.clone(),
        })
        .collect();
    let mut search = Search {
        meaning,
        scene,
        catalogue,
        things: &things,
        objs: Vec::with_capacity(meaning.objects.len()),
        fitting: 0,
        denoted: vec![BTreeSet::new(); meaning.objects.len()],
        plans: BTreeSet::new(),
    };
    search.objects();
    if search.fitting == 0 {
        return Err(Rejection::NoReferent);
    }
    Ok((search.plans, search.denoted))
}

struct Search<'a> {
    meaning: &'a Meaning,
    scene: &'a Scene,
    catalogue: &'a Catalogue,
    things: &'a [Thing],
    /// The object each mention denotes so far (indices into `things`).
    objs: Vec<usize>,
    /// Readings that fit the scene, executable or not.
    fitting: usize,
    /// Per object mention, what it denotes in those readings.
    denoted: Vec<BTreeSet<usize>>,
    plans: BTreeSet<Vec<String>>,
}

impl Search<'_> {
    /// Assign the next object mention every way its description allows.
    fn objects(&mut self) {
        let i = self.objs.len();
        let Some(r) = self.meaning.objects.get(i) else {
            return self.fits_places();
        };
        for t in 0..self.things.len() {
            if self.may_denote(r, t) {
                self.objs.push(t);
                self.objects();
                self.objs.pop();
            }
        }
    }

    /// What the description says by itself, and what it says about earlier mentions.
    fn may_denote(&self, r: &ObjRef, t: usize) -> bool {
        let thing = &self.things[t];
        let kind = |model: &str, variant: &Option<String>| {
            thing.model == model && variant.as_ref().is_none_or(|v| thing.variant.as_ref() == Some(v))
        };
        match r {
            ObjRef::Named { model, variant }
            | ObjRef::On { model, variant, .. }
            | ObjRef::NextTo { model, variant, .. } => kind(model, variant),
            ObjRef::Other { model, of } => {
                thing.model == *model && self.objs.get(*of).is_some_and(|&o| o != t)
            }
            ObjRef::It => self.objs.contains(&t),
        }
    }

    /// Relations between mentions once all are assigned, then every reading of the places.
    fn fits_places(&mut self) {
        let related = (self.meaning.objects.iter().zip(&self.objs)).all(|(r, &t)| match r {
            ObjRef::NextTo { anchor, .. } => (self.objs.get(*anchor))
                .is_some_and(|&a| a != t && self.things[a].zone == self.things[t].zone),
            _ => true,
        });
        if !related {
            return;
        }
        let mut zones = Vec::with_capacity(self.meaning.places.len());
        self.places(&mut zones);
    }

    fn places(&mut self, zones: &mut Vec<String>) {
        let k = zones.len();
        if k == self.meaning.places.len() {
            return self.act_out(zones);
        }
        for z in self.place_candidates(k) {
            zones.push(z);
            self.places(zones);
            zones.pop();
        }
    }

    /// The zones place mention `k` may be.
    fn place_candidates(&self, k: usize) -> Vec<String> {
        let zone_with = |pred: &dyn Fn(&Zone) -> bool| -> Vec<String> {
            (self.scene.zones.iter())
                .filter(|z| pred(z))
                .map(|z| z.color.clone())
                .collect()
        };
        match &self.meaning.places[k] {
            PlaceRef::Colour(c) => zone_with(&|z| z.color == *c),
            PlaceRef::Named(n) => zone_with(&|z| z.names.iter().any(|m| m.eq_ignore_ascii_case(n))),
            PlaceRef::Me => match self.meaning.me {
                Some(m) if m != k && !matches!(self.meaning.places[m], PlaceRef::Me) => {
                    self.place_candidates(m)
                }
                _ => Vec::new(),
            },
            PlaceRef::By(o) => (self.objs.get(*o))
                .map(|&t| vec![self.things[t].zone.clone()])
                .unwrap_or_default(),
        }
    }

    /// One full reading: objects "on" a place must start there; then the plan, if it runs.
    fn act_out(&mut self, zones: &[String]) {
        let on_place = (self.meaning.objects.iter().zip(&self.objs)).all(|(r, &t)| match r {
            ObjRef::On { place, .. } => zones.get(*place) == Some(&self.things[t].zone),
            _ => true,
        });
        if !on_place {
            return;
        }
        self.fitting += 1;
        for (d, &t) in self.denoted.iter_mut().zip(&self.objs) {
            d.insert(t);
        }
        let steps = self.plan(zones);
        let untouched: BTreeSet<&str> = (self.meaning.untouched.iter())
            .filter_map(|&m| self.objs.get(m))
            .map(|&t| self.things[t].name.as_str())
            .collect();
        let touches = |s: &Step| matches!(s, Step::Pick { object } if untouched.contains(object.as_str()));
        if steps.iter().any(touches) || !self.runs(&steps) {
            return;
        }
        self.plans.insert(steps.iter().map(ToString::to_string).collect());
    }

    /// The acts with the moves they need.
    fn plan(&self, zones: &[String]) -> Vec<Step> {
        let mut at: Vec<String> = self.things.iter().map(|t| t.zone.clone()).collect();
        let mut robot: Option<String> = None;
        let mut steps = Vec::new();
        for act in &self.meaning.acts {
            let (pick, place) = match *act {
                Act::Go { place } => {
                    // A visit always drives: a visit to where the robot already is fails to run.
                    drive(&mut steps, &mut robot, &zones[place], true);
                    continue;
                }
                Act::Pick { obj } => (Some(obj), None),
                Act::Place { obj, place } => (None, Some((obj, place))),
                Act::Put { obj, place } => (Some(obj), Some((obj, place))),
            };
            if let Some(obj) = pick {
                let t = self.objs[obj];
                drive(&mut steps, &mut robot, &at[t], false);
                steps.push(Step::Pick {
                    object: self.things[t].name.clone(),
                });
            }
            if let Some((obj, place)) = place {
                let t = self.objs[obj];
                drive(&mut steps, &mut robot, &zones[place], false);
                steps.push(Step::Place {
                    object: self.things[t].name.clone(),
                });
                at[t].clone_from(&zones[place]);
            }
        }
        steps
    }

    /// Whether the steps run by the symbolic rules (any spot will do: reach and room are the
    /// generator's business, not the sentence's).
    fn runs(&self, steps: &[Step]) -> bool {
        let Ok(mut world) = SymbolicWorld::new(self.scene, self.catalogue) else {
            return false;
        };
        let mut spot = |z: &Zone, _: &Placed, _: &[Footprint]| Ok(z.center);
        steps.iter().all(|s| world.step(s, &mut spot).is_ok())
    }
}

/// A move to `zone` unless the robot is there already (or `always`).
fn drive(steps: &mut Vec<Step>, robot: &mut Option<String>, zone: &str, always: bool) {
    if always || robot.as_deref() != Some(zone) {
        steps.push(Step::MoveTo {
            zone: zone.to_string(),
        });
        *robot = Some(zone.to_string());
    }
}
