//! Scenes as USD (docs/twin/scenes.md): every committed scene exports as `.usda` whose structure is
//! sound (balanced, one Xform per body, deterministic), and Pixar's own USD (`usd-core`, in
//! scripts/test-requirements.txt) opens it with the prim counts, transforms and box sizes the
//! twin uses.

use std::path::PathBuf;
use std::process::Command;

use kitchen_r_sim::furniture;
use kitchen_r_sim::usd_export::{prim_name, scene_usda};
use kitchen_r_sim::world::object_shapes;

use crate::common::assets;

/// Braces, brackets and parentheses outside string literals nest and close.
fn balanced(text: &str) -> Result<(), String> {
    let mut stack = Vec::new();
    let mut in_string = false;
    let mut escaped = false;
    for (n, line) in text.lines().enumerate() {
        for c in line.chars() {
            if in_string {
                match (escaped, c) {
                    (true, _) => escaped = false,
                    (false, '\\') => escaped = true,
                    (false, '"') => in_string = false,
                    _ => {}
                }
                continue;
            }
            match c {
                '"' => in_string = true,
                '{' | '[' | '(' => stack.push(c),
                '}' | ']' | ')' => {
                    let open = stack.pop().ok_or(format!("line {}: stray {c}", n + 1))?;
                    if !matches!((open, c), ('{', '}') | ('[', ']') | ('(', ')')) {
                        return Err(format!("line {}: {open} closed by {c}", n + 1));
                    }
                }
                _ => {}
            }
        }
        if in_string {
            return Err(format!("line {}: unterminated string", n + 1));
        }
    }
    if stack.is_empty() {
        Ok(())
    } else {
        Err(format!("unclosed {stack:?}"))
    }
}

#[test]
fn every_committed_scene_exports_as_sound_deterministic_usda() {
    let a = assets();
    for scene in &a.scenes {
        let text = scene_usda(scene, &a.catalogue, &a.robot).unwrap();
        assert_eq!(
            text,
            scene_usda(scene, &a.catalogue, &a.robot).unwrap(),
            "{}",
            scene.id
        );
        assert!(text.starts_with("#usda 1.0\n"), "{}", scene.id);
        assert!(text.contains("    metersPerUnit = 1\n") && text.contains("    upAxis = \"Z\"\n"));
        balanced(&text).unwrap_or_else(|e| panic!("{}: {e}", scene.id));
        let defs = |kind: &str, name: &str| {
            text.lines()
                .filter(|l| l.trim_start().starts_with(&format!("def {kind} \"{name}\"")))
                .count()
        };
        let mut bodies: Vec<String> = scene.furniture.iter().map(|f| f.id.clone()).collect();
        bodies.extend(scene.zones.iter().map(|z| z.color.clone()));
        bodies.extend(scene.key_objects.iter().map(|o| o.name()));
        bodies.extend(["Room", "Robot"].map(String::from));
        for b in &bodies {
            assert_eq!(defs("Xform", &prim_name(b)), 1, "{}: one Xform for {b}", scene.id);
        }
        // Every furniture part and object shape is one geometry prim, nothing more.
        let parts: usize = scene
            .furniture
            .iter()
            .map(|f| furniture::parts(scene, f).len())
            .sum();
        let shapes: usize = scene
            .key_objects
            .iter()
            .map(|o| object_shapes(&a.catalogue.model(&o.model).unwrap().shape).len())
            .sum();
        let geometry = ["Cube", "Cylinder", "Sphere"]
            .iter()
            .map(|k| {
                text.lines()
                    .filter(|l| l.trim_start().starts_with(&format!("def {k} ")))
                    .count()
            })
            .sum::<usize>();
        // Floor and four walls, one plate per zone, the robot's base and column.
        assert_eq!(
            geometry,
            parts + shapes + 5 + scene.zones.len() + 2,
            "{}",
            scene.id
        );
    }
}

fn pxr_available() -> bool {
    Command::new("python3")
        .args(["-c", "import pxr"])
        .output()
        .is_ok_and(|o| o.status.success())
}

#[test]
fn pixar_usd_opens_every_exported_scene_with_our_transforms_and_sizes() {
    assert!(
        pxr_available(),
        "Pixar's USD is missing: pip install -r scripts/test-requirements.txt (usd-core)"
    );
    let a = assets();
    let dir = std::env::temp_dir().join(format!("kitchen-r-usd-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut files: Vec<PathBuf> = Vec::new();
    for scene in &a.scenes {
        let path = dir.join(format!("{}.usda", scene.id));
        std::fs::write(&path, scene_usda(scene, &a.catalogue, &a.robot).unwrap()).unwrap();
        files.push(path);
    }
    let out = Command::new("python3")
        .arg(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/py/usd_open.py"))
        .args(&files)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for (scene, path) in a.scenes.iter().zip(&files) {
        let s = &v[path.to_str().unwrap()];
        assert_eq!(s["up_axis"], "Z");
        assert_eq!(s["meters_per_unit"], 1.0);
        assert_eq!(s["default_prim"], scene.id.as_str());
        let root = format!("/{}", prim_name(&scene.id));
        let xforms = s["counts"]["Xform"].as_u64().unwrap() as usize;
        // Root, Room, Furniture, Zones, Objects, Robot and one per body.
        let bodies = scene.furniture.len() + scene.zones.len() + scene.key_objects.len();
        assert_eq!(xforms, 6 + bodies, "{}: {}", scene.id, s["counts"]);
        let close = |got: &serde_json::Value, want: [f64; 3], what: &str| {
            for k in 0..3 {
                let g = got[k].as_f64().unwrap();
                assert!(
                    (g - want[k]).abs() < 1e-9,
                    "{} {what}: {got} vs {want:?}",
                    scene.id
                );
            }
        };
        for f in &scene.furniture {
            let t = &s["translations"][format!("{root}/Furniture/{}", prim_name(&f.id))];
            close(t, [f.pose[0], f.pose[1], 0.0], &f.id);
            // Each part's world box as USD sizes it: the part's full size, rotated with the item.
            for (i, p) in furniture::parts(scene, f).iter().enumerate() {
                let c = &s["cubes"][format!("{root}/Furniture/{}/part_{i}", prim_name(&f.id))];
                close(c, p.half.map(|h| 2.0 * h), &format!("{} part {i}", f.id));
            }
        }
        for z in &scene.zones {
            let t = &s["translations"][format!("{root}/Zones/{}", prim_name(&z.color))];
            close(t, [z.center[0], z.center[1], z.height], &z.color);
        }
        for o in &scene.key_objects {
            let h = a.catalogue.model(&o.model).unwrap().shape.half_height();
            let t = &s["translations"][format!("{root}/Objects/{}", prim_name(&o.name()))];
            close(t, scene.key_object_start(o, h).unwrap(), &o.name());
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}
