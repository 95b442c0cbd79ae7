//! MJCF to the description tree, read with `mjcf-rs` (the parser half of rapier3d-mjcf, which
//! resolves `<default>` classes, `<include>` and degree angles). Bodies are frames; a body's one
//! hinge or slide joint (at the body's origin) joins it to its parent, a body without one is fixed
//! to it; a site is a frame fixed to its body. MJCF gives geoms half sizes: they are doubled here.
//! Joints carry no velocity or effort limit in MJCF; the sidecar's `[arm]` gives them.

use std::path::Path;

use mjcf_rs::body::{GeomType, JointType};
use mjcf_rs::glam::DQuat;

use super::tree::{Geom, Joint, JointKind, Link, Shape, Tree};
use crate::ContentError;

pub(crate) fn tree(path: &Path) -> Result<Tree, ContentError> {
    let invalid = |message: String| ContentError::Invalid {
        path: path.to_path_buf(),
        message,
    };
    let model =
        mjcf_rs::Model::from_file(path).map_err(|e| invalid(format!("not a valid MJCF file: {e}")))?;
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
        let pose = |p: &mjcf_rs::Pose| (p.translation.to_array(), p.rotation != DQuat::IDENTITY);
        let (origin, rotated) = pose(&b.pose);
        let moving: Vec<_> = b.joints.iter().filter(|j| j.type_ != JointType::Free).collect();
        let joint = match moving.as_slice() {
            [] => Joint::fixed(format!("{name} (fixed to its parent)"), origin, rotated),
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
                    axis: j.axis,
                    limits: j.range,
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
                let (origin, rotated) = pose(&g.pose);
                Geom {
                    shape: shape(g),
                    origin,
                    rotated,
                    color: g.rgba,
                }
            })
            .collect();
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
            let (origin, rotated) = pose(&s.pose);
            links.push(Link {
                name: site.clone(),
                parent: Some((
                    body_index,
                    Joint::fixed(format!("{site} (site)"), origin, rotated),
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
        GeomType::Capsule => Shape::Capsule { radius: s[0] },
        GeomType::Sphere => Shape::Other("sphere"),
        _ => Shape::Other("other"),
    }
}
