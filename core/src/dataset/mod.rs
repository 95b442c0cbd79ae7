//! The instruction dataset and its on-disk layout (`assets/dataset/`).
//!
//! Files (JSON Lines, one record per line, sorted by id):
//! - `dev.jsonl`: public dev split with ground truth: [`Instruction`] records.
//! - `test.jsonl`: public test split *without* plans: [`PublicInstruction`] records.
//! - `test_ground_truth.jsonl`: test ground truth ([`Instruction`] records), held by the server
//!   and never served.
//! - `manifest.json`: [`Manifest`] (kind, counts, generator version; the seed of a public
//!   sample; the digest of the private phrasings of a private set; what the language composer
//!   did, when it ran).
//!
//! Ids are `dev-NNNN` and `test-NNNN`. The generator ([`generate()`]) is deterministic: the same
//! seed gives byte-identical files ([`write()`]); `assets/dataset/` holds the output for
//! [`COMMITTED_SEED`], and a test regenerates it byte for byte.
//!
//! Two kinds of set ([`DatasetKind`]): a *public sample* is generated from public files only
//! (the committed one, or any seed), so its test answers can be rebuilt by anyone who guesses or
//! reads the seed; a *private* set is generated with private phrasings
//! ([`templates::load_private_phrasings`], [`generate_with`]) that replace the public ones in its
//! test split, and its manifest records neither the seed nor the phrasings, only their digest.
//!
//! Submodules: [`templates`] (the template file and private phrasings), [`symbolic`] (the
//! executability rule and place targets, also usable to check any plan against a scene),
//! `generate` and `rng` (the generator), `sha256` (the phrasings digest).

use std::path::Path;

mod generate;
pub mod language;
mod rng;
mod sha256;
pub mod symbolic;
pub mod templates;
#[cfg(test)]
mod tests;

pub use generate::{COMMITTED_SEED, GENERATOR_VERSION, GenerateOptions, generate, generate_with, write};
pub use sha256::sha256_hex;

use serde::{Deserialize, Serialize};

use crate::ContentError;

/// Total number of instructions in a generated dataset (paper, Language Instructions).
pub const TOTAL_INSTRUCTIONS: usize = 563;
/// How many of them go to the public dev split; the rest are the test split.
pub const DEV_INSTRUCTIONS: usize = 163;
/// Number of instruction templates (paper, Language Instructions).
pub const TEMPLATE_COUNT: usize = 58;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Split {
    Dev,
    Test,
}

impl Split {
    pub fn as_str(self) -> &'static str {
        match self {
            Split::Dev => "dev",
            Split::Test => "test",
        }
    }
}

impl std::str::FromStr for Split {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "dev" => Ok(Split::Dev),
            "test" => Ok(Split::Test),
            other => Err(format!("unknown split {other:?} (expected `dev` or `test`)")),
        }
    }
}

impl std::fmt::Display for Split {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// An instruction with its ground truth.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Instruction {
    pub id: String,
    pub scene: String,
    /// The English instruction a planner reads.
    pub instruction: String,
    /// Canonical ground-truth steps (see [`crate::plan::Step`]).
    pub plan: Vec<String>,
    /// Template id the instruction came from.
    pub template: String,
    /// For each `place` step of the plan, in order: the world position `[x, y, z]` the placed
    /// object's centre must end within 5 cm of.
    pub place_targets: Vec<[f64; 3]>,
}

/// What participants get for the test split.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PublicInstruction {
    pub id: String,
    pub scene: String,
    pub instruction: String,
}

impl From<&Instruction> for PublicInstruction {
    fn from(i: &Instruction) -> Self {
        PublicInstruction {
            id: i.id.clone(),
            scene: i.scene.clone(),
            instruction: i.instruction.clone(),
        }
    }
}

/// Where a set's test answers can be rebuilt from.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DatasetKind {
    /// Generated from public files only: its answers can be rebuilt from them (the committed
    /// `assets/dataset/` is one). Manifests written before kinds existed are public samples.
    #[default]
    PublicSample,
    /// Generated with private phrasings for the test split, outside the repository.
    Private,
}

impl DatasetKind {
    pub fn as_str(self) -> &'static str {
        match self {
            DatasetKind::PublicSample => "public_sample",
            DatasetKind::Private => "private",
        }
    }
}

impl std::fmt::Display for DatasetKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// What a manifest says about the private phrasings of a private set: never their text.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PrivatePhrasingsSummary {
    /// Templates that have private phrasings.
    pub templates: usize,
    /// Private phrasings in all.
    pub phrasings: usize,
    /// SHA-256 of the phrasings file's bytes, 64 lower-case hex digits: lets the organiser check
    /// which file a set was made from without revealing it.
    pub sha256: String,
}

/// `manifest.json`. Fields are written in this order; `seed` and `private_phrasings` are
/// omitted when absent.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    #[serde(default)]
    pub kind: DatasetKind,
    /// The generator seed of a public sample; never written for a private set.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    pub generator_version: u32,
    pub templates: usize,
    pub dev: usize,
    pub test: usize,
    /// Present exactly for a private set.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub private_phrasings: Option<PrivatePhrasingsSummary>,
    /// Present when the test split was composed with language features ([`language`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub language: Option<LanguageSummary>,
}

/// What the composer did over a test split: its features, how many instructions it said, how
/// many kept their template phrasing (no rendering passed the checker), and the renderings the
/// uniqueness checker refused, by reason. Counts only: never a text.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LanguageSummary {
    pub features: Vec<language::Feature>,
    pub composed: usize,
    pub template_phrased: usize,
    pub rejected: std::collections::BTreeMap<String, usize>,
}

impl Manifest {
    /// Whether the set's test answers can be rebuilt from public files.
    pub fn is_public_sample(&self) -> bool {
        self.kind == DatasetKind::PublicSample
    }

    pub fn is_private(&self) -> bool {
        self.kind == DatasetKind::Private
    }

    /// A short identifier of the set, for tagging scores: `dataset-seed-20241-gen-3` for a public
    /// sample, `dataset-private-<first 12 hex digits of the phrasings digest>-gen-3` for a
    /// private set (which names no seed). Two private sets made from the same phrasings file
    /// with different seeds share a tag.
    pub fn tag(&self) -> String {
        match (&self.private_phrasings, self.seed) {
            (Some(p), _) if self.is_private() => format!(
                "dataset-private-{}-gen-{}",
                p.sha256.get(..12).unwrap_or(&p.sha256),
                self.generator_version
            ),
            (_, Some(seed)) => format!("dataset-seed-{seed}-gen-{}", self.generator_version),
            _ => format!("dataset-unseeded-gen-{}", self.generator_version),
        }
    }

    /// The kind agrees with the other fields: a private set names no seed and has a phrasings
    /// summary; a public sample has no phrasings summary.
    pub fn check(&self) -> Result<(), String> {
        match self.kind {
            DatasetKind::Private if self.seed.is_some() => {
                Err("a private set's manifest must not record its seed".into())
            }
            DatasetKind::Private if self.private_phrasings.is_none() => {
                Err("a private set's manifest needs `private_phrasings`".into())
            }
            DatasetKind::PublicSample if self.private_phrasings.is_some() => {
                Err("a manifest with `private_phrasings` must have kind \"private\"".into())
            }
            _ => Ok(()),
        }
    }
}

/// Both splits with ground truth, as the server holds them.
#[derive(Debug, Clone, PartialEq)]
pub struct Dataset {
    pub manifest: Manifest,
    pub dev: Vec<Instruction>,
    pub test: Vec<Instruction>,
}

impl Dataset {
    /// Load `dev.jsonl`, `test_ground_truth.jsonl` and `manifest.json` from `dir`.
    pub fn load(dir: &Path) -> Result<Dataset, ContentError> {
        let manifest_path = dir.join("manifest.json");
        let text = read(&manifest_path)?;
        let manifest: Manifest = serde_json::from_str(&text).map_err(|e| ContentError::Parse {
            path: manifest_path.clone(),
            message: e.to_string(),
        })?;
        manifest.check().map_err(|message| ContentError::Invalid {
            path: manifest_path,
            message,
        })?;
        Ok(Dataset {
            manifest,
            dev: read_jsonl(&dir.join("dev.jsonl"))?,
            test: read_jsonl(&dir.join("test_ground_truth.jsonl"))?,
        })
    }

    pub fn split(&self, split: Split) -> &[Instruction] {
        match split {
            Split::Dev => &self.dev,
            Split::Test => &self.test,
        }
    }
}

fn read(path: &Path) -> Result<String, ContentError> {
    std::fs::read_to_string(path).map_err(|source| ContentError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Read a JSON Lines file of records.
pub fn read_jsonl<T: serde::de::DeserializeOwned>(path: &Path) -> Result<Vec<T>, ContentError> {
    read(path)?
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(n, l)| {
            serde_json::from_str(l).map_err(|e| ContentError::Parse {
                path: path.to_path_buf(),
                message: format!("line {}: {e}", n + 1),
            })
        })
        .collect()
}
