//! `kitchen-r sim render`: every camera's RGB and depth from a few robot poses, plus a top-down
//! orthographic view with the zones tinted in their plan colours, written as PNG.

use std::path::{Path, PathBuf};

use kitchen_r_core::scene::Scene;
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::config::{SensorsConfig, SimConfig};
use crate::episode::{EpisodeConfig, key_object_placement};
use crate::error::SimError;
use crate::generator::{EpisodeParams, draw_background, draw_start};
use crate::sensors::camera::{CameraImage, Projection, RenderCtx};
use crate::sensors::png::{write_depth, write_rgb};
use crate::sim::{Assets, Sim};
use crate::types::Action;
use crate::world::Style;

/// Depth that maps to black in depth PNGs (m).
const DEPTH_PNG_RANGE: f32 = 5.0;
/// Top-down resolution (m per pixel).
const TOPDOWN_SCALE: f64 = 0.01;

/// The scene as authored: every key object at its start, background drawn with `seed`, the robot
/// at a drawn start, no plan.
pub fn scene_episode(
    assets: &Assets,
    scene: &Scene,
    params: &EpisodeParams,
    seed: u64,
) -> Result<EpisodeConfig, SimError> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let cat = &assets.catalogue;
    let objects = scene
        .key_objects
        .iter()
        .map(|o| key_object_placement(scene, cat, o))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(EpisodeConfig {
        id: format!("{}-view-{seed}", scene.id),
        scene: scene.id.clone(),
        seed,
        robot_start: draw_start(&mut rng, scene, params),
        background: draw_background(&mut rng, scene, cat, params, &objects),
        objects,
        style: Style::of(scene),
        plan: Vec::new(),
        place_targets: Vec::new(),
    })
}

fn write_pair(img: &CameraImage, dir: &Path, prefix: &str, out: &mut Vec<PathBuf>) -> Result<(), SimError> {
    let rgb = dir.join(format!("{prefix}_{}_rgb.png", img.name));
    let depth = dir.join(format!("{prefix}_{}_depth.png", img.name));
    write_rgb(img, &rgb)?;
    write_depth(img, DEPTH_PNG_RANGE, &depth)?;
    out.extend([rgb, depth]);
    Ok(())
}

/// Render `scene_id` into `out`; returns the files written.
pub fn render_scene(scene_id: &str, out: &Path, seed: u64) -> Result<Vec<PathBuf>, SimError> {
    let assets = Assets::load_default()?;
    let params = EpisodeParams::load_default()?;
    let scene = assets.scene(scene_id)?.clone();
    std::fs::create_dir_all(out).map_err(|source| SimError::Io {
        path: out.to_path_buf(),
        source,
    })?;
    let mut ep = scene_episode(&assets, &scene, &params, seed)?;
    let (mut sim, obs) = Sim::new(
        assets,
        SimConfig::load_default()?,
        SensorsConfig::load_default()?,
        &ep,
    )?;
    let mut written = Vec::new();
    for img in &obs.images {
        write_pair(img, out, "start", &mut written)?;
    }
    let path = out.join("topdown.png");
    write_rgb(&topdown(&sim, &scene), &path)?;
    written.push(path);
    // From every zone's approach point, as a policy would see the work surface.
    for z in &scene.zones {
        ep.robot_start = z.approach;
        sim.reset(&ep)?;
        // Hold the gripper 0.2 m above the zone centre, pointing down, as before a grasp.
        let reach = (z.center[0] - z.approach[0]).hypot(z.center[1] - z.approach[1]);
        let down = [
            std::f64::consts::FRAC_1_SQRT_2,
            0.0,
            std::f64::consts::FRAC_1_SQRT_2,
            0.0,
        ];
        let pregrasp = Action::new(0.0, 0.0, [reach, 0.0, z.height + 0.2], down, 1.0);
        for _ in 0..40 {
            sim.step(&pregrasp, false)?;
        }
        let obs = sim.observe();
        for img in &obs.images {
            write_pair(img, out, &format!("zone_{}", z.color), &mut written)?;
        }
    }
    let sheet = out.join("contact_sheet.png");
    contact_sheet(&written, &sheet)?;
    written.push(sheet);
    Ok(written)
}

/// A contact sheet of a batch: the first base-camera frame (the first camera if none is called
/// `base`) of each of the first `n` episodes, twice enlarged, four to a row, in batch order.
pub fn batch_sheet(batch: &[EpisodeConfig], n: usize, path: &Path) -> Result<(), SimError> {
    let assets = Assets::load_default()?;
    let sensors = SensorsConfig::load_default()?;
    let camera = sensors.cameras.iter().position(|c| c.name == "base").unwrap_or(0);
    let mut sim: Option<Sim> = None;
    let mut tiles = Vec::new();
    for ep in batch.iter().take(n) {
        let obs = match sim.as_mut() {
            Some(s) => s.reset(ep)?,
            None => {
                let (s, obs) = Sim::new(assets.clone(), SimConfig::load_default()?, sensors.clone(), ep)?;
                sim = Some(s);
                obs
            }
        };
        let img = obs
            .images
            .get(camera)
            .ok_or_else(|| SimError::Config("configs/sensors.toml has no camera".into()))?;
        tiles.push(image::RgbImage::from_raw(img.width, img.height, img.rgb.clone()).unwrap_or_default());
    }
    tile(&tiles, 2, path)
}

/// `tiles` enlarged `scale` times, four to a row.
fn tile(tiles: &[image::RgbImage], scale: u32, path: &Path) -> Result<(), SimError> {
    let Some(first) = tiles.first() else { return Ok(()) };
    let (w, h) = (first.width() * scale, first.height() * scale);
    let cols = (tiles.len() as u32).min(4);
    let rows = (tiles.len() as u32).div_ceil(cols);
    let mut sheet = image::RgbImage::new(w * cols, h * rows);
    for (i, t) in tiles.iter().enumerate() {
        let big = image::imageops::resize(t, w, h, image::imageops::FilterType::Nearest);
        let (x, y) = ((i as u32 % cols) * w, (i as u32 / cols) * h);
        image::imageops::replace(&mut sheet, &big, i64::from(x), i64::from(y));
    }
    sheet.save(path).map_err(|e| SimError::Image {
        path: path.to_path_buf(),
        message: e.to_string(),
    })
}

/// Every camera RGB image written so far, three times enlarged, tiled four to a row.
fn contact_sheet(files: &[PathBuf], path: &Path) -> Result<(), SimError> {
    let err = |p: &Path, e: image::ImageError| SimError::Image {
        path: p.to_path_buf(),
        message: e.to_string(),
    };
    let tiles = files
        .iter()
        .filter(|p| p.to_string_lossy().ends_with("_rgb.png"))
        .map(|p| image::open(p).map_err(|e| err(p, e)))
        .collect::<Result<Vec<_>, _>>()?;
    let tiles: Vec<image::RgbImage> = tiles.iter().map(|t| t.to_rgb8()).collect();
    tile(&tiles, 3, path)
}

/// Orthographic view from above, north up, zones tinted with their top-down colours.
pub fn topdown(sim: &Sim, scene: &Scene) -> CameraImage {
    let t = scene.room.wall_thickness;
    let [rx, ry] = scene.room.size;
    let (w, h) = (
        ((rx + 2.0 * t) / TOPDOWN_SCALE) as u32,
        ((ry + 2.0 * t) / TOPDOWN_SCALE) as u32,
    );
    let top = scene.room.wall_height + 1.0;
    // Camera x looks down, image left is west (-x), image up is north (+y).
    let m = Matrix3::from_columns(&[
        -nalgebra::Vector3::z(),
        -nalgebra::Vector3::x(),
        nalgebra::Vector3::y(),
    ]);
    let rot = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m));
    let pose = Isometry3::from_parts(Translation3::new(rx / 2.0, ry / 2.0, top), rot);
    let ctx = RenderCtx {
        world: &sim.world,
        materials: &sim.materials.list,
        light: sim.light(),
    };
    let mut img = ctx.render(
        "topdown",
        &pose,
        Projection::Ortho { scale: TOPDOWN_SCALE },
        w,
        h,
        top + 1.0,
    );
    for v in 0..h {
        for u in 0..w {
            let i = (v * w + u) as usize;
            let x = rx / 2.0 + (f64::from(u) + 0.5 - f64::from(w) / 2.0) * TOPDOWN_SCALE;
            let y = ry / 2.0 - (f64::from(v) + 0.5 - f64::from(h) / 2.0) * TOPDOWN_SCALE;
            let z = top - f64::from(img.depth[i]);
            for zone in &scene.zones {
                let inside = (x - zone.center[0]).abs() <= zone.size[0] / 2.0
                    && (y - zone.center[1]).abs() <= zone.size[1] / 2.0
                    && (z - zone.height).abs() < 0.03;
                if inside {
                    for k in 0..3 {
                        let c = f32::from(img.rgb[i * 3 + k]) / 255.0;
                        img.rgb[i * 3 + k] = ((c * 0.4 + zone.rgb[k] * 0.6) * 255.0) as u8;
                    }
                }
            }
        }
    }
    img
}
