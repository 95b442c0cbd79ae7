//! The scene file schema (`assets/scenes/<id>.toml`).
//!
//! Coordinates: a right-handed world frame, z up, metres, origin at the south-west floor corner
//! of the room, x east, y north; yaw in radians counter-clockwise from +x. Colours are sRGB in
//! `[0, 1]`. Furniture is described by its outer box; how a kind is built out of parts (legs,
//! shelf boards) is the simulator's business, unless the item brings its own boxes (read from
//! USD) or a glTF mesh. Adding a scene is adding a file here.

use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, BTreeSet};

use crate::catalogue::{Catalogue, Role};
// Defined beside the catalogue's colour variants (so the catalogue need not import the scene)
// and still named here, where scene files use it.
pub use crate::catalogue::Rgb;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    /// Stable identifier, also the file stem (`kitchen_a`).
    pub id: String,
    pub name: String,
    /// What a planner is told about the scene, in English.
    pub description: String,
    pub room: Room,
    #[serde(rename = "furniture")]
    pub furniture: Vec<Furniture>,
    #[serde(rename = "zone")]
    pub zones: Vec<Zone>,
    /// Where the key objects start.
    #[serde(rename = "key_object", default)]
    pub key_objects: Vec<KeyObject>,
    /// Surfaces on which background objects may be scattered.
    #[serde(rename = "background_area", default)]
    pub background_areas: Vec<Area>,
    /// Segments over whose union the robot's start position is drawn (paper, BASELINE VALIDATION
    /// step 1); the robot faces `heading` there.
    #[serde(rename = "start_segment")]
    pub start_segments: Vec<Segment>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Room {
    /// Inner floor size `[x, y]`; walls stand just outside it.
    pub size: [f64; 2],
    pub wall_height: f64,
    pub wall_thickness: f64,
    pub floor_color: Rgb,
    pub wall_color: Rgb,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FurnitureKind {
    Counter,
    Table,
    Shelf,
    Sink,
    Stove,
    Fridge,
    Cabinet,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Furniture {
    pub id: String,
    pub kind: FurnitureKind,
    /// Footprint centre on the floor and yaw: `[x, y, yaw]`.
    pub pose: [f64; 3],
    /// Outer dimensions before scaling: `[along local x, along local y, height]`.
    pub size: [f64; 3],
    /// Uniform scale applied to `size` (the paper's per-asset scale).
    #[serde(default = "one")]
    pub scale: f64,
    pub color: Rgb,
    /// Shelves only: heights above the floor of the boards objects stand on.
    #[serde(default)]
    pub levels: Vec<f64>,
    /// The item's own boxes, replacing those the simulator derives from `kind`: how furniture
    /// read from USD keeps the geometry of its file. Empty (the usual case) for authored items.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub parts: Vec<BoxPart>,
    /// A glTF 2.0 mesh the item is made of instead (see [`MeshRef`]); `size` must be its
    /// bounding box, which the rules here (footprint, surfaces) use.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mesh: Option<MeshRef>,
}

/// A furniture mesh: `file` relative to the scene file (a full path once loaded), y-up as glTF
/// has it and turned z-up, multiplied by `scale`, its footprint centred on the item's pose and
/// its lowest point on the floor.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeshRef {
    pub file: String,
    #[serde(default = "one")]
    pub scale: f64,
}

/// One box of a furniture item, in the item's frame (origin at the footprint centre on the
/// floor, x along `size[0]`), already scaled.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoxPart {
    pub center: [f64; 3],
    /// Full size along the item's x, y, z.
    pub size: [f64; 3],
    pub color: Rgb,
    /// Seen by cameras, never collides (door seams, handles).
    #[serde(default)]
    pub decoration: bool,
}

/// A coloured area objects are taken from or put on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Zone {
    /// Colour name used in plans: `move to the <color> zone`. Unique in the scene.
    pub color: String,
    /// Colour painted in the top-down image (never visible to the robot's policy).
    pub rgb: Rgb,
    /// The furniture the zone lies on.
    pub furniture: String,
    /// Zone centre in world `[x, y]`.
    pub center: [f64; 2],
    /// Extent along world x and y.
    pub size: [f64; 2],
    /// Height of the supporting surface above the floor.
    pub height: f64,
    /// Where the base centre stops to work at this zone: `[x, y, yaw]`.
    pub approach: [f64; 3],
    /// Referring expressions for the zone by the furniture that holds it, with their article
    /// ("the dining table", "the shelf by the fridge"): instructions may name the place this way
    /// instead of by colour, while plan steps always use the colour. Each is unique in the scene.
    #[serde(default)]
    pub names: Vec<String>,
}

/// A key object's starting place.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KeyObject {
    /// Catalogue model id (`cup`).
    pub model: String,
    /// Colour variant from the catalogue (`red`), if any.
    #[serde(default)]
    pub variant: Option<String>,
    /// Zone the object starts in.
    pub zone: String,
    /// Offset of the object's centre from the zone centre, world axes.
    #[serde(default)]
    pub offset: [f64; 2],
    #[serde(default)]
    pub yaw: f64,
}

impl KeyObject {
    /// The name plans use: `red cup`, or `bowl` when there is no variant.
    pub fn name(&self) -> String {
        match &self.variant {
            Some(v) => format!("{v} {}", self.model),
            None => self.model.clone(),
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Area {
    pub center: [f64; 2],
    pub size: [f64; 2],
    pub height: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Segment {
    pub from: [f64; 2],
    pub to: [f64; 2],
    pub heading: f64,
}

fn one() -> f64 {
    1.0
}

impl Furniture {
    /// Outer dimensions after scaling.
    pub fn scaled_size(&self) -> [f64; 3] {
        self.size.map(|s| s * self.scale)
    }

    /// Heights objects can stand on: the top, plus shelf boards.
    pub fn surfaces(&self) -> Vec<f64> {
        let mut s: Vec<f64> = self.levels.iter().map(|l| l * self.scale).collect();
        s.push(self.scaled_size()[2]);
        s
    }

    /// Whether world point `p` lies over the footprint (with `margin` metres of slack).
    pub fn covers(&self, p: [f64; 2], margin: f64) -> bool {
        let [cx, cy, yaw] = self.pose;
        let (dx, dy) = (p[0] - cx, p[1] - cy);
        let (s, c) = yaw.sin_cos();
        let (lx, ly) = (c * dx + s * dy, -s * dx + c * dy);
        let [sx, sy, _] = self.scaled_size();
        lx.abs() <= sx / 2.0 + margin && ly.abs() <= sy / 2.0 + margin
    }
}

impl Scene {
    pub fn zone(&self, color: &str) -> Option<&Zone> {
        self.zones.iter().find(|z| z.color == color)
    }

    pub fn furniture(&self, id: &str) -> Option<&Furniture> {
        self.furniture.iter().find(|f| f.id == id)
    }

    pub fn key_object(&self, name: &str) -> Option<&KeyObject> {
        self.key_objects.iter().find(|o| o.name() == name)
    }

    /// World position of a key object's centre at the start, given its model's half height.
    pub fn key_object_start(&self, obj: &KeyObject, half_height: f64) -> Option<[f64; 3]> {
        let z = self.zone(&obj.zone)?;
        Some([
            z.center[0] + obj.offset[0],
            z.center[1] + obj.offset[1],
            z.height + half_height,
        ])
    }

    /// Check references and geometry; the message says what to fix.
    pub fn validate(&self, catalogue: &Catalogue) -> Result<(), String> {
        let [rx, ry] = self.room.size;
        let inside = |p: [f64; 2]| p[0] > 0.0 && p[0] < rx && p[1] > 0.0 && p[1] < ry;
        unique(self.furniture.iter().map(|f| f.id.clone()), "furniture id")?;
        unique(self.zones.iter().map(|z| z.color.clone()), "zone colour")?;
        unique(self.key_objects.iter().map(|o| o.name()), "key object name")?;
        for f in &self.furniture {
            if !inside([f.pose[0], f.pose[1]]) || f.size.iter().any(|s| *s <= 0.0) || f.scale <= 0.0 {
                return Err(format!(
                    "furniture {:?}: pose outside the room or non-positive size",
                    f.id
                ));
            }
        }
        for z in &self.zones {
            let f = self
                .furniture(&z.furniture)
                .ok_or_else(|| format!("zone {:?} lies on unknown furniture {:?}", z.color, z.furniture))?;
            if !f.covers(z.center, 0.0) {
                return Err(format!(
                    "zone {:?}: centre is not over furniture {:?}",
                    z.color, f.id
                ));
            }
            if !f.surfaces().iter().any(|h| (h - z.height).abs() < 1e-6) {
                return Err(format!(
                    "zone {:?}: height {} is neither the top nor a shelf level of {:?} ({:?})",
                    z.color,
                    z.height,
                    f.id,
                    f.surfaces()
                ));
            }
            let a = [z.approach[0], z.approach[1]];
            if !inside(a) || self.furniture.iter().any(|f| f.covers(a, 0.0)) {
                return Err(format!(
                    "zone {:?}: approach point {a:?} is not on free floor",
                    z.color
                ));
            }
        }
        self.check_zone_names()?;
        for o in &self.key_objects {
            let model = catalogue
                .model(&o.model)
                .ok_or_else(|| format!("key object {:?}: unknown catalogue model", o.name()))?;
            if model.role != Role::Key {
                return Err(format!(
                    "key object {:?}: model {:?} is not a key object",
                    o.name(),
                    o.model
                ));
            }
            if let Some(v) = &o.variant
                && !model.variants.contains_key(v)
            {
                return Err(format!(
                    "key object {:?}: model has no colour variant {v:?}",
                    o.name()
                ));
            }
            if self.zone(&o.zone).is_none() {
                return Err(format!("key object {:?}: unknown zone {:?}", o.name(), o.zone));
            }
        }
        if self.start_segments.is_empty() {
            return Err("at least one start_segment is needed".into());
        }
        for s in &self.start_segments {
            if !inside(s.from) || !inside(s.to) {
                return Err(format!("start segment {:?}..{:?} leaves the room", s.from, s.to));
            }
        }
        Ok(())
    }
}

impl Scene {
    /// Zone `names` are referring expressions a planner must resolve to exactly one zone: each
    /// starts with "the ", is lower-case, names no zone colour of the scene (instructions would
    /// become ambiguous) and is used by one zone only.
    fn check_zone_names(&self) -> Result<(), String> {
        let mut seen: BTreeMap<&str, &str> = BTreeMap::new();
        for z in &self.zones {
            for name in &z.names {
                let bad = |why: String| {
                    Err(format!(
                        "scene {:?}, zone {:?}: name {name:?} {why}",
                        self.id, z.color
                    ))
                };
                let rest = name.strip_prefix("the ").unwrap_or_default();
                if rest.trim().is_empty() {
                    return bad(
                        "must be \"the \" followed by the furniture, e.g. \"the dining table\"".into(),
                    );
                }
                if name.trim() != name || name.contains("  ") || name.contains(['{', '}']) {
                    return bad("has stray spaces or braces".into());
                }
                if name.to_lowercase() != *name {
                    return bad("must be lower-case".into());
                }
                let words: Vec<&str> = name.split(|c: char| !c.is_alphanumeric()).collect();
                if let Some(c) = self.zones.iter().find(|c| words.contains(&c.color.as_str())) {
                    return bad(format!("contains the zone colour {:?}", c.color));
                }
                match seen.insert(name, &z.color) {
                    Some(other) if other == z.color => return bad("is listed twice".into()),
                    Some(other) => return bad(format!("is also a name of zone {other:?}")),
                    None => {}
                }
            }
        }
        Ok(())
    }
}

fn unique(items: impl Iterator<Item = String>, what: &str) -> Result<(), String> {
    let mut seen = BTreeSet::new();
    for i in items {
        if !seen.insert(i.clone()) {
            return Err(format!("duplicate {what} {i:?}"));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kitchen_a() -> (Scene, Catalogue) {
        let dir = crate::assets::assets_dir();
        let cat = Catalogue::load(&dir.join("objects.toml")).unwrap();
        let scene = Scene::load(&dir.join("scenes/kitchen_a.toml"), &cat).unwrap();
        (scene, cat)
    }

    #[test]
    fn committed_zones_have_names() {
        let dir = crate::assets::assets_dir();
        let cat = Catalogue::load(&dir.join("objects.toml")).unwrap();
        for s in Scene::load_all(&dir.join("scenes"), &cat).unwrap() {
            for z in &s.zones {
                assert!(!z.names.is_empty(), "{} {}", s.id, z.color);
            }
        }
    }

    #[test]
    fn bad_zone_names_are_refused_naming_scene_and_zone() {
        let (scene, cat) = kitchen_a();
        for (name, why) in [
            ("dining table", "must be \"the \""),
            ("the ", "must be \"the \""),
            ("the Dining table", "lower-case"),
            ("the red table", "zone colour \"red\""),
            ("the dining table", "also a name of zone \"red\""),
            ("the middle shelf", "listed twice"),
            ("the  table", "stray spaces"),
        ] {
            let mut s = scene.clone();
            s.zones.last_mut().unwrap().names.push(name.into());
            let err = s.validate(&cat).unwrap_err();
            assert!(
                err.contains("scene \"kitchen_a\", zone \"purple\"") && err.contains(why),
                "{name:?}: {err}"
            );
        }
        // A colour inside another word is not a colour.
        let mut s = scene;
        s.zones[0].names.push("the covered counter".into());
        s.validate(&cat).unwrap();
    }
}
