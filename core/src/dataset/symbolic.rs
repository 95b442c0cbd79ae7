//! Symbolic execution of a plan against a scene's initial object placement, and the geometry of
//! place targets.
//!
//! This is the executability rule of the benchmark (paper, Language Instructions: "every
//! generated instruction is executable within its corresponding scene"): `move to` drives to a
//! zone other than the current one; `pick` needs an empty gripper and the robot at the object's
//! zone; `place` puts the held object into the zone the robot is at, never into the zone it
//! was picked up from (that would be a no-op, or a detour the instruction cannot express). A place target is a free spot in that zone: the object's footprint keeps
//! [`ZONE_MARGIN`] from the zone edge and [`OBJECT_GAP`] from every other object there, and
//! the arm reaches it from the zone's approach pose ([`crate::reach`]).

use crate::catalogue::Catalogue;
use crate::plan::{Step, parse_plan};
use crate::reach::ArmReach;
use crate::scene::{Scene, Zone};

use super::rng::SplitMix64;
use super::templates::PLAN_LEN;

/// Distance an object's footprint keeps from its zone's edge.
pub const ZONE_MARGIN: f64 = 0.03;
/// Free gap between the footprints of two objects in one zone.
pub const OBJECT_GAP: f64 = 0.02;
/// Random spots tried before a zone counts as full.
const SPOT_TRIES: usize = 96;

/// Footprint of an object already in a zone: centre and bounding-circle radius.
pub type Footprint = ([f64; 2], f64);

/// The geometry of an object being placed, from its catalogue model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placed {
    /// Footprint bounding-circle radius.
    pub radius: f64,
    /// Centre height above the supporting surface.
    pub half_height: f64,
    /// Grasp point relative to the centre, object frame.
    pub grasp_offset: [f64; 3],
}

impl Placed {
    pub fn of(model: &crate::catalogue::ObjectModel) -> Placed {
        Placed {
            radius: model.shape.footprint_radius(),
            half_height: model.shape.half_height(),
            grasp_offset: model.grasp_offset,
        }
    }
}

/// Chooses a place spot: given the zone, the placed object and the other footprints.
pub type SpotChooser<'a> = dyn FnMut(&Zone, &Placed, &[Footprint]) -> Result<[f64; 2], String> + 'a;

/// A key object during symbolic execution.
#[derive(Debug, Clone)]
struct Obj {
    name: String,
    placed: Placed,
    zone: String,
    xy: [f64; 2],
}

/// Robot, gripper and object state while a plan runs.
#[derive(Debug, Clone)]
pub struct SymbolicWorld<'s> {
    scene: &'s Scene,
    robot_at: Option<String>,
    held: Option<usize>,
    /// Zone the held object was picked up from.
    picked_from: Option<String>,
    objects: Vec<Obj>,
}

/// Round to whole millimetres so targets print short and compare exactly.
pub fn mm(v: f64) -> f64 {
    (v * 1000.0).round() / 1000.0
}

/// Whether a footprint of `radius` centred at `xy` lies inside `zone` with [`ZONE_MARGIN`].
pub fn fits_in_zone(zone: &Zone, radius: f64, xy: [f64; 2]) -> bool {
    (0..2).all(|i| (xy[i] - zone.center[i]).abs() <= zone.size[i] / 2.0 - ZONE_MARGIN - radius + 1e-9)
}

impl<'s> SymbolicWorld<'s> {
    /// The scene at its start: robot nowhere in particular, gripper empty.
    pub fn new(scene: &'s Scene, catalogue: &Catalogue) -> Result<SymbolicWorld<'s>, String> {
        let mut objects = Vec::new();
        for o in &scene.key_objects {
            let m = catalogue
                .model(&o.model)
                .ok_or_else(|| format!("unknown model {:?}", o.model))?;
            let z = scene
                .zone(&o.zone)
                .ok_or_else(|| format!("unknown zone {:?}", o.zone))?;
            objects.push(Obj {
                name: o.name(),
                placed: Placed::of(m),
                zone: o.zone.clone(),
                xy: [z.center[0] + o.offset[0], z.center[1] + o.offset[1]],
            });
        }
        Ok(SymbolicWorld {
            scene,
            robot_at: None,
            held: None,
            picked_from: None,
            objects,
        })
    }

    /// Apply one step. For a `place`, `spot` chooses where the object's centre goes, given the
    /// zone, the object's geometry and the other objects' footprints in that zone; the returned
    /// value is then the world target `[x, y, z]`.
    pub fn step(&mut self, step: &Step, spot: &mut SpotChooser<'_>) -> Result<Option<[f64; 3]>, String> {
        match step {
            Step::MoveTo { zone } => {
                self.scene
                    .zone(zone)
                    .ok_or_else(|| format!("no {zone} zone in the scene"))?;
                if self.robot_at.as_deref() == Some(zone) {
                    return Err(format!("`{step}` while already at the {zone} zone"));
                }
                self.robot_at = Some(zone.clone());
                Ok(None)
            }
            Step::Pick { object } => {
                let i = self.find(object)?;
                if let Some(h) = self.held {
                    return Err(format!("`{step}` while holding the {}", self.objects[h].name));
                }
                if self.robot_at.as_deref() != Some(&self.objects[i].zone) {
                    return Err(format!("`{step}` away from the {} zone", self.objects[i].zone));
                }
                self.held = Some(i);
                self.picked_from = Some(self.objects[i].zone.clone());
                Ok(None)
            }
            Step::Place { object } => {
                let i = self.find(object)?;
                if self.held != Some(i) {
                    return Err(format!("`{step}` without holding it"));
                }
                let zone_name = self.robot_at.clone().ok_or("place before any move")?;
                if self.picked_from.take().as_ref() == Some(&zone_name) {
                    return Err(format!(
                        "`{step}` back into the {zone_name} zone it was picked from"
                    ));
                }
                let zone = self.scene.zone(&zone_name).ok_or("robot at an unknown zone")?;
                let others: Vec<Footprint> = (self.objects.iter().enumerate())
                    .filter(|(j, o)| *j != i && o.zone == zone_name)
                    .map(|(_, o)| (o.xy, o.placed.radius))
                    .collect();
                let xy = spot(zone, &self.objects[i].placed, &others)?;
                let o = &mut self.objects[i];
                (o.zone, o.xy) = (zone_name, xy);
                self.held = None;
                Ok(Some([xy[0], xy[1], mm(zone.height + o.placed.half_height)]))
            }
        }
    }

    fn find(&self, name: &str) -> Result<usize, String> {
        (self.objects.iter().position(|o| o.name == name)).ok_or_else(|| format!("no {name} in the scene"))
    }
}

/// Whether `xy` is a legal spot: inside the zone and clear of `others`.
pub fn spot_is_free(zone: &Zone, radius: f64, others: &[Footprint], xy: [f64; 2]) -> bool {
    fits_in_zone(zone, radius, xy)
        && others.iter().all(|(p, r)| {
            // Squares, not `hypot`: only correctly rounded operations, so the generated
            // dataset is the same on every platform.
            let (dx, dy, min) = (p[0] - xy[0], p[1] - xy[1], r + radius + OBJECT_GAP - 1e-9);
            dx * dx + dy * dy >= min * min
        })
}

/// Whether the arm can place `placed` with its centre at `xy` in `zone` from the zone's
/// approach pose ([`ArmReach::can_place`]).
pub fn spot_is_reachable(arm: &ArmReach, zone: &Zone, placed: &Placed, xy: [f64; 2]) -> bool {
    arm.can_place(zone, placed.half_height, placed.grasp_offset, xy)
}

/// A random free spot on the millimetre grid that the arm reaches from the zone's approach
/// pose, or an error when the zone looks full.
pub fn random_spot(
    rng: &mut SplitMix64,
    arm: &ArmReach,
    zone: &Zone,
    placed: &Placed,
    others: &[Footprint],
) -> Result<[f64; 2], String> {
    let radius = placed.radius;
    let half = |i: usize| ((zone.size[i] / 2.0 - ZONE_MARGIN - radius) * 1000.0).floor() as i64;
    let (hx, hy) = (half(0), half(1));
    if hx < 0 || hy < 0 {
        return Err(format!("the object does not fit in the {} zone", zone.color));
    }
    for _ in 0..SPOT_TRIES {
        let xy = [
            mm(zone.center[0] + rng.symmetric(hx) as f64 / 1000.0),
            mm(zone.center[1] + rng.symmetric(hy) as f64 / 1000.0),
        ];
        if spot_is_free(zone, radius, others, xy) && spot_is_reachable(arm, zone, placed, xy) {
            return Ok(xy);
        }
    }
    Err(format!("no free spot in reach left in the {} zone", zone.color))
}

/// Run `plan` from the scene's start, choosing place spots with `rng`; the place targets.
/// Reach is that of the committed robot ([`ArmReach::committed`]); see [`plan_targets_with`].
pub fn plan_targets(
    scene: &Scene,
    catalogue: &Catalogue,
    plan: &[Step],
    rng: &mut SplitMix64,
) -> Result<Vec<[f64; 3]>, String> {
    plan_targets_with(scene, catalogue, ArmReach::committed()?, plan, rng)
}

/// [`plan_targets`] for the arm `arm` (the robot description in `assets/robots/`).
pub fn plan_targets_with(
    scene: &Scene,
    catalogue: &Catalogue,
    arm: &ArmReach,
    plan: &[Step],
    rng: &mut SplitMix64,
) -> Result<Vec<[f64; 3]>, String> {
    let mut world = SymbolicWorld::new(scene, catalogue)?;
    let mut spot = |z: &Zone, p: &Placed, others: &[Footprint]| random_spot(rng, arm, z, p, others);
    let mut targets = Vec::new();
    for s in plan {
        targets.extend(world.step(s, &mut spot)?);
    }
    Ok(targets)
}

/// Check a ground-truth plan and its place targets against a scene: every step canonical, 4 to 8
/// steps, executable from the start, and each target a free spot in the zone it is placed in,
/// within the committed arm's reach ([`ArmReach::committed`]) and at the right height.
pub fn check_plan(
    scene: &Scene,
    catalogue: &Catalogue,
    plan: &[String],
    targets: &[[f64; 3]],
) -> Result<(), String> {
    check_plan_with(scene, catalogue, ArmReach::committed()?, plan, targets)
}

/// [`check_plan`] for the arm `arm`.
pub fn check_plan_with(
    scene: &Scene,
    catalogue: &Catalogue,
    arm: &ArmReach,
    plan: &[String],
    targets: &[[f64; 3]],
) -> Result<(), String> {
    let steps = parse_plan(plan).map_err(|e| e.to_string())?;
    if steps.iter().zip(plan).any(|(s, p)| s.to_string() != *p) {
        return Err("a step is not in canonical form".into());
    }
    if !PLAN_LEN.contains(&steps.len()) {
        return Err(format!("{} steps, expected 4 to 8", steps.len()));
    }
    let mut world = SymbolicWorld::new(scene, catalogue)?;
    let mut next = targets.iter();
    let mut spot = |z: &Zone, p: &Placed, others: &[Footprint]| {
        let t = next.next().ok_or("fewer place targets than place steps")?;
        let xy = [t[0], t[1]];
        if !spot_is_free(z, p.radius, others, xy) {
            return Err(format!("target {t:?} is not a free spot in the {} zone", z.color));
        }
        if !spot_is_reachable(arm, z, p, xy) {
            return Err(format!(
                "target {t:?} is out of the arm's reach from the {} zone's approach pose",
                z.color
            ));
        }
        Ok(xy)
    };
    let mut produced = Vec::new();
    for s in &steps {
        produced.extend(world.step(s, &mut spot)?);
    }
    if produced.len() != targets.len() {
        return Err("more place targets than place steps".into());
    }
    match produced
        .iter()
        .zip(targets)
        .find(|(p, t)| (p[2] - t[2]).abs() > 1e-9)
    {
        Some((p, t)) => Err(format!(
            "target {t:?} has the wrong height (expected z = {})",
            p[2]
        )),
        None => Ok(()),
    }
}
