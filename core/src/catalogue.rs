//! The object catalogue (`assets/objects.toml`): key objects the robot manipulates and
//! background objects that are scattered at random but never manipulated.
//!
//! Every model's origin is the centre of its bounding box, which is the "geometric centre" the
//! manipulation success check measures. Adding an object model is adding an entry here.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::ContentError;

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
