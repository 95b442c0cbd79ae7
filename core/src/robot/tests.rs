use std::path::{Path, PathBuf};

use super::*;

fn shipped() -> PathBuf {
    crate::assets::assets_dir().join(SHIPPED)
}

/// Every number the twin reads, bit for bit (JSON prints the shortest round-trip form of each
/// float, so equal text is equal bits, signs of zero included).
fn bits(d: &RobotDesc) -> String {
    serde_json::to_string(d).unwrap()
}

/// The URDF and its sidecar say exactly what the retired `assets/robot.toml` said, so every
/// episode is bit-identical to the ones before the URDF (docs/twin/robot.md).
#[test]
fn the_shipped_urdf_is_the_retired_robot_toml_bit_for_bit() {
    let urdf = RobotDesc::load(&shipped()).unwrap();
    let text = include_str!("testdata/legacy_robot.toml");
    let mut legacy: RobotDesc = toml::from_str(text).unwrap();
    // What the old schema did not say: effort limits (ViperX 300's servos) and link masses.
    for (l, u) in legacy.arm.joints.iter_mut().zip(&urdf.arm.joints) {
        l.effort = u.effort;
        l.mass = u.mass;
    }
    assert_eq!(urdf, legacy);
    assert_eq!(bits(&urdf), bits(&legacy));
    let effort: Vec<f64> = urdf.arm.joints.iter().map(|j| j.effort).collect();
    assert_eq!(effort, [10.0, 20.0, 15.0, 2.0, 5.0, 1.0]);
    let mass: Vec<Option<f64>> = urdf.arm.joints.iter().map(|j| j.mass).collect();
    assert_eq!(mass, [0.9, 0.8, 0.6, 0.4, 0.3, 0.35].map(Some));
}

/// A copy of the shipped robot in a temporary directory with `edit` applied to the URDF and
/// `side` to the sidecar, loaded.
fn load_edited(
    edit: (&str, &str),
    side: (&str, &str),
) -> (PathBuf, Result<RobotDesc, ContentError>, tempfile::TempDir) {
    let dir = tempfile::tempdir().unwrap();
    let urdf = std::fs::read_to_string(shipped()).unwrap();
    let toml = std::fs::read_to_string(sidecar::Sidecar::path(&shipped())).unwrap();
    assert!(
        urdf.contains(edit.0) && toml.contains(side.0),
        "the edit must apply"
    );
    let path = dir.path().join("edited.urdf");
    std::fs::write(&path, urdf.replacen(edit.0, edit.1, 1)).unwrap();
    std::fs::write(dir.path().join("edited.toml"), toml.replacen(side.0, side.1, 1)).unwrap();
    let r = RobotDesc::load(&path);
    (path, r, dir)
}

fn error_of(edit: (&str, &str), side: (&str, &str)) -> String {
    let (path, r, _dir) = load_edited(edit, side);
    let e = r.unwrap_err().to_string();
    assert!(e.contains(&path.display().to_string()), "names the file: {e}");
    e
}

const NONE: (&str, &str) = ("[frames]", "[frames]");
const NO_EDIT: (&str, &str) = ("</robot>", "</robot>");

#[test]
fn an_arm_without_six_or_seven_revolute_joints_is_refused_with_the_joints_it_has() {
    let e = error_of(
        (
            "<joint name=\"wrist_rotate\" type=\"revolute\">",
            "<joint name=\"wrist_rotate\" type=\"fixed\">",
        ),
        NONE,
    );
    assert!(e.contains("5 revolute joints") && e.contains("6 or 7"), "{e}");
    assert!(
        e.contains("\"wrist_angle\"") && e.contains("<link name=\"ee_tcp_link\">"),
        "{e}"
    );
    let e = error_of(
        (
            "<joint name=\"elbow\" type=\"revolute\">",
            "<joint name=\"elbow\" type=\"continuous\">",
        ),
        NONE,
    );
    assert!(e.contains("<joint name=\"elbow\"> (continuous)"), "{e}");
}

#[test]
fn a_missing_named_frame_is_refused_with_the_sidecar_key_to_fix() {
    let e = error_of(NO_EDIT, ("tool = \"ee_tcp_link\"", "tool = \"tcp\""));
    assert!(
        e.contains("no <link name=\"tcp\">") && e.contains("[frames] tool"),
        "{e}"
    );
}

#[test]
fn rotated_joints_and_any_axis_load_and_a_missing_sidecar_is_refused() {
    let (_, r, _dir) = load_edited(
        (
            "<origin xyz=\"0.06 0.0 0.30\"/>",
            "<origin xyz=\"0.06 0.0 0.30\" rpy=\"0 0.1 0\"/>",
        ),
        NONE,
    );
    let d = r.unwrap();
    let q = d.arm.joints[2].rotation.expect("the elbow's frame is turned");
    let half = 0.05f64;
    assert!(
        (q[0] - half.cos()).abs() < 1e-12 && (q[2] - half.sin()).abs() < 1e-12,
        "{q:?}"
    );
    assert!(
        d.arm
            .joints
            .iter()
            .enumerate()
            .all(|(i, j)| i == 2 || j.rotation.is_none())
    );
    let (_, r, _dir) = load_edited(
        (
            "<axis xyz=\"0 1 0\"/>\n    <limit lower=\"-1.85\"",
            "<axis xyz=\"0 0.6 0.8\"/>\n    <limit lower=\"-1.85\"",
        ),
        NONE,
    );
    let Axis::Along(a) = r.unwrap().arm.joints[1].axis else {
        panic!("a tilted axis is read as given")
    };
    assert!((a[1] - 0.6).abs() < 1e-12 && (a[2] - 0.8).abs() < 1e-12, "{a:?}");
    let e = error_of(
        (
            "<axis xyz=\"0 1 0\"/>\n    <limit lower=\"-1.85\"",
            "<axis xyz=\"0 0 0\"/>\n    <limit lower=\"-1.85\"",
        ),
        NONE,
    );
    assert!(
        e.contains("<joint name=\"shoulder\">: axis") && e.contains("non-zero"),
        "{e}"
    );
    let dir = tempfile::tempdir().unwrap();
    let lone = dir.path().join("lone.urdf");
    std::fs::copy(shipped(), &lone).unwrap();
    let e = RobotDesc::load(&lone).unwrap_err().to_string();
    assert!(e.contains("lone.toml") && e.contains("[frames]"), "{e}");
}

#[test]
fn malformed_xml_and_unknown_formats_name_the_file() {
    let (_, r, _dir) = load_edited(("</robot>", "</robt>"), NONE);
    let e = r.unwrap_err().to_string();
    assert!(e.contains("edited.urdf") && e.contains("not a valid URDF"), "{e}");
    let e = RobotDesc::load(Path::new("robot.sdf")).unwrap_err().to_string();
    assert!(
        e.contains("robot.sdf") && e.contains("URDF (.urdf) or MJCF"),
        "{e}"
    );
}

/// The test robot in MJCF (`tests/robots/`): a different arm on a different base, same mapping.
#[test]
fn the_mjcf_test_robot_maps_onto_six_revolute_joints() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/robots/long_arm.xml");
    let d = RobotDesc::load(&path).unwrap();
    let shipped = RobotDesc::load(&shipped()).unwrap();
    assert_eq!(d.arm.joints.len(), 6);
    assert_ne!(d.arm.mount, shipped.arm.mount);
    assert_ne!(d.base.body_radius, shipped.base.body_radius);
    assert!(
        d.arm
            .joints
            .iter()
            .all(|j| j.max_velocity > 0.0 && j.effort > 0.0)
    );
    assert_eq!(d.arm.mount, [0.15, -0.1, 0.73]);
    assert_eq!(d.arm.joints[2].origin, [0.05, 0.0, 0.33]);
    assert_eq!(
        (d.base.body_radius, d.base.clearance, d.base.mass),
        (0.26, 0.03, 50.0)
    );
    assert_eq!(
        (d.base.column_center, d.base.column_size),
        ([0.12, -0.1, 0.52], [0.12, 0.14, 0.42])
    );
    let g = &d.gripper;
    assert_eq!(
        (g.tcp_offset, g.palm_back, g.max_opening, g.finger_thickness),
        (0.1, 0.065, 0.09, 0.012)
    );
    let axes: Vec<Axis> = d.arm.joints.iter().map(|j| j.axis).collect();
    assert_eq!(axes, [Axis::Z, Axis::Y, Axis::Y, Axis::X, Axis::Y, Axis::X]);
}

fn robosuite_sidecar(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../configs/robots/robosuite/{name}.toml"))
}

/// The four robosuite arms map from the wheel's own MJCF: turned frames, mesh links, seven
/// joints where the arm has them, the gripper file's hand meshes on the last link.
#[test]
fn robosuite_arms_and_grippers_load_from_the_wheel() {
    let Some(_) = crate::assets::robosuite_assets_for_tests() else {
        return;
    };
    for (name, joints) in [("panda", 7), ("ur5e", 6), ("kinova3", 7), ("xarm7", 7)] {
        let d = RobotDesc::load(&robosuite_sidecar(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(d.arm.joints.len(), joints, "{name}");
        // Mesh links (xArm 7's link7 is a bare frame between two joints).
        let shaped = d.arm.joints.iter().filter(|j| !j.shapes.is_empty()).count();
        assert!(shaped + 1 >= joints, "{name}: mesh links");
        assert!(
            d.arm.joints.iter().any(|j| j.rotation.is_some()),
            "{name}: turned frames"
        );
        assert!(
            d.arm.flange.is_some() && !d.arm.hand_shapes.is_empty(),
            "{name}: the gripper"
        );
        let meshes = d
            .arm
            .joints
            .iter()
            .flat_map(|j| &j.shapes)
            .filter(|s| matches!(s.geometry, Geometry::Mesh { .. }));
        assert!(meshes.count() >= shaped, "{name}");
    }
    // The Panda hand's two slide fingers give the widest gap: 2 × 0.04 m.
    let panda = RobotDesc::load(&robosuite_sidecar("panda")).unwrap();
    assert!((panda.gripper.max_opening - 0.08).abs() < 1e-12);
}

/// A mounting sidecar whose files the twin cannot map names the file, the element and the fix.
#[test]
fn a_mounted_description_the_twin_cannot_map_is_refused_with_the_fix() {
    let Some(_) = crate::assets::robosuite_assets_for_tests() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(robosuite_sidecar("panda")).unwrap();
    let side = dir.path().join("panda.toml");
    std::fs::write(&side, text.replace("tip = \"right_hand\"", "tip = \"hand\"")).unwrap();
    let e = RobotDesc::load(&side).unwrap_err().to_string();
    assert!(
        e.contains("robot.xml") && e.contains("<body name=\"hand\">") && e.contains("[arm] tip"),
        "{e}"
    );
    std::fs::write(&side, text.replace("home = [0.0, ", "home = [")).unwrap();
    let e = RobotDesc::load(&side).unwrap_err().to_string();
    assert!(e.contains("7 joints") && e.contains("[arm] home"), "{e}");
}
