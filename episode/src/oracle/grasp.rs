//! Where the oracle grasps in the physical grasp mode (docs/twin/robot.md), where only the two
//! finger contacts hold an object: a two-point pinch resists gravity and the hand's accelerations
//! without turning the object only when the line through the contacts passes through the object's
//! centre of mass, so objects are taken at their centre (the catalogue's uniform solids have it at
//! the bounding-box centre), raised only as far as keeps the fingertips at the surface the object
//! stands on. Rim grasps (a bowl, a cylinder with a horizontal `grasp_offset`: the plate) and
//! meshes keep the catalogue's point. The abstract mode, scored by positions, keeps the catalogue's
//! `grasp_offset`.

use kitchen_r_core::catalogue::{ObjectModel, Shape};

/// Fingertips this far above the surface at the grasp, m: a hand that pressed them into the
/// counter would hold the object by the tips' edges only.
const TIP_CLEARANCE: f64 = -0.01;

/// `model` with the physical mode's grasp point; `finger_reach`: how far the fingertips reach
/// below the TCP, m.
pub(super) fn physical_grasp(mut model: ObjectModel, finger_reach: f64) -> ObjectModel {
    let [x, y, _] = model.grasp_offset;
    let rim = x.hypot(y) > 1e-6;
    match model.shape {
        Shape::Sphere { .. } | Shape::Cuboid { .. } => {}
        Shape::Cylinder { .. } if !rim => {}
        _ => return model,
    }
    let above_centre = finger_reach + TIP_CLEARANCE - model.shape.half_height();
    model.grasp_offset = [0.0, 0.0, above_centre.max(0.0)];
    model
}
