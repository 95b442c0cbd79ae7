//! The instruction dataset and its on-disk layout (`assets/dataset/`).
//!
//! Files (JSON Lines, one record per line, sorted by id):
//! - `dev.jsonl`: public dev split with ground truth: [`Instruction`] records.
//! - `test.jsonl`: public test split *without* plans: [`PublicInstruction`] records.
//! - `test_ground_truth.jsonl`: test ground truth ([`Instruction`] records), held by the server
//!   and never served.
//! - `manifest.json`: [`Manifest`] (seed, counts, generator version).
//!
//! Ids are `dev-NNNN` and `test-NNNN`. The generator ([`generate()`]) is deterministic: the same
//! seed gives byte-identical files ([`write`]); `assets/dataset/` holds the output for
//! [`COMMITTED_SEED`], and a test regenerates it byte for byte.
//!
//! Submodules: [`templates`] (the template file), [`symbolic`] (the executability rule and place
//! targets, also usable to check any plan against a scene), `generate` and `rng` (the generator).

use std::path::Path;

mod generate;
mod rng;
pub mod symbolic;
pub mod templates;
#[cfg(test)]
mod tests;

pub use generate::{COMMITTED_SEED, GENERATOR_VERSION, generate, write};

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

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    pub seed: u64,
    pub generator_version: u32,
    pub templates: usize,
    pub dev: usize,
    pub test: usize,
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
        let manifest = serde_json::from_str(&text).map_err(|e| ContentError::Parse {
            path: manifest_path,
            message: e.to_string(),
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
