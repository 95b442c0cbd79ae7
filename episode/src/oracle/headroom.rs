//! Headroom under shelf boards. The twin's shelves have a board every level (0.4 m apart in the
//! committed scenes), and a top-down hand carries its wrist 0.17 m above the tool centre point:
//! the stow height and the machine's default approach heights would drive the wrist into the
//! board above the level being served, and a link pressed into fixed geometry freezes the arm.
//! So the oracle caps tool heights over a shelf and reaches in or out horizontally.

use kitchen_r_core::scene::Scene;

/// Thickness of the twin's shelf boards (`sim/src/furniture.rs`): a surface at height `s` is a
/// board whose underside is at `s − BOARD`.
const BOARD: f64 = 0.02;
/// Tool centre point to the top of the wrist link with the tool pointing down (0.07 + 0.10 m
/// of the shipped robot description, the link radius and a margin).
pub(super) const WRIST_CLEAR: f64 = 0.23;
/// The link radius and margin above the highest wrist joint that [`WRIST_CLEAR`] allows.
const WRIST_MARGIN: f64 = 0.06;

/// The clearance a top-down hand of `robot` needs under a board: [`WRIST_CLEAR`], or more for
/// an arm whose wrist stands higher above its tool (a mounted UR5e's or Kinova's, measured on
/// its kinematics by `kitchen_r_sim::robot::wrist`). The shipped arm keeps the constant exactly.
pub(super) fn wrist_clear(robot: &kitchen_r_sim::robot::desc::RobotDesc) -> f64 {
    let own = kitchen_r_sim::robot::wrist::wrist_height(robot).map_or(0.0, |h| h + WRIST_MARGIN);
    if own > WRIST_CLEAR + 1e-3 {
        own
    } else {
        WRIST_CLEAR
    }
}
/// Slack around furniture footprints, m.
const MARGIN: f64 = 0.1;

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
    fn the_shipped_arm_keeps_its_clearance_and_a_higher_wrist_gets_more() {
        let mut robot = kitchen_r_sim::robot::desc::RobotDesc::load_default().unwrap();
        assert_eq!(wrist_clear(&robot).to_bits(), WRIST_CLEAR.to_bits());
        // The wrist-rotate link 10 cm longer: the wrist stands 10 cm higher over a top-down tool.
        robot.arm.joints[5].origin[0] += 0.10;
        let c = wrist_clear(&robot);
        assert!((c - (WRIST_CLEAR + 0.10)).abs() < 1e-3, "{c}");
    }

    #[test]
    fn a_shelf_level_has_a_ceiling_and_a_counter_top_has_none() {
        let scenes = Scene::load_all(
            &kitchen_r_core::assets::assets_dir().join("scenes"),
            &kitchen_r_core::catalogue::Catalogue::load(
                &kitchen_r_core::assets::assets_dir().join("objects.toml"),
            )
            .unwrap(),
        )
        .unwrap();
        let b = scenes.iter().find(|s| s.id == "kitchen_b").unwrap();
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
