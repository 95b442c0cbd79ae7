//! Where the oracle grasps in the physical grasp mode (docs/twin/robot.md), where only the two
//! finger contacts hold an object: a two-point pinch resists gravity and the hand's accelerations
//! without turning the object only when the line through the contacts passes through the object's
//! centre of mass, so objects are taken at their centre (the catalogue's uniform solids have it at
//! the bounding-box centre), raised only as far as keeps the fingertips at the surface the object
//! stands on. A bowl is pinched at its wall, which the pads straddle as deep as its floor allows;
//! so is this mode's plate, a dish (the catalogue's `[object.physical]` variant). Meshes keep the
//! catalogue's point. The abstract mode, scored by positions, keeps the catalogue's
//! `grasp_offset`.

use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, FRAC_PI_8};

use kitchen_r_core::catalogue::{ObjectModel, Shape};
use kitchen_r_sim::oracle::manip::{closing_axis, tool_yaw};

/// Fingertips this far above the surface at the grasp, m: at it. Until 2026-11-30 they were
/// aimed 1 cm into it, where the arm's joint motors stopped them; the hand now follows its
/// targets, and fingertips pressed into the counter pushed a fork 4 cm along its length as they
/// closed, so it hung off-centre and swung into the arm (test split: 10 of 42 fork places
/// failed, none with the tips at the surface).
const TIP_CLEARANCE: f64 = 0.0;

/// Fingertips this far above a dish's inside floor at the grasp, m: as deep as the hand's
/// tracking allows, for the longest contact down the wall (the plate's 2 cm rim: with 5 mm the
/// pads covered 1.1 cm of it, a couple no larger than the plate's own turning moment, and half
/// the plates worked loose on the way; docs/twin/robot.md).
const DISH_FLOOR_CLEARANCE: f64 = 0.001;

/// Fingertips this far above a deeper bowl's inside floor, m: its 6 cm wall gives the pads
/// contact enough, and 1 mm let the inner fingertip catch in the floor's facets when the bowl
/// shifted in the hand; the bowl then hung on the finger, was lifted again as the hand rose
/// from the place and carried into the next pick (dev-0086).
const BOWL_FLOOR_CLEARANCE: f64 = 0.005;

/// Bowls no taller than this are dishes (the physical mode's plate), m.
const DISH_HEIGHT: f64 = 0.03;

/// Room the fingers give a placed object on each side as they open, m: opened fully, the outer
/// finger of a pinch at a bowl's wall swept 4–5 cm out and knocked a neighbouring apple off the
/// counter (dev-0132).
const RELEASE_ROOM: f64 = 0.015;

/// `model` with the physical mode's grasp point; `finger_reach`: how far the fingertips reach
/// below the TCP, m.
pub(super) fn physical_grasp(mut model: ObjectModel, finger_reach: f64) -> ObjectModel {
    let [x, y, _] = model.grasp_offset;
    let rim = x.hypot(y) > 1e-6;
    match model.shape {
        Shape::Bowl {
            radius,
            height,
            thickness,
        } if rim => {
            // The pads centred on the wall and as deep as the inside allows: the longer the
            // pads' contact down the wall, the larger the couple that holds the bowl level.
            let r = (radius - thickness / 2.0) / x.hypot(y);
            let floor = -height / 2.0 + thickness;
            let clearance = if height > DISH_HEIGHT {
                BOWL_FLOOR_CLEARANCE
            } else {
                DISH_FLOOR_CLEARANCE
            };
            model.grasp_offset = [x * r, y * r, floor + clearance + finger_reach];
            return model;
        }
        Shape::Sphere { .. } | Shape::Cuboid { .. } => {}
        Shape::Cylinder { .. } if !rim => {}
        _ => return model,
    }
    let above_centre = finger_reach + TIP_CLEARANCE - model.shape.half_height();
    model.grasp_offset = [0.0, 0.0, above_centre.max(0.0)];
    model
}

/// A round object's top may stand this far into the room behind the TCP that the hand's own
/// geometry leaves ([`under_palm`]) before the grasp point rises, m: the shipped hand's wrist
/// capsule ends just over an apple grasped at its centre, and picks all of them.
const PALM_SLACK: f64 = 0.002;

/// `model` (its physical grasp point) raised so that a sphere's top stays out of the hand:
/// `palm_reach`, how far the hand's geometry stands behind the TCP
/// (`kitchen_r_sim::robot::palm::palm_reach`). robosuite's Panda hand reaches 3.1 cm behind
/// its grip site: an apple grasped at its centre was pressed into the counter by the palm, the
/// fingers stopped short of it and 25 of the dev split's 62 apple picks failed.
pub(super) fn under_palm(mut model: ObjectModel, palm_reach: f64) -> ObjectModel {
    if let Shape::Sphere { radius } = model.shape {
        let press = radius - model.grasp_offset[2] - palm_reach;
        if press > PALM_SLACK {
            model.grasp_offset[2] += press;
        }
    }
    model
}

/// Turns of a held object about its vertical axis a place may make, rad, in the order tried.
const PLACE_TURNS: [f64; 5] = [0.0, FRAC_PI_4, -FRAC_PI_4, FRAC_PI_2, -FRAC_PI_2];

/// Room the hand (its 11 cm palm and the fingers opening round a pinch) keeps from the footprint
/// of another object when it puts a bowl down, m, measured from the tool centre.
const HAND_ROOM: f64 = 0.075;

/// How far to turn a held bowl (or the physical mode's dish plate) about its vertical axis before
/// it is put down at `target` (world), rad: 0 unless the hand, pinching the wall at the grasp
/// point, would come within [`HAND_ROOM`] of a neighbour (`(centre, footprint radius)`, world);
/// then the turn of [`PLACE_TURNS`] that leaves the most room, the first of equals. A turn must
/// keep the top-down tool within its quarter turn of straight ahead (the pick-and-place
/// machine's rule; past it the fingers swap and the hand stays where it was). `yaw_in_base`:
/// the held object's yaw relative to the base, whose yaw (world) is `base_yaw`. A bowl put down
/// beside an apple with the hand on the apple's side knocked the apple off the counter
/// (dev-0031, 0086, 0132: the next task's pick failed).
pub(super) fn place_turn(
    model: &ObjectModel,
    yaw_in_base: f64,
    base_yaw: f64,
    target: [f64; 3],
    neighbours: &[([f64; 2], f64)],
) -> f64 {
    let (Shape::Bowl { .. }, Some(axis)) = (&model.shape, closing_axis(model)) else {
        return 0.0;
    };
    if neighbours.is_empty() {
        return 0.0;
    }
    let [gx, gy, _] = model.grasp_offset;
    // The tool's yaw in the base frame as the machine takes it: closing along the rim point's
    // radius.
    let tool = tool_yaw(axis + yaw_in_base);
    let room = |turn: f64| {
        let (s, c) = (base_yaw + yaw_in_base + turn).sin_cos();
        let hand = [target[0] + c * gx - s * gy, target[1] + s * gx + c * gy];
        neighbours
            .iter()
            .map(|(n, r)| (hand[0] - n[0]).hypot(hand[1] - n[1]) - r)
            .fold(f64::INFINITY, f64::min)
    };
    if room(0.0) >= HAND_ROOM {
        return 0.0;
    }
    let mut best = (0.0, room(0.0));
    for turn in PLACE_TURNS {
        let r = room(turn);
        // Clear of the quarter turn's ends, where round-off could swap the fingers.
        if (tool + turn).abs() < FRAC_PI_2 - 0.05 && r > best.1 + 1e-9 {
            best = (turn, r);
        }
    }
    best.0
}

/// Tool yaws (base frame, rad) a pick or place of an object with no closing direction of its own
/// may take, in the order tried: straight ahead first, then turns either way up to an eighth of
/// a turn. Turned further (3/8 and a quarter), the wrist's tracking tilted the pads and a cup's
/// squeeze was not built before the lift: cups dropped on the arm's swing to its carry pose (5
/// of 10 places in the episodes that needed a turn, none with this range).
const FREE_YAWS: [f64; 5] = [0.0, FRAC_PI_8, -FRAC_PI_8, FRAC_PI_4, -FRAC_PI_4];

/// Room a finger keeps from another object's footprint when it comes down beside or opens round
/// an object, m: less, and the tool's yaw is turned.
const FINGER_ROOM: f64 = 0.02;

/// A finger's footprint seen from above, m: half its thickness along the closing axis and half
/// its width across it (the shipped gripper's 1.2 × 2.5 cm pads, rounded up for other arms').
const FINGER_HALF: [f64; 2] = [0.008, 0.015];

/// The tool yaw (base frame, rad) over an object with no closing direction of its own (a sphere,
/// an upright cylinder pinched at its centre; see [`closing_axis`]) standing or put down at
/// `centre` (world), with the fingers `gap` apart: 0 (closing along the base's sideways axis)
/// unless a finger would come within [`FINGER_ROOM`] of a neighbour (`(centre, footprint
/// radius)`, world); then the yaw of [`FREE_YAWS`] that leaves the most room, the first of
/// equals. `base_yaw`: the base's yaw (world). An apple picked beside a bowl just put down had a
/// finger land on the bowl's wall, 6 mm away, and was lifted pinched against it (dev-0086).
pub(super) fn free_yaw(
    model: &ObjectModel,
    base_yaw: f64,
    centre: [f64; 2],
    gap: f64,
    neighbours: &[([f64; 2], f64)],
) -> f64 {
    if closing_axis(model).is_some() || neighbours.is_empty() {
        return 0.0;
    }

    let reach = gap / 2.0 + FINGER_HALF[0];
    let room = |yaw: f64| {
        // The closing axis is the tool's y: a quarter turn from its yaw.
        let (s, c) = (base_yaw + yaw + FRAC_PI_2).sin_cos();
        let mut least = f64::INFINITY;
        for side in [-1.0, 1.0] {
            let finger = [centre[0] + side * reach * c, centre[1] + side * reach * s];
            for (n, r) in neighbours {
                let d = [n[0] - finger[0], n[1] - finger[1]];
                let along = (d[0] * c + d[1] * s).abs() - FINGER_HALF[0];
                let across = (-d[0] * s + d[1] * c).abs() - FINGER_HALF[1];
                least = least.min(along.max(0.0).hypot(across.max(0.0)) - r);
            }
        }
        least
    };
    let mut best = (0.0, room(0.0));
    if best.1 >= FINGER_ROOM {
        return 0.0;
    }
    for yaw in FREE_YAWS {
        let r = room(yaw);
        if r > best.1 + 1e-9 {
            best = (yaw, r);
        }
    }
    best.0
}

/// The width the fingers close on in the physical grasp (`model` as [`physical_grasp`] left it):
/// a bowl's wall at its rim point, across a sphere, an upright cylinder or a box's narrower
/// side; `None` for shapes it does not know (meshes).
fn pinch_width(model: &ObjectModel) -> Option<f64> {
    match (&model.shape, closing_axis(model)) {
        (Shape::Bowl { thickness, .. }, Some(_)) => Some(*thickness),
        (Shape::Sphere { radius }, _) | (Shape::Cylinder { radius, .. }, None) => Some(2.0 * radius),
        (Shape::Cuboid { size }, _) => Some(size[0].min(size[1])),
        _ => None,
    }
}

/// The gripper command (0 closed, 1 open) a place opens to in the physical grasp: the pinched
/// width and [`RELEASE_ROOM`] on each side, at most fully open.
pub(super) fn release_gripper(model: &ObjectModel, max_opening: f64) -> f64 {
    pinch_width(model).map_or(1.0, |w| opening_round(w, max_opening))
}

/// The gripper command (0 closed, 1 open) that opens the fingers to `width` m and
/// [`RELEASE_ROOM`] on each side, at most fully open.
fn opening_round(width: f64, max_opening: f64) -> f64 {
    ((width + 2.0 * RELEASE_ROOM) / max_opening).min(1.0)
}

/// Seconds the fingers are given past their opening time before the hand moves.
const OPEN_SETTLE_S: f64 = 0.3;

/// How an empty hand whose fingers are still closed round what a place put down opens before it
/// moves: `(seconds to stay, gripper command)`, opening from `gap` (a fraction of the widest,
/// `max_opening` m) no wider than a release would, at `opening_speed` m/s.
pub(super) fn open_in_place(gap: f64, max_opening: f64, opening_speed: f64) -> (f64, f64) {
    let to = opening_round(gap * max_opening, max_opening);
    let opening = (to - gap) * max_opening / opening_speed.max(1e-3);
    (opening + OPEN_SETTLE_S, to)
}

#[cfg(test)]
mod tests {
    use kitchen_r_core::catalogue::Catalogue;

    use super::*;

    #[test]
    fn a_bowl_is_pinched_mid_wall_with_the_fingertips_just_above_its_floor() {
        let cat = Catalogue::load(&kitchen_r_core::assets::assets_dir().join("objects.toml")).unwrap();
        let bowl = cat.model("bowl").unwrap().clone();
        let Shape::Bowl {
            radius,
            height,
            thickness,
        } = bowl.shape
        else {
            panic!("the catalogue's bowl is a bowl")
        };
        let reach = 0.025;
        let g = physical_grasp(bowl.clone(), reach).grasp_offset;
        // Radially at the wall's middle, in the catalogue's direction.
        assert!(
            (g[0].hypot(g[1]) - (radius - thickness / 2.0)).abs() < 1e-12,
            "{g:?}"
        );
        assert!(g[1].atan2(g[0]).abs() < 1e-12);
        // The fingertips (reach below the tool centre) just above the inside floor.
        let tips = g[2] - reach;
        let floor = -height / 2.0 + thickness;
        assert!(
            (tips - floor - BOWL_FLOOR_CLEARANCE).abs() < 1e-12,
            "tips at {tips}"
        );
        // The physical mode's plate, a dish, is pinched at its rim wall the same way.
        let plate = cat
            .model("plate")
            .unwrap()
            .in_mode(kitchen_r_core::GraspMode::Physical);
        let Shape::Bowl {
            radius, thickness, ..
        } = plate.shape
        else {
            panic!("the physical mode's plate is a dish")
        };
        let Shape::Bowl { height, .. } = plate.shape else {
            unreachable!()
        };
        let g = physical_grasp(plate, reach).grasp_offset;
        assert!(
            (g[0].hypot(g[1]) - (radius - thickness / 2.0)).abs() < 1e-12,
            "{g:?}"
        );
        // Its 2 cm rim is pinched deeper than the bowl's 6 cm wall.
        let tips = g[2] - reach;
        assert!(
            (tips - (-height / 2.0 + thickness) - DISH_FLOOR_CLEARANCE).abs() < 1e-12,
            "tips at {tips}"
        );
    }

    /// An apple's top stays out of a hand that reaches close behind the TCP (the Panda's, 3.1
    /// cm), and the grasp point is left as it is for a hand that leaves it room (the shipped
    /// one, 4 cm) and for a cup, whose flat top the palm rests on.
    #[test]
    fn a_round_objects_grasp_rises_out_of_a_low_palm() {
        let cat = Catalogue::load(&kitchen_r_core::assets::assets_dir().join("objects.toml")).unwrap();
        let apple = physical_grasp(cat.model("apple").unwrap().clone(), 0.025);
        assert_eq!(apple.grasp_offset[2], 0.0);
        let raised = under_palm(apple.clone(), 0.0313);
        assert!(
            (raised.grasp_offset[2] - (0.04 - 0.0313)).abs() < 1e-12,
            "{:?}",
            raised.grasp_offset
        );
        assert_eq!(under_palm(apple.clone(), 0.040).grasp_offset, apple.grasp_offset);
        let cup = physical_grasp(cat.model("cup").unwrap().clone(), 0.025);
        assert_eq!(under_palm(cup.clone(), 0.0313).grasp_offset, cup.grasp_offset);
    }

    #[test]
    fn the_fingers_come_down_beside_a_round_object_away_from_its_neighbour() {
        let cat = Catalogue::load(&kitchen_r_core::assets::assets_dir().join("objects.toml")).unwrap();
        let apple = physical_grasp(cat.model("apple").unwrap().clone(), 0.025);
        let (gap, centre) = (0.09, [1.0, 1.0]);
        // Base facing +x: the fingers close along world y, 5.3 cm each side of the centre. A
        // bowl 6 mm beside the apple along y is where a finger would land: the tool turns as
        // far as it may, an eighth of a turn, the first of the two equal ways.
        let bowl = ([1.0, 1.0 + 0.04 + 0.006 + 0.08], 0.08);
        assert_eq!(free_yaw(&apple, 0.0, centre, gap, &[bowl]), FRAC_PI_4);
        // The same bowl along x is out of the fingers' way: no turn.
        let ahead = ([1.0 + 0.04 + 0.006 + 0.08, 1.0], 0.08);
        assert_eq!(free_yaw(&apple, 0.0, centre, gap, &[ahead]), 0.0);
        // With the base turned a quarter the same bowl along y is now ahead of it.
        assert_eq!(free_yaw(&apple, FRAC_PI_2, centre, gap, &[bowl]), 0.0);
        // Neighbours ahead and to the left: the turn away from both.
        assert_eq!(free_yaw(&apple, 0.0, centre, gap, &[bowl, ahead]), FRAC_PI_4);
        // Objects with a closing direction of their own keep it.
        let bowl_model = physical_grasp(cat.model("bowl").unwrap().clone(), 0.025);
        assert_eq!(free_yaw(&bowl_model, 0.0, centre, gap, &[bowl]), 0.0);
    }

    #[test]
    fn a_bowl_is_put_down_with_the_hand_away_from_a_neighbour() {
        let cat = Catalogue::load(&kitchen_r_core::assets::assets_dir().join("objects.toml")).unwrap();
        let bowl = physical_grasp(cat.model("bowl").unwrap().clone(), 0.025);
        let target = [1.0, 1.0, 0.8];
        // Base facing +x, the bowl's grasp point along +x (the tool straight ahead): an apple
        // 15 cm along +x is in the hand's way, so the bowl turns a quarter and the hand works
        // from the side, 16 cm from the apple's centre.
        let apple = ([1.15, 1.0], 0.04);
        let turn = place_turn(&bowl, 0.0, 0.0, target, &[apple]);
        assert_eq!(turn.abs(), FRAC_PI_2);
        // The grasp point at 45° (the tool at −45°) with a neighbour beyond it: the tool has
        // no room to turn further clockwise, so the bowl turns the other way.
        let turned = place_turn(&bowl, FRAC_PI_4, 0.0, target, &[([1.106, 1.106], 0.04)]);
        assert!(turned > 0.0, "{turned}");
        // Nothing within the hand's room: no turn, so other places run as before.
        assert_eq!(place_turn(&bowl, 0.0, 0.0, target, &[([1.5, 1.0], 0.04)]), 0.0);
        assert_eq!(place_turn(&bowl, 0.0, 0.0, target, &[]), 0.0);
        // Objects pinched at their centre have nothing to turn.
        let apple_model = physical_grasp(cat.model("apple").unwrap().clone(), 0.025);
        assert_eq!(place_turn(&apple_model, 0.0, 0.0, target, &[apple]), 0.0);
    }

    #[test]
    fn a_place_opens_the_fingers_only_a_little_wider_than_what_they_pinched() {
        let cat = Catalogue::load(&kitchen_r_core::assets::assets_dir().join("objects.toml")).unwrap();
        let physical = |id: &str| {
            let m = cat
                .model(id)
                .unwrap()
                .in_mode(kitchen_r_core::GraspMode::Physical);
            physical_grasp(m, 0.025)
        };
        let max = 0.2;
        // The dish plate, pinched at its 4 mm rim: 1.5 cm of room each side.
        let g = release_gripper(&physical("plate"), max);
        assert!((g * max - (0.004 + 0.03)).abs() < 1e-12, "{g}");
        // The apple, pinched across its 8 cm.
        let g = release_gripper(&physical("apple"), max);
        assert!((g * max - (0.08 + 0.03)).abs() < 1e-12, "{g}");
        // Never wider than fully open, and fully open for a shape of unknown width.
        assert_eq!(release_gripper(&physical("apple"), 0.05), 1.0);
        let mut mesh = physical("apple");
        mesh.shape = Shape::Mesh {
            file: "none.obj".into(),
            scale: 1.0,
            size: [0.08; 3],
        };
        assert_eq!(release_gripper(&mesh, max), 1.0);
    }
}
