//! Catalogue objects described in MJCF (robosuite's `objects/*.xml`: a body holding mesh geoms,
//! docs/twin/scenes.md): a catalogue `mesh` shape may name such a file instead of a mesh, and the
//! twin builds the object from the meshes of its colliding geoms (`kitchen_r_sim::mesh`). Read
//! with `mjcf-rs`, as robot descriptions are (`robot/mjcf.rs`): `<default>` classes resolved, mesh
//! files against the file's `meshdir`, each mesh's `scale` per axis. Only what a catalogue model
//! can hold is taken: a geom that is not a mesh is refused with what to change; geoms that do not
//! collide (`contype` and `conaffinity` both 0: robosuite's visual copies) are skipped.

use std::path::{Path, PathBuf};

use mjcf_rs::body::GeomType;

use crate::ContentError;

/// One colliding mesh geom of an MJCF object, in the object file's frame.
#[derive(Debug, Clone, PartialEq)]
pub struct ObjectMesh {
    /// The mesh file (STL, OBJ, glTF or MuJoCo's binary `.msh`), a full path.
    pub file: PathBuf,
    /// The `<mesh scale>`, per axis.
    pub scale: [f64; 3],
    /// The geom's pose composed with its bodies': translation (m) and rotation `w, x, y, z`.
    pub translation: [f64; 3],
    pub rotation: [f64; 4],
}

/// The colliding mesh geoms of the MJCF object file `path`.
pub fn object_meshes(path: &Path) -> Result<Vec<ObjectMesh>, ContentError> {
    let invalid = |message: String| ContentError::Invalid {
        path: path.to_path_buf(),
        message,
    };
    let model =
        mjcf_rs::Model::from_file(path).map_err(|e| invalid(format!("not a valid MJCF file: {e}")))?;
    let dir = path.parent().unwrap_or(Path::new("."));
    // Every body's pose in the file's frame (parents come first in `bodies`).
    let mut world: Vec<mjcf_rs::Pose> = Vec::with_capacity(model.bodies.len());
    let mut out = Vec::new();
    for entry in &model.bodies {
        let b = &entry.body;
        let pose = match entry.parent.and_then(|p| world.get(p)) {
            Some(parent) => *parent * b.pose,
            None => b.pose,
        };
        world.push(pose);
        for g in &b.geoms {
            if g.contype == 0 && g.conaffinity == 0 {
                continue;
            }
            let name = g.name.as_deref().unwrap_or("");
            let (GeomType::Mesh, Some(m)) = (&g.type_, &g.mesh) else {
                return Err(invalid(format!(
                    "<geom name=\"{name}\" type=\"{:?}\">: a catalogue object is made of meshes; make it a mesh \
                     geom, or give the catalogue a shape kind (sphere, cylinder, cuboid) instead",
                    g.type_
                )));
            };
            let mesh = model
                .assets
                .mesh(m)
                .ok_or_else(|| invalid(format!("<geom mesh=\"{m}\">: no <mesh name=\"{m}\"> in <asset>")))?;
            let file = model.resolve_mesh_file(mesh, dir).ok_or_else(|| {
                invalid(format!(
                    "<mesh name=\"{m}\"> has no file: inline meshes are not read"
                ))
            })?;
            let p = pose * g.pose;
            let q = p.rotation;
            out.push(ObjectMesh {
                file,
                scale: mesh.scale,
                translation: p.translation.to_array(),
                rotation: [q.w, q.x, q.y, q.z],
            });
        }
    }
    if out.is_empty() {
        return Err(invalid(
            "no colliding mesh geom: a catalogue object needs at least one <geom type=\"mesh\">".into(),
        ));
    }
    Ok(out)
}
