//! An object from a glTF 2.0, OBJ or STL mesh (docs/twin/scenes.md) with catalogue changes only:
//! the cup's cylinder replaced by a mesh file of the same cup, and the oracle completes a dev
//! instruction that picks and places it. Here because the oracle policy lives in this crate.

use std::f64::consts::TAU;
use std::path::{Path, PathBuf};

use kitchen_r_core::dataset::Split;
use kitchen_r_sim::usd_export::scene_usda;
use kitchen_r_sim::{Assets, SensorsConfig, Sim, SimConfig};

use crate::eval::{episode_configs, instructions};

const CUP: &str = "shape = { kind = \"cylinder\", radius = 0.04, height = 0.10 }";

/// A closed cylinder of radius `r` and height `h` (glTF's y-up), `n` segments, a vertex at angle
/// 0 so the bounding box is exact.
fn cylinder(r: f32, h: f32, n: u32) -> (Vec<[f32; 3]>, Vec<u32>) {
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
    (pos, idx)
}

/// Boxes given in our z-up frame as (centre, size), written in glTF's y-up frame.
fn boxes(list: &[([f32; 3], [f32; 3])]) -> (Vec<[f32; 3]>, Vec<u32>) {
    let (mut pos, mut idx) = (Vec::new(), Vec::new());
    for (c, s) in list {
        let base = pos.len() as u32;
        for k in 0..8 {
            let d = [k & 1, (k >> 1) & 1, (k >> 2) & 1].map(|b| if b == 1 { 0.5 } else { -0.5 });
            let p = [c[0] + d[0] * s[0], c[1] + d[1] * s[1], c[2] + d[2] * s[2]];
            pos.push([p[0], p[2], -p[1]]);
        }
        for q in [
            [0, 1, 3, 2],
            [4, 5, 7, 6],
            [0, 1, 5, 4],
            [2, 3, 7, 6],
            [0, 2, 6, 4],
            [1, 3, 7, 5],
        ] {
            idx.extend([q[0], q[1], q[2], q[0], q[2], q[3]].map(|i| base + i));
        }
    }
    (pos, idx)
}

/// `name.gltf` with its `name.bin` in `dir`.
fn write_gltf(dir: &Path, name: &str, (pos, idx): (Vec<[f32; 3]>, Vec<u32>)) {
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

/// Positions in glTF's y-up frame turned to our z-up one, as OBJ and STL are read.
fn z_up(pos: &[[f32; 3]]) -> Vec<[f32; 3]> {
    pos.iter().map(|p| [p[0], -p[2], p[1]]).collect()
}

/// `name.obj` in `dir` (z-up, 1-based faces).
fn write_obj(dir: &Path, name: &str, (pos, idx): &(Vec<[f32; 3]>, Vec<u32>)) {
    let mut text = String::from("# a test mesh\no cup\n");
    for p in z_up(pos) {
        text += &format!("v {} {} {}\n", p[0], p[1], p[2]);
    }
    for t in idx.chunks(3) {
        text += &format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    std::fs::write(dir.join(format!("{name}.obj")), text).unwrap();
}

/// `name.stl` in `dir` (ASCII STL, z-up).
fn write_stl(dir: &Path, name: &str, (pos, idx): &(Vec<[f32; 3]>, Vec<u32>)) {
    let pos = z_up(pos);
    let mut text = format!("solid {name}\n");
    for t in idx.chunks(3) {
        text += "facet normal 0 0 0\nouter loop\n";
        for i in t {
            let p = pos[*i as usize];
            text += &format!("vertex {} {} {}\n", p[0], p[1], p[2]);
        }
        text += "endloop\nendfacet\n";
    }
    text += &format!("endsolid {name}\n");
    std::fs::write(dir.join(format!("{name}.stl")), text).unwrap();
}

/// The committed assets with the cup's shape line replaced by `shape` and the same cup in
/// `meshes/` as glTF, OBJ and STL.
fn assets_dir(tag: &str, shape: &str) -> PathBuf {
    let src = kitchen_r_core::assets::assets_dir();
    let dir = std::env::temp_dir().join(format!("kitchen-r-mesh-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(dir.join("scenes")).unwrap();
    std::fs::create_dir_all(dir.join("meshes")).unwrap();
    crate::test_oracle::copy_shipped_robot(&src, &dir);
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
    let cup = cylinder(0.04, 0.10, 24);
    write_obj(&dir.join("meshes"), "cup", &cup);
    write_stl(&dir.join("meshes"), "cup", &cup);
    write_gltf(&dir.join("meshes"), "cup", cup);
    dir
}

#[test]
fn obj_and_stl_read_as_the_same_cup_as_gltf() {
    let dir = assets_dir("formats", CUP);
    let read = |ext: &str| {
        let file = dir.join(format!("meshes/cup.{ext}"));
        kitchen_r_sim::mesh::load(&file.to_string_lossy(), 1.0).unwrap()
    };
    let gltf = read("gltf");
    let sorted = |m: &kitchen_r_sim::mesh::MeshData| {
        let mut v: Vec<[i64; 3]> = m
            .vertices
            .iter()
            .map(|p| p.map(|c| (c * 1e6).round() as i64))
            .collect();
        v.sort_unstable();
        v.dedup();
        v
    };
    for ext in ["obj", "stl"] {
        let m = read(ext);
        assert_eq!(m.triangles.len(), gltf.triangles.len(), "{ext}");
        assert!(
            (0..3).all(|k| (m.size[k] - gltf.size[k]).abs() < 1e-6),
            "{ext}: {:?}",
            m.size
        );
        assert_eq!(sorted(&m), sorted(&gltf), "{ext}: other vertices");
    }
    let err = match kitchen_r_sim::mesh::load(&dir.join("objects.toml").to_string_lossy(), 1.0) {
        Err(e) => e.to_string(),
        Ok(_) => panic!("a .toml read as a mesh"),
    };
    assert!(
        err.contains(".gltf") && err.contains(".obj") && err.contains(".stl"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).ok();
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
    crate::test_oracle::assert_oracle_completes(&assets, cfg, ins);
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

#[test]
fn a_mesh_table_from_gltf_passes_the_content_checks_and_the_oracle_works_at_it() {
    let dir = assets_dir("table", CUP);
    // kitchen_a's table (1.2 x 0.8 x 0.75) as a glTF mesh: a top and four legs.
    let (top, leg) = (0.04f32, 0.05f32);
    let mut parts = vec![([0.0, 0.0, 0.75 - top / 2.0], [1.2, 0.8, top])];
    for (a, b) in [(-1.0f32, -1.0f32), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
        parts.push((
            [a * (0.6 - leg), b * (0.4 - leg), (0.75 - top) / 2.0],
            [leg, leg, 0.75 - top],
        ));
    }
    write_gltf(&dir.join("meshes"), "table", boxes(&parts));
    let scene = std::fs::read_to_string(dir.join("scenes/kitchen_a.toml")).unwrap();
    let table = "kind = \"table\"\npose = [2.5, 1.6, 0.0]\nsize = [1.2, 0.8, 0.75]\n";
    assert!(
        scene.contains(table),
        "kitchen_a's table changed: update this test"
    );
    let meshed = scene.replacen(
        table,
        &format!("{table}mesh = {{ file = \"../meshes/table.gltf\" }}\n"),
        1,
    );
    std::fs::write(dir.join("scenes/kitchen_a.toml"), meshed).unwrap();
    let assets = Assets::load(&dir).unwrap();
    let scene = assets.scene("kitchen_a").unwrap();
    assert!(scene.furniture("table").unwrap().mesh.is_some());
    scene.check_layout().unwrap();
    scene.check_contents(&assets.catalogue).unwrap();
    let at_table: Vec<String> = scene
        .zones
        .iter()
        .filter(|z| z.furniture == "table")
        .map(|z| format!("move to the {} zone", z.color))
        .collect();
    let dev = instructions(Split::Dev, None).unwrap();
    let ins = dev
        .iter()
        .filter(|i| i.scene == "kitchen_a" && i.plan.iter().any(|s| at_table.contains(s)))
        .max_by_key(|i| i.plan.len())
        .unwrap();
    let cfg = &episode_configs(&assets, std::slice::from_ref(ins), 0, None).unwrap()[0];
    crate::test_oracle::assert_oracle_completes(&assets, cfg, ins);
    // The table top renders where the mesh puts it.
    let view = Sim::new(
        assets.clone(),
        SimConfig::load_default().unwrap(),
        SensorsConfig::load_default().unwrap(),
        cfg,
    )
    .unwrap()
    .0;
    let img = kitchen_r_sim::render::topdown(&view, scene);
    let [rx, ry] = scene.room.size;
    let scale = (rx + 2.0 * scene.room.wall_thickness) / f64::from(img.width);
    // Near the top's four corners (a background object may stand on one).
    let seen: Vec<f64> = [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)]
        .iter()
        .map(|(a, b)| {
            let (x, y) = (2.5 + a * 0.55, 1.6 + b * 0.35);
            let u = ((x - rx / 2.0) / scale + f64::from(img.width) / 2.0 - 0.5).round() as u32;
            let v = ((ry / 2.0 - y) / scale + f64::from(img.height) / 2.0 - 0.5).round() as u32;
            scene.room.wall_height + 1.0 - f64::from(img.depth[(v * img.width + u) as usize])
        })
        .collect();
    assert!(
        seen.iter().filter(|z| (*z - 0.75).abs() < 0.005).count() >= 2,
        "table top seen at {seen:?}"
    );
    std::fs::remove_dir_all(&dir).ok();
}
