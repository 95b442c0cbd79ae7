//! The benchmark content the server holds in memory: both dataset splits with ground truth, the
//! scenes and the catalogue, read once at start from the configured assets directory.
//!
//! Policy: test ground truth never leaves this module except as scores. The public files are
//! rendered here once (dev with plans, test without) so a download is a memory copy.

use std::collections::HashMap;
use std::path::Path;
use std::sync::Mutex;

use anyhow::Context;
use bytes::Bytes;
use kitchen_r_core::catalogue::Catalogue;
use kitchen_r_core::dataset::{Dataset, Instruction, PublicInstruction, Split};
use kitchen_r_core::scene::Scene;
use serde::Serialize;

use crate::plans::IdIndex;

#[derive(Debug)]
pub struct Content {
    pub dataset: Dataset,
    pub index: IdIndex,
    pub scenes: Vec<Scene>,
    pub catalogue: Catalogue,
    dev_jsonl: Bytes,
    test_jsonl: Bytes,
    /// Rendered top-down PNGs by scene id: drawn on first request, then served from memory.
    topdown: Mutex<HashMap<String, Bytes>>,
}

/// What the scene list shows about a scene.
#[derive(Debug, Clone, Serialize)]
pub struct SceneSummary {
    pub id: String,
    pub name: String,
    pub description: String,
    /// Zone colours, usable in `move to the <colour> zone`.
    pub zones: Vec<String>,
    /// Key object names, usable in `pick the <object>`.
    pub key_objects: Vec<String>,
}

impl Content {
    /// Load `objects.toml`, `scenes/*.toml` and `dataset/` from `assets`.
    pub fn load(assets: &Path) -> anyhow::Result<Content> {
        let catalogue = Catalogue::load(&assets.join("objects.toml"))?;
        let scenes = Scene::load_all(&assets.join("scenes"), &catalogue)?;
        let dataset_dir = assets.join("dataset");
        let dataset = Dataset::load(&dataset_dir).with_context(|| {
            format!(
                "no dataset in {} (generate one with `kitchen-r dataset generate --seed S --out {}`)",
                dataset_dir.display(),
                dataset_dir.display()
            )
        })?;
        Content::new(dataset, scenes, catalogue)
    }

    pub fn new(dataset: Dataset, scenes: Vec<Scene>, catalogue: Catalogue) -> anyhow::Result<Content> {
        for inst in dataset.dev.iter().chain(&dataset.test) {
            anyhow::ensure!(
                scenes.iter().any(|s| s.id == inst.scene),
                "instruction {} refers to unknown scene {:?}",
                inst.id,
                inst.scene
            );
        }
        let index = IdIndex::new(&dataset.dev, &dataset.test);
        let dev_jsonl = jsonl(dataset.dev.iter())?;
        let test_jsonl = jsonl(dataset.test.iter().map(PublicInstruction::from))?;
        Ok(Content {
            dataset,
            index,
            scenes,
            catalogue,
            dev_jsonl,
            test_jsonl,
            topdown: Mutex::default(),
        })
    }

    /// The public file of a split: dev with ground-truth plans, test without.
    pub fn public_jsonl(&self, split: Split) -> Bytes {
        match split {
            Split::Dev => self.dev_jsonl.clone(),
            Split::Test => self.test_jsonl.clone(),
        }
    }

    /// Ground truth of a split: for scoring only.
    pub fn ground_truth(&self, split: Split) -> &[Instruction] {
        self.dataset.split(split)
    }

    pub fn scene(&self, id: &str) -> Option<&Scene> {
        self.scenes.iter().find(|s| s.id == id)
    }

    /// The scene's top-down PNG (zones coloured), rendered once and cached. `None` for an
    /// unknown scene. Rendering is pure CPU work of a few milliseconds, so callers on the async
    /// runtime run it on a blocking thread.
    pub fn topdown_png(&self, id: &str) -> Option<Bytes> {
        if let Some(png) = self.topdown.lock().unwrap_or_else(|p| p.into_inner()).get(id) {
            return Some(png.clone());
        }
        let scene = self.scene(id)?;
        let png = Bytes::from(kitchen_r_core::topdown::render_topdown(
            scene,
            &self.catalogue,
            kitchen_r_core::topdown::DEFAULT_PX_PER_M,
        ));
        self.topdown
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .insert(id.to_string(), png.clone());
        Some(png)
    }

    pub fn scene_summaries(&self) -> Vec<SceneSummary> {
        self.scenes
            .iter()
            .map(|s| SceneSummary {
                id: s.id.clone(),
                name: s.name.clone(),
                description: s.description.clone(),
                zones: s.zones.iter().map(|z| z.color.clone()).collect(),
                key_objects: s.key_objects.iter().map(|o| o.name()).collect(),
            })
            .collect()
    }

    /// Identifies the dataset a score was computed against, for the scoring run's version.
    pub fn dataset_tag(&self) -> String {
        let m = &self.dataset.manifest;
        format!("dataset-seed-{}-gen-{}", m.seed, m.generator_version)
    }
}

fn jsonl<T: Serialize>(items: impl Iterator<Item = T>) -> anyhow::Result<Bytes> {
    let mut out = Vec::new();
    for item in items {
        serde_json::to_writer(&mut out, &item)?;
        out.push(b'\n');
    }
    Ok(out.into())
}
