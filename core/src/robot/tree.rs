//! What a URDF or MJCF file says that the twin reads, in one shape: a tree of frames (URDF links,
//! MJCF bodies and sites), each joined to its parent by a joint, with collision geometry and a
//! colour. Positions are kept as the file writes them, rotations beside them as unit quaternions
//! (`w, x, y, z`), so a chain without rotations reaches the kinematics with the file's numbers
//! unchanged.

use std::path::PathBuf;

/// A frame of the description.
#[derive(Debug, Clone)]
pub(crate) struct Link {
    pub name: String,
    /// The parent's index and the joint from it (`None`: a root).
    pub parent: Option<(usize, Joint)>,
    pub geoms: Vec<Geom>,
    /// kg, from the frame's inertial element.
    pub mass: Option<f64>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum JointKind {
    Fixed,
    Revolute,
    Prismatic,
    /// Anything else (continuous, ball, free, planar...), by the file's name for it.
    Other(&'static str),
}

#[derive(Debug, Clone)]
pub(crate) struct Joint {
    pub name: String,
    pub kind: JointKind,
    /// Translation from the parent frame to this frame (the joint's frame at zero).
    pub origin: [f64; 3],
    /// Whether the frame is also rotated against its parent (URDF `rpy`, MJCF `quat`/`euler`...).
    pub rotated: bool,
    /// That rotation, `w, x, y, z` (identity when not `rotated`).
    pub rotation: [f64; 4],
    pub axis: [f64; 3],
    /// `[lower, upper]` (rad or m).
    pub limits: Option<[f64; 2]>,
    /// rad/s or m/s.
    pub velocity: Option<f64>,
    /// N·m or N.
    pub effort: Option<f64>,
}

impl Joint {
    /// A frame fixed to its parent (an MJCF body without a joint, or a site).
    pub(super) fn fixed(name: String, origin: [f64; 3], rotation: [f64; 4]) -> Joint {
        Joint {
            name,
            kind: JointKind::Fixed,
            origin,
            rotated: rotation != IDENTITY,
            rotation,
            axis: [1.0, 0.0, 0.0],
            limits: None,
            velocity: None,
            effort: None,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Shape {
    /// Full sizes.
    Box([f64; 3]),
    Cylinder {
        radius: f64,
        length: f64,
    },
    Capsule {
        radius: f64,
        /// Between the end caps' centres.
        length: f64,
    },
    Sphere {
        radius: f64,
    },
    /// A mesh file (index into [`Tree::meshes`]).
    Mesh(usize),
    Other(&'static str),
}

/// The unit quaternion of no rotation, `w, x, y, z`.
pub(crate) const IDENTITY: [f64; 4] = [1.0, 0.0, 0.0, 0.0];

#[derive(Debug, Clone, Copy)]
pub(crate) struct Geom {
    pub shape: Shape,
    /// Centre in the frame.
    pub origin: [f64; 3],
    pub rotated: bool,
    /// `w, x, y, z`.
    pub rotation: [f64; 4],
    /// Whether it collides (URDF `<collision>`; MJCF `contype` or `conaffinity` non-zero), or
    /// is drawn only.
    pub collides: bool,
    /// `rgba` (URDF: the link's visual colour; MJCF: the geom's own).
    pub color: Option<[f64; 4]>,
}

/// The whole description.
#[derive(Debug, Clone)]
pub(crate) struct Tree {
    pub links: Vec<Link>,
    /// How the file names a frame and a collision shape: `link`/`collision` (URDF) or
    /// `body`/`geom` (MJCF), for error messages.
    pub frame_tag: &'static str,
    pub geom_tag: &'static str,
    /// Mesh files the geoms name: path and scale.
    pub meshes: Vec<(PathBuf, [f64; 3])>,
}

impl Tree {
    pub(crate) fn find(&self, name: &str) -> Option<usize> {
        self.links.iter().position(|l| l.name == name)
    }

    pub(crate) fn children(&self, of: usize) -> impl Iterator<Item = (usize, &Joint)> {
        self.links
            .iter()
            .enumerate()
            .filter_map(move |(i, l)| l.parent.as_ref().filter(|(p, _)| *p == of).map(|(_, j)| (i, j)))
    }

    /// `<link name="x">` or `<body name="x">`.
    pub(crate) fn frame(&self, i: usize) -> String {
        format!("<{} name=\"{}\">", self.frame_tag, self.links[i].name)
    }
}

/// `a + b`, component-wise.
pub(crate) fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
