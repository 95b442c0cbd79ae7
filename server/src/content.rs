//! The benchmark content the server holds in memory: both dataset splits with ground truth, the
//! scenes and the catalogue, read once at start.
//!
//! The dev split always comes from the assets directory (public, with plans). The test split is
//! either the repository's *public sample* (`<assets>/dataset`, whose answers anyone can rebuild
//! from public files: labelled as such wherever it shows) or an organiser's *private test set*
//! (`serve --test-set DIR`, generated outside the repository with private phrasings and a secret
//! seed). In contest mode the server refuses to start on anything but a private set.
//!
//! Policy: test ground truth never leaves this module except as scores and as the episodes
//! handed to simulation workers. The public files are rendered here once (dev with plans, test
//! without) so a download is a memory copy.

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

/// What kind of test split the server holds.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum TestSetKind {
    /// Generated from public phrasings and/or a published seed: its answers are public.
    PublicSample,
    /// Generated with private phrasings and a seed that is not recorded.
    Private,
}

/// The test split's provenance, as `GET /api/v1/dataset/manifest` and the start-up line show it.
#[derive(Debug, Clone, PartialEq, Serialize, utoipa::ToSchema)]
pub struct TestSetInfo {
    pub kind: TestSetKind,
    pub instructions: usize,
    /// A human sentence: what the set is and whether it can run a contest.
    pub notice: String,
    /// sha256 of the private phrasings file the set was generated with (never the phrasings).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub phrasings_sha256: Option<String>,
    /// Identifies the set scores were computed against (a digest; for a private set, of its
    /// public parts only: see `ground_truth_digest`).
    pub version: String,
}

/// The notice shown wherever a public sample is served.
pub(crate) const PUBLIC_SAMPLE_NOTICE: &str = "public sample: its answers are public; not for a contest";

#[derive(Debug)]
pub(crate) struct Content {
    pub dataset: Dataset,
    pub test_set: TestSetInfo,
    pub index: IdIndex,
    pub scenes: Vec<Scene>,
    pub catalogue: Catalogue,
    dev_jsonl: Bytes,
    test_jsonl: Bytes,
    /// Rendered top-down PNGs by scene id: drawn on first request, then served from memory.
    topdown: Mutex<HashMap<String, Bytes>>,
}

/// What the scene list shows about a scene.
#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub(crate) struct SceneSummary {
    pub id: String,
    pub name: String,
    pub description: String,
    /// Zone colours, usable in `move to the <colour> zone`.
    pub zones: Vec<String>,
    /// Key object names, usable in `pick the <object>`.
    pub key_objects: Vec<String>,
}

impl Content {
    /// Load `objects.toml`, `scenes/*.toml` and `dataset/` from `assets`; the test split from
    /// `test_set` (a directory written by `kitchen-r dataset generate`) when given.
    pub(crate) fn load(assets: &Path, test_set: Option<&Path>) -> anyhow::Result<Content> {
        let catalogue = Catalogue::load(&assets.join("objects.toml"))?;
        let scenes = Scene::load_all(&assets.join("scenes"), &catalogue)?;
        let dataset_dir = assets.join("dataset");
        let mut dataset = Dataset::load(&dataset_dir).with_context(|| {
            format!(
                "no dataset in {} (generate one with `kitchen-r dataset generate --seed S --out {}`)",
                dataset_dir.display(),
                dataset_dir.display()
            )
        })?;
        if let Some(dir) = test_set {
            let private = Dataset::load(dir).with_context(|| {
                format!(
                    "reading the test set {} (it needs test_ground_truth.jsonl and \
                     manifest.json as `kitchen-r dataset generate --out DIR` writes them)",
                    dir.display()
                )
            })?;
            // The manifest describes where the test split came from.
            dataset.test = private.test;
            dataset.manifest = private.manifest;
        }
        Content::new(dataset, scenes, catalogue)
    }

    pub(crate) fn new(dataset: Dataset, scenes: Vec<Scene>, catalogue: Catalogue) -> anyhow::Result<Content> {
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
        let test_set = test_set_info(&dataset);
        Ok(Content {
            dataset,
            test_set,
            index,
            scenes,
            catalogue,
            dev_jsonl,
            test_jsonl,
            topdown: Mutex::default(),
        })
    }

    /// Refuse to run a contest on a test set whose answers can be rebuilt from public material.
    pub(crate) fn check_contest_ready(&self) -> anyhow::Result<()> {
        match self.test_set.kind {
            TestSetKind::Private => Ok(()),
            TestSetKind::PublicSample => anyhow::bail!(
                "contest = true, but the test split is a public sample ({}): its answers can be \
                 rebuilt from public files. Generate a private set outside the repository with \
                 `kitchen-r dataset generate --seed <secret> --phrasings <private file> --out DIR`, \
                 check it with `kitchen-r dataset audit DIR`, then serve it with \
                 `--test-set DIR` (see docs/private-test-set.md)",
                self.test_set.notice
            ),
        }
    }

    /// The public file of a split: dev with ground-truth plans, test without.
    pub(crate) fn public_jsonl(&self, split: Split) -> Bytes {
        match split {
            Split::Dev => self.dev_jsonl.clone(),
            Split::Test => self.test_jsonl.clone(),
        }
    }

    /// Ground truth of a split: for scoring only.
    /// Whether `id` names a test-split instruction.
    pub(crate) fn is_test(&self, id: &str) -> bool {
        self.ground_truth(Split::Test).iter().any(|i| i.id == id)
    }

    pub(crate) fn ground_truth(&self, split: Split) -> &[Instruction] {
        self.dataset.split(split)
    }

    pub(crate) fn scene(&self, id: &str) -> Option<&Scene> {
        self.scenes.iter().find(|s| s.id == id)
    }

    /// The scene's top-down PNG (zones coloured), rendered once and cached. `None` for an
    /// unknown scene. Rendering is pure CPU work of a few milliseconds, so callers on the async
    /// runtime run it on a blocking thread.
    pub(crate) fn topdown_png(&self, id: &str) -> Option<Bytes> {
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

    /// An episode's path drawn over `scene`'s top-down map; `None` for an unknown scene.
    pub(crate) fn path_png(&self, scene: &str, plot: &kitchen_r_core::topdown::PathPlot) -> Option<Vec<u8>> {
        let scene = self.scene(scene)?;
        Some(kitchen_r_core::topdown::render_path_plot(
            scene,
            &self.catalogue,
            kitchen_r_core::topdown::DEFAULT_PX_PER_M,
            plot,
        ))
    }

    pub(crate) fn scene_summaries(&self) -> Vec<SceneSummary> {
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

    /// Identifies the ground truth a score was computed against, for the scoring run's version
    /// ([`ground_truth_digest`]): a regenerated or fixed set gives a new tag, which a rescore
    /// records.
    pub(crate) fn dataset_tag(&self) -> String {
        format!("dataset-{}", self.test_set.version)
    }
}

/// The provenance of the test split from the manifest (`Dataset::load` has checked that a
/// private set records its phrasings' digest and no seed).
fn test_set_info(dataset: &Dataset) -> TestSetInfo {
    let m = &dataset.manifest;
    let (kind, notice) = match m.is_private() {
        true => (
            TestSetKind::Private,
            "private test set: generated outside the repository with private phrasings".to_string(),
        ),
        false => (TestSetKind::PublicSample, PUBLIC_SAMPLE_NOTICE.to_string()),
    };
    TestSetInfo {
        phrasings_sha256: m.private_phrasings.as_ref().map(|p| p.sha256.clone()),
        version: ground_truth_digest(dataset, kind == TestSetKind::PublicSample),
        kind,
        instructions: dataset.test.len(),
        notice,
    }
}

/// First 16 hex digits of the sha256 of the dev ground truth and the test split. The test plans
/// and place targets go in only when they are public anyway: every team sees this digest (in
/// the manifest route and in scorer versions), and a digest of hidden answers would let anyone
/// confirm a guessed answer set offline. A private set's tag still changes with its instructions.
fn ground_truth_digest(dataset: &Dataset, test_answers_public: bool) -> String {
    use sha2::{Digest, Sha256};
    let mut h = Sha256::new();
    for i in &dataset.dev {
        h.update(
            serde_json::to_vec(&(&i.id, &i.scene, &i.instruction, &i.plan, &i.place_targets))
                .unwrap_or_default(),
        );
        h.update(b"\n");
    }
    for i in &dataset.test {
        let answers = test_answers_public.then_some((&i.plan, &i.place_targets));
        h.update(serde_json::to_vec(&(&i.id, &i.scene, &i.instruction, answers)).unwrap_or_default());
        h.update(b"\n");
    }
    hex::encode(h.finalize())[..16].to_string()
}

fn jsonl<T: Serialize>(items: impl Iterator<Item = T>) -> anyhow::Result<Bytes> {
    let mut out = Vec::new();
    for item in items {
        serde_json::to_writer(&mut out, &item)?;
        out.push(b'\n');
    }
    Ok(out.into())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn assets() -> std::path::PathBuf {
        kitchen_r_core::assets::assets_dir()
    }

    #[test]
    fn the_repository_test_split_is_a_public_sample_and_cannot_run_a_contest() {
        let c = Content::load(&assets(), None).unwrap();
        assert_eq!(c.test_set.kind, TestSetKind::PublicSample);
        assert_eq!(c.test_set.notice, PUBLIC_SAMPLE_NOTICE);
        let e = c.check_contest_ready().unwrap_err().to_string();
        assert!(e.contains("public sample") && e.contains("--test-set"), "{e}");
    }

    #[test]
    fn a_private_set_is_served_instead_of_the_public_sample() {
        let dir = tempfile::tempdir().unwrap();
        let public = assets().join("dataset");
        let gt = std::fs::read_to_string(public.join("test_ground_truth.jsonl")).unwrap();
        let two: String = gt.lines().take(2).map(|l| format!("{l}\n")).collect();
        std::fs::write(dir.path().join("test_ground_truth.jsonl"), two).unwrap();
        std::fs::write(dir.path().join("dev.jsonl"), "").unwrap();
        let manifest = |extra: &str| {
            format!(
                r#"{{"kind": "private", {extra} "generator_version": 3, "templates": 58, "dev": 0, "test": 2,
                "private_phrasings": {{"templates": 1, "phrasings": 4, "sha256": "{}"}}}}"#,
                "a".repeat(64)
            )
        };
        std::fs::write(dir.path().join("manifest.json"), manifest("")).unwrap();
        let c = Content::load(&assets(), Some(dir.path())).unwrap();
        assert_eq!(c.test_set.kind, TestSetKind::Private);
        assert_eq!(c.ground_truth(Split::Test).len(), 2);
        assert!(
            c.ground_truth(Split::Dev).len() > 100,
            "dev stays the public split"
        );
        c.check_contest_ready().unwrap();
        let public = Content::load(&assets(), None).unwrap();
        assert_ne!(c.dataset_tag(), public.dataset_tag());
        // A set that records its seed is not private, whatever its kind says.
        std::fs::write(dir.path().join("manifest.json"), manifest(r#""seed": 7,"#)).unwrap();
        let e = format!("{:#}", Content::load(&assets(), Some(dir.path())).unwrap_err());
        assert!(e.contains("seed"), "{e}");
    }
}
