//! Meshes from glTF 2.0, OBJ and STL, for objects (`Shape::Mesh` in the catalogue) and furniture
//! (`mesh` in a scene file): read once when the assets load, kept in a process-wide cache by file
//! and scale. A dynamic object collides and renders as the mesh's convex hull; static furniture
//! as its triangles (a parry `TriMesh`). The ray caster casts against any parry shape, so both
//! render without a renderer change.
//!
//! The glTF reader takes the default scene's mesh nodes with their transforms, positions and
//! triangle indices of every `TRIANGLES` primitive, from a `.glb`'s binary chunk or `.bin` files
//! beside a `.gltf` (no embedded `data:` URIs, no images: materials and textures are not read;
//! the object's colour is the catalogue's). glTF is y-up: the mesh is turned z-up (x stays, glTF
//! y becomes our z, glTF z becomes our -y).
//!
//! OBJ and STL are read with `mesh-loader`, the reader rapier's own URDF and MJCF mesh loader
//! uses; every mesh of the file is taken, positions and faces only. Neither format names an up
//! axis: they are read z-up, as URDF, MJCF and ROS read them (CAD exports STL z-up, and a robot
//! description's OBJ and STL meshes are in their link's z-up frame).
//!
//! MuJoCo's binary `.msh` and MJCF object files (robosuite's `objects/*.xml`, their colliding mesh
//! geoms merged) are read by `crate::mesh_mjcf`.
//!
//! Whatever the format, the mesh is multiplied by the scale and centred on its bounding box,
//! which is the catalogue's model origin.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::{Arc, Mutex, OnceLock};

use nalgebra::{Matrix4, Point3};

use kitchen_r_core::catalogue::{Catalogue, Shape};
use kitchen_r_core::scene::Scene;
use rapier3d::math::Vector;
use rapier3d::prelude::SharedShape;

use crate::error::SimError;
use crate::mesh_raw::{Raw, mesh_error};

/// A mesh as the twin uses it.
#[derive(Debug)]
pub struct MeshData {
    /// Vertices, z-up, scaled, centred on the bounding box (m).
    pub vertices: Vec<[f64; 3]>,
    pub triangles: Vec<[u32; 3]>,
    /// Bounding box size (m).
    pub size: [f64; 3],
    /// Where the bounding box's centre was in the file's frame (m, scaled): a robot link's
    /// mesh is placed back there.
    pub center: [f64; 3],
    /// The convex hull it collides and renders as.
    pub hull: SharedShape,
    /// The triangle mesh static furniture collides and renders as, built on first use (its BVH
    /// once per process, not at every world build).
    trimesh: OnceLock<Option<SharedShape>>,
}

type Cache = Mutex<BTreeMap<(String, u64), Arc<MeshData>>>;

fn cache() -> &'static Cache {
    static CACHE: OnceLock<Cache> = OnceLock::new();
    CACHE.get_or_init(|| Mutex::new(BTreeMap::new()))
}

/// The mesh of `file` at `scale`, read on first use.
pub fn load(file: &str, scale: f64) -> Result<Arc<MeshData>, SimError> {
    let key = (file.to_string(), scale.to_bits());
    if let Some(m) = cache().lock().ok().and_then(|c| c.get(&key).cloned()) {
        return Ok(m);
    }
    let mesh = Arc::new(read(Path::new(file), scale)?);
    if let Ok(mut c) = cache().lock() {
        c.insert(key, mesh.clone());
    }
    Ok(mesh)
}

/// A mesh already loaded (every catalogue mesh is, by [`crate::sim::Assets::load`]).
pub fn cached(file: &str, scale: f64) -> Option<Arc<MeshData>> {
    cache()
        .lock()
        .ok()?
        .get(&(file.to_string(), scale.to_bits()))
        .cloned()
}

/// Load the mesh of `file` at `scale` and check it measures `want` (1 mm), so a wrong size is
/// reported when the assets load, not as a misplaced body later; `what` names the size's owner.
fn load_sized(file: &str, scale: f64, want: [f64; 3], what: &str) -> Result<(), SimError> {
    let mesh = load(file, scale)?;
    if (0..3).any(|k| (mesh.size[k] - want[k]).abs() > 1e-3) {
        return Err(SimError::Mesh {
            path: file.into(),
            message: format!(
                "{what} {want:?}, but the mesh measures {:?} (z-up, scaled by {scale}); write that size",
                mesh.size.map(|v| (v * 1e4).round() / 1e4)
            ),
        });
    }
    Ok(())
}

/// Read every mesh of the catalogue and check each against its stated `size`.
pub fn load_catalogue(catalogue: &Catalogue) -> Result<(), SimError> {
    for m in &catalogue.objects {
        if let Shape::Mesh { file, scale, size } = &m.shape {
            load_sized(
                file,
                *scale,
                *size,
                &format!("object {:?}: size in the catalogue", m.id),
            )?;
        }
    }
    Ok(())
}

/// Read every furniture mesh of the scenes and check each against the item's outer box
/// (`size` × `scale`).
pub fn load_scenes(scenes: &[Scene]) -> Result<(), SimError> {
    for s in scenes {
        for f in &s.furniture {
            let Some(m) = &f.mesh else { continue };
            let what = format!("scene {:?}, furniture {:?}: outer box", s.id, f.id);
            load_sized(&m.file, m.scale, f.scaled_size(), &what)?;
        }
    }
    Ok(())
}

/// Read every mesh of a robot description's links and hand (uniform scales only).
pub fn load_robot(robot: &kitchen_r_core::robot::RobotDesc) -> Result<(), SimError> {
    let shapes = robot
        .arm
        .joints
        .iter()
        .flat_map(|j| j.shapes.iter())
        .chain(&robot.arm.hand_shapes);
    for s in shapes {
        if let kitchen_r_core::robot::Geometry::Mesh { file, scale } = &s.geometry {
            if scale[1] != scale[0] || scale[2] != scale[0] {
                return Err(mesh_error(
                    file,
                    format!("scale {scale:?}: the twin scales a robot mesh uniformly; give one value thrice"),
                ));
            }
            let name = file.to_string_lossy();
            let mesh = load(&name, scale[0])?;
            let key = (name.to_string(), scale[0].to_bits());
            if let Ok(mut c) = robot_hulls().lock()
                && !c.contains_key(&key)
            {
                let hull = coarse_hull(&mesh).ok_or_else(|| mesh_error(file, "the mesh is flat".into()))?;
                c.insert(key, hull);
            }
        }
    }
    Ok(())
}

/// Most vertices of a robot link's collision hull.
const ROBOT_HULL_VERTICES: usize = 32;

fn robot_hulls() -> &'static Mutex<BTreeMap<(String, u64), SharedShape>> {
    static HULLS: OnceLock<Mutex<BTreeMap<(String, u64), SharedShape>>> = OnceLock::new();
    HULLS.get_or_init(|| Mutex::new(BTreeMap::new()))
}

/// A robot link mesh's collision hull (centred like the mesh), loaded by [`load_robot`]: the
/// convex hull of at most [`ROBOT_HULL_VERTICES`] of the mesh's hull vertices, picked farthest
/// first. A CAD link's full hull has hundreds of vertices, and every arm link is queried against
/// the scene at every substep; the coarse hull lies inside the full one and costs a fraction.
pub fn robot_hull(file: &str, scale: f64) -> Option<SharedShape> {
    robot_hulls()
        .lock()
        .ok()?
        .get(&(file.to_string(), scale.to_bits()))
        .cloned()
}

fn coarse_hull(mesh: &MeshData) -> Option<SharedShape> {
    let all: Vec<Vector> = match mesh.hull.as_convex_polyhedron() {
        Some(p) => p.points().to_vec(),
        None => points(&mesh.vertices),
    };
    if all.len() <= ROBOT_HULL_VERTICES {
        return SharedShape::convex_hull(&all);
    }
    let mut picked = vec![all[0]];
    let mut dist: Vec<f32> = all.iter().map(|p| (*p - all[0]).length_squared()).collect();
    while picked.len() < ROBOT_HULL_VERTICES {
        let (far, _) = dist
            .iter()
            .enumerate()
            .fold((0, -1.0f32), |b, (i, d)| if *d > b.1 { (i, *d) } else { b });
        let p = all[far];
        picked.push(p);
        for (d, q) in dist.iter_mut().zip(&all) {
            *d = d.min((*q - p).length_squared());
        }
    }
    SharedShape::convex_hull(&picked)
}

impl MeshData {
    /// The mesh as a triangle mesh shape (static furniture), if parry accepts it.
    pub fn trimesh(&self) -> Option<SharedShape> {
        self.trimesh
            .get_or_init(|| SharedShape::trimesh(points(&self.vertices), self.triangles.clone()).ok())
            .clone()
    }
}

/// Vertices as parry's single-precision points.
fn points(vertices: &[[f64; 3]]) -> Vec<Vector> {
    vertices
        .iter()
        .map(|v| Vector::new(v[0] as f32, v[1] as f32, v[2] as f32))
        .collect()
}

fn read(path: &Path, scale: f64) -> Result<MeshData, SimError> {
    let (vertices, triangles) = read_raw(path, scale)?;
    centred(path, vertices, triangles)
}

/// Vertices and triangles of a mesh file, by its extension, before centring.
pub(crate) fn read_raw(path: &Path, scale: f64) -> Result<Raw, SimError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("gltf" | "glb") => read_gltf(path, scale),
        Some("obj" | "stl") => read_obj_stl(path, scale),
        Some("msh") => crate::mesh_mjcf::read_msh(path, scale),
        // An MJCF object's meshes are files of the formats above, read with this function.
        Some("xml") => crate::mesh_mjcf::read_object(path, scale, read_raw),
        _ => Err(mesh_error(
            path,
            "unknown mesh format: give a glTF 2.0 (.gltf, .glb), OBJ (.obj), STL (.stl) or MuJoCo (.msh) file, \
             or an MJCF object (.xml)"
                .into(),
        )),
    }
}

fn read_obj_stl(path: &Path, scale: f64) -> Result<Raw, SimError> {
    let bad = |message: String| mesh_error(path, message);
    let scene = mesh_loader::Loader::default()
        .merge_meshes(true)
        .load(path)
        .map_err(|e| match e.kind() {
            std::io::ErrorKind::NotFound => SimError::Io {
                path: path.to_path_buf(),
                source: e,
            },
            _ => bad(format!("not a readable OBJ or STL file: {e}")),
        })?;
    let mesh = scene
        .meshes
        .into_iter()
        .next()
        .ok_or_else(|| bad("no mesh in the file".into()))?;
    let count = mesh.vertices.len();
    if mesh.faces.iter().flatten().any(|i| *i as usize >= count) {
        return Err(bad("face indices out of range".into()));
    }
    let vertices = mesh
        .vertices
        .iter()
        .map(|v| v.map(|c| f64::from(c) * scale))
        .collect();
    Ok((vertices, mesh.faces))
}

fn read_gltf(path: &Path, scale: f64) -> Result<Raw, SimError> {
    let bad = |message: String| mesh_error(path, message);
    let bytes = std::fs::read(path).map_err(|source| SimError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let gltf = gltf::Gltf::from_slice(&bytes).map_err(|e| bad(format!("not glTF 2.0: {e}")))?;
    let dir = path.parent().unwrap_or(Path::new("."));
    let mut buffers = Vec::new();
    for b in gltf.buffers() {
        let data = match b.source() {
            gltf::buffer::Source::Bin => gltf
                .blob
                .clone()
                .ok_or_else(|| bad("the .glb has no binary chunk".into()))?,
            gltf::buffer::Source::Uri(uri) if uri.starts_with("data:") => {
                return Err(bad(
                    "embedded data: URIs are not read; write a .glb or a .bin beside the .gltf".into(),
                ));
            }
            gltf::buffer::Source::Uri(uri) => {
                std::fs::read(dir.join(uri)).map_err(|source| SimError::Io {
                    path: dir.join(uri),
                    source,
                })?
            }
        };
        buffers.push(data);
    }
    let scene = gltf
        .default_scene()
        .or_else(|| gltf.scenes().next())
        .ok_or_else(|| bad("no scene".into()))?;
    let mut vertices = Vec::new();
    let mut triangles = Vec::new();
    let mut stack: Vec<(gltf::Node, Matrix4<f64>)> =
        scene.nodes().map(|n| (n, Matrix4::identity())).collect();
    while let Some((node, parent)) = stack.pop() {
        // glTF stores matrices column-major, as nalgebra reads nested arrays.
        let m = parent * Matrix4::from(node.transform().matrix()).cast::<f64>();
        stack.extend(node.children().map(|c| (c, m)));
        let Some(mesh) = node.mesh() else { continue };
        for prim in mesh.primitives() {
            if prim.mode() != gltf::mesh::Mode::Triangles {
                return Err(bad(format!(
                    "mesh {}: only TRIANGLES primitives are read",
                    mesh.index()
                )));
            }
            let reader = prim.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
            let base = vertices.len() as u32;
            let positions = reader
                .read_positions()
                .ok_or_else(|| bad(format!("mesh {} has no POSITION", mesh.index())))?;
            for p in positions {
                let w = m.transform_point(&Point3::from(p.map(f64::from)));
                // glTF y-up to our z-up.
                vertices.push([w[0] * scale, -w[2] * scale, w[1] * scale]);
            }
            let count = vertices.len() as u32 - base;
            let idx: Vec<u32> = match reader.read_indices() {
                Some(i) => i.into_u32().collect(),
                None => (0..count).collect(),
            };
            if !idx.len().is_multiple_of(3) || idx.iter().any(|i| *i >= count) {
                return Err(bad(format!(
                    "mesh {}: indices out of range or not triangles",
                    mesh.index()
                )));
            }
            triangles.extend(idx.chunks(3).map(|t| [base + t[0], base + t[1], base + t[2]]));
        }
    }
    if triangles.is_empty() {
        return Err(bad("no triangles in the default scene".into()));
    }
    Ok((vertices, triangles))
}

/// The mesh centred on its bounding box, with its size and convex hull.
fn centred(path: &Path, mut vertices: Vec<[f64; 3]>, triangles: Vec<[u32; 3]>) -> Result<MeshData, SimError> {
    let bad = |message: String| mesh_error(path, message);
    if triangles.is_empty() {
        return Err(bad("no triangles in the file".into()));
    }
    let lo = (0..3).map(|k| vertices.iter().map(|v| v[k]).fold(f64::INFINITY, f64::min));
    let hi = (0..3).map(|k| vertices.iter().map(|v| v[k]).fold(f64::NEG_INFINITY, f64::max));
    let (lo, hi): (Vec<f64>, Vec<f64>) = (lo.collect(), hi.collect());
    let center = [0, 1, 2].map(|k| (lo[k] + hi[k]) / 2.0);
    for v in &mut vertices {
        *v = [0, 1, 2].map(|k| v[k] - center[k]);
    }
    let hull = SharedShape::convex_hull(&points(&vertices))
        .ok_or_else(|| bad("the mesh is flat: it has no convex hull".into()))?;
    Ok(MeshData {
        size: [0, 1, 2].map(|k| hi[k] - lo[k]),
        center,
        vertices,
        triangles,
        hull,
        trimesh: OnceLock::new(),
    })
}
