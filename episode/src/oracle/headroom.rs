//! Headroom under shelf boards. The twin's shelves have a board every level (0.4 m apart in the
//! committed scenes), and a top-down hand carries its wrist 0.17 m above the tool centre point:
//! the stow height and the machine's default approach heights would drive the wrist into the
//! board above the level being served, and a link pressed into fixed geometry freezes the arm.
//! So the oracle caps tool heights over a shelf and reaches in or out horizontally.

use kitchen_r_core::catalogue::Shape;
use kitchen_r_core::scene::Scene;
use nalgebra::{Isometry3, Point3, UnitQuaternion, Vector3};

use super::arm::LeanAt;

/// Thickness of the twin's shelf boards (`sim/src/furniture.rs`): a surface at height `s` is a
/// board whose underside is at `s − BOARD`.
const BOARD: f64 = 0.02;
/// Tool centre point to the top of the wrist link with the tool pointing down (0.07 + 0.10 m
/// of the shipped robot description, the link radius and a margin).
pub(super) const WRIST_CLEAR: f64 = 0.23;
/// The link radius and margin above the highest wrist joint that [`WRIST_CLEAR`] allows.
const WRIST_MARGIN: f64 = 0.06;

/// How the hand of an arm works under a board: the tool's clearance below the board and the
/// lean of its fingers away from the base there (`None`: straight down).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Headroom {
    pub clear: f64,
    pub tilt: Option<Lean>,
}

/// A leaning hand's turn about its tool centre point, rad.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Lean {
    /// About the base's left axis: the wrist stands back towards the board's front edge.
    Reach(f64),
    /// About the tool's own closing axis, so both fingers stay level (flat work, see [`for_work`]).
    Closing(f64),
}

/// `pose` leaned by `tilt` about its own position, the fingers turned away from the base
/// (`undo`: the lean taken off a leaned pose). [`Lean::Reach`] turns about the base's left
/// axis; [`Lean::Closing`] about the tool's own closing axis (tool y), so both fingers stay level
/// over flat work (`headroom::for_work`).
pub(super) fn tilted(pose: Isometry3<f64>, tilt: Option<Lean>, undo: bool) -> Isometry3<f64> {
    let turn = match tilt {
        None => return pose,
        // Negative about the base's left axis: the fingers point away from the base.
        Some(Lean::Reach(a)) => {
            let r = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), -a);
            let r = if undo { r.inverse() } else { r };
            return Isometry3::from_parts(pose.translation, r * pose.rotation);
        }
        Some(Lean::Closing(a)) => {
            // Turned by θ about tool y, the approach axis (tool x) moves along −tool z: the sign
            // that points it away from the base (base +x), or, closing along the base's forward
            // axis, to the base's right (the side the arms are mounted on). The lean keeps the
            // sign of tool z's components, so a leaned pose finds the same sign.
            let z = pose.rotation * Vector3::z();
            let s = if z.x.abs() > 1e-3 {
                -z.x.signum()
            } else {
                z.y.signum()
            };
            UnitQuaternion::from_axis_angle(&Vector3::y_axis(), s * a)
        }
    };
    let rotation = if undo {
        pose.rotation * turn.inverse()
    } else {
        pose.rotation * turn
    };
    Isometry3::from_parts(pose.translation, rotation)
}

/// An object centre (or place target) this close over the surface it stands on is flat work
/// (a fork 6 mm, a plate 10 mm; an apple, a bowl or a cup stands 3–5 cm over it).
const FLAT: f64 = 0.015;

/// A flat object this wide in every direction from its centre is plate-like, m ([`plate_like`]).
const WIDE: f64 = 0.05;

/// Whether an object is flat and reaches [`WIDE`] beyond its centre in every horizontal
/// direction (a plate, not a fork): tilted by a leaning hand, its edge hangs far below its
/// centre (a plate's 8 cm at 45°), so it is put down only level (`OraclePolicy::start_task`).
pub(super) fn plate_like(shape: &Shape) -> bool {
    let narrowest = match shape {
        Shape::Sphere { radius } | Shape::Cylinder { radius, .. } | Shape::Bowl { radius, .. } => *radius,
        Shape::Cuboid { size } | Shape::Mesh { size, .. } => size[0].min(size[1]) / 2.0,
    };
    shape.half_height() <= FLAT && narrowest >= WIDE
}

/// The headroom of a hand working at world `w` under a board, given the arm's `room` for it
/// ([`headroom`]). Turned about the base's left axis, a leaning hand pinches a fork lying
/// across the reach (closed along the base's forward axis) with one finger over the other; the
/// lower one strikes the board the fork lies on and the hand closes too high (dev: every fork
/// pick on the 0.85 m level failed with every arm). So flat work leans about the closing axis
/// instead, both fingers level (on the 18 dev instructions with such a pick: Panda 114 of 125
/// tasks against 86, Kinova3 115 against 102; straight down, the Panda's hand did not reach
/// the fork, 86). Other work, and a hand that does not lean, keep `room`.
pub(super) fn for_work(room: Headroom, scene: &Scene, w: [f64; 3]) -> Headroom {
    let Some(Lean::Reach(a)) = room.tilt else {
        return room;
    };
    let flat = surface_below(scene, [w[0], w[1]], w[2]).is_some_and(|s| w[2] - s <= FLAT);
    if !flat {
        return room;
    }
    Headroom {
        clear: room.clear,
        tilt: Some(Lean::Closing(a)),
    }
}

/// How far a hand leaning sideways under a board sinks before it pulls back, m: at the cap
/// under the board, pulling a fork out pressed the xArm7's links into the board and froze the
/// arm (dev-0030, 0052 and 0150: the move after the pick never started; 2, 4 and 6 cm all freed
/// it on dev-0052).
const SINK: f64 = 0.04;
/// The least a sinking tool keeps over the surface below it, m: the Kinova3's hand, 7 cm over
/// the shelf after a fork pick (its room under the board is 4.4 cm, its lift 6), sunk 4 cm
/// and stuck instead (the moves after 20 fork picks, dev).
const SINK_ABOVE: f64 = 0.08;

/// How far a hand at world `tool` sinks before it pulls back out from under a board (see
/// `arm::ArmPath::prelude`): [`SINK`], but no lower than [`SINK_ABOVE`] over the surface
/// below it.
pub(super) fn sink_before_pullback(scene: &Scene, tool: [f64; 3]) -> f64 {
    surface_below(scene, [tool[0], tool[1]], tool[2])
        .map_or(0.0, |s| (tool[2] - s - SINK_ABOVE).clamp(0.0, SINK))
}

/// The highest surface at or below `z` over world `xy`, if any.
fn surface_below(scene: &Scene, xy: [f64; 2], z: f64) -> Option<f64> {
    scene
        .furniture
        .iter()
        .filter(|f| f.covers(xy, 0.0))
        .flat_map(|f| f.surfaces())
        .filter(|s| *s <= z + 1e-3)
        .max_by(f64::total_cmp)
}

/// The lean of a high wrist's tool under a board, rad. Straight down, a Kinova Gen3's wrist
/// (0.33 m over its tool) caps the tool below the 0.85 m shelf level itself, and the Panda's,
/// UR5e's and xArm7's wrists strike the board above a cup; leaning the fingers 45° away from the
/// base stands the wrist back towards the board's front edge and lower (dev, the 14 first
/// instructions with shelf work: Kinova3 88/95 tasks against 61, Panda 89/95 against 71).
const TILT: f64 = std::f64::consts::FRAC_PI_4;
/// The least clearance a leaning hand keeps under a board, m: the shipped arm's plus 0.02 m, the
/// least measured (the Panda leaning at 0.25 m: 89/95 tasks of those 14 instructions; leaning
/// at the shipped 0.23 m was not tried).
const TILTED_CLEAR: f64 = WRIST_CLEAR + 0.02;

/// The headroom a hand of `robot` needs under a board: [`WRIST_CLEAR`] straight down for an
/// arm whose wrist stands no higher than the shipped one's (the shipped arm keeps the constant
/// exactly); a higher wrist (a mounted UR5e's or Kinova's, measured on its kinematics by
/// `kitchen_r_sim::robot::wrist`) leans its tool by [`TILT`] and keeps its wrist's height over
/// the tool (to the centimetre, so the cap does not move with the IK's last digits), at least
/// [`TILTED_CLEAR`]: leaning, the wrist stands back from the column the margin guarded.
/// With `lean` false the tool stays straight down and a higher wrist keeps its height plus
/// [`WRIST_MARGIN`] (the physical grasp's rule: its pinches are planned top-down).
/// `wrist_height`: the arm's, over a top-down tool (`kitchen_r_sim::robot::wrist::wrist_height`).
pub(super) fn headroom(wrist_height: Option<f64>, lean: bool) -> Headroom {
    let straight = Headroom {
        clear: WRIST_CLEAR,
        tilt: None,
    };
    let Some(h) = wrist_height else {
        return straight;
    };
    match (h + WRIST_MARGIN > WRIST_CLEAR + 1e-3, lean) {
        (false, _) => straight,
        (true, false) => Headroom {
            clear: h + WRIST_MARGIN,
            tilt: None,
        },
        (true, true) => Headroom {
            clear: ((h * 100.0).round() / 100.0).max(TILTED_CLEAR),
            tilt: Some(Lean::Reach(TILT)),
        },
    }
}

/// Slack around furniture footprints, m.
const MARGIN: f64 = 0.1;

/// How far past a board's edge a straightening hand's tool is before it turns upright, m: its
/// wrist (a UR5e's link radius, 4.5 cm) stands over the tool once upright.
const TURN_CLEAR: f64 = 0.05;

/// The fraction of the way from world `from` (a tool under a board, at height `z`) to `to`
/// after which the tool is [`TURN_CLEAR`] out from under every board above it: where a leaning
/// hand pulling back may straighten, or going in may lean ([`lean_outside`]). 0 with no board
/// above, 1 if the way never leaves it.
pub(super) fn out_from_under(scene: &Scene, from: [f64; 2], to: [f64; 2], z: f64) -> f64 {
    let over: Vec<_> = (scene.furniture.iter())
        .filter(|f| f.covers(from, 0.0) && f.surfaces().iter().any(|s| *s - BOARD > z))
        .collect();
    if over.is_empty() {
        return 0.0;
    }
    const STEPS: usize = 100;
    (0..=STEPS)
        .map(|i| i as f64 / STEPS as f64)
        .find(|t| {
            let p = [from[0] + t * (to[0] - from[0]), from[1] + t * (to[1] - from[1])];
            over.iter().all(|f| !f.covers(p, TURN_CLEAR))
        })
        .unwrap_or(1.0)
}

/// How a leaning hand turns only outside the boards ([`super::arm::Prelude`]'s `keep_lean` and
/// `lean_at`), for a task that starts with the tool at `tool` and stows it at `stow` (base
/// frame; the base at `base`, world): pulling back from under a board (`here_max` set), a
/// leaning tool keeps its lean until it is out; going in under one to work at world `work`
/// (`target_max` set), the hand turns to `turn_in` (a lean, or a held plate levelled) at the
/// board's edge on the line from the stow position to the work. The shipped arm never leans:
/// for it, nothing.
pub(super) fn lean_outside(
    scene: &Scene,
    base: &Isometry3<f64>,
    tool: &Isometry3<f64>,
    stow: &Isometry3<f64>,
    (here_max, target_max): (Option<f64>, Option<f64>),
    work: Option<[f64; 3]>,
    turn_in: Option<UnitQuaternion<f64>>,
) -> (f64, Option<LeanAt>) {
    let t = (base * tool).translation;
    let s = (base * stow).translation;
    let leaning = (tool.rotation * Vector3::x()).xy().norm() > LEANING;
    let keep_lean = match (leaning, here_max) {
        (true, Some(_)) => out_from_under(scene, [t.x, t.y], [s.x, s.y], t.z),
        _ => 0.0,
    };
    let lean_at = match (turn_in, work, target_max) {
        (Some(r), Some(w), Some(_)) => {
            let f = out_from_under(scene, [w[0], w[1]], [s.x, s.y], w[2]);
            let at = Point3::new(w[0] + f * (s.x - w[0]), w[1] + f * (s.y - w[1]), s.z);
            Some(((base.inverse() * at).coords, r))
        }
        _ => None,
    };
    (keep_lean, lean_at)
}

/// A tool whose approach axis has this large a horizontal component leans (about 11°; the
/// oracle's leans are 45°, a top-down hand has none).
const LEANING: f64 = 0.2;

/// The highest the tool centre point may be over world `xy` when working at height `z`: `clear`
/// under the lowest board above `z`, or `None` with nothing overhead.
pub(super) fn max_tool_z(scene: &Scene, xy: [f64; 2], z: f64, clear: f64) -> Option<f64> {
    scene
        .furniture
        .iter()
        .filter(|f| f.covers(xy, MARGIN))
        .flat_map(|f| f.surfaces())
        .map(|s| s - BOARD)
        .filter(|under| *under > z + 1e-3)
        .min_by(f64::total_cmp)
        .map(|under| under - clear)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_hand_sinks_before_pulling_back_only_as_far_as_keeps_it_over_the_shelf() {
        let s = kitchen_b();
        // Over the purple zone's 0.85 m shelf level (the wall shelf at x 0.2, y 1.7).
        assert!((sink_before_pullback(&s, [0.2, 1.7, 0.976]) - SINK).abs() < 1e-12);
        assert!((sink_before_pullback(&s, [0.2, 1.7, 0.95]) - 0.02).abs() < 1e-9);
        assert_eq!(sink_before_pullback(&s, [0.2, 1.7, 0.92]), 0.0);
    }

    #[test]
    fn a_tool_is_out_from_under_a_board_a_margin_past_its_edge() {
        let s = kitchen_b();
        // From the purple zone's 0.85 m shelf level (the wall shelf at x 0.2) out into the room.
        let (from, to) = ([0.2, 1.7], [1.0, 1.7]);
        let f = out_from_under(&s, from, to, 0.9);
        let at = |t: f64| [from[0] + t * (to[0] - from[0]), 1.7];
        let shelf = s.furniture.iter().find(|f| f.covers(from, 0.0)).unwrap();
        assert!(!shelf.covers(at(f), TURN_CLEAR), "{f}");
        assert!(shelf.covers(at(f - 0.01), TURN_CLEAR), "{f}");
        // On the shelf's top (1.6 m) nothing is overhead; in the room there is no furniture.
        assert_eq!(out_from_under(&s, from, to, 1.61), 0.0);
        assert_eq!(out_from_under(&s, [1.0, 1.7], to, 0.9), 0.0);
    }

    #[test]
    fn of_the_catalogue_only_the_plate_is_plate_like() {
        let assets = kitchen_r_core::assets::assets_dir();
        let catalogue = kitchen_r_core::catalogue::Catalogue::load(&assets.join("objects.toml")).unwrap();
        for id in ["apple", "bowl", "cup", "fork", "plate"] {
            let shape = &catalogue.model(id).unwrap().shape;
            assert_eq!(plate_like(shape), id == "plate", "{id}");
        }
    }

    /// The committed kitchen_b, whose west-wall shelf holds the purple zone's 0.85 m board.
    fn kitchen_b() -> Scene {
        let assets = kitchen_r_core::assets::assets_dir();
        let catalogue = kitchen_r_core::catalogue::Catalogue::load(&assets.join("objects.toml")).unwrap();
        Scene::load_all(&assets.join("scenes"), &catalogue)
            .unwrap()
            .into_iter()
            .find(|s| s.id == "kitchen_b")
            .unwrap()
    }

    #[test]
    fn the_shipped_arm_keeps_its_clearance_and_a_higher_wrist_leans() {
        let mut robot = kitchen_r_sim::robot::desc::RobotDesc::load_default().unwrap();
        let wrist =
            |robot: &kitchen_r_sim::robot::desc::RobotDesc| kitchen_r_sim::robot::wrist::wrist_height(robot);
        for lean in [false, true] {
            let shipped = headroom(wrist(&robot), lean);
            assert_eq!(shipped.clear.to_bits(), WRIST_CLEAR.to_bits());
            assert_eq!(shipped.tilt, None);
        }
        // The wrist-rotate link 15 cm longer: the wrist stands 0.32 m over a top-down tool.
        robot.arm.joints[5].origin[0] += 0.15;
        let h = headroom(wrist(&robot), true);
        assert!((h.clear - 0.32).abs() < 1e-3, "{h:?}");
        assert_eq!(h.tilt, Some(Lean::Reach(TILT)));
        let h = headroom(wrist(&robot), false);
        assert!((h.clear - (0.32 + WRIST_MARGIN)).abs() < 1e-3, "{h:?}");
        assert_eq!(h.tilt, None);
    }

    #[test]
    fn flat_work_under_a_board_leans_about_the_closing_axis() {
        let b = &kitchen_b();
        let leaning = headroom(Some(0.33), true);
        // A fork on the purple zone's 0.85 m board, a cup standing on it.
        let fork = for_work(leaning, b, [0.2, 1.7, 0.856]);
        assert_eq!(fork.tilt, Some(Lean::Closing(TILT)));
        assert_eq!(fork.clear, leaning.clear);
        assert_eq!(for_work(leaning, b, [0.2, 1.7, 0.90]), leaning);
        // The shipped arm keeps its straight-down hand.
        let shipped = headroom(None, true);
        assert_eq!(for_work(shipped, b, [0.2, 1.7, 0.856]), shipped);
    }

    #[test]
    fn a_shelf_level_has_a_ceiling_and_a_counter_top_has_none() {
        let b = &kitchen_b();
        // The purple zone: the 0.85 m board of the west-wall shelf, the next board at 1.25 m.
        let m = max_tool_z(b, [0.2, 1.7], 0.9, WRIST_CLEAR).unwrap();
        assert!((m - (1.23 - WRIST_CLEAR)).abs() < 1e-9, "{m}");
        let counter = b
            .zones
            .iter()
            .find(|z| {
                b.furniture
                    .iter()
                    .any(|f| f.id == z.furniture && f.levels.is_empty())
            })
            .unwrap();
        assert_eq!(
            max_tool_z(b, counter.center, counter.height + 0.05, WRIST_CLEAR),
            None
        );
    }
}
