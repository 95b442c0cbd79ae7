//! The paper's randomisation (Customization and Randomization; BASELINE VALIDATION step 2) of any
//! episode, in particular one built from a dataset instruction: key-object poses within the
//! configured radius of their start point, object colours, floor, wall and furniture colours and
//! patterns, the light, background objects and the robot start.
//!
//! Each aspect is switched in `[randomise]` of `configs/episodes.toml` and drawn from its own
//! ChaCha8 stream seeded from `(seed, aspect)`: the same seed gives the same episode, and switching
//! one aspect off leaves every other aspect's draws as they were. An aspect that is off leaves
//! the episode's value untouched, so with everything off an episode is exactly the one given.
//!
//! Key-object poses are only ever drawn where the episode stays feasible: inside the zone with
//! its margin, clear of the other objects, within the arm's reach from the zone's approach pose,
//! and with every place target of the plan still a free spot (the dataset's own rule,
//! [`kitchen_r_core::dataset::symbolic::check_plan`]). A draw that breaks a rule is redrawn; an
//! object with no valid draw keeps its pose.

use kitchen_r_core::catalogue::Catalogue;
use kitchen_r_core::dataset::symbolic::{Placed, check_plan, fits_in_zone, spot_is_free, spot_is_reachable};
use kitchen_r_core::reach::ArmReach;
use kitchen_r_core::scene::{KeyObject, Scene, Zone};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::config::LightConfig;
use crate::episode::{EpisodeConfig, ObjectPlacement, in_disc};
use crate::error::SimError;
use crate::generator::{EpisodeParams, draw_background, draw_start, generate};
use crate::material::Pattern;
pub use crate::randomise_settings::Randomise;
use crate::seeds::sub_seed;
use crate::world::Style;

/// Draws per object before it keeps its pose.
const POSE_TRIES: usize = 32;
/// Whole layouts tried before the objects keep their poses (the plan check failed each time).
const LAYOUT_TRIES: usize = 8;

/// The independent draw streams, one per aspect.
#[derive(Debug, Clone, Copy)]
enum Aspect {
    RobotStart = 1,
    ObjectPose,
    ObjectColors,
    SceneColors,
    Furniture,
    FloorTile,
    Patterns,
    Light,
    Background,
}

fn stream(seed: u64, aspect: Aspect) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(sub_seed(seed, 0x7261_6e64_0000 + aspect as u64))
}

/// Uniform in `[lo, hi]` (a point range gives its point).
fn uniform(rng: &mut ChaCha8Rng, [lo, hi]: [f64; 2]) -> f64 {
    lo + (hi - lo) * rng.random::<f64>()
}

fn jitter(rng: &mut ChaCha8Rng, c: [f32; 3], j: f32) -> [f32; 3] {
    c.map(|v| (v + (rng.random::<f32>() * 2.0 - 1.0) * j).clamp(0.0, 1.0))
}

/// Randomise `cfg` (an episode of `scene`) with `seed`: every aspect switched on in
/// `p.randomise` is redrawn, the others are left as they are. The collection and evaluation paths
/// call this on episodes built from dataset instructions
/// ([`EpisodeConfig::from_instruction`]); the result is validated.
pub fn randomise(
    cfg: &mut EpisodeConfig,
    scene: &Scene,
    cat: &Catalogue,
    p: &EpisodeParams,
    seed: u64,
) -> Result<(), SimError> {
    let r = &p.randomise;
    r.validate()?;
    if cfg.scene != scene.id {
        return Err(SimError::Episode(format!(
            "config is for scene {:?}, not {:?}",
            cfg.scene, scene.id
        )));
    }
    if r.robot_start {
        cfg.robot_start = draw_start(&mut stream(seed, Aspect::RobotStart), scene, p);
    }
    if r.object_pose {
        object_poses(cfg, scene, cat, p, &mut stream(seed, Aspect::ObjectPose))?;
    }
    if r.colors {
        object_colors(&mut cfg.objects, cat, r, &mut stream(seed, Aspect::ObjectColors));
        let rng = &mut stream(seed, Aspect::SceneColors);
        cfg.style.floor_color = jitter(rng, cfg.style.floor_color, p.color_jitter);
        cfg.style.wall_color = jitter(rng, cfg.style.wall_color, p.color_jitter);
    }
    if r.textures && !p.floor_tiles.is_empty() {
        let rng = &mut stream(seed, Aspect::FloorTile);
        cfg.style.floor_tile = p.floor_tiles[rng.random_range(0..p.floor_tiles.len())];
    }
    looks(&mut cfg.style, scene, p, seed)?;
    if r.background {
        let rng = &mut stream(seed, Aspect::Background);
        cfg.background = draw_background(rng, scene, cat, p, &cfg.objects);
    }
    cfg.validate(scene, cat)
}

/// The looks the generator does not draw: furniture colours (`colors`), floor, wall and furniture
/// patterns (`textures`) and the light (`lights`).
pub fn looks(style: &mut Style, scene: &Scene, p: &EpisodeParams, seed: u64) -> Result<(), SimError> {
    let r = &p.randomise;
    r.validate()?;
    if r.colors {
        let rng = &mut stream(seed, Aspect::Furniture);
        for f in &scene.furniture {
            let c = style.furniture_colors.get(&f.id).copied().unwrap_or(f.color);
            style
                .furniture_colors
                .insert(f.id.clone(), jitter(rng, c, r.furniture_jitter));
        }
    }
    if r.textures {
        patterns(style, r, &mut stream(seed, Aspect::Patterns));
    }
    if r.lights {
        style.light = Some(light(r, &mut stream(seed, Aspect::Light)));
    }
    Ok(())
}

/// Generated episode `index` of the batch drawn with `seed` ([`generate`]) with [`looks`] drawn
/// too: the single-object validation episodes of `kitchen-r episodes generate`.
pub fn generate_varied(
    scene: &Scene,
    cat: &Catalogue,
    p: &EpisodeParams,
    seed: u64,
    index: u64,
) -> Result<EpisodeConfig, SimError> {
    let mut cfg = generate(scene, cat, p, seed, index)?;
    looks(&mut cfg.style, scene, p, cfg.seed)?;
    Ok(cfg)
}

fn patterns(style: &mut Style, r: &Randomise, rng: &mut ChaCha8Rng) {
    let mut contrast = || uniform(rng, r.pattern_contrast.map(f64::from)) as f32;
    let (c1, c2, c3) = (contrast(), contrast(), contrast());
    let size = |rng: &mut ChaCha8Rng, range: [f64; 2]| uniform(rng, range) as f32;
    style.floor_pattern = Some(match rng.random_range(0..3u32) {
        0 => Pattern::Tiles {
            size: style.floor_tile,
            contrast: c1,
        },
        1 => Pattern::Checker {
            size: size(rng, [0.3, 0.6]),
            contrast: c1,
        },
        _ => Pattern::Planks {
            size: size(rng, [0.12, 0.3]),
            contrast: c1,
        },
    });
    style.wall_pattern = Some(match rng.random_range(0..4u32) {
        0 => Pattern::Plain,
        1 => Pattern::Stripes {
            size: size(rng, [0.4, 1.5]),
            contrast: c2,
        },
        2 => Pattern::Checker {
            size: size(rng, [0.15, 0.4]),
            contrast: c2,
        },
        _ => Pattern::Planks {
            size: size(rng, [0.15, 0.4]),
            contrast: c2,
        },
    });
    style.furniture_pattern = Some(match rng.random_range(0..3u32) {
        0 => Pattern::Plain,
        1 => Pattern::Stripes {
            size: size(rng, [0.02, 0.06]),
            contrast: c3,
        },
        _ => Pattern::Planks {
            size: size(rng, [0.06, 0.15]),
            contrast: c3,
        },
    });
}

fn light(r: &Randomise, rng: &mut ChaCha8Rng) -> LightConfig {
    let azimuth = rng.random::<f64>() * std::f64::consts::TAU;
    let elevation = uniform(rng, r.light_elevation_deg).to_radians();
    LightConfig {
        direction: [
            elevation.cos() * azimuth.cos(),
            elevation.cos() * azimuth.sin(),
            elevation.sin(),
        ],
        ambient: uniform(rng, r.ambient),
        diffuse: uniform(rng, r.diffuse),
    }
}

/// Colour variants for objects whose name does not say their colour (`bowl`, not `red cup`) and
/// whose model is the only one of its kind in the episode (so no name becomes ambiguous), then a
/// small jitter for every object.
fn object_colors(objects: &mut [ObjectPlacement], cat: &Catalogue, r: &Randomise, rng: &mut ChaCha8Rng) {
    let models: Vec<String> = objects.iter().map(|o| o.model.clone()).collect();
    for o in objects.iter_mut() {
        let Some(m) = cat.model(&o.model) else { continue };
        let alone = models.iter().filter(|x| **x == o.model).count() == 1;
        let draw = rng.random_range(0..=m.variants.len());
        if o.name == o.model && alone && draw > 0 {
            o.color = m.variants.values().nth(draw - 1).copied().unwrap_or(o.color);
        }
        o.color = jitter(rng, o.color, r.object_color_jitter);
    }
}

/// The zone whose surface `o` stands on, if any.
fn zone_of<'s>(scene: &'s Scene, cat: &Catalogue, o: &ObjectPlacement) -> Option<&'s Zone> {
    let hh = cat.model(&o.model)?.shape.half_height();
    scene.zones.iter().find(|z| {
        (0..2).all(|i| (o.position[i] - z.center[i]).abs() <= z.size[i] / 2.0 + 1e-6)
            && (o.position[2] - (z.height + hh)).abs() < 0.02
    })
}

/// `scene` with its key objects replaced by `objects` (each in zone `zones[i]`), for the plan
/// check.
fn with_objects(scene: &Scene, objects: &[ObjectPlacement], zones: &[&Zone]) -> Scene {
    let mut s = scene.clone();
    s.key_objects = objects
        .iter()
        .zip(zones)
        .map(|(o, z)| {
            let variant = o
                .name
                .strip_suffix(o.model.as_str())
                .map(str::trim)
                .filter(|v| !v.is_empty())
                .map(String::from);
            KeyObject {
                model: o.model.clone(),
                variant,
                zone: z.color.clone(),
                offset: [o.position[0] - z.center[0], o.position[1] - z.center[1]],
                yaw: o.yaw,
            }
        })
        .collect();
    s
}

/// Key-object poses within `p.radius` of where they are, feasible for the plan (module docs).
fn object_poses(
    cfg: &mut EpisodeConfig,
    scene: &Scene,
    cat: &Catalogue,
    p: &EpisodeParams,
    rng: &mut ChaCha8Rng,
) -> Result<(), SimError> {
    let Some(zones) = cfg
        .objects
        .iter()
        .map(|o| zone_of(scene, cat, o))
        .collect::<Option<Vec<&Zone>>>()
    else {
        // An object off every zone (a hand-made episode): nothing to draw around.
        return Ok(());
    };
    let arm = ArmReach::committed().map_err(SimError::Config)?;
    let checked = |objects: &[ObjectPlacement]| {
        check_plan(
            &with_objects(scene, objects, &zones),
            cat,
            &cfg.plan,
            &cfg.place_targets,
        )
        .is_ok()
    };
    let plan_checked = checked(&cfg.objects);
    let yaw_range = p.randomise.yaw_range_deg.to_radians();
    for _ in 0..LAYOUT_TRIES {
        let mut drawn: Vec<ObjectPlacement> = Vec::with_capacity(cfg.objects.len());
        for (i, o) in cfg.objects.iter().enumerate() {
            let m = cat
                .model(&o.model)
                .ok_or_else(|| SimError::UnknownObject(o.model.clone()))?;
            let placed = Placed::of(m);
            let z = zones[i];
            // Objects drawn already, and those still at their given pose, in this zone.
            let others: Vec<([f64; 2], f64)> = (drawn.iter().chain(&cfg.objects[i + 1..]))
                .enumerate()
                .filter(|(j, _)| zones[if *j < i { *j } else { *j + 1 }].color == z.color)
                .filter_map(|(_, x)| {
                    let r = cat.model(&x.model)?.shape.footprint_radius();
                    Some(([x.position[0], x.position[1]], r))
                })
                .collect();
            let mut next = o.clone();
            for _ in 0..POSE_TRIES {
                let d = in_disc(rng, p.radius);
                let xy = [o.position[0] + d[0], o.position[1] + d[1]];
                let yaw = o.yaw + (rng.random::<f64>() * 2.0 - 1.0) * yaw_range;
                let ok = fits_in_zone(z, placed.radius, xy)
                    && spot_is_free(z, placed.radius, &others, xy)
                    && spot_is_reachable(arm, z, &placed, xy);
                if ok {
                    (next.position[0], next.position[1], next.yaw) = (xy[0], xy[1], yaw);
                    break;
                }
            }
            drawn.push(next);
        }
        if !plan_checked || checked(&drawn) {
            cfg.objects = drawn;
            return Ok(());
        }
    }
    Ok(())
}
