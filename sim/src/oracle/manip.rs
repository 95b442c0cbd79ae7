//! The pick-and-place state machine of the paper (§Manipulation Module): ten phases, each an
//! end-effector target given in the frame of the object (or of its target place), joined by a
//! raised-cosine blend `α(τ) = (1 − cos πτ)/2` of position (lerp) and orientation (slerp), so the
//! commanded pose has zero velocity at every phase boundary.
//!
//! | # | phase | frame | target | gripper |
//! |---|---|---|---|---|
//! | 1 | `PreGrasp` | object | grasp point + `approach_height` up | open |
//! | 2 | `Descend` | object | grasp point | open |
//! | 3 | `Grasp` | object | grasp point (hold still) | closes |
//! | 4 | `Lift` | object | grasp point + `lift_height` up | closed |
//! | 5 | `Carry` | base | `carry` stow pose for driving | closed |
//! | 6 | `Transport` | target | target grasp point + `approach_height` up | closed |
//! | 7 | `Lower` | target | target grasp point + `release_height` up | closed |
//! | 8 | `Release` | target | same (hold still) | opens |
//! | 9 | `Retreat` | target | target grasp point + `retreat_height` up | open |
//! | 10 | `Home` | base | `home` pose | open |
//!
//! A pick runs phases 1–5 starting from `home`, a place runs 6–10 starting from `carry`.
//! The grasp point is the object centre plus the catalogue's `grasp_offset` in the object frame
//! (upright, turned by the object's yaw). Grasps are top-down: the tool's approach axis (x) points
//! down and its closing axis (y) lies across the object's narrow horizontal axis: the short side
//! of a box (the fork), the radial direction for a rim grasp (plate, bowl: a horizontal
//! grasp offset), any direction for round objects (the one needing no wrist turn). Of the two
//! opposite tool yaws that do this, the one nearer the base's forward one is used. End-effector
//! frame as in docs/twin/robot.md: x approach, y closing axis, top-down = +π/2 about y.

use std::f64::consts::{FRAC_PI_2, PI};

use kitchen_r_core::catalogue::{ObjectModel, Shape};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

/// The raised-cosine blend weight at normalised time `τ ∈ [0, 1]` (clamped).
pub fn alpha(tau: f64) -> f64 {
    (1.0 - (PI * tau.clamp(0.0, 1.0)).cos()) / 2.0
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Phase {
    PreGrasp,
    Descend,
    Grasp,
    Lift,
    Carry,
    Transport,
    Lower,
    Release,
    Retreat,
    Home,
}

impl Phase {
    pub const ALL: [Phase; 10] = [
        Phase::PreGrasp,
        Phase::Descend,
        Phase::Grasp,
        Phase::Lift,
        Phase::Carry,
        Phase::Transport,
        Phase::Lower,
        Phase::Release,
        Phase::Retreat,
        Phase::Home,
    ];

    /// Gripper command at the end of the phase (0 closed, 1 open).
    pub fn gripper(self) -> f64 {
        match self {
            Phase::Grasp | Phase::Lift | Phase::Carry | Phase::Transport | Phase::Lower => 0.0,
            _ => 1.0,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Phase::PreGrasp => "pre_grasp",
            Phase::Descend => "descend",
            Phase::Grasp => "grasp",
            Phase::Lift => "lift",
            Phase::Carry => "carry",
            Phase::Transport => "transport",
            Phase::Lower => "lower",
            Phase::Release => "release",
            Phase::Retreat => "retreat",
            Phase::Home => "home",
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct ManipParams {
    /// Stow pose in the base frame a pick starts from and a place returns to.
    pub home: Isometry3<f64>,
    /// Pose in the base frame an object is carried in while the base drives.
    pub carry: Isometry3<f64>,
    /// Height of `PreGrasp` and `Transport` above the grasp point, m.
    pub approach_height: f64,
    /// Height of `Lift` above the grasp point, m.
    pub lift_height: f64,
    /// Height above its target at which the object is let go, m.
    pub release_height: f64,
    /// Height of `Retreat` above the target grasp point, m.
    pub retreat_height: f64,
    /// Seconds per phase, in [`Phase::ALL`] order.
    pub durations: [f64; 10],
    /// Tool yaw (base frame, rad) over an object whose closing direction does not matter (no
    /// [`closing_axis`]: a sphere, an upright cylinder taken at its centre): 0 closes the
    /// fingers along the base's sideways axis; a caller turns it to keep the fingers off a
    /// neighbour.
    pub free_yaw: f64,
}

/// A top-down tool orientation turned by `yaw` about the vertical.
pub fn top_down(yaw: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw)
        * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), FRAC_PI_2)
}

impl Default for ManipParams {
    /// `home` = `carry`: tool straight down above the arm's side of the base (0.30 m ahead of the
    /// base centre, 0.12 m right) at 1.10 m, higher than any counter, so the straight blends to
    /// and from it keep the hand and a held object above the surfaces they cross. The arm's reset
    /// configuration puts the tool lower (0.24, −0.12, 0.81); the oracle commands `home` while it
    /// drives, so the arm is there by the first pick (else use [`PhasePlan::starting_from`]).
    fn default() -> Self {
        let stow = Isometry3::from_parts(Translation3::new(0.30, -0.12, 1.10), top_down(0.0));
        ManipParams {
            home: stow,
            carry: stow,
            approach_height: 0.12,
            lift_height: 0.15,
            release_height: 0.01,
            retreat_height: 0.12,
            durations: [3.0, 2.0, 1.0, 2.0, 3.0, 3.0, 2.0, 1.0, 2.0, 3.0],
            free_yaw: 0.0,
        }
    }
}

/// One phase of a plan: where the end effector must be (base frame) and the gripper command when
/// the phase ends.
#[derive(Debug, Clone, PartialEq)]
pub struct PhaseTarget {
    pub phase: Phase,
    pub ee_in_base: Isometry3<f64>,
    pub gripper: f64,
    pub duration: f64,
}

/// A blended sequence of phase targets from a start pose.
#[derive(Debug, Clone, PartialEq)]
pub struct PhasePlan {
    start: Isometry3<f64>,
    start_gripper: f64,
    targets: Vec<PhaseTarget>,
}

impl PhasePlan {
    /// Replace the start pose and gripper (default: `home`/open for a pick, `carry`/closed for a
    /// place) with where the arm really is.
    pub fn starting_from(mut self, ee_in_base: Isometry3<f64>, gripper: f64) -> Self {
        self.start = ee_in_base;
        self.start_gripper = gripper;
        self
    }

    pub fn targets(&self) -> &[PhaseTarget] {
        &self.targets
    }

    /// The plan from `phase` on (the phases before it dropped): a plan resumed from a state
    /// that is past them, e.g. a pick whose object is already in the hand starts at `Lift`.
    pub fn from_phase(mut self, phase: Phase) -> Self {
        let keep = self.targets.iter().position(|p| p.phase == phase);
        if let Some(i) = keep {
            self.targets.drain(..i);
        }
        self
    }

    pub fn duration(&self) -> f64 {
        self.targets.iter().map(|p| p.duration).sum()
    }

    /// The blended end-effector pose (base frame), gripper command and phase at time `t` seconds
    /// from the start; clamped to the plan's span.
    pub fn target_at(&self, t: f64) -> (Isometry3<f64>, f64, Phase) {
        let (mut from, mut g_from, mut t0) = (self.start, self.start_gripper, 0.0);
        let last = self.targets.len() - 1;
        for (i, p) in self.targets.iter().enumerate() {
            if t < t0 + p.duration || i == last {
                let a = if p.duration > 0.0 {
                    alpha((t - t0) / p.duration)
                } else {
                    1.0
                };
                let pos = from.translation.vector.lerp(&p.ee_in_base.translation.vector, a);
                let rot = slerp(&from.rotation, &p.ee_in_base.rotation, a);
                let g = g_from + a * (p.gripper - g_from);
                return (Isometry3::from_parts(pos.into(), rot), g, p.phase);
            }
            (from, g_from, t0) = (p.ee_in_base, p.gripper, t0 + p.duration);
        }
        unreachable!("a plan always has phases")
    }
}

/// Slerp along the shorter arc; falls back to a normalised lerp when the two are so close that
/// nalgebra's slerp declines (it returns `None` for (nearly) equal rotations as well as for
/// opposite ones).
pub fn slerp(a: &UnitQuaternion<f64>, b: &UnitQuaternion<f64>, t: f64) -> UnitQuaternion<f64> {
    a.try_slerp(b, t, 1e-9).unwrap_or_else(|| {
        let bq = if a.coords.dot(&b.coords) < 0.0 {
            -b.into_inner()
        } else {
            b.into_inner()
        };
        UnitQuaternion::new_normalize(a.into_inner().lerp(&bq, t))
    })
}

/// The upright frame at a pose: its position, turned by the yaw of its x axis.
pub fn upright(pose: &Isometry3<f64>) -> Isometry3<f64> {
    let x = pose.rotation * Vector3::x();
    let yaw = if x.x.hypot(x.y) > 1e-6 {
        x.y.atan2(x.x)
    } else {
        let y = pose.rotation * Vector3::y();
        y.y.atan2(y.x) - FRAC_PI_2
    };
    Isometry3::from_parts(
        pose.translation,
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw),
    )
}

/// The base frame as an isometry in the world.
pub fn base_isometry(base_pose_world: [f64; 3]) -> Isometry3<f64> {
    let [x, y, yaw] = base_pose_world;
    Isometry3::new(Vector3::new(x, y, 0.0), Vector3::z() * yaw)
}

/// Direction (radians, object frame) the fingers must close along, if it matters.
pub fn closing_axis(model: &ObjectModel) -> Option<f64> {
    let [ox, oy, _] = model.grasp_offset;
    match model.shape {
        Shape::Cuboid { size } => Some(if size[0] <= size[1] { 0.0 } else { FRAC_PI_2 }),
        _ if ox.hypot(oy) > 1e-6 => Some(oy.atan2(ox)),
        _ => None,
    }
}

/// The yaw (base frame) of a top-down tool whose fingers close along direction `axis` (base
/// frame), taken in (−π/2, π/2] so the wrist never turns more than a quarter turn from straight
/// ahead (the two fingers are alike: a half turn is the same grip).
pub fn tool_yaw(axis: f64) -> f64 {
    let y = axis - FRAC_PI_2;
    let w = y - PI * (y / PI).round();
    if w <= -FRAC_PI_2 { w + PI } else { w }
}

/// Top-down tool targets at `heights` above the grasp point of an object standing at `frame`
/// (upright, world), expressed in the base frame.
fn object_targets(
    frame: &Isometry3<f64>,
    model: &ObjectModel,
    base: &Isometry3<f64>,
    heights: &[(Phase, f64)],
    params: &ManipParams,
) -> Vec<PhaseTarget> {
    let frame_in_base = base.inverse() * frame;
    let frame_yaw = frame_in_base.rotation.scaled_axis().z;
    // Tool yaw in the base frame with the closing axis (tool y) along the required direction.
    let tool_yaw = closing_axis(model).map_or(params.free_yaw, |axis| tool_yaw(axis + frame_yaw));
    let in_frame_rot =
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), tool_yaw - frame_yaw) * top_down(0.0);
    let [gx, gy, gz] = model.grasp_offset;
    heights
        .iter()
        .map(|&(phase, h)| {
            let local = Isometry3::from_parts(Translation3::new(gx, gy, gz + h), in_frame_rot);
            PhaseTarget {
                phase,
                ee_in_base: frame_in_base * local,
                gripper: phase.gripper(),
                duration: params.durations[phase as usize],
            }
        })
        .collect()
}

fn base_target(phase: Phase, pose: Isometry3<f64>, params: &ManipParams) -> PhaseTarget {
    PhaseTarget {
        phase,
        ee_in_base: pose,
        gripper: phase.gripper(),
        duration: params.durations[phase as usize],
    }
}

/// Phases 1–5: take the object standing at `object_pose_world` and stow it for driving.
#[derive(Debug, Clone, PartialEq)]
pub struct PickPlan {
    pub plan: PhasePlan,
    object_yaw_in_base: f64,
}

impl PickPlan {
    pub fn new(
        object_pose_world: &Isometry3<f64>,
        model: &ObjectModel,
        base_pose_world: [f64; 3],
        params: &ManipParams,
    ) -> PickPlan {
        let base = base_isometry(base_pose_world);
        let frame = upright(object_pose_world);
        let heights = [
            (Phase::PreGrasp, params.approach_height),
            (Phase::Descend, 0.0),
            (Phase::Grasp, 0.0),
            (Phase::Lift, params.lift_height),
        ];
        let mut targets = object_targets(&frame, model, &base, &heights, params);
        targets.push(base_target(Phase::Carry, params.carry, params));
        PickPlan {
            plan: PhasePlan {
                start: params.home,
                start_gripper: Phase::Home.gripper(),
                targets,
            },
            object_yaw_in_base: (base.inverse() * frame).rotation.scaled_axis().z,
        }
    }

    /// The object's yaw relative to the base when grasped: place it with the same relative yaw
    /// (see [`PlacePlan::target_keeping_grip`]) and the hand needs no re-grasp.
    pub fn object_yaw_in_base(&self) -> f64 {
        self.object_yaw_in_base
    }

    pub fn target_at(&self, t: f64) -> (Isometry3<f64>, f64, Phase) {
        self.plan.target_at(t)
    }

    pub fn duration(&self) -> f64 {
        self.plan.duration()
    }
}

/// Phases 6–10: put the held object down with its centre at `target_world` and go home.
#[derive(Debug, Clone, PartialEq)]
pub struct PlacePlan {
    pub plan: PhasePlan,
}

impl PlacePlan {
    /// `target_world`: where the object's centre should end, with the yaw it should end at. The
    /// yaw must be the one the grip implies ([`PlacePlan::target_keeping_grip`]); otherwise an
    /// off-centre grasp point puts the centre elsewhere.
    pub fn new(
        target_world: &Isometry3<f64>,
        model: &ObjectModel,
        base_pose_world: [f64; 3],
        params: &ManipParams,
    ) -> PlacePlan {
        let base = base_isometry(base_pose_world);
        let heights = [
            (Phase::Transport, params.approach_height),
            (Phase::Lower, params.release_height),
            (Phase::Release, params.release_height),
            (Phase::Retreat, params.retreat_height),
        ];
        let mut targets = object_targets(&upright(target_world), model, &base, &heights, params);
        targets.push(base_target(Phase::Home, params.home, params));
        PlacePlan {
            plan: PhasePlan {
                start: params.carry,
                start_gripper: Phase::Carry.gripper(),
                targets,
            },
        }
    }

    /// The target pose for an object centre at `centre_world` that keeps the object's yaw
    /// relative to the base from the pick ([`PickPlan::object_yaw_in_base`]).
    pub fn target_keeping_grip(
        centre_world: [f64; 3],
        object_yaw_in_base: f64,
        base_pose_world: [f64; 3],
    ) -> Isometry3<f64> {
        let [x, y, z] = centre_world;
        Isometry3::new(
            Vector3::new(x, y, z),
            Vector3::z() * (base_pose_world[2] + object_yaw_in_base),
        )
    }

    pub fn target_at(&self, t: f64) -> (Isometry3<f64>, f64, Phase) {
        self.plan.target_at(t)
    }

    pub fn duration(&self) -> f64 {
        self.plan.duration()
    }
}
