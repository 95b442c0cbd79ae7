//! Episode configurations (paper, BASELINE VALIDATION steps 1–2).
//!
//! An [`EpisodeConfig`] is the complete initial state of one episode: scene, robot start, every
//! object with its model, colour and pose, floor and wall looks, the ground-truth plan and the
//! place targets. [`Sim::reset`](crate::Sim::reset) reads nothing else, so a saved batch replays
//! exactly. Configs come from the seeded generator in [`crate::generator`] (distribution in
//! `configs/episodes.toml`) or from a dataset instruction ([`EpisodeConfig::from_instruction`]).

use std::path::Path;

use kitchen_r_core::catalogue::{Catalogue, ObjectModel};
use kitchen_r_core::dataset::Instruction;
use kitchen_r_core::plan::parse_plan;
use kitchen_r_core::scene::{KeyObject, Scene};
use rand::RngExt;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::error::SimError;
use crate::world::Style;

/// One object's initial state.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ObjectPlacement {
    /// Name used in plans (`red cup`, `bowl`); background objects use their model id.
    pub name: String,
    /// Catalogue model id.
    pub model: String,
    /// sRGB in [0, 1].
    pub color: [f32; 3],
    /// World position of the object's centre (m).
    pub position: [f64; 3],
    /// Rotation about z (rad).
    pub yaw: f64,
}

/// The initial state and task of one episode.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpisodeConfig {
    pub id: String,
    pub scene: String,
    /// Seed the configuration was drawn with (kept for the record; reset is fully determined by
    /// the other fields).
    pub seed: u64,
    /// Base centre `[x, y, yaw]`.
    pub robot_start: [f64; 3],
    /// Key objects, in the order plans and success checks index them.
    pub objects: Vec<ObjectPlacement>,
    pub background: Vec<ObjectPlacement>,
    pub style: Style,
    /// Canonical plan steps (`move to the blue zone`, ...).
    pub plan: Vec<String>,
    /// For each `place` step, in order: where the object's centre must end (world, m).
    pub place_targets: Vec<[f64; 3]>,
}

/// Colour of `model` under an optional variant name.
pub fn object_color(model: &ObjectModel, variant: Option<&str>) -> [f32; 3] {
    variant
        .and_then(|v| model.variants.get(v).copied())
        .unwrap_or(model.color)
}

/// The scene's key object start as a placement.
pub fn key_object_placement(
    scene: &Scene,
    cat: &Catalogue,
    o: &KeyObject,
) -> Result<ObjectPlacement, SimError> {
    let model = cat
        .model(&o.model)
        .ok_or_else(|| SimError::UnknownObject(o.model.clone()))?;
    let position = scene
        .key_object_start(o, model.shape.half_height())
        .ok_or_else(|| SimError::Episode(format!("{}: unknown zone {:?}", o.name(), o.zone)))?;
    Ok(ObjectPlacement {
        name: o.name(),
        model: o.model.clone(),
        color: object_color(model, o.variant.as_deref()),
        position,
        yaw: o.yaw,
    })
}

impl EpisodeConfig {
    /// Check the config against its scene and the catalogue.
    pub fn validate(&self, scene: &Scene, cat: &Catalogue) -> Result<(), SimError> {
        let bad = |m: String| Err(SimError::Episode(m));
        if self.scene != scene.id {
            return bad(format!("config is for scene {:?}", self.scene));
        }
        for o in self.objects.iter().chain(&self.background) {
            if cat.model(&o.model).is_none() {
                return Err(SimError::UnknownObject(o.model.clone()));
            }
            if o.position
                .iter()
                .chain(std::iter::once(&o.yaw))
                .any(|v| !v.is_finite())
            {
                return bad(format!("object {:?} has a non-finite pose", o.name));
            }
        }
        let steps = parse_plan(&self.plan)?;
        let places = steps
            .iter()
            .filter(|s| matches!(s, kitchen_r_core::plan::Step::Place { .. }))
            .count();
        if places != self.place_targets.len() {
            return bad(format!(
                "{places} place steps but {} place targets",
                self.place_targets.len()
            ));
        }
        for s in &steps {
            if let Some(name) = s.object()
                && !self.objects.iter().any(|o| o.name == name)
            {
                return bad(format!("plan step {s} names an object not in the episode"));
            }
            if let kitchen_r_core::plan::Step::MoveTo { zone } = s
                && scene.zone(zone).is_none()
            {
                return bad(format!("plan step {s} names a zone not in the scene"));
            }
        }
        Ok(())
    }
}

/// A saved batch's episode for `ins`: it must be the instruction's task in its scene.
pub(crate) fn batch_episode(
    cfg: &EpisodeConfig,
    ins: &Instruction,
    scene: &Scene,
    cat: &Catalogue,
) -> Result<EpisodeConfig, SimError> {
    if cfg.scene != ins.scene || cfg.plan != ins.plan || cfg.place_targets != ins.place_targets {
        return Err(SimError::Episode(format!(
            "the batch's episode {:?} is not the task of instruction {:?}",
            cfg.id, ins.id
        )));
    }
    cfg.validate(scene, cat)?;
    Ok(cfg.clone())
}

/// The instruction an episode's task amounts to (id, scene, plan, place targets), for paths that
/// take instructions (a policy endpoint's jobs).
pub fn as_instruction(cfg: &EpisodeConfig) -> Instruction {
    Instruction {
        id: cfg.id.clone(),
        scene: cfg.scene.clone(),
        instruction: String::new(),
        plan: cfg.plan.clone(),
        template: String::new(),
        place_targets: cfg.place_targets.clone(),
    }
}

/// Save a batch as pretty JSON.
pub fn save_batch(batch: &[EpisodeConfig], path: &Path) -> Result<(), SimError> {
    let text = serde_json::to_string_pretty(batch).map_err(|e| SimError::Parse {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    std::fs::write(path, text).map_err(|source| SimError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Load a batch saved by [`save_batch`].
pub fn load_batch(path: &Path) -> Result<Vec<EpisodeConfig>, SimError> {
    let text = std::fs::read_to_string(path).map_err(|source| SimError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    serde_json::from_str(&text).map_err(|e| SimError::Parse {
        path: path.to_path_buf(),
        message: e.to_string(),
    })
}

/// A uniform draw in the disc of radius `r`.
pub(crate) fn in_disc(rng: &mut ChaCha8Rng, r: f64) -> [f64; 2] {
    let rho = r * rng.random::<f64>().sqrt();
    let a = rng.random::<f64>() * std::f64::consts::TAU;
    [rho * a.cos(), rho * a.sin()]
}
