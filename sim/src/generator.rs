//! The seeded episode generator (paper, BASELINE VALIDATION steps 1–2) with its distribution
//! parameters from `configs/episodes.toml`: robot start segments, the object set, the five points
//! objects start from and are placed at, the radius around them, colours and background objects.
//! Fixed values in [`Overrides`] replace the corresponding draw. Draws use ChaCha8 seeded per
//! episode from `(seed, index)`, so any episode of a batch can be regenerated alone.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

use kitchen_r_core::catalogue::Catalogue;
use kitchen_r_core::dataset::Instruction;
use kitchen_r_core::dataset::symbolic::{Placed, spot_is_reachable};
use kitchen_r_core::plan::Step;
use kitchen_r_core::reach::ArmReach;
use kitchen_r_core::scene::{Scene, Segment, Zone};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::episode::{
    EpisodeConfig, ObjectPlacement, batch_episode, in_disc, key_object_placement, object_color,
};
use crate::error::{SimError, read_toml};
use crate::randomise_settings::Randomise;
use crate::seeds::sub_seed;
use crate::world::Style;

/// `configs/episodes.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EpisodeParams {
    /// Catalogue models one of which is manipulated per episode.
    pub objects: Vec<String>,
    /// Draw a colour variant of the object (else the model's default colour).
    pub random_variants: bool,
    /// Cycle through `objects` over a batch instead of drawing (uniform object types).
    pub balance_objects: bool,
    /// Radius around the start and goal points (m).
    pub radius: f64,
    /// Inclusive range of background objects per episode.
    pub background_count: [u32; 2],
    /// Max per-channel change of floor and wall colours.
    pub color_jitter: f32,
    /// Floor tile sizes to draw from (m).
    pub floor_tiles: Vec<f32>,
    /// Per scene id: start segments and the five points.
    pub scene: BTreeMap<String, SceneParams>,
    /// Fixed values that replace draws.
    pub fixed: Overrides,
    /// One switch per randomised aspect, and the ranges ([`mod@crate::randomise`]).
    pub randomise: Randomise,
    /// Whole episodes by instruction id (a saved batch, `eval --episodes-file`) that
    /// [`EpisodeConfig::from_instruction`] returns instead of building one. Never read from a
    /// file: only a local run hands its batch in this way.
    #[serde(skip)]
    pub batch: Option<Arc<BTreeMap<String, EpisodeConfig>>>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(default, deny_unknown_fields)]
pub struct SceneParams {
    /// Robot start segments; empty = the scene's `start_segment` list.
    pub start_segments: Vec<Segment>,
    /// Zone colours whose centres are the points; empty = the scene's first five zones.
    pub points: Vec<String>,
}

/// Fixed episode attributes (paper: "attributes can be assigned desired values directly").
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(default, deny_unknown_fields)]
pub struct Overrides {
    pub object: Option<String>,
    pub variant: Option<String>,
    /// Start and goal point (zone colour).
    pub start: Option<String>,
    pub goal: Option<String>,
    pub robot_start: Option<[f64; 3]>,
    pub background_count: Option<u32>,
}

impl Default for EpisodeParams {
    fn default() -> Self {
        EpisodeParams {
            objects: ["apple", "bowl", "cup", "fork", "plate"]
                .map(String::from)
                .to_vec(),
            random_variants: true,
            balance_objects: true,
            radius: 0.05,
            background_count: [2, 5],
            color_jitter: 0.06,
            floor_tiles: vec![0.25, 0.3, 0.4, 0.5],
            scene: BTreeMap::new(),
            fixed: Overrides::default(),
            randomise: Randomise::default(),
            batch: None,
        }
    }
}

impl EpisodeParams {
    pub fn load(path: &Path) -> Result<EpisodeParams, SimError> {
        let p: EpisodeParams = read_toml(path)?;
        p.randomise.validate()?;
        Ok(p)
    }

    /// `configs/episodes.toml` when present, else the defaults.
    pub fn load_default() -> Result<EpisodeParams, SimError> {
        let path = crate::config::configs_dir().join("episodes.toml");
        if path.is_file() {
            EpisodeParams::load(&path)
        } else {
            Ok(EpisodeParams::default())
        }
    }

    fn segments<'a>(&'a self, scene: &'a Scene) -> &'a [Segment] {
        match self.scene.get(&scene.id) {
            Some(p) if !p.start_segments.is_empty() => &p.start_segments,
            _ => &scene.start_segments,
        }
    }

    /// The point zones of `scene`.
    pub fn points(&self, scene: &Scene) -> Vec<String> {
        match self.scene.get(&scene.id) {
            Some(p) if !p.points.is_empty() => p.points.clone(),
            _ => scene.zones.iter().take(5).map(|z| z.color.clone()).collect(),
        }
    }
}

/// The robot start when it is not randomised: the fixed one, else the first start segment's
/// midpoint.
pub fn fixed_start(scene: &Scene, p: &EpisodeParams) -> [f64; 3] {
    if let Some(s) = p.fixed.robot_start {
        return s;
    }
    match p.segments(scene).first() {
        Some(s) => [
            (s.from[0] + s.to[0]) / 2.0,
            (s.from[1] + s.to[1]) / 2.0,
            s.heading,
        ],
        None => [scene.room.size[0] / 2.0, scene.room.size[1] / 2.0, 0.0],
    }
}

/// Robot start: uniform over the union of the start segments (by length).
pub fn draw_start(rng: &mut ChaCha8Rng, scene: &Scene, p: &EpisodeParams) -> [f64; 3] {
    if let Some(s) = p.fixed.robot_start {
        return s;
    }
    let segs = p.segments(scene);
    let len = |s: &Segment| (s.to[0] - s.from[0]).hypot(s.to[1] - s.from[1]);
    let total: f64 = segs.iter().map(len).sum();
    let mut u = rng.random::<f64>() * total;
    for s in segs {
        let l = len(s);
        if u <= l || std::ptr::eq(s, segs.last().unwrap_or(s)) {
            let t = if l > 0.0 { (u / l).min(1.0) } else { 0.0 };
            return [
                s.from[0] + t * (s.to[0] - s.from[0]),
                s.from[1] + t * (s.to[1] - s.from[1]),
                s.heading,
            ];
        }
        u -= l;
    }
    [scene.room.size[0] / 2.0, scene.room.size[1] / 2.0, 0.0]
}

/// Background objects on the scene's background areas, not overlapping each other or `keep`.
pub fn draw_background(
    rng: &mut ChaCha8Rng,
    scene: &Scene,
    cat: &Catalogue,
    p: &EpisodeParams,
    keep: &[ObjectPlacement],
) -> Vec<ObjectPlacement> {
    let models: Vec<_> = cat.background_models().collect();
    if models.is_empty() || scene.background_areas.is_empty() {
        return Vec::new();
    }
    let [lo, hi] = p.background_count;
    let n = p
        .fixed
        .background_count
        .unwrap_or_else(|| rng.random_range(lo..=hi.max(lo)));
    let radius = |name: &str| cat.model(name).map_or(0.05, |m| m.shape.footprint_radius());
    let mut placed: Vec<ObjectPlacement> = Vec::new();
    for _ in 0..n {
        let m = models[rng.random_range(0..models.len())];
        let r = m.shape.footprint_radius();
        for _attempt in 0..20 {
            let a = &scene.background_areas[rng.random_range(0..scene.background_areas.len())];
            let (fx, fy) = ((a.size[0] / 2.0 - r).max(0.0), (a.size[1] / 2.0 - r).max(0.0));
            let x = a.center[0] + rng.random_range(-1.0..=1.0) * fx;
            let y = a.center[1] + rng.random_range(-1.0..=1.0) * fy;
            let yaw = rng.random::<f64>() * std::f64::consts::TAU;
            let clear = placed
                .iter()
                .chain(keep)
                .all(|o| (o.position[0] - x).hypot(o.position[1] - y) > r + radius(&o.model) + 0.01);
            if clear {
                let color = m
                    .color
                    .map(|c| (c + rng.random_range(-0.1..=0.1f32)).clamp(0.0, 1.0));
                let position = [x, y, a.height + m.shape.half_height()];
                placed.push(ObjectPlacement {
                    name: m.id.clone(),
                    model: m.id.clone(),
                    color,
                    position,
                    yaw,
                });
                break;
            }
        }
    }
    placed
}

fn pick<'a>(rng: &mut ChaCha8Rng, fixed: &'a Option<String>, from: &'a [String]) -> Option<&'a String> {
    fixed
        .as_ref()
        .or_else(|| (!from.is_empty()).then(|| &from[rng.random_range(0..from.len())]))
}

/// Episode `index` of the batch drawn with `seed` in `scene`. An aspect switched off in
/// `p.randomise` is still drawn (so the other aspects' draws do not move) and then replaced by
/// its fixed value: the zone centres and yaw 0, the default colours, the scene's tile, no
/// background, [`fixed_start`].
pub fn generate(
    scene: &Scene,
    cat: &Catalogue,
    p: &EpisodeParams,
    seed: u64,
    index: u64,
) -> Result<EpisodeConfig, SimError> {
    let episode_seed = sub_seed(seed, index);
    let mut rng = ChaCha8Rng::seed_from_u64(episode_seed);
    let r = &p.randomise;
    let robot_start = match draw_start(&mut rng, scene, p) {
        _ if !r.robot_start => fixed_start(scene, p),
        s => s,
    };
    let model_id = match (&p.fixed.object, p.balance_objects && !p.objects.is_empty()) {
        (Some(o), _) => o.clone(),
        (None, true) => p.objects[(index % p.objects.len() as u64) as usize].clone(),
        (None, false) => pick(&mut rng, &None, &p.objects)
            .cloned()
            .ok_or_else(|| SimError::Config("episodes: empty object set".into()))?,
    };
    let model = cat
        .model(&model_id)
        .ok_or_else(|| SimError::UnknownObject(model_id.clone()))?;
    let variants: Vec<String> = model.variants.keys().cloned().collect();
    let variant = match p.random_variants {
        true => pick(&mut rng, &p.fixed.variant, &variants).cloned(),
        false => None,
    }
    .filter(|_| r.colors)
    .or_else(|| p.fixed.variant.clone());
    let points = p.points(scene);
    if points.len() < 2 {
        return Err(SimError::Config(format!(
            "episodes: scene {:?} needs at least two points",
            scene.id
        )));
    }
    let start = pick(&mut rng, &p.fixed.start, &points)
        .cloned()
        .unwrap_or_default();
    let goals: Vec<String> = points.iter().filter(|z| **z != start).cloned().collect();
    let goal = pick(&mut rng, &p.fixed.goal, &goals).cloned().unwrap_or_default();
    let zone = |c: &str| {
        scene
            .zone(c)
            .ok_or_else(|| SimError::Episode(format!("unknown zone {c:?}")))
    };
    let (zs, zg) = (zone(&start)?, zone(&goal)?);
    let hh = model.shape.half_height();
    let pose = |d: [f64; 2]| if r.object_pose { d } else { [0.0, 0.0] };
    let arm = ArmReach::committed().map_err(SimError::Config)?;
    let placed = Placed::of(model);
    let ds = pose(reachable_near(&mut rng, arm, zs, &placed, p.radius));
    let dg = pose(reachable_near(&mut rng, arm, zg, &placed, p.radius));
    let name = match &variant {
        Some(v) => format!("{v} {}", model.id),
        None => model.id.clone(),
    };
    let object = ObjectPlacement {
        name: name.clone(),
        model: model.id.clone(),
        color: object_color(model, variant.as_deref()),
        position: [zs.center[0] + ds[0], zs.center[1] + ds[1], zs.height + hh],
        yaw: match rng.random::<f64>() * std::f64::consts::TAU {
            _ if !r.object_pose => 0.0,
            yaw => yaw,
        },
    };
    let target = [zg.center[0] + dg[0], zg.center[1] + dg[1], zg.height + hh];
    let plan = [
        Step::MoveTo { zone: start.clone() },
        Step::Pick { object: name.clone() },
        Step::MoveTo { zone: goal.clone() },
        Step::Place { object: name },
    ]
    .iter()
    .map(ToString::to_string)
    .collect();
    let mut style = Style::of(scene);
    let j = p.color_jitter;
    for c in style.floor_color.iter_mut().chain(style.wall_color.iter_mut()) {
        let v = (*c + rng.random_range(-j..=j)).clamp(0.0, 1.0);
        if r.colors {
            *c = v;
        }
    }
    if !p.floor_tiles.is_empty() {
        let tile = p.floor_tiles[rng.random_range(0..p.floor_tiles.len())];
        if r.textures {
            style.floor_tile = tile;
        }
    }
    let objects = vec![object];
    let background = match r.background {
        true => draw_background(&mut rng, scene, cat, p, &objects),
        false => Vec::new(),
    };
    let cfg = EpisodeConfig {
        id: format!("{}-{seed}-{index:04}", scene.id),
        scene: scene.id.clone(),
        seed: episode_seed,
        robot_start,
        objects,
        background,
        style,
        plan,
        place_targets: vec![target],
    };
    cfg.validate(scene, cat)?;
    Ok(cfg)
}

/// Draws before a point falls back to the zone centre.
const REACH_TRIES: usize = 32;

/// An offset in the disc of `radius` around `zone`'s centre from which the arm can pick (and at
/// which it can place) `placed`, seen from the zone's approach pose. A uniform draw, redrawn
/// while out of reach: a shelf's far edge can be, and an episode the robot cannot do measures
/// nothing. The object may overhang the zone's edge (the paper's distribution is the disc).
fn reachable_near(
    rng: &mut ChaCha8Rng,
    arm: &ArmReach,
    zone: &Zone,
    placed: &Placed,
    radius: f64,
) -> [f64; 2] {
    for _ in 0..REACH_TRIES {
        let d = in_disc(rng, radius);
        let xy = [zone.center[0] + d[0], zone.center[1] + d[1]];
        if spot_is_reachable(arm, zone, placed, xy) {
            return d;
        }
    }
    [0.0, 0.0]
}

/// `n` episodes cycling through `scenes`.
pub fn batch(
    scenes: &[Scene],
    cat: &Catalogue,
    p: &EpisodeParams,
    seed: u64,
    n: usize,
) -> Result<Vec<EpisodeConfig>, SimError> {
    if scenes.is_empty() {
        return Err(SimError::Config("no scenes".into()));
    }
    (0..n)
        .map(|i| generate(&scenes[i % scenes.len()], cat, p, seed, i as u64))
        .collect()
}

/// Drawn here, not in `episode.rs`: the episode's data does not depend on how it is drawn.
impl EpisodeConfig {
    /// The episode of a dataset instruction: every key object of the scene at its start, the
    /// instruction's plan and place targets; the robot start and background objects are drawn
    /// with `seed` from `params`. When `params.batch` holds an episode for the instruction's id
    /// (a saved batch run locally), that episode, checked against the instruction.
    pub fn from_instruction(
        ins: &Instruction,
        scene: &Scene,
        cat: &Catalogue,
        params: &EpisodeParams,
        seed: u64,
    ) -> Result<EpisodeConfig, SimError> {
        if ins.scene != scene.id {
            return Err(SimError::Episode(format!(
                "instruction is for scene {:?}, not {:?}",
                ins.scene, scene.id
            )));
        }
        if let Some(cfg) = params.batch.as_ref().and_then(|b| b.get(&ins.id)) {
            return batch_episode(cfg, ins, scene, cat);
        }
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let objects = scene
            .key_objects
            .iter()
            .map(|o| key_object_placement(scene, cat, o))
            .collect::<Result<Vec<_>, _>>()?;
        let cfg = EpisodeConfig {
            id: ins.id.clone(),
            scene: scene.id.clone(),
            seed,
            robot_start: draw_start(&mut rng, scene, params),
            background: draw_background(&mut rng, scene, cat, params, &objects),
            objects,
            style: Style::of(scene),
            plan: ins.plan.clone(),
            place_targets: ins.place_targets.clone(),
        };
        cfg.validate(scene, cat)?;
        Ok(cfg)
    }
}
