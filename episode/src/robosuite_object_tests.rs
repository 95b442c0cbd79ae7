//! robosuite 1.5.2's objects (milk, cereal, can, bread, lemon, bottle) as key objects through the
//! object catalogue (`configs/objects/robosuite.toml`), read from the unpacked wheel that
//! `ROBOSUITE_ASSETS` points at: each loads from its own MJCF file and meshes, and the oracle
//! picks and places robosuite's milk carton where a dev instruction has a cup. Skips with the command that
//! fetches the wheel outside CI and fails in CI without it. Here because the oracle lives in this
//! crate.

use std::path::{Path, PathBuf};

use kitchen_r_core::catalogue::{Catalogue, Role, Shape};
use kitchen_r_core::dataset::Split;
use kitchen_r_sim::Assets;

use crate::eval::{episode_configs, instructions};

const CUP: &str = "shape = { kind = \"cylinder\", radius = 0.04, height = 0.10 }";
/// The cup's lines after its shape, up to its grasp point (2 cm above its centre).
const CUP_REST: &str =
    "mass = 0.15\nfriction = 0.8\ncolor = [0.90, 0.90, 0.88]\ngrasp_offset = [0.0, 0.0, 0.02]";
const CUP_GRASP: &str = "grasp_offset = [0.0, 0.0, 0.02]";

fn robosuite_catalogue() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/objects/robosuite.toml")
}

#[test]
fn robosuite_objects_load_and_the_oracle_picks_one() {
    if kitchen_r_core::assets::robosuite_assets_for_tests().is_none() {
        return;
    }
    let cat = Catalogue::load(&robosuite_catalogue()).unwrap();
    let ids: Vec<&str> = cat.objects.iter().map(|m| m.id.as_str()).collect();
    assert_eq!(ids, ["milk", "cereal", "can", "bread", "lemon", "bottle"]);
    for m in &cat.objects {
        assert_eq!(m.role, Role::Key, "{}", m.id);
        let Shape::Mesh { file, .. } = &m.shape else {
            panic!("{}: not a mesh shape", m.id)
        };
        assert!(file.ends_with(&format!("objects/{}.xml", m.id)), "{file}");
    }
    // Each object's meshes read from the wheel measure the catalogue's size (to 1 mm).
    kitchen_r_sim::mesh::load_catalogue(&cat).unwrap();

    // The shipped assets with the cup made of robosuite's milk carton, by its catalogue line,
    // grasped at its centre as the catalogue grasps it.
    let text = std::fs::read_to_string(robosuite_catalogue()).unwrap();
    let milk = text
        .lines()
        .find(|l| l.starts_with("shape") && l.contains("objects/milk.xml"))
        .unwrap();
    let src = kitchen_r_core::assets::assets_dir();
    let dir = std::env::temp_dir().join(format!("kitchen-r-robosuite-milk-{}", std::process::id()));
    std::fs::create_dir_all(dir.join("scenes")).unwrap();
    crate::test_oracle::copy_shipped_robot(&src, &dir);
    std::fs::copy(
        src.join("scenes/kitchen_a.toml"),
        dir.join("scenes/kitchen_a.toml"),
    )
    .unwrap();
    let objects = std::fs::read_to_string(src.join("objects.toml")).unwrap();
    let cup = format!("{CUP}\n{CUP_REST}");
    assert!(
        objects.contains(&cup),
        "the cup's lines changed: update this test"
    );
    let rest = CUP_REST.replace(CUP_GRASP, "grasp_offset = [0.0, 0.0, 0.0]");
    let with_milk = objects.replacen(&cup, &format!("{milk}\n{rest}"), 1);
    std::fs::write(dir.join("objects.toml"), with_milk).unwrap();
    let assets = Assets::load(&dir).unwrap();
    assert!(matches!(
        assets.catalogue.model("cup").unwrap().shape,
        Shape::Mesh { .. }
    ));
    let dev = instructions(Split::Dev, None).unwrap();
    let ins = dev
        .iter()
        .filter(|i| {
            i.scene == "kitchen_a" && i.plan.iter().any(|s| s.starts_with("pick") && s.ends_with("cup"))
        })
        .min_by_key(|i| i.plan.len())
        .unwrap();
    let cfg = &episode_configs(&assets, std::slice::from_ref(ins), 0, None).unwrap()[0];
    crate::test_oracle::assert_oracle_completes(&assets, cfg, ins);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn an_mjcf_object_made_of_a_box_is_refused_with_the_geom_and_what_to_change() {
    let dir = std::env::temp_dir().join(format!("kitchen-r-mjcf-box-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("crate.xml");
    std::fs::write(
        &file,
        r#"<mujoco model="crate"><worldbody><body name="object">
<geom name="side" type="box" size="0.05 0.05 0.05"/></body></worldbody></mujoco>"#,
    )
    .unwrap();
    let err = kitchen_r_sim::mesh::load(&file.to_string_lossy(), 1.0)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("crate.xml") && err.contains("<geom name=\"side\"") && err.contains("make it a mesh"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).ok();
}
