//! MJCF to the description tree, read with `mjcf-rs` (the parser half of rapier3d-mjcf, which
//! resolves `<default>` classes, `<include>` and degree angles). Bodies are frames; a body's one
//! hinge or slide joint (at the body's origin) joins it to its parent, a body without one is fixed
//! to it; a site is a frame fixed to its body. MJCF gives geoms half sizes: they are doubled here.
//! Joints carry no velocity or effort limit in MJCF; the sidecar's `[arm]` gives them. A hinge
//! without a `range` turns freely: the twin gives it ±2π. Mesh geoms name `<asset><mesh>` files
//! (resolved against the file's `meshdir`); a geom collides when its `contype` or `conaffinity`
//! is non-zero, and takes its colour from its `rgba` or its material's.

use std::path::Path;

use mjcf_rs::body::{GeomType, JointType};
use mjcf_rs::glam::DQuat;

use super::tree::{Geom, IDENTITY, Joint, JointKind, Link, Shape, Tree};
use crate::ContentError;

pub(crate) fn tree(path: &Path) -> Result<Tree, ContentError> {
    let invalid = |message: String| ContentError::Invalid {
        path: path.to_path_buf(),
        message,
    };
    let model =
        mjcf_rs::Model::from_file(path).map_err(|e| invalid(format!("not a valid MJCF file: {e}")))?;
    let dir = path.parent().unwrap_or(Path::new("."));
    let mut meshes = Vec::new();
    let mut links = Vec::new();
    // Where each body went in `links` (its named sites follow it).
    let mut at = Vec::new();
    // The world body (id 0, the root) too, so body ids and positions in `links` line up.
    for (id, entry) in model.bodies.iter().enumerate() {
        let b = &entry.body;
        let name = match (&b.name, id) {
            (Some(n), _) => n.clone(),
            (None, 0) => "world".into(),
            (None, _) => format!("body{id}"),
        };
        let pose = |p: &mjcf_rs::Pose| {
            let q = p.rotation;
            let rotation = if q == DQuat::IDENTITY {
                IDENTITY
            } else {
                [q.w, q.x, q.y, q.z]
            };
            (p.translation.to_array(), rotation)
        };
        let (origin, rotation) = pose(&b.pose);
        let rotated = rotation != IDENTITY;
        let moving: Vec<_> = b.joints.iter().filter(|j| j.type_ != JointType::Free).collect();
        let joint = match moving.as_slice() {
            [] => Joint::fixed(format!("{name} (fixed to its parent)"), origin, rotation),
            [j] => {
                let jname = j.name.clone().unwrap_or_else(|| format!("{name}'s joint"));
                if j.pos != [0.0; 3] {
                    return Err(invalid(format!(
                        "<joint name=\"{jname}\">: pos {:?}: put the joint at its body's origin (pos=\"0 0 0\") and \
                         move the body instead",
                        j.pos
                    )));
                }
                Joint {
                    name: jname,
                    kind: match j.type_ {
                        JointType::Hinge => JointKind::Revolute,
                        JointType::Slide => JointKind::Prismatic,
                        JointType::Ball => JointKind::Other("ball"),
                        JointType::Free => JointKind::Other("free"),
                    },
                    origin,
                    rotated,
                    rotation,
                    axis: j.axis,
                    limits: j.range.or(match j.type_ {
                        JointType::Hinge => Some([-std::f64::consts::TAU, std::f64::consts::TAU]),
                        _ => None,
                    }),
                    velocity: None,
                    effort: None,
                }
            }
            _ => {
                return Err(invalid(format!(
                    "<body name=\"{name}\"> has {} joints: give each joint a body of its own",
                    moving.len()
                )));
            }
        };
        let geoms = b
            .geoms
            .iter()
            .map(|g| {
                let (origin, rotation) = pose(&g.pose);
                let material = || model.assets.material(g.material.as_deref()?)?.rgba;
                let shape = match (&g.type_, &g.mesh) {
                    (GeomType::Mesh, Some(m)) => {
                        let mesh = model.assets.mesh(m).ok_or_else(|| {
                            invalid(format!("<geom mesh=\"{m}\">: no <mesh name=\"{m}\"> in <asset>"))
                        })?;
                        let file = model.resolve_mesh_file(mesh, dir).ok_or_else(|| {
                            invalid(format!(
                                "<mesh name=\"{m}\"> has no file: inline meshes are not read"
                            ))
                        })?;
                        meshes.push((file, mesh.scale));
                        Shape::Mesh(meshes.len() - 1)
                    }
                    _ => shape(g),
                };
                Ok(Geom {
                    shape,
                    origin,
                    rotated: rotation != IDENTITY,
                    rotation,
                    collides: g.contype != 0 || g.conaffinity != 0,
                    color: g.rgba.or_else(material),
                })
            })
            .collect::<Result<Vec<_>, ContentError>>()?;
        let parent = match entry.parent {
            Some(p) => Some((
                *at.get(p)
                    .ok_or_else(|| invalid(format!("body {name:?} comes before its parent")))?,
                joint,
            )),
            None => None,
        };
        at.push(links.len());
        links.push(Link {
            name,
            parent,
            geoms,
            mass: b.inertial.as_ref().map(|i| i.mass),
        });
        let body_index = links.len() - 1;
        for s in &b.sites {
            let Some(site) = &s.name else { continue };
            let (origin, rotation) = pose(&s.pose);
            links.push(Link {
                name: site.clone(),
                parent: Some((
                    body_index,
                    Joint::fixed(format!("{site} (site)"), origin, rotation),
                )),
                geoms: Vec::new(),
                mass: None,
            });
        }
    }
    Ok(Tree {
        links,
        frame_tag: "body",
        geom_tag: "geom",
        meshes,
    })
}

fn shape(g: &mjcf_rs::body::Geom) -> Shape {
    let s = g.size;
    match g.type_ {
        GeomType::Box => Shape::Box([2.0 * s[0], 2.0 * s[1], 2.0 * s[2]]),
        GeomType::Cylinder => Shape::Cylinder {
            radius: s[0],
            length: 2.0 * s[1],
        },
        GeomType::Capsule => Shape::Capsule {
            radius: s[0],
            length: 2.0 * s[1],
        },
        GeomType::Sphere => Shape::Sphere { radius: s[0] },
        _ => Shape::Other("other"),
    }
}
