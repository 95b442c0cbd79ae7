//! URDF to the description tree, read with `urdf-rs`. Links are frames, joints join them;
//! collision geometry gives the shapes, and the link's first coloured visual (its own material or
//! one named at the top of the file) the colour of every shape of the link. Mesh files are named
//! relative to the URDF file (`package://` is not resolved).

use std::path::Path;

use super::frame::rpy;
use super::tree::{Geom, Joint, JointKind, Link, Shape, Tree};
use crate::ContentError;

pub(crate) fn tree(path: &Path) -> Result<Tree, ContentError> {
    let invalid = |message: String| ContentError::Invalid {
        path: path.to_path_buf(),
        message,
    };
    let text = std::fs::read_to_string(path).map_err(|source| ContentError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let robot =
        urdf_rs::read_from_string(&text).map_err(|e| invalid(format!("not a valid URDF file: {e}")))?;
    let dir = path.parent().unwrap_or(Path::new("."));
    let mut meshes = Vec::new();
    let mut links: Vec<Link> = robot
        .links
        .iter()
        .map(|l| {
            let color = l.visual.iter().find_map(|v| {
                let m = v.material.as_ref()?;
                let named = || robot.materials.iter().find(|n| n.name == m.name)?.color.as_ref();
                m.color.as_ref().or_else(named).map(|c| c.rgba.0)
            });
            Link {
                name: l.name.clone(),
                parent: None,
                geoms: l
                    .collision
                    .iter()
                    .map(|c| Geom {
                        shape: shape(&c.geometry, dir, &mut meshes),
                        origin: c.origin.xyz.0,
                        rotated: c.origin.rpy.0 != [0.0; 3],
                        rotation: rpy(c.origin.rpy.0),
                        collides: true,
                        color,
                    })
                    .collect(),
                mass: (l.inertial.mass.value > 0.0).then_some(l.inertial.mass.value),
            }
        })
        .collect();
    for j in &robot.joints {
        let at = |name: &str, role: &str| {
            links.iter().position(|l| l.name == name).ok_or_else(|| {
                invalid(format!(
                    "<joint name=\"{}\">: its {role} link \"{name}\" is not a <link> of this file",
                    j.name
                ))
            })
        };
        let (parent, child) = (at(&j.parent.link, "parent")?, at(&j.child.link, "child")?);
        if links[child].parent.is_some() {
            return Err(invalid(format!(
                "<joint name=\"{}\">: link \"{}\" has two parent joints",
                j.name, j.child.link
            )));
        }
        let kind = match j.joint_type {
            urdf_rs::JointType::Fixed => JointKind::Fixed,
            urdf_rs::JointType::Revolute => JointKind::Revolute,
            urdf_rs::JointType::Prismatic => JointKind::Prismatic,
            urdf_rs::JointType::Continuous => JointKind::Other("continuous"),
            urdf_rs::JointType::Floating => JointKind::Other("floating"),
            urdf_rs::JointType::Planar => JointKind::Other("planar"),
            urdf_rs::JointType::Spherical => JointKind::Other("spherical"),
        };
        let moving = matches!(kind, JointKind::Revolute | JointKind::Prismatic);
        let lim = &j.limit;
        links[child].parent = Some((
            parent,
            Joint {
                name: j.name.clone(),
                kind,
                origin: j.origin.xyz.0,
                rotated: j.origin.rpy.0 != [0.0; 3],
                rotation: rpy(j.origin.rpy.0),
                axis: j.axis.xyz.0,
                limits: moving.then_some([lim.lower, lim.upper]),
                velocity: (moving && lim.velocity > 0.0).then_some(lim.velocity),
                effort: (moving && lim.effort > 0.0).then_some(lim.effort),
            },
        ));
    }
    Ok(Tree {
        links,
        frame_tag: "link",
        geom_tag: "collision",
        meshes,
    })
}

fn shape(g: &urdf_rs::Geometry, dir: &Path, meshes: &mut Vec<(std::path::PathBuf, [f64; 3])>) -> Shape {
    match g {
        urdf_rs::Geometry::Box { size } => Shape::Box(size.0),
        urdf_rs::Geometry::Cylinder { radius, length } => Shape::Cylinder {
            radius: *radius,
            length: *length,
        },
        urdf_rs::Geometry::Capsule { radius, length } => Shape::Capsule {
            radius: *radius,
            length: *length,
        },
        urdf_rs::Geometry::Sphere { radius } => Shape::Sphere { radius: *radius },
        urdf_rs::Geometry::Mesh { filename, scale } => {
            meshes.push((dir.join(filename), scale.map_or([1.0; 3], |s| s.0)));
            Shape::Mesh(meshes.len() - 1)
        }
    }
}
