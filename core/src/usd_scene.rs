//! A scene read from a USD ASCII file (the paper's "a new scene is a USD file and its scale in the
//! config"): `assets/scenes/<id>.toml` holding `usd = "<file>.usda"` and optionally `scale`
//! (metres per file unit; default the file's `metersPerUnit`, else 1).
//!
//! What is read is the layout `kitchen-r sim export --usd` writes (see `docs/twin/scenes.md`),
//! through the small parser in [`crate::usda`]: a root prim (the layer's `defaultPrim`) with
//! `Room`, `Furniture`, `Zones` and `Objects` children. Geometry and poses come from the prims
//! themselves: each furniture `Xform`'s `xformOp:translate`/`xformOp:orient` is its pose and its
//! `Cube` children (size × `xformOp:scale`, `primvars:displayColor`, `PhysicsCollisionAPI` or not)
//! become its parts; a zone's pose is its surface centre and its `Cube` plate gives its size and
//! colour; a key object's translate is its start. What geometry cannot say comes from `kitchenr:`
//! attributes: furniture kind, outer box, scale and shelf levels; zone colour name, furniture,
//! approach pose and names; object model, variant and zone; the room; start segments. Object
//! shapes are the catalogue's (the file's object geometry is not read). The result is validated
//! like any scene file.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::ContentError;
use crate::catalogue::Rgb;
use crate::scene::{Area, BoxPart, Furniture, FurnitureKind, KeyObject, Room, Scene, Segment, Zone};
use crate::usda::{self, Attr, Layer, Prim, Value};

/// The scene file's pointer to a USD file.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UsdSource {
    /// The `.usda` file, relative to the scene file.
    pub usd: PathBuf,
    /// Metres per unit of the file's lengths; default: the file's `metersPerUnit`, else 1.
    #[serde(default)]
    pub scale: Option<f64>,
}

impl UsdSource {
    /// `Some` when the scene file at `path` is a USD pointer (it has a `usd` key).
    pub fn from_toml(path: &Path, text: &str) -> Result<Option<UsdSource>, ContentError> {
        // A file that is not TOML at all is reported by the scene parser, as before.
        let Ok(table) = toml::from_str::<toml::Table>(text) else {
            return Ok(None);
        };
        if !table.contains_key("usd") {
            return Ok(None);
        }
        toml::from_str(text).map(Some).map_err(|e| ContentError::Parse {
            path: path.to_path_buf(),
            message: format!("{e}(a USD scene file holds `usd = \"FILE.usda\"` and optionally `scale`)"),
        })
    }

    /// Read the scene; its id is the stem of `scene_file`.
    pub fn read(&self, scene_file: &Path) -> Result<Scene, ContentError> {
        let path = scene_file.parent().unwrap_or(Path::new(".")).join(&self.usd);
        let text = std::fs::read_to_string(&path).map_err(|source| ContentError::Io {
            path: path.clone(),
            source,
        })?;
        let invalid = |message: String| ContentError::Invalid {
            path: path.clone(),
            message,
        };
        let layer = usda::parse(&text).map_err(invalid)?;
        let id = scene_file
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        scene_from_layer(&layer, &id, self.scale).map_err(invalid)
    }
}

/// Build a scene from a parsed layer; lengths are multiplied by `scale` (default: the layer's
/// `metersPerUnit`, else 1).
pub fn scene_from_layer(layer: &Layer, id: &str, scale: Option<f64>) -> Result<Scene, String> {
    if let Some(up) = layer.meta.get("upAxis")
        && *up != Value::Str("Z".into())
    {
        return Err(format!(
            "upAxis is {up:?}: Kitchen-R scenes are z-up (upAxis = \"Z\")"
        ));
    }
    let k = match (scale, layer.meta.get("metersPerUnit")) {
        (Some(s), _) => s,
        (None, Some(Value::Number(m))) => *m,
        _ => 1.0,
    };
    if !(k.is_finite() && k > 0.0) {
        return Err(format!("scale {k} must be a positive number of metres per unit"));
    }
    let root = layer.default_prim().ok_or("the file defines no prim")?;
    let group = |name: &str| {
        root.children.iter().find(|c| c.name == name).ok_or_else(|| {
            format!(
                "line {}: root prim \"{}\" has no child \"{name}\"",
                root.line, root.name
            )
        })
    };
    let furniture = group("Furniture")?
        .children
        .iter()
        .map(|p| furniture(p, k))
        .collect::<Result<Vec<_>, _>>()?;
    let zones = group("Zones")?
        .children
        .iter()
        .map(|p| zone(p, k))
        .collect::<Result<Vec<_>, _>>()?;
    let objects = match root.children.iter().find(|c| c.name == "Objects") {
        Some(g) => g
            .children
            .iter()
            .map(|p| key_object(p, k, &zones))
            .collect::<Result<_, _>>()?,
        None => Vec::new(),
    };
    let segments = fives(root, "startSegments")?
        .iter()
        .map(|v| Segment {
            from: [v[0] * k, v[1] * k],
            to: [v[2] * k, v[3] * k],
            heading: v[4],
        })
        .collect();
    let areas = fives(root, "backgroundAreas")?
        .iter()
        .map(|v| Area {
            center: [v[0] * k, v[1] * k],
            size: [v[2] * k, v[3] * k],
            height: v[4] * k,
        })
        .collect();
    Ok(Scene {
        id: id.to_string(),
        name: opt_string(root, "name")?.unwrap_or_else(|| id.to_string()),
        description: opt_string(root, "description")?.unwrap_or_default(),
        room: room(group("Room")?, k)?,
        furniture,
        zones,
        key_objects: objects,
        background_areas: areas,
        start_segments: segments,
    })
}

fn room(p: &Prim, k: f64) -> Result<Room, String> {
    let size = numbers(p, "kitchenr:size", 2)?;
    Ok(Room {
        size: [size[0] * k, size[1] * k],
        wall_height: numbers(p, "kitchenr:wallHeight", 1)?[0] * k,
        wall_thickness: numbers(p, "kitchenr:wallThickness", 1)?[0] * k,
        floor_color: color(p, required(p, "kitchenr:floorColor")?)?,
        wall_color: color(p, required(p, "kitchenr:wallColor")?)?,
    })
}

fn furniture(p: &Prim, k: f64) -> Result<Furniture, String> {
    let kind_attr = required(p, "kitchenr:kind")?;
    let kind_name = text(kind_attr)?;
    let kind: FurnitureKind = toml::Value::String(kind_name.clone()).try_into().map_err(|_| {
        format!(
            "line {}: furniture \"{}\": unknown kitchenr:kind {kind_name:?} (counter, table, shelf, sink, stove, fridge or cabinet)",
            kind_attr.line, p.name
        )
    })?;
    let xf = Xf::of(p)?;
    let yaw = xf.yaw(p)?;
    let mut parts = Vec::new();
    for c in &p.children {
        if c.kind != "Cube" {
            return Err(format!(
                "line {}: furniture \"{}\": only Cube parts are read, not {} \"{}\"",
                c.line, p.name, c.kind, c.name
            ));
        }
        let cx = Xf::of(c)?;
        if (cx.q[0] - 1.0).abs() > 1e-9 || cx.q[1..].iter().any(|v| v.abs() > 1e-9) {
            return Err(format!(
                "line {}: part \"{}\" of \"{}\" is rotated in the item's frame; parts must be axis-aligned there (orient (1, 0, 0, 0))",
                c.line, c.name, p.name
            ));
        }
        let edge = c
            .attrs
            .get("size")
            .map_or(Ok(2.0), |a| numbers_of(a, 1).map(|v| v[0]))?;
        let collides = matches!(c.meta.get("apiSchemas"), Some(Value::List(l))
            if l.contains(&Value::Str("PhysicsCollisionAPI".into())));
        parts.push(BoxPart {
            center: cx.t.map(|v| v * k),
            size: [0, 1, 2].map(|i| edge * cx.s[i] * k),
            color: display_color(c)?.unwrap_or([0.5; 3]),
            decoration: !collides,
        });
    }
    let scale = opt_numbers::<1>(p, "kitchenr:scale")?.map_or(1.0, |v| v[0]);
    let size = match opt_numbers::<3>(p, "kitchenr:size")? {
        Some(s) => s.map(|v| v * k),
        // A footprint centred on the prim's origin, as tall as the highest part.
        None => bounding_size(&parts).ok_or_else(|| {
            format!(
                "line {}: furniture \"{}\" has neither kitchenr:size nor Cube parts",
                p.line, p.name
            )
        })?,
    };
    Ok(Furniture {
        id: opt_string(p, "id")?.unwrap_or_else(|| p.name.clone()),
        kind,
        pose: [xf.t[0] * k, xf.t[1] * k, yaw],
        size,
        scale,
        color: match p.attrs.get("kitchenr:color") {
            Some(a) => color(p, a)?,
            None => parts.first().map_or([0.5; 3], |b| b.color),
        },
        levels: opt_list(p, "kitchenr:levels")?.iter().map(|l| l * k).collect(),
        parts,
        mesh: None,
    })
}

fn bounding_size(parts: &[BoxPart]) -> Option<[f64; 3]> {
    let solid: Vec<&BoxPart> = parts.iter().filter(|b| !b.decoration).collect();
    if solid.is_empty() {
        return None;
    }
    let reach = |i: usize| {
        solid
            .iter()
            .map(|b| b.center[i].abs() + b.size[i] / 2.0)
            .fold(0.0, f64::max)
    };
    let top = solid
        .iter()
        .map(|b| b.center[2] + b.size[2] / 2.0)
        .fold(0.0, f64::max);
    Some([2.0 * reach(0), 2.0 * reach(1), top])
}

fn zone(p: &Prim, k: f64) -> Result<Zone, String> {
    let xf = Xf::of(p)?;
    let plate = p.children.iter().find(|c| c.kind == "Cube").ok_or_else(|| {
        format!(
            "line {}: zone \"{}\" has no Cube plate (its area and colour)",
            p.line, p.name
        )
    })?;
    let px = Xf::of(plate)?;
    let edge = plate
        .attrs
        .get("size")
        .map_or(Ok(2.0), |a| numbers_of(a, 1).map(|v| v[0]))?;
    let approach = numbers(p, "kitchenr:approach", 3)?;
    let names = match p.attrs.get("kitchenr:names") {
        Some(a) => match &a.value {
            Some(Value::List(l)) => l
                .iter()
                .map(|v| text_value(v, a.line))
                .collect::<Result<_, _>>()?,
            _ => {
                return Err(format!(
                    "line {}: kitchenr:names must be a list of strings",
                    a.line
                ));
            }
        },
        None => Vec::new(),
    };
    Ok(Zone {
        color: opt_string(p, "color")?.unwrap_or_else(|| p.name.clone()),
        rgb: display_color(plate)?.ok_or_else(|| {
            format!(
                "line {}: zone plate \"{}\" has no primvars:displayColor",
                plate.line, plate.name
            )
        })?,
        furniture: text(required(p, "kitchenr:furniture")?)?,
        center: [xf.t[0] * k, xf.t[1] * k],
        size: [edge * px.s[0] * k, edge * px.s[1] * k],
        height: xf.t[2] * k,
        approach: [approach[0] * k, approach[1] * k, approach[2]],
        names,
    })
}

fn key_object(p: &Prim, k: f64, zones: &[Zone]) -> Result<KeyObject, String> {
    let xf = Xf::of(p)?;
    let (x, y) = (xf.t[0] * k, xf.t[1] * k);
    let zone = match opt_string(p, "zone")? {
        Some(z) => zones
            .iter()
            .find(|c| c.color == z)
            .ok_or_else(|| format!("line {}: object \"{}\": unknown zone {z:?}", p.line, p.name))?,
        None => zones
            .iter()
            .find(|z| {
                (x - z.center[0]).abs() <= z.size[0] / 2.0 && (y - z.center[1]).abs() <= z.size[1] / 2.0
            })
            .ok_or_else(|| {
                format!(
                    "line {}: object \"{}\" stands in no zone and names none (kitchenr:zone)",
                    p.line, p.name
                )
            })?,
    };
    Ok(KeyObject {
        model: text(required(p, "kitchenr:model")?)?,
        variant: opt_string(p, "variant")?,
        zone: zone.color.clone(),
        offset: [x - zone.center[0], y - zone.center[1]],
        yaw: xf.yaw(p)?,
    })
}

/// A prim's `xformOp:translate`, `xformOp:orient` (w, x, y, z) and `xformOp:scale`.
struct Xf {
    t: [f64; 3],
    q: [f64; 4],
    s: [f64; 3],
}

impl Xf {
    fn of(p: &Prim) -> Result<Xf, String> {
        if let Some(order) = p.attrs.get("xformOpOrder") {
            let known = ["xformOp:translate", "xformOp:orient", "xformOp:scale"];
            let Some(Value::List(ops)) = &order.value else {
                return Err(format!("line {}: xformOpOrder must be a list", order.line));
            };
            let names: Vec<String> = ops
                .iter()
                .map(|v| text_value(v, order.line))
                .collect::<Result<_, _>>()?;
            let expected: Vec<&str> = known
                .iter()
                .copied()
                .filter(|k| names.iter().any(|n| n == k))
                .collect();
            if names != expected {
                return Err(format!(
                    "line {}: prim \"{}\": xformOpOrder {names:?} is not read; write xformOp:translate, xformOp:orient, xformOp:scale (any of them, in that order)",
                    order.line, p.name
                ));
            }
        }
        let get = |name: &str, n: usize| p.attrs.get(name).map(|a| numbers_of(a, n)).transpose();
        let t = get("xformOp:translate", 3)?.map_or([0.0; 3], |v| [v[0], v[1], v[2]]);
        let q = get("xformOp:orient", 4)?.map_or([1.0, 0.0, 0.0, 0.0], |v| [v[0], v[1], v[2], v[3]]);
        let s = get("xformOp:scale", 3)?.map_or([1.0; 3], |v| [v[0], v[1], v[2]]);
        Ok(Xf { t, q, s })
    }

    /// Heading of a rotation about z only; anything else is refused.
    fn yaw(&self, p: &Prim) -> Result<f64, String> {
        let [w, x, y, z] = self.q;
        let n = (w * w + x * x + y * y + z * z).sqrt();
        if n == 0.0 || x.abs() / n > 1e-6 || y.abs() / n > 1e-6 {
            return Err(format!(
                "line {}: prim \"{}\" turns about an axis other than z; furniture, zones and objects stand upright",
                p.line, p.name
            ));
        }
        Ok(2.0 * z.atan2(w))
    }
}

fn required<'a>(p: &'a Prim, name: &str) -> Result<&'a Attr, String> {
    p.attrs
        .get(name)
        .ok_or_else(|| format!("line {}: prim \"{}\" needs the attribute {name}", p.line, p.name))
}

fn flat(v: &Value, out: &mut Vec<f64>, line: usize) -> Result<(), String> {
    match v {
        Value::Number(x) => out.push(*x),
        Value::Tuple(items) | Value::List(items) => {
            for i in items {
                flat(i, out, line)?;
            }
        }
        other => return Err(format!("line {line}: expected numbers, found {other:?}")),
    }
    Ok(())
}

/// The attribute's value, or an error naming its line.
fn value(a: &Attr) -> Result<&Value, String> {
    a.value
        .as_ref()
        .ok_or_else(|| format!("line {}: attribute has no value", a.line))
}

/// Exactly `n` numbers (a scalar, a tuple or a one-element array of a tuple).
fn numbers_of(a: &Attr, n: usize) -> Result<Vec<f64>, String> {
    let mut v = Vec::new();
    flat(value(a)?, &mut v, a.line)?;
    if v.len() != n {
        return Err(format!(
            "line {}: expected {n} numbers, found {}",
            a.line,
            v.len()
        ));
    }
    Ok(v)
}

fn numbers(p: &Prim, name: &str, n: usize) -> Result<Vec<f64>, String> {
    numbers_of(required(p, name)?, n)
}

fn opt_numbers<const N: usize>(p: &Prim, name: &str) -> Result<Option<[f64; N]>, String> {
    p.attrs
        .get(name)
        .map(|a| numbers_of(a, N).map(|v| std::array::from_fn(|i| v[i])))
        .transpose()
}

fn opt_list(p: &Prim, name: &str) -> Result<Vec<f64>, String> {
    let mut v = Vec::new();
    if let Some(a) = p.attrs.get(name)
        && let Some(value) = &a.value
    {
        flat(value, &mut v, a.line)?;
    }
    Ok(v)
}

/// A flat list of 5-number records (start segments, background areas) on the root prim.
fn fives(p: &Prim, name: &str) -> Result<Vec<[f64; 5]>, String> {
    let v = opt_list(p, &format!("kitchenr:{name}"))?;
    if v.len() % 5 != 0 {
        let line = p
            .attrs
            .get(&format!("kitchenr:{name}"))
            .map_or(p.line, |a| a.line);
        return Err(format!(
            "line {line}: kitchenr:{name} holds {} numbers, not a multiple of 5",
            v.len()
        ));
    }
    Ok(v.chunks(5).map(|c| [c[0], c[1], c[2], c[3], c[4]]).collect())
}

fn text_value(v: &Value, line: usize) -> Result<String, String> {
    match v {
        Value::Str(s) | Value::Word(s) => Ok(s.clone()),
        other => Err(format!("line {line}: expected a string, found {other:?}")),
    }
}

fn text(a: &Attr) -> Result<String, String> {
    text_value(value(a)?, a.line)
}

fn opt_string(p: &Prim, name: &str) -> Result<Option<String>, String> {
    p.attrs.get(&format!("kitchenr:{name}")).map(text).transpose()
}

fn color(p: &Prim, a: &Attr) -> Result<Rgb, String> {
    let v = numbers_of(a, 3).map_err(|e| format!("{e} (a colour of prim \"{}\")", p.name))?;
    Ok([v[0] as f32, v[1] as f32, v[2] as f32])
}

/// The first `primvars:displayColor`, if any.
fn display_color(p: &Prim) -> Result<Option<Rgb>, String> {
    let Some(a) = p.attrs.get("primvars:displayColor") else {
        return Ok(None);
    };
    let mut v = Vec::new();
    flat(value(a)?, &mut v, a.line)?;
    if v.len() < 3 {
        return Err(format!(
            "line {}: primvars:displayColor needs three numbers",
            a.line
        ));
    }
    Ok(Some([v[0] as f32, v[1] as f32, v[2] as f32]))
}
