//! Arm motions outside the pick-and-place state machine: getting the tool clear of the work
//! surface and back to the stow pose before the base drives, blended with the same raised
//! cosine as the machine's phases so the commanded pose never jumps.

use kitchen_r_sim::oracle::manip::alpha;
use nalgebra::{Isometry3, UnitQuaternion, Vector3};

/// Tool speed used to size a blend's duration, m/s (about the machine's phase speeds).
const TOOL_SPEED: f64 = 0.15;
/// Wrist turn rate used to size a blend's duration, rad/s.
const TOOL_TURN: f64 = 0.8;
/// Shortest blend, s: even a tiny correction gets a smooth start and stop.
const MIN_BLEND: f64 = 0.5;
/// A tool this far below the stow height is near a work surface: it rises first.
const LOW: f64 = 0.05;
/// How far a low tool rises before moving sideways, m (the machine's retreat height).
const RISE: f64 = 0.10;

/// A sequence of tool poses (base frame) visited with raised-cosine blends.
#[derive(Debug, Clone, PartialEq)]
pub struct ArmPath {
    start: Isometry3<f64>,
    legs: Vec<(Isometry3<f64>, f64)>,
}

fn slerp(a: &UnitQuaternion<f64>, b: &UnitQuaternion<f64>, t: f64) -> UnitQuaternion<f64> {
    a.try_slerp(b, t, 1e-9).unwrap_or_else(|| {
        let bq = if a.coords.dot(&b.coords) < 0.0 {
            -b.into_inner()
        } else {
            b.into_inner()
        };
        UnitQuaternion::new_normalize(a.into_inner().lerp(&bq, t))
    })
}

fn blend_time(a: &Isometry3<f64>, b: &Isometry3<f64>) -> f64 {
    let d = (b.translation.vector - a.translation.vector).norm();
    (d / TOOL_SPEED).max(a.rotation.angle_to(&b.rotation) / TOOL_TURN).max(MIN_BLEND)
}

impl ArmPath {
    /// From `from` to `to`, rising by [`RISE`] first when the tool is low (it may be around
    /// an object it just released, or hold one just lifted off a counter).
    pub fn clear_then(from: Isometry3<f64>, to: Option<Isometry3<f64>>, stow_z: f64) -> ArmPath {
        let mut legs = Vec::new();
        let mut at = from;
        if from.translation.z < stow_z - LOW {
            let up = Isometry3::from_parts((from.translation.vector + Vector3::z() * RISE).into(), from.rotation);
            legs.push((up, blend_time(&at, &up)));
            at = up;
        }
        if let Some(to) = to
            && ((to.translation.vector - at.translation.vector).norm() > 0.005
                || to.rotation.angle_to(&at.rotation) > 0.02)
        {
            legs.push((to, blend_time(&at, &to)));
        }
        ArmPath { start: from, legs }
    }

    pub fn duration(&self) -> f64 {
        self.legs.iter().map(|l| l.1).sum()
    }

    /// The blended pose `t` seconds after the start (clamped to the last pose).
    pub fn at(&self, t: f64) -> Isometry3<f64> {
        let (mut from, mut t0) = (self.start, 0.0);
        for &(to, dur) in &self.legs {
            if t < t0 + dur {
                let a = alpha((t - t0) / dur);
                let pos = from.translation.vector.lerp(&to.translation.vector, a);
                return Isometry3::from_parts(pos.into(), slerp(&from.rotation, &to.rotation, a));
            }
            (from, t0) = (to, t0 + dur);
        }
        from
    }
}

#[cfg(test)]
mod tests {
    use kitchen_r_sim::oracle::manip::top_down;
    use nalgebra::Translation3;

    use super::*;

    #[test]
    fn a_low_tool_rises_before_going_to_stow_and_ends_there() {
        let low = Isometry3::from_parts(Translation3::new(0.6, 0.0, 0.95), top_down(0.3));
        let stow = Isometry3::from_parts(Translation3::new(0.24, -0.12, 0.81 + 0.4), top_down(0.0));
        let p = ArmPath::clear_then(low, Some(stow), stow.translation.z);
        let mid = p.at(p.legs[0].1);
        assert!((mid.translation.z - 1.05).abs() < 1e-9 && (mid.translation.x - 0.6).abs() < 1e-9);
        assert!((p.at(p.duration() + 1.0).translation.vector - stow.translation.vector).norm() < 1e-12);
        assert_eq!(p.at(0.0), low);
    }

    #[test]
    fn a_tool_already_at_stow_needs_no_motion() {
        let stow = Isometry3::from_parts(Translation3::new(0.24, -0.12, 0.81), top_down(0.0));
        let p = ArmPath::clear_then(stow, Some(stow), 0.81);
        assert_eq!(p.duration(), 0.0);
        assert_eq!(p.at(3.0), stow);
    }
}
