//! The arm's reach for place targets: a conservative rule, computed from the robot description
//! (`assets/robots/`, docs/twin/robot.md), that the dataset generator applies to every place spot
//! it draws and that [`check_plan`](crate::dataset::symbolic::check_plan) applies to committed
//! targets, so every generated instruction is executable by the oracle (DESIGN, Feasibility).
//!
//! The oracle places top-down (`kitchen_r_sim::oracle::manip`): it lets an object go with the
//! tool centre point (TCP) [`RELEASE_HEIGHT`] above the object's grasp point at the target, the
//! grasp point being the object centre plus the catalogue's `grasp_offset` turned by the yaw the
//! object was picked with. With the tool pointing down, the wrist-angle joint stands
//! `wrist_back` (the wrist-rotate origin plus the TCP offset) straight above the TCP, and the
//! shoulder reaches it with two links (shoulder → elbow, elbow → wrist) in the vertical plane
//! the waist turns to. So, with the base at the zone's approach pose, a target centre `c` on a
//! surface of height `s` is accepted when
//!
//! ```text
//! h  = |c_xy − waist_xy| + |grasp_offset_xy| + BASE_SLACK
//! dz = s + half_height + grasp_offset_z + RELEASE_HEIGHT + wrist_back − shoulder_z
//! h² + dz² ≤ (upper_arm + forearm + ALLOWANCE)²
//! ```
//!
//! `waist_xy` is the waist axis in the world with the base at the approach pose. The grasp
//! offset is taken in its worst direction (straight away from the waist): the yaw an object is
//! carried with depends on how it was picked up. [`BASE_SLACK`] covers where the base really
//! stops: the oracle squares up on the approach point to 3 cm and its heading to 0.015 rad
//! (`episode/src/oracle/task.rs`, ~1.5 cm at the arm's reach). [`ALLOWANCE`] is what the arm
//! gains over the straight top-down chain by tilting the tool (the RMP controller weighs the
//! position attractor ten times the orientation one) and what the 5 cm place tolerance absorbs;
//! it is measured in the twin (`worker/tests/it/place_reach.rs`).
//!
//! Everything here is `+ − × ÷` and `sqrt`, correctly rounded on every platform; the approach
//! yaw's cosine and sine are exact for quarter turns (every committed approach pose), so the
//! generated dataset does not depend on the platform's `libm`.

use std::path::Path;
use std::sync::OnceLock;

use crate::ContentError;
use crate::robot::RobotDesc;
use crate::scene::Zone;

/// Height above the target grasp point at which the oracle lets go, m (the `release_height`
/// of `kitchen_r_sim::oracle::manip::ManipParams`).
pub const RELEASE_HEIGHT: f64 = 0.01;
/// How far the base may stand from the approach pose when it places, m.
pub const BASE_SLACK: f64 = 0.045;
/// Reach beyond the straight top-down chain that the twin's arm and the place tolerance
/// provide, m; validated in the twin by `worker/tests/it/place_reach.rs`: at the rule's limit,
/// with the base the whole [`BASE_SLACK`] away and the grasp point on the far side, the oracle
/// lets objects go within 4.6 cm of the target (plates; 3.4 cm the others), inside the 5 cm
/// place tolerance. From the nominal pose the rule's limit sits at about the straight chain
/// itself, some 4 cm short of the nearest target the oracle ever missed (the first committed
/// dataset's nine misses, 4–8 cm beyond the chain: the `tests` below refuse them).
pub const ALLOWANCE: f64 = 0.04;

/// The arm as the reach rule sees it: base frame, metres.
#[derive(Debug, Clone, PartialEq)]
pub struct ArmReach {
    /// The waist axis, base frame `[x, y]`.
    pub waist: [f64; 2],
    /// Height of the shoulder joint above the floor.
    pub shoulder_z: f64,
    /// Shoulder → elbow plus elbow → wrist-angle joint: the straightened arm.
    pub links: f64,
    /// Wrist-angle joint to the TCP along the tool's approach axis.
    pub wrist_back: f64,
}

impl ArmReach {
    /// From a robot description (a six-joint ViperX-class arm like the shipped one: waist about
    /// z, shoulder straight above it, wrist-rotate along the forearm).
    pub fn from_desc(r: &RobotDesc) -> Result<ArmReach, String> {
        let j = &r.arm.joints;
        if j.len() != 6 {
            return Err(format!("{} arm joints, the reach rule knows six", j.len()));
        }
        let norm = |v: [f64; 3]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        if j[1].origin[0] != 0.0 || j[1].origin[1] != 0.0 {
            return Err("the shoulder must stand on the waist axis".into());
        }
        let [m, o0, o1] = [r.arm.mount, j[0].origin, j[1].origin];
        let forearm = [0, 1, 2].map(|i| j[3].origin[i] + j[4].origin[i]);
        Ok(ArmReach {
            waist: [m[0] + o0[0], m[1] + o0[1]],
            shoulder_z: m[2] + o0[2] + o1[2],
            links: norm(j[2].origin) + norm(forearm),
            wrist_back: norm(j[5].origin) + r.gripper.tcp_offset,
        })
    }

    /// The arm of the robot description at `path` (URDF or MJCF, with its sidecar).
    pub fn load(path: &Path) -> Result<ArmReach, ContentError> {
        let desc = RobotDesc::load(path)?;
        ArmReach::from_desc(&desc).map_err(|message| ContentError::Invalid {
            path: path.to_path_buf(),
            message,
        })
    }

    /// The shipped robot ([`SHIPPED`](crate::robot::SHIPPED) in
    /// [`assets_dir`](crate::assets::assets_dir)), read once per process: the committed
    /// instructions are generated for it.
    pub fn committed() -> Result<&'static ArmReach, String> {
        static ARM: OnceLock<Result<ArmReach, String>> = OnceLock::new();
        ARM.get_or_init(|| {
            ArmReach::load(&crate::assets::assets_dir().join(crate::robot::SHIPPED))
                .map_err(|e| e.to_string())
        })
        .as_ref()
        .map_err(Clone::clone)
    }

    /// The waist axis in the world with the base at `approach` (`[x, y, yaw]`).
    pub fn waist_at(&self, approach: [f64; 3]) -> [f64; 2] {
        let (c, s) = cos_sin(approach[2]);
        let [wx, wy] = self.waist;
        [approach[0] + c * wx - s * wy, approach[1] + s * wx + c * wy]
    }

    /// How much of the allowed reach placing at `xy` in `zone` leaves over, m² (negative: out
    /// of reach); see the module documentation for the rule. `half_height` and `grasp_offset`
    /// come from the placed object's catalogue model.
    pub fn place_headroom(&self, zone: &Zone, half_height: f64, grasp_offset: [f64; 3], xy: [f64; 2]) -> f64 {
        let w = self.waist_at(zone.approach);
        let (dx, dy) = (xy[0] - w[0], xy[1] - w[1]);
        let [gx, gy, gz] = grasp_offset;
        let h = (dx * dx + dy * dy).sqrt() + (gx * gx + gy * gy).sqrt() + BASE_SLACK;
        let dz = zone.height + half_height + gz + RELEASE_HEIGHT + self.wrist_back - self.shoulder_z;
        let r = self.links + ALLOWANCE;
        r * r - (h * h + dz * dz)
    }

    /// Whether the arm can place an object centre at `xy` in `zone` from its approach pose.
    pub fn can_place(&self, zone: &Zone, half_height: f64, grasp_offset: [f64; 3], xy: [f64; 2]) -> bool {
        self.place_headroom(zone, half_height, grasp_offset, xy) >= 0.0
    }
}

/// `(cos yaw, sin yaw)`, exact at multiples of a quarter turn.
fn cos_sin(yaw: f64) -> (f64, f64) {
    let quarters = yaw / std::f64::consts::FRAC_PI_2;
    let k = quarters.round();
    if (quarters - k).abs() < 1e-9 {
        match (k as i64).rem_euclid(4) {
            0 => (1.0, 0.0),
            1 => (0.0, 1.0),
            2 => (-1.0, 0.0),
            _ => (0.0, -1.0),
        }
    } else {
        (yaw.cos(), yaw.sin())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::catalogue::Catalogue;
    use crate::scene::Scene;

    fn arm() -> &'static ArmReach {
        ArmReach::committed().unwrap()
    }

    #[test]
    fn the_committed_arm() {
        let a = arm();
        assert_eq!(a.waist, [0.20, -0.12]);
        assert!((a.shoulder_z - 0.90).abs() < 1e-12);
        assert!((a.links - (0.06f64.hypot(0.30) + 0.30)).abs() < 1e-12);
        assert!((a.wrist_back - 0.17).abs() < 1e-12);
    }

    #[test]
    fn quarter_turns_are_exact() {
        use std::f64::consts::{FRAC_PI_2, PI};
        assert_eq!(cos_sin(FRAC_PI_2), (0.0, 1.0));
        assert_eq!(cos_sin(PI), (-1.0, 0.0));
        assert_eq!(cos_sin(-FRAC_PI_2), (0.0, -1.0));
        assert_eq!(cos_sin(0.0), (1.0, 0.0));
        let (c, s) = cos_sin(0.3);
        assert_eq!((c, s), (0.3f64.cos(), 0.3f64.sin()));
    }

    /// The place targets the oracle failed on in the first committed dataset (all far left of
    /// the right-mounted arm) are refused; the zone centres are accepted for every key object.
    #[test]
    fn refuses_the_targets_the_oracle_missed_and_keeps_zone_centres() {
        let dir = crate::assets::assets_dir();
        let cat = Catalogue::load(&dir.join("objects.toml")).unwrap();
        let scenes = Scene::load_all(&dir.join("scenes"), &cat).unwrap();
        let scene = |id: &str| scenes.iter().find(|s| s.id == id).unwrap();
        let missed = [
            ("kitchen_a", "blue", "apple", [1.363, 3.719]),
            ("kitchen_a", "green", "cup", [2.832, 3.714]),
            ("kitchen_c", "orange", "bowl", [3.751, 3.603]),
            ("kitchen_b", "yellow", "cup", [5.703, 3.206]),
            ("kitchen_a", "green", "cup", [2.871, 3.72]),
            ("kitchen_c", "blue", "apple", [0.304, 3.619]),
            ("kitchen_a", "green", "cup", [2.84, 3.701]),
            ("kitchen_a", "green", "apple", [2.838, 3.721]),
            ("kitchen_a", "green", "cup", [2.833, 3.684]),
        ];
        for (s, zone, model, xy) in missed {
            let z = scene(s).zone(zone).unwrap();
            let m = cat.model(model).unwrap();
            assert!(
                !arm().can_place(z, m.shape.half_height(), m.grasp_offset, xy),
                "{s} {zone} {model} {xy:?}"
            );
        }
        for s in &scenes {
            for z in &s.zones {
                for m in cat.key_models() {
                    assert!(
                        arm().can_place(z, m.shape.half_height(), m.grasp_offset, z.center),
                        "{} {} {}",
                        s.id,
                        z.color,
                        m.id
                    );
                }
            }
        }
    }
}
