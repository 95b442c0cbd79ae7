//! A link's shapes as the twin builds them: every geom on the link's frame and on the frames
//! fixed to it (not beyond a moving joint), placed in the link's frame, meshes by file.

use super::frame::Frame;
use super::tree::{Geom, JointKind, Shape, Tree};
use super::{Geometry, LinkShape, PoseDesc};

/// Colour of a part whose file gives none.
pub(crate) const GREY: [f32; 3] = [0.5, 0.5, 0.5];

pub(crate) fn rgb(c: Option<[f64; 4]>) -> [f32; 3] {
    c.map_or(GREY, |c| [c[0] as f32, c[1] as f32, c[2] as f32])
}

/// `from` and every frame fixed to it (rotations included), with its transform from `from`;
/// `skip` frames and what hangs from them are left out.
pub(crate) fn fixed_frames(t: &Tree, from: usize, skip: &[usize]) -> Vec<(usize, Frame)> {
    let mut out = vec![(from, Frame::IDENTITY)];
    let mut k = 0;
    while k < out.len() {
        let (at, f) = out[k];
        for (c, j) in t.children(at) {
            if j.kind == JointKind::Fixed && !skip.contains(&c) {
                out.push((c, f.then(&Frame::new(j.origin, j.rotation))));
            }
        }
        k += 1;
    }
    out
}

/// The shapes on `set` (frames with their transforms into the link's frame), each placed by
/// `into` (the link's frame in the frame the shapes are wanted in). Visual-only geoms are kept
/// only when `visuals` (a link whose file gives separate visual and collision geoms draws the
/// collision ones: fewer, and what the twin collides with).
pub(crate) fn link_shapes(
    t: &Tree,
    set: &[(usize, Frame)],
    into: &Frame,
    colour: Option<[f64; 4]>,
) -> Result<Vec<LinkShape>, String> {
    let geoms: Vec<(&Geom, Frame)> = set
        .iter()
        .flat_map(|(l, f)| t.links[*l].geoms.iter().map(move |g| (g, *f)))
        .collect();
    let any_collides = geoms.iter().any(|(g, _)| g.collides);
    let mut out = Vec::new();
    for (g, f) in geoms {
        if any_collides && !g.collides {
            continue;
        }
        let geometry = match g.shape {
            Shape::Box(size) => Geometry::Box { size },
            Shape::Cylinder { radius, length } => Geometry::Cylinder { radius, length },
            Shape::Capsule { radius, length } => Geometry::Capsule { radius, length },
            Shape::Sphere { radius } => Geometry::Sphere { radius },
            Shape::Mesh(i) => {
                let (file, scale) = &t.meshes[i];
                Geometry::Mesh {
                    file: file.clone(),
                    scale: *scale,
                }
            }
            Shape::Other(kind) => {
                return Err(format!(
                    "a {kind} {} on {}: the twin reads boxes, cylinders, capsules, spheres and meshes; \
                     replace it by one of those",
                    t.geom_tag,
                    t.frame(set[0].0)
                ));
            }
        };
        let at = into.then(&f).then(&Frame::new(g.origin, g.rotation));
        out.push(LinkShape {
            geometry,
            pose: PoseDesc {
                xyz: at.t,
                quat: at.rotation(),
            },
            color: rgb(g.color.or(colour)),
            collides: true,
        });
    }
    Ok(out)
}
