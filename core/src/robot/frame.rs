//! Rigid transforms between the description's frames: a translation and, where the file gives
//! one, a rotation (`w, x, y, z`). A transform without rotation composes by adding translations
//! only, so a chain written without rotations keeps the file's numbers exactly.

use mjcf_rs::glam::{DQuat, DVec3, EulerRot};

use super::tree::{IDENTITY, add};

#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Frame {
    pub t: [f64; 3],
    /// `None`: no rotation.
    pub q: Option<[f64; 4]>,
}

fn quat(q: [f64; 4]) -> DQuat {
    DQuat::from_xyzw(q[1], q[2], q[3], q[0])
}

fn wxyz(q: DQuat) -> [f64; 4] {
    [q.w, q.x, q.y, q.z]
}

/// The unit quaternion of a URDF `rpy` (fixed axes x, then y, then z).
pub(crate) fn rpy(r: [f64; 3]) -> [f64; 4] {
    if r == [0.0; 3] {
        return IDENTITY;
    }
    wxyz(DQuat::from_euler(EulerRot::ZYX, r[2], r[1], r[0]))
}

/// `v` turned by the unit quaternion `q`.
pub(crate) fn rotate(q: [f64; 4], v: [f64; 3]) -> [f64; 3] {
    (quat(q) * DVec3::from_array(v)).to_array()
}

impl Frame {
    pub(crate) const IDENTITY: Frame = Frame { t: [0.0; 3], q: None };

    pub(crate) fn new(t: [f64; 3], q: [f64; 4]) -> Frame {
        let n = (q.iter().map(|v| v * v).sum::<f64>()).sqrt();
        let q = if q == IDENTITY || n == 0.0 {
            None
        } else {
            Some(q.map(|v| v / n))
        };
        Frame { t, q }
    }

    /// `self` then `other` (other's translation is in self's frame).
    pub(crate) fn then(&self, other: &Frame) -> Frame {
        let t = match self.q {
            None => add(self.t, other.t),
            Some(q) => add(self.t, rotate(q, other.t)),
        };
        let q = match (self.q, other.q) {
            (None, x) | (x, None) => x,
            (Some(a), Some(b)) => Some(wxyz(quat(a) * quat(b))),
        };
        Frame { t, q }
    }

    /// The rotation, identity included.
    pub(crate) fn rotation(&self) -> [f64; 4] {
        self.q.unwrap_or(IDENTITY)
    }
}
