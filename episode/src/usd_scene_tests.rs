//! A scene read from `.usda` (docs/twin/scenes.md): kitchen_a exported by `kitchen-r sim export
//! --usd` and named by a scene file (`usd = "…"`, `scale`) reads back as the same scene, passes
//! the same content checks as the TOML scenes, and the oracle completes a whole dev instruction
//! in it. Here rather than in `sim` because the oracle policy lives in this crate.

use std::path::PathBuf;

use kitchen_r_core::dataset::Split;
use kitchen_r_core::scene::{BoxPart, Scene};
use kitchen_r_sim::Assets;
use kitchen_r_sim::usd_export::scene_usda;

use crate::eval::{episode_configs, instructions};

/// A fresh assets directory: the committed catalogue and robot, and scene files written by
/// `scenes` as (file name, contents).
fn assets_dir(tag: &str, scenes: &[(&str, String)]) -> PathBuf {
    let src = kitchen_r_core::assets::assets_dir();
    let dir = std::env::temp_dir().join(format!("kitchen-r-usd-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(dir.join("scenes")).unwrap();
    std::fs::copy(src.join("objects.toml"), dir.join("objects.toml")).unwrap();
    crate::test_oracle::copy_shipped_robot(&src, &dir);
    for (name, text) in scenes {
        std::fs::write(dir.join("scenes").join(name), text).unwrap();
    }
    dir
}

fn kitchen_a_usda(assets: &Assets) -> String {
    scene_usda(
        assets.scene("kitchen_a").unwrap(),
        &assets.catalogue,
        &assets.robot,
    )
    .unwrap()
}

/// `read` is `want` up to float rounding of yaws and object offsets (read back from
/// quaternions and world positions), with the furniture's derived boxes as its own parts.
fn assert_same_scene(read: &Scene, want: &Scene) {
    let mut r = read.clone();
    assert_eq!(r.id, "kitchen_usd");
    r.id = want.id.clone();
    for (f, w) in r.furniture.iter_mut().zip(&want.furniture) {
        let derived: Vec<BoxPart> = kitchen_r_sim::furniture::parts(want, w)
            .into_iter()
            .map(|p| BoxPart {
                center: p.center,
                size: p.half.map(|h| 2.0 * h),
                color: p.color,
                decoration: p.decoration,
            })
            .collect();
        assert_eq!(f.parts, derived, "{}", f.id);
        f.parts.clear();
        for k in 0..3 {
            assert!(
                (f.pose[k] - w.pose[k]).abs() < 1e-12,
                "{}: {:?} vs {:?}",
                f.id,
                f.pose,
                w.pose
            );
        }
        f.pose = w.pose;
    }
    for (o, w) in r.key_objects.iter_mut().zip(&want.key_objects) {
        assert!((o.offset[0] - w.offset[0]).abs() < 1e-12 && (o.offset[1] - w.offset[1]).abs() < 1e-12);
        assert!((o.yaw - w.yaw).abs() < 1e-12, "{}", o.name());
        (o.offset, o.yaw) = (w.offset, w.yaw);
    }
    assert_eq!(&r, want);
}

#[test]
fn a_usd_scene_reads_back_passes_the_content_checks_and_the_oracle_completes_an_instruction() {
    let committed = Assets::load_default().unwrap();
    let dir = assets_dir(
        "oracle",
        &[
            ("kitchen_usd.usda", kitchen_a_usda(&committed)),
            (
                "kitchen_usd.toml",
                "usd = \"kitchen_usd.usda\"\nscale = 1.0\n".into(),
            ),
        ],
    );
    let assets = Assets::load(&dir).unwrap();
    let scene = assets.scene("kitchen_usd").unwrap();
    assert_same_scene(scene, committed.scene("kitchen_a").unwrap());
    // The checks every committed scene passes: zones over their furniture at a surface height,
    // approach points on free floor, every zone and start reachable with clearance.
    scene.check_layout().unwrap();
    scene.check_contents(&assets.catalogue).unwrap();

    let dev = instructions(Split::Dev, None).unwrap();
    let mut ins = dev
        .into_iter()
        .filter(|i| i.scene == "kitchen_a")
        .max_by_key(|i| i.plan.len())
        .unwrap();
    ins.scene = "kitchen_usd".into();
    let cfg = &episode_configs(&assets, std::slice::from_ref(&ins), 0, None).unwrap()[0];
    crate::test_oracle::assert_oracle_completes(&assets, cfg, &ins);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn the_scale_setting_multiplies_every_length_and_defaults_to_meters_per_unit() {
    let committed = Assets::load_default().unwrap();
    let text = kitchen_a_usda(&committed);
    let half = text.replacen("metersPerUnit = 1", "metersPerUnit = 0.5", 1);
    let dir = assets_dir(
        "scale",
        &[
            ("kitchen.usda", text),
            ("half.usda", half),
            ("one.toml", "usd = \"kitchen.usda\"\n".into()),
            ("two.toml", "usd = \"kitchen.usda\"\nscale = 2.0\n".into()),
            ("half.toml", "usd = \"half.usda\"\n".into()),
            ("half_two.toml", "usd = \"half.usda\"\nscale = 2\n".into()),
        ],
    );
    let assets = Assets::load(&dir).unwrap();
    let [one, two, half, half_two] = ["one", "two", "half", "half_two"].map(|id| assets.scene(id).unwrap());
    // Doubling is exact in binary floating point, so the comparison can be exact.
    let doubled = |s: &Scene| {
        let mut s = s.clone();
        s.room.size = s.room.size.map(|v| v * 2.0);
        s.room.wall_height *= 2.0;
        s.room.wall_thickness *= 2.0;
        for f in &mut s.furniture {
            f.pose = [f.pose[0] * 2.0, f.pose[1] * 2.0, f.pose[2]];
            f.size = f.size.map(|v| v * 2.0);
            f.levels.iter_mut().for_each(|l| *l *= 2.0);
            for p in &mut f.parts {
                p.center = p.center.map(|v| v * 2.0);
                p.size = p.size.map(|v| v * 2.0);
            }
        }
        for z in &mut s.zones {
            z.center = z.center.map(|v| v * 2.0);
            z.size = z.size.map(|v| v * 2.0);
            z.height *= 2.0;
            z.approach = [z.approach[0] * 2.0, z.approach[1] * 2.0, z.approach[2]];
        }
        for o in &mut s.key_objects {
            o.offset = o.offset.map(|v| v * 2.0);
        }
        for g in &mut s.start_segments {
            (g.from, g.to) = (g.from.map(|v| v * 2.0), g.to.map(|v| v * 2.0));
        }
        for a in &mut s.background_areas {
            (a.center, a.size, a.height) =
                (a.center.map(|v| v * 2.0), a.size.map(|v| v * 2.0), a.height * 2.0);
        }
        s.id = "two".into();
        s
    };
    assert_eq!(*two, doubled(one));
    // Without `scale`, the file's metersPerUnit is the scale; `scale` overrides it.
    let mut h = doubled(half);
    h.id = "one".into();
    assert_eq!(h, *one);
    let mut h2 = half_two.clone();
    h2.id = "two".into();
    assert_eq!(h2, *two);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_malformed_usd_scene_is_refused_naming_the_file_and_line() {
    let committed = Assets::load_default().unwrap();
    let text = kitchen_a_usda(&committed);
    // Break the kind of the first furniture item and drop a closing brace elsewhere.
    let bad_kind = text.replacen("kitchenr:kind = \"fridge\"", "kitchenr:kind = \"fridg\"", 1);
    let line = bad_kind.lines().position(|l| l.contains("\"fridg\"")).unwrap() + 1;
    for (name, usda, want) in [
        (
            "kind",
            bad_kind,
            format!("line {line}: furniture \"fridge\": unknown kitchenr:kind \"fridg\""),
        ),
        (
            "header",
            text.replacen("#usda 1.0", "#usda 2.0", 1),
            "line 1: not USD ASCII".into(),
        ),
    ] {
        let dir = assets_dir(
            &format!("bad-{name}"),
            &[("k.usda", usda), ("k.toml", "usd = \"k.usda\"\n".into())],
        );
        let err = Assets::load(&dir).unwrap_err().to_string();
        assert!(err.contains("k.usda") && err.contains(&want), "{name}: {err}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
