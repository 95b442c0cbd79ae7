//! An object from a glTF 2.0 mesh (issue #27 item 3) with catalogue changes only: the cup's
//! cylinder replaced by a mesh file of the same cup, and the oracle completes a dev instruction
//! that picks and places it. Here because the oracle policy lives in this crate.

use std::f64::consts::TAU;
use std::path::{Path, PathBuf};

use kitchen_r_core::dataset::Split;
use kitchen_r_sim::usd_export::scene_usda;
use kitchen_r_sim::{Assets, SensorsConfig, Sim, SimConfig};

use crate::eval::{episode_configs, instructions};
use crate::oracle::OraclePolicy;
use crate::runner::{RunOptions, run_episode};

const CUP: &str = "shape = { kind = \"cylinder\", radius = 0.04, height = 0.10 }";

/// A closed cylinder of radius `r` and height `h` as glTF (y-up, as glTF has it): `name.gltf`
/// with its `name.bin`, `n` segments, a vertex at angle 0 so the bounding box is exact.
fn write_cylinder(dir: &Path, name: &str, r: f32, h: f32, n: u32) {
    let mut pos: Vec<[f32; 3]> = Vec::new();
    for y in [-h / 2.0, h / 2.0] {
        for i in 0..n {
            let a = TAU * f64::from(i) / f64::from(n);
            pos.push([r * a.cos() as f32, y, r * a.sin() as f32]);
        }
    }
    pos.push([0.0, -h / 2.0, 0.0]);
    pos.push([0.0, h / 2.0, 0.0]);
    let mut idx: Vec<u32> = Vec::new();
    for i in 0..n {
        let j = (i + 1) % n;
        idx.extend([i, j, n + j, i, n + j, n + i, 2 * n, j, i, 2 * n + 1, n + i, n + j]);
    }
    let mut bin: Vec<u8> = pos.iter().flatten().flat_map(|v| v.to_le_bytes()).collect();
    let p_len = bin.len();
    bin.extend(idx.iter().flat_map(|i| i.to_le_bytes()));
    let lo = [0, 1, 2].map(|k| pos.iter().map(|p| p[k]).fold(f32::INFINITY, f32::min));
    let hi = [0, 1, 2].map(|k| pos.iter().map(|p| p[k]).fold(f32::NEG_INFINITY, f32::max));
    let json = format!(
        r#"{{"asset": {{"version": "2.0"}}, "scene": 0, "scenes": [{{"nodes": [0]}}],
"nodes": [{{"mesh": 0}}], "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}, "indices": 1}}]}}],
"buffers": [{{"uri": "{name}.bin", "byteLength": {}}}],
"bufferViews": [{{"buffer": 0, "byteOffset": 0, "byteLength": {p_len}}}, {{"buffer": 0, "byteOffset": {p_len}, "byteLength": {}}}],
"accessors": [{{"bufferView": 0, "componentType": 5126, "count": {}, "type": "VEC3", "min": {lo:?}, "max": {hi:?}}},
{{"bufferView": 1, "componentType": 5125, "count": {}, "type": "SCALAR"}}]}}"#,
        bin.len(),
        bin.len() - p_len,
        pos.len(),
        idx.len()
    );
    std::fs::write(dir.join(format!("{name}.gltf")), json).unwrap();
    std::fs::write(dir.join(format!("{name}.bin")), bin).unwrap();
}

/// The committed assets with the cup's shape line replaced by `shape` and a glTF cup in
/// `meshes/`.
fn assets_dir(tag: &str, shape: &str) -> PathBuf {
    let src = kitchen_r_core::assets::assets_dir();
    let dir = std::env::temp_dir().join(format!("kitchen-r-mesh-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(dir.join("scenes")).unwrap();
    std::fs::create_dir_all(dir.join("meshes")).unwrap();
    std::fs::copy(src.join("robot.toml"), dir.join("robot.toml")).unwrap();
    std::fs::copy(
        src.join("scenes/kitchen_a.toml"),
        dir.join("scenes/kitchen_a.toml"),
    )
    .unwrap();
    let objects = std::fs::read_to_string(src.join("objects.toml")).unwrap();
    assert!(
        objects.contains(CUP),
        "the cup's shape line changed: update this test"
    );
    std::fs::write(dir.join("objects.toml"), objects.replacen(CUP, shape, 1)).unwrap();
    write_cylinder(&dir.join("meshes"), "cup", 0.04, 0.10, 24);
    dir
}

#[test]
fn a_mesh_cup_from_gltf_is_picked_and_placed_by_the_oracle() {
    let dir = assets_dir(
        "oracle",
        "shape = { kind = \"mesh\", file = \"meshes/cup.gltf\", size = [0.08, 0.08, 0.1] }",
    );
    let assets = Assets::load(&dir).unwrap();
    let dev = instructions(Split::Dev, None).unwrap();
    let ins = dev
        .iter()
        .filter(|i| {
            i.scene == "kitchen_a" && i.plan.iter().any(|s| s.starts_with("pick") && s.ends_with("cup"))
        })
        .max_by_key(|i| i.plan.len())
        .unwrap();
    let cfg = &episode_configs(&assets, std::slice::from_ref(ins), 0, None).unwrap()[0];
    let blind = SensorsConfig {
        cameras: Vec::new(),
        lidar: None,
        ..SensorsConfig::default()
    };
    let (mut sim, _) = Sim::new(assets.clone(), SimConfig::load_default().unwrap(), blind, cfg).unwrap();
    let run = RunOptions {
        privileged: true,
        ..RunOptions::default()
    };
    let out = run_episode(&mut sim, &mut OraclePolicy::new(&assets), &run, None, &mut ()).unwrap();
    assert_eq!(out.tasks.len(), ins.plan.len());
    assert!(out.tasks.iter().all(|t| t.success), "{}: {:?}", ins.id, out.tasks);
    // The cameras see it (the hull renders through the ray caster's generic shape path) and
    // the USD export writes it as a Mesh prim.
    let (_, obs) = Sim::new(
        assets.clone(),
        SimConfig::load_default().unwrap(),
        SensorsConfig::load_default().unwrap(),
        cfg,
    )
    .unwrap();
    assert!(!obs.images.is_empty());
    // From above, the cup's top is where the mesh says (its hull is cast against), not the
    // counter under it.
    let view = Sim::new(
        assets.clone(),
        SimConfig::load_default().unwrap(),
        SensorsConfig::load_default().unwrap(),
        cfg,
    )
    .unwrap()
    .0;
    let scene = assets.scene("kitchen_a").unwrap();
    let img = kitchen_r_sim::render::topdown(&view, scene);
    let (w, h) = (f64::from(img.width), f64::from(img.height));
    let t = scene.room.wall_thickness;
    let [rx, ry] = scene.room.size;
    let scale = (rx + 2.0 * t) / w;
    let top = scene.room.wall_height + 1.0;
    let cups: Vec<_> = cfg.objects.iter().filter(|o| o.model == "cup").collect();
    assert!(!cups.is_empty());
    for cup in cups {
        let [x, y, z] = cup.position;
        let u = ((x - rx / 2.0) / scale + w / 2.0 - 0.5).round() as u32;
        let v = ((ry / 2.0 - y) / scale + h / 2.0 - 0.5).round() as u32;
        let seen = top - f64::from(img.depth[(v * img.width + u) as usize]);
        assert!(
            (seen - (z + 0.05)).abs() < 0.005,
            "{}: top seen at {seen}, cup top at {}",
            cup.name,
            z + 0.05
        );
    }
    let usda = scene_usda(
        assets.scene("kitchen_a").unwrap(),
        &assets.catalogue,
        &assets.robot,
    )
    .unwrap();
    assert!(usda.contains("def Mesh \"shape_0\""), "no Mesh prim for the cup");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_mesh_whose_catalogue_size_is_wrong_is_refused_with_the_measured_size() {
    let dir = assets_dir(
        "size",
        "shape = { kind = \"mesh\", file = \"meshes/cup.gltf\", size = [0.08, 0.08, 0.2] }",
    );
    let err = Assets::load(&dir).unwrap_err().to_string();
    assert!(
        err.contains("cup.gltf")
            && err.contains("object \"cup\"")
            && err.contains("measures [0.08, 0.08, 0.1]"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).ok();
}
