//! Arm motions outside the pick-and-place state machine: getting the tool clear of the work
//! surface and back to the stow pose before the base drives, blended with the same raised
//! cosine as the machine's phases so the commanded pose never jumps.

use kitchen_r_sim::oracle::manip::{alpha, slerp};
use nalgebra::{Isometry3, UnitQuaternion, Vector3};

/// Tool speed used to size a blend's duration, m/s (about the machine's phase speeds).
const TOOL_SPEED: f64 = 0.15;
/// Wrist turn rate used to size a blend's duration, rad/s.
const TOOL_TURN: f64 = 0.8;
/// Shortest blend, s: even a tiny correction gets a smooth start and stop.
const MIN_BLEND: f64 = 0.5;
/// A tool this far below the stow height is near a work surface: it rises first.
pub(super) const LOW: f64 = 0.05;
/// How far a low tool rises before moving sideways, m (the machine's retreat height).
const RISE: f64 = 0.10;

/// A tool whose approach axis has this large a sideways (base y) component leans sideways.
const SIDEWAYS: f64 = 0.2;

/// A sequence of tool poses (base frame) visited with raised-cosine blends.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct ArmPath {
    start: Isometry3<f64>,
    legs: Vec<(Isometry3<f64>, f64)>,
}

fn blend_time(a: &Isometry3<f64>, b: &Isometry3<f64>) -> f64 {
    let d = (b.translation.vector - a.translation.vector).norm();
    (d / TOOL_SPEED)
        .max(a.rotation.angle_to(&b.rotation) / TOOL_TURN)
        .max(MIN_BLEND)
}

/// Where a task's prelude may go and how it departs from the plain one
/// (`OraclePolicy::start_task` decides).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(super) struct Prelude {
    /// The highest the tool may be where it starts (under a shelf board, see
    /// [`super::headroom`]).
    pub here_max: Option<f64>,
    /// How far a hand leaning sideways sinks before it pulls back from under a board, m
    /// (`headroom::sink_before_pullback`).
    pub sink: f64,
    /// The orientation (base frame) the tool stows with and ends turned to, instead of the
    /// stow pose's: a hand holding a plate tilted levels it before it goes in under a board.
    pub turn_to: Option<UnitQuaternion<f64>>,
    /// Seconds the tool stays where it is before it moves, while the fingers open: a place ends
    /// as the object touches down, with the fingers still squeezing it (the physical grasp).
    pub open_first: f64,
    /// The fraction of the pull back from under a board for which a hand leaning towards the
    /// board keeps its lean (0: it straightens on the whole way out), until its tool is out
    /// ([`super::headroom::lean_outside`]): straightened under the board, the UR5e's wrist rose
    /// into it and stopped the arm (dev-0138). A hand leaning sideways keeps its lean all the
    /// way out anyway.
    pub keep_lean: f64,
    /// Where (base frame, its height ignored) and to what orientation a hand that goes in under
    /// a board leaning turns first, outside the board's edge: the machine would turn it on the
    /// way in, and half turned the UR5e's wrist struck the board's front edge (dev-0049) and a
    /// Kinova3 finger met the shelf under a fork (dev-0150). A six-joint arm's hand leaning
    /// sideways still turns on the way in, but levels a held plate here instead of at the stow
    /// position (`OraclePolicy::start_task`). Leaning at the stow position instead, close over
    /// the shoulder, the UR5e and the Panda could not hold the lean (whole dev: 951 and 930 of
    /// 975 tasks).
    pub lean_at: Option<LeanAt>,
}

/// Where (base frame) and to what orientation a hand turns before it goes in under a board
/// ([`Prelude::lean_at`]).
pub(super) type LeanAt = (Vector3<f64>, UnitQuaternion<f64>);

impl ArmPath {
    /// The motion before a task: a tool stays where it is for `open_first` seconds, then a low
    /// tool rises by [`RISE`] (it may be around an object it
    /// just released, or hold one just lifted off a surface), capped at `here_max` under a
    /// board; under a board it then pulls back horizontally to the stow position (a hand leaning
    /// sideways sinks by `sink` first); a move then goes to `stow`, a manipulation lowers the
    /// tool to `target_max` when the work is under a board; with `turn_to`, the tool ends turned
    /// to it (see [`Prelude`]).
    pub(super) fn prelude(
        from: Isometry3<f64>,
        stow: Isometry3<f64>,
        target_max: Option<f64>,
        is_move: bool,
        how: Prelude,
    ) -> ArmPath {
        let stow = how
            .turn_to
            .map_or(stow, |r| Isometry3::from_parts(stow.translation, r));
        let mut path = ArmPath {
            start: from,
            legs: Vec::new(),
        };
        if how.open_first > 0.0 {
            path.legs.push((from, how.open_first));
        }
        let z = from.translation.z;
        if z < stow.translation.z - LOW {
            let up = (z + RISE).min(how.here_max.unwrap_or(f64::INFINITY));
            path.go(from.rotation, [from.translation.x, from.translation.y, up]);
        }
        let s = stow.translation.vector;
        let at = path.end().translation.vector;
        if how.here_max.is_some() && (at.xy() - s.xy()).norm() > 0.05 {
            // A hand leaning sideways (about its closing axis over flat work, see
            // `headroom::for_work`) turns a held fork's length as it straightens: under the
            // board its end strikes the shelf and the arm sticks (the Panda, dev). It
            // straightens out in the open, on the next leg. A top-down hand (the shipped arm's)
            // and one leaning towards the board turn on the way out as before.
            let sideways = (from.rotation * Vector3::x()).y.abs() > SIDEWAYS;
            // Leaning sideways, it first sinks a little (see `headroom::sink_before_pullback`).
            if sideways && how.sink > 0.0 {
                path.go(from.rotation, [at.x, at.y, at.z - how.sink]);
            }
            let at = path.end().translation.vector;
            if !sideways && how.keep_lean > 0.0 {
                let out = at.lerp(&Vector3::new(s.x, s.y, at.z), how.keep_lean);
                path.go(from.rotation, out.into());
            }
            path.go(
                if sideways { from.rotation } else { stow.rotation },
                [s.x, s.y, at.z],
            );
        }
        if is_move {
            path.go(stow.rotation, [s.x, s.y, s.z]);
        } else if let Some(m) = target_max {
            let at = path.end();
            if at.translation.z > m {
                path.go(at.rotation, [at.translation.x, at.translation.y, m]);
            }
        }
        if let Some(r) = how.turn_to {
            let p = path.end().translation.vector;
            path.go(r, [p.x, p.y, p.z]);
        }
        if let (false, Some((at, r))) = (is_move, how.lean_at) {
            let end = path.end();
            let z = end.translation.z;
            path.go(end.rotation, [at.x, at.y, z]);
            path.go(r, [at.x, at.y, z]);
        }
        path
    }

    fn end(&self) -> Isometry3<f64> {
        self.legs.last().map_or(self.start, |l| l.0)
    }

    /// Append a leg to `p` with orientation `rot`, unless it is already there.
    fn go(&mut self, rot: UnitQuaternion<f64>, p: [f64; 3]) {
        let at = self.end();
        let to = Isometry3::from_parts(Vector3::from(p).into(), rot);
        if (to.translation.vector - at.translation.vector).norm() > 0.005
            || to.rotation.angle_to(&at.rotation) > 0.02
        {
            let d = blend_time(&at, &to);
            self.legs.push((to, d));
        }
    }

    pub(super) fn duration(&self) -> f64 {
        self.legs.iter().map(|l| l.1).sum()
    }

    /// The blended pose `t` seconds after the start (clamped to the last pose).
    pub(super) fn at(&self, t: f64) -> Isometry3<f64> {
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
    use nalgebra::{Translation3, UnitQuaternion};

    use super::*;

    #[test]
    fn a_low_tool_rises_before_going_to_stow_and_ends_there() {
        let low = Isometry3::from_parts(Translation3::new(0.6, 0.0, 0.95), top_down(0.3));
        let stow = Isometry3::from_parts(Translation3::new(0.30, -0.12, 1.10), top_down(0.0));
        let p = ArmPath::prelude(low, stow, None, true, Prelude::default());
        let mid = p.at(p.legs[0].1);
        assert!((mid.translation.z - 1.05).abs() < 1e-9 && (mid.translation.x - 0.6).abs() < 1e-9);
        assert!((p.at(p.duration() + 1.0).translation.vector - stow.translation.vector).norm() < 1e-12);
        assert_eq!(p.at(0.0), low);
    }

    #[test]
    fn under_a_board_the_tool_rises_only_to_the_cap_and_pulls_back_level() {
        let low = Isometry3::from_parts(Translation3::new(0.6, 0.0, 0.95), top_down(0.0));
        let stow = Isometry3::from_parts(Translation3::new(0.30, -0.12, 1.10), top_down(0.0));
        let under_a_board = Prelude {
            here_max: Some(1.0),
            ..Prelude::default()
        };
        let p = ArmPath::prelude(low, stow, None, true, under_a_board);
        let legs: Vec<[f64; 3]> = p.legs.iter().map(|l| l.0.translation.vector.into()).collect();
        assert_eq!(
            legs,
            vec![[0.6, 0.0, 1.0], [0.30, -0.12, 1.0], [0.30, -0.12, 1.10]]
        );
        // Reaching into a shelf from stow: straight down to the cap first.
        let p = ArmPath::prelude(stow, stow, Some(1.0), false, Prelude::default());
        assert_eq!(p.end().translation.vector, Vector3::new(0.30, -0.12, 1.0));
    }

    #[test]
    fn a_leaning_hand_turns_only_outside_the_boards() {
        let stow = Isometry3::from_parts(Translation3::new(0.30, -0.12, 1.10), top_down(0.0));
        let lean = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), -std::f64::consts::FRAC_PI_4);
        let leaning = Isometry3::from_parts(Translation3::new(0.7, -0.12, 0.95), lean * top_down(0.0));
        let how = Prelude {
            here_max: Some(0.98),
            keep_lean: 0.5,
            lean_at: Some((Vector3::new(0.45, -0.12, 0.0), leaning.rotation)),
            ..Prelude::default()
        };
        // Out from under one board and in under another (a pick after a place on a shelf).
        let path = ArmPath::prelude(leaning, stow, Some(0.98), false, how);
        let legs: Vec<([f64; 3], f64)> = (path.legs.iter())
            .map(|l| {
                (
                    l.0.translation.vector.into(),
                    l.0.rotation.angle_to(&leaning.rotation),
                )
            })
            .collect();
        let lean_kept = |l: &([f64; 3], f64)| l.1 < 1e-12;
        // Up to the cap and half way back still leaning, then upright to the stow position.
        assert_eq!(legs[0].0, [0.7, -0.12, 0.98]);
        assert_eq!(legs[1].0, [0.5, -0.12, 0.98]);
        assert!(legs[..2].iter().all(lean_kept), "{legs:?}");
        assert_eq!(legs[2].0, [0.30, -0.12, 0.98]);
        assert!(path.legs[2].0.rotation.angle_to(&stow.rotation) < 1e-12);
        // Out to the board's edge upright, and leaning there.
        assert_eq!(legs[3].0, [0.45, -0.12, 0.98]);
        assert!(!lean_kept(&legs[3]));
        assert!(lean_kept(&legs[4]) && legs[4].0 == legs[3].0, "{legs:?}");
        assert_eq!(legs.len(), 5);
        // A move goes to the stow pose and does not lean.
        let path = ArmPath::prelude(leaning, stow, None, true, how);
        assert_eq!(path.end(), stow);
    }

    #[test]
    fn fingers_still_closed_round_a_placed_object_open_before_the_tool_moves() {
        let low = Isometry3::from_parts(Translation3::new(0.6, 0.0, 0.95), top_down(0.0));
        let stow = Isometry3::from_parts(Translation3::new(0.30, -0.12, 1.10), top_down(0.0));
        let how = Prelude {
            open_first: 0.4,
            ..Prelude::default()
        };
        let p = ArmPath::prelude(low, stow, None, true, how);
        assert_eq!(p.at(0.39), low);
        assert!(p.at(0.6).translation.z > low.translation.z);
        let plain = ArmPath::prelude(low, stow, None, true, Prelude::default());
        assert!((p.duration() - plain.duration() - 0.4).abs() < 1e-12);
    }

    #[test]
    fn a_tool_already_at_stow_needs_no_motion() {
        let stow = Isometry3::from_parts(Translation3::new(0.24, -0.12, 0.81), top_down(0.0));
        let p = ArmPath::prelude(stow, stow, None, true, Prelude::default());
        assert_eq!(p.duration(), 0.0);
        assert_eq!(p.at(3.0), stow);
    }
}
