//! Where the oracle grasps in the physical grasp mode (docs/twin/robot.md), where only the two
//! finger contacts hold an object: a two-point pinch resists gravity and the hand's accelerations
//! without turning the object only when the line through the contacts passes through the object's
//! centre of mass, so objects are taken at their centre (the catalogue's uniform solids have it at
//! the bounding-box centre), raised only as far as keeps the fingertips at the surface the object
//! stands on. A bowl is pinched at its wall, which the pads straddle as deep as its floor allows;
//! so is this mode's plate, a dish (the catalogue's `[object.physical]` variant). Meshes keep the
//! catalogue's point. The abstract mode, scored by positions, keeps the catalogue's
//! `grasp_offset`.

use kitchen_r_core::catalogue::{ObjectModel, Shape};

/// Fingertips this far above the surface at the grasp, m: a hand that pressed them into the
/// counter would hold the object by the tips' edges only.
const TIP_CLEARANCE: f64 = -0.01;

/// Fingertips this far above a bowl's inside floor at the grasp, m.
const BOWL_FLOOR_CLEARANCE: f64 = 0.005;

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
            model.grasp_offset = [x * r, y * r, floor + BOWL_FLOOR_CLEARANCE + finger_reach];
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
        let g = physical_grasp(plate, reach).grasp_offset;
        assert!(
            (g[0].hypot(g[1]) - (radius - thickness / 2.0)).abs() < 1e-12,
            "{g:?}"
        );
    }
}
