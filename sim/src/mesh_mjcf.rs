//! Catalogue objects from MJCF object files and MuJoCo's binary `.msh` meshes (robosuite's
//! `objects/*.xml`, docs/twin/scenes.md): the colliding mesh geoms that
//! [`kitchen_r_core::catalogue_mjcf`] lists are read, scaled per axis by their `<mesh scale>`,
//! placed at their geom poses and merged into one mesh, which `crate::mesh` then scales by the
//! catalogue's `scale` and centres like any other.

use std::path::Path;

use nalgebra::{Point3, Quaternion, Translation3, UnitQuaternion};

use crate::error::SimError;
use crate::mesh_raw::{Raw, ReadRaw, mesh_error};

/// An MJCF object file's colliding meshes as one mesh (file frame, z-up, times `scale`), each
/// mesh file read with `read_raw` (`crate::mesh`'s reader by extension).
pub(crate) fn read_object(path: &Path, scale: f64, read_raw: ReadRaw) -> Result<Raw, SimError> {
    let meshes = kitchen_r_core::catalogue_mjcf::object_meshes(path).map_err(SimError::Content)?;
    let (mut vertices, mut triangles): Raw = (Vec::new(), Vec::new());
    for m in meshes {
        let (v, t) = read_raw(&m.file, 1.0)?;
        let [w, x, y, z] = m.rotation;
        let rot = UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z));
        let pose = Translation3::from(m.translation) * rot;
        let base = u32::try_from(vertices.len()).map_err(|_| mesh_error(path, "too many vertices".into()))?;
        vertices.extend(v.iter().map(|p| {
            let local = Point3::new(p[0] * m.scale[0], p[1] * m.scale[1], p[2] * m.scale[2]);
            let p = (pose * local).coords * scale;
            [p.x, p.y, p.z]
        }));
        triangles.extend(t.iter().map(|f| f.map(|i| base + i)));
    }
    Ok((vertices, triangles))
}

/// MuJoCo's binary mesh: four little-endian `i32` counts (vertices, normals, texture
/// coordinates, faces), then the vertices' `f32` triples, the normals, the texture coordinates
/// and the faces' `i32` index triples. Read z-up as MJCF has it.
pub(crate) fn read_msh(path: &Path, scale: f64) -> Result<Raw, SimError> {
    let bad = |message: String| mesh_error(path, message);
    let bytes = std::fs::read(path).map_err(|source| SimError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let word = |i: usize| -> Option<[u8; 4]> { bytes.get(4 * i..4 * i + 4)?.try_into().ok() };
    let count = |i: usize| {
        word(i)
            .map(i32::from_le_bytes)
            .and_then(|n| usize::try_from(n).ok())
    };
    let (Some(nv), Some(nn), Some(nt), Some(nf)) = (count(0), count(1), count(2), count(3)) else {
        return Err(bad(
            "not a MuJoCo .msh file: no header of four non-negative counts".into(),
        ));
    };
    let faces_at = 4 + 3 * nv + 3 * nn + 2 * nt;
    if bytes.len() != 4 * (faces_at + 3 * nf) {
        return Err(bad(format!(
            "not a MuJoCo .msh file: {} bytes for {nv} vertices, {nn} normals, {nt} texture coordinates and {nf} faces",
            bytes.len()
        )));
    }
    if nf == 0 {
        return Err(bad(
            "no faces (MuJoCo would take the vertices' convex hull): give the faces".into(),
        ));
    }
    let float = |i: usize| word(i).map_or(0.0, |w| f64::from(f32::from_le_bytes(w)) * scale);
    let vertices = (0..nv).map(|k| [0, 1, 2].map(|c| float(4 + 3 * k + c))).collect();
    let mut triangles = Vec::with_capacity(nf);
    for k in 0..nf {
        let f = [0, 1, 2].map(|c| word(faces_at + 3 * k + c).map_or(-1, i32::from_le_bytes));
        let f = f.map(|i| u32::try_from(i).ok().filter(|i| (*i as usize) < nv));
        let [Some(a), Some(b), Some(c)] = f else {
            return Err(bad(format!("face {k}: indices out of range")));
        };
        triangles.push([a, b, c]);
    }
    Ok((vertices, triangles))
}
