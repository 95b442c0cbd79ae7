//! The object catalogue (`assets/objects.toml`): key objects the robot manipulates and
//! background objects that are scattered at random but never manipulated.
//!
//! Every model's origin is the centre of its bounding box, which is the "geometric centre" the
//! manipulation success check measures. Adding an object model is adding an entry here.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::ContentError;
use crate::grasp_mode::GraspMode;

/// sRGB colour, each channel in `[0, 1]`.
pub type Rgb = [f32; 3];

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Catalogue {
    #[serde(rename = "object")]
    pub objects: Vec<ObjectModel>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Role {
    Key,
    Background,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObjectModel {
    /// Model id, also the noun used in plans (`cup`).
    pub id: String,
    pub role: Role,
    pub shape: Shape,
    /// Kilograms.
    pub mass: f64,
    /// Coulomb friction coefficient.
    pub friction: f64,
    /// Colour when no variant is named.
    pub color: Rgb,
    /// Named colour variants (`red = [0.8, 0.1, 0.1]`), used as `the red cup`.
    #[serde(default)]
    pub variants: BTreeMap<String, Rgb>,
    /// Grasp point relative to the object's centre, object frame, metres.
    #[serde(default)]
    pub grasp_offset: [f64; 3],
    /// What the physical grasp mode makes of this model instead (`[object.physical]`), where
    /// only friction holds what the fingers pinch; [`ObjectModel::in_mode`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub physical: Option<PhysicalVariant>,
}

/// An object as the physical grasp mode builds it, where it differs from the abstract one.
///
/// Why a variant at all: the abstract grasp carries what it attaches, whatever it weighs, while
/// a pinch holds an object against turning only by its squeeze times the height of wall the
/// pads cover. A 0.4 kg solid disc has no wall (docs/twin/robot.md, "The physical grasp").
/// Keeping the abstract model unchanged keeps every abstract-mode result (and the images the
/// camera baselines learnt from) as it was. The variant keeps the model's bounding box, so
/// layouts, resting heights and the success checks are the same in both modes (checked at load).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PhysicalVariant {
    /// The collision and render shape (the model's own when absent).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shape: Option<Shape>,
    /// Kilograms (the model's own when absent).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mass: Option<f64>,
}

impl ObjectModel {
    /// This model as grasp mode `mode` builds it: the abstract mode's is the model itself, the
    /// physical mode's has the `[object.physical]` variant's shape and mass where it gives them.
    pub fn in_mode(&self, mode: GraspMode) -> ObjectModel {
        let mut m = self.clone();
        if let (GraspMode::Physical, Some(v)) = (mode, m.physical.take()) {
            m.shape = v.shape.unwrap_or(m.shape);
            m.mass = v.mass.unwrap_or(m.mass);
        }
        m
    }
}

/// Collision and render shape, centred on the model origin.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Shape {
    Sphere {
        radius: f64,
    },
    /// Axis along z.
    Cylinder {
        radius: f64,
        height: f64,
    },
    Cuboid {
        size: [f64; 3],
    },
    /// An open bowl: a base disc and a rim wall of the given thickness, axis along z.
    Bowl {
        radius: f64,
        height: f64,
        thickness: f64,
    },
    /// A triangle mesh from a glTF 2.0 file (`.gltf` with its `.bin`, or `.glb`), OBJ, STL, MuJoCo
    /// `.msh`, or an MJCF object file (`.xml`: its colliding mesh geoms, [`crate::catalogue_mjcf`]),
    /// relative to the catalogue file or starting with `${VAR}`; glTF is y-up and turned z-up,
    /// multiplied by `scale` and centred on its bounding box. `size` is that bounding box, which the rules here (resting height,
    /// footprint) use; the simulator checks it against the file. Collides and renders as the
    /// mesh's convex hull.
    Mesh {
        file: String,
        #[serde(default = "one")]
        scale: f64,
        size: [f64; 3],
    },
}

fn one() -> f64 {
    1.0
}

impl Shape {
    /// Half of the bounding-box height: how far the centre sits above the supporting surface.
    pub fn half_height(&self) -> f64 {
        match self {
            Shape::Sphere { radius } => *radius,
            Shape::Cylinder { height, .. } | Shape::Bowl { height, .. } => height / 2.0,
            Shape::Cuboid { size } | Shape::Mesh { size, .. } => size[2] / 2.0,
        }
    }

    /// Radius of the footprint's bounding circle.
    pub fn footprint_radius(&self) -> f64 {
        match self {
            Shape::Sphere { radius } | Shape::Cylinder { radius, .. } | Shape::Bowl { radius, .. } => *radius,
            Shape::Cuboid { size } | Shape::Mesh { size, .. } => {
                (size[0] * size[0] + size[1] * size[1]).sqrt() / 2.0
            }
        }
    }
}

/// Why `v` cannot stand in for `m` in the physical mode, if it cannot.
fn check_physical_variant(m: &ObjectModel, v: &PhysicalVariant) -> Result<(), String> {
    if v.mass.is_some_and(|kg| kg <= 0.0) {
        return Err("mass must be > 0".into());
    }
    if let Some(shape) = &v.shape {
        if matches!(shape, Shape::Mesh { .. }) || matches!(m.shape, Shape::Mesh { .. }) {
            return Err("shape: a mesh has no variant; give the physical mode's shape as a sphere, cylinder, cuboid or bowl".into());
        }
        let same = |a: f64, b: f64| (a - b).abs() < 1e-9;
        if !same(shape.half_height(), m.shape.half_height())
            || !same(shape.footprint_radius(), m.shape.footprint_radius())
        {
            return Err(format!(
                "shape: its bounding box ({:.3} m tall, footprint radius {:.3} m) must be the model's ({:.3} m, {:.3} m), \
                 so layouts and success checks are the same in both grasp modes",
                2.0 * shape.half_height(),
                shape.footprint_radius(),
                2.0 * m.shape.half_height(),
                m.shape.footprint_radius()
            ));
        }
    }
    Ok(())
}

impl Catalogue {
    pub fn load(path: &Path) -> Result<Catalogue, ContentError> {
        let text = std::fs::read_to_string(path).map_err(|source| ContentError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let mut cat: Catalogue = toml::from_str(&text).map_err(|e| ContentError::Parse {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        // Mesh files are named relative to the catalogue or to an environment variable
        // (`${ROBOSUITE_ASSETS}/objects/milk.xml`); from here on they are full paths.
        let dir = path.parent().unwrap_or(Path::new("."));
        for m in &mut cat.objects {
            if let Shape::Mesh { file, .. } = &mut m.shape {
                *file = crate::robot::resolve_file(dir, file, path)?
                    .to_string_lossy()
                    .into_owned();
            }
        }
        let mut seen = std::collections::BTreeSet::new();
        for m in &cat.objects {
            if !seen.insert(&m.id) {
                return Err(ContentError::Invalid {
                    path: path.to_path_buf(),
                    message: format!("duplicate object id {:?}", m.id),
                });
            }
            if m.mass <= 0.0 || m.friction < 0.0 {
                return Err(ContentError::Invalid {
                    path: path.to_path_buf(),
                    message: format!("object {:?}: mass must be > 0 and friction >= 0", m.id),
                });
            }
            if let Some(v) = &m.physical {
                check_physical_variant(m, v).map_err(|message| ContentError::Invalid {
                    path: path.to_path_buf(),
                    message: format!("object {:?}: [object.physical] {message}", m.id),
                })?;
            }
        }
        Ok(cat)
    }

    pub fn model(&self, id: &str) -> Option<&ObjectModel> {
        self.objects.iter().find(|m| m.id == id)
    }

    pub fn key_models(&self) -> impl Iterator<Item = &ObjectModel> {
        self.objects.iter().filter(|m| m.role == Role::Key)
    }

    pub fn background_models(&self) -> impl Iterator<Item = &ObjectModel> {
        self.objects.iter().filter(|m| m.role == Role::Background)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn load_str(dir: &Path, text: &str) -> Result<Catalogue, ContentError> {
        let path = dir.join("objects.toml");
        std::fs::write(&path, text).unwrap();
        Catalogue::load(&path)
    }

    const PLATE: &str = r#"
[[object]]
id = "plate"
role = "key"
shape = { kind = "cylinder", radius = 0.11, height = 0.02 }
mass = 0.4
friction = 0.7
color = [1.0, 1.0, 1.0]
grasp_offset = [0.095, 0.0, 0.0]
[object.physical]
"#;

    #[test]
    fn the_physical_variant_replaces_shape_and_mass_in_the_physical_mode_only() {
        let dir = tempfile::tempdir().unwrap();
        let cat = load_str(
            dir.path(),
            &format!("{PLATE}shape = {{ kind = \"bowl\", radius = 0.11, height = 0.02, thickness = 0.004 }}\nmass = 0.12\n"),
        )
        .unwrap();
        let plate = cat.model("plate").unwrap();
        let abstract_ = plate.in_mode(GraspMode::Abstract);
        assert_eq!(abstract_.shape, plate.shape);
        assert_eq!(abstract_.mass, 0.4);
        let p = &plate.in_mode(GraspMode::Physical);
        assert!(matches!(p.shape, Shape::Bowl { thickness, .. } if thickness == 0.004));
        assert_eq!(p.mass, 0.12);
        assert_eq!(p.grasp_offset, plate.grasp_offset);
        assert!(p.physical.is_none());
    }

    #[test]
    fn a_physical_variant_of_another_size_is_refused_with_both_sizes() {
        let dir = tempfile::tempdir().unwrap();
        let err = load_str(
            dir.path(),
            &format!(
                "{PLATE}shape = {{ kind = \"bowl\", radius = 0.11, height = 0.03, thickness = 0.004 }}\n"
            ),
        )
        .unwrap_err()
        .to_string();
        assert!(err.contains("\"plate\": [object.physical] shape"), "{err}");
        assert!(
            err.contains("0.030 m tall") && err.contains("(0.020 m, 0.110 m)"),
            "{err}"
        );
        let err = load_str(dir.path(), &format!("{PLATE}mass = 0.0\n"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("mass must be > 0"), "{err}");
    }
}
