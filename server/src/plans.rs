//! Plan files: parsing, validation and EM scoring of an uploaded JSON Lines file.
//!
//! Policy: a file is accepted whole or refused whole. Refusals name the problem and its 1-based
//! line so a participant can fix the file without guessing; nothing of a refused file is stored
//! and it never uses quota. Blank lines are skipped. Keys other than `id` and `plan` are
//! ignored, so the downloaded dev file (which also carries the instruction text) is itself a
//! valid submission, and dropped before storage: what is stored is [`PlanFile::to_jsonl`], one
//! `{"id", "plan"}` object per line in the file's order, so a line's extra fields (a 4 MB
//! random one, say) cost no disk. Instructions absent from the file score 0 and produce a warning. A UTF-8
//! byte-order mark at the start (Windows editors write one) is skipped, not refused.
//!
//! This module is pure (no I/O) so the parser can be fuzzed and benchmarked on its own.

use std::collections::HashMap;

use kitchen_r_core::dataset::{Instruction, Split};
use kitchen_r_core::metrics::PlanMatch;
use serde_json::Value;

use crate::config::PlanLimits;

/// Why a plan file was refused. `line` is 1-based.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PlanFileError {
    #[error("the file is empty: expected one JSON object per line")]
    Empty,
    #[error("the body is larger than {limit} bytes (limit crossed on line {line})")]
    TooLarge { limit: usize, line: usize },
    #[error("line {line}: not valid UTF-8")]
    NotUtf8 { line: usize },
    #[error("line {line}: not valid JSON: {message}")]
    NotJson { line: usize, message: String },
    #[error("line {line}: expected a JSON object like {{\"id\": \"...\", \"plan\": [\"...\"]}}")]
    NotObject { line: usize },
    #[error("line {line}: missing \"id\" (a string)")]
    MissingId { line: usize },
    #[error("line {line}: unknown instruction id {id:?} in the {split} split")]
    UnknownId { line: usize, id: String, split: Split },
    #[error("line {line}: instruction {id:?} belongs to the {other} split, not {split}")]
    WrongSplit {
        line: usize,
        id: String,
        split: Split,
        other: Split,
    },
    #[error("line {line}: duplicate id {id:?} (first seen on line {first})")]
    DuplicateId { line: usize, id: String, first: usize },
    #[error("line {line}: \"plan\" must be a list of strings")]
    PlanNotList { line: usize },
    #[error("line {line}: step {step} of \"plan\" is not a string")]
    StepNotString { line: usize, step: usize },
    #[error("line {line}: step {step} is {chars} characters long; the limit is {limit}")]
    StepTooLong {
        line: usize,
        step: usize,
        chars: usize,
        limit: usize,
    },
    #[error("line {line}: the plan has {steps} steps; the limit is {limit}")]
    TooManySteps { line: usize, steps: usize, limit: usize },
}

impl PlanFileError {
    /// The offending line, when the problem has one.
    pub fn line(&self) -> Option<usize> {
        use PlanFileError::*;
        match self {
            Empty => None,
            TooLarge { line, .. }
            | NotUtf8 { line }
            | NotJson { line, .. }
            | NotObject { line }
            | MissingId { line }
            | UnknownId { line, .. }
            | WrongSplit { line, .. }
            | DuplicateId { line, .. }
            | PlanNotList { line }
            | StepNotString { line, .. }
            | StepTooLong { line, .. }
            | TooManySteps { line, .. } => Some(*line),
        }
    }

    pub fn code(&self) -> &'static str {
        use PlanFileError::*;
        match self {
            Empty => "empty_file",
            TooLarge { .. } => "body_too_large",
            NotUtf8 { .. } => "not_utf8",
            NotJson { .. } => "not_json",
            NotObject { .. } => "not_an_object",
            MissingId { .. } => "missing_id",
            UnknownId { .. } => "unknown_id",
            WrongSplit { .. } => "wrong_split",
            DuplicateId { .. } => "duplicate_id",
            PlanNotList { .. } => "plan_not_a_list",
            StepNotString { .. } => "step_not_a_string",
            StepTooLong { .. } => "step_too_long",
            TooManySteps { .. } => "too_many_steps",
        }
    }
}

/// Where every instruction id lives, built once per dataset.
#[derive(Debug, Clone, Default)]
pub struct IdIndex {
    ids: HashMap<String, (Split, usize)>,
}

impl IdIndex {
    pub fn new(dev: &[Instruction], test: &[Instruction]) -> IdIndex {
        let dev = dev
            .iter()
            .enumerate()
            .map(|(i, x)| (x.id.clone(), (Split::Dev, i)));
        let test = test
            .iter()
            .enumerate()
            .map(|(i, x)| (x.id.clone(), (Split::Test, i)));
        IdIndex {
            ids: dev.chain(test).collect(),
        }
    }

    fn get(&self, id: &str) -> Option<(Split, usize)> {
        self.ids.get(id).copied()
    }
}

/// A validated file: for each instruction of the split (by its index there), the submitted plan.
#[derive(Debug, Clone, PartialEq)]
pub struct PlanFile {
    pub plans: Vec<Option<Vec<String>>>,
    /// The instructions' indices in the order the file lists them.
    pub order: Vec<usize>,
}

impl PlanFile {
    /// The file as stored: one `{"id": ..., "plan": [...]}` line per plan, in the file's order,
    /// without any other field. `split` is the split the file was parsed for.
    pub fn to_jsonl(&self, split: &[Instruction]) -> String {
        let mut out = String::new();
        for &pos in &self.order {
            let line = serde_json::json!({"id": split[pos].id, "plan": self.plans[pos]});
            out.push_str(&line.to_string());
            out.push('\n');
        }
        out
    }
}

/// The line where a body of `limit` bytes stops: for the "too large" message.
pub(crate) fn line_at(body: &[u8], limit: usize) -> usize {
    body[..limit.min(body.len())]
        .iter()
        .filter(|b| **b == b'\n')
        .count()
        + 1
}

/// The UTF-8 encoding of U+FEFF, which some editors put at the start of a file.
const UTF8_BOM: &[u8] = b"\xEF\xBB\xBF";

/// Parse and validate `body` for `split` (which has `split_len` instructions).
pub fn parse(
    body: &[u8],
    split: Split,
    split_len: usize,
    index: &IdIndex,
    limits: &PlanLimits,
) -> Result<PlanFile, PlanFileError> {
    // The mark is inside line 1, so line numbers are unchanged.
    let body = body.strip_prefix(UTF8_BOM).unwrap_or(body);
    let mut plans: Vec<Option<Vec<String>>> = vec![None; split_len];
    let mut first_line: Vec<usize> = vec![0; split_len];
    let mut order = Vec::new();
    for (n, raw) in body.split(|b| *b == b'\n').enumerate() {
        let line = n + 1;
        let text = std::str::from_utf8(raw).map_err(|_| PlanFileError::NotUtf8 { line })?;
        if text.trim().is_empty() {
            continue;
        }
        let (id, plan) = parse_line(text, line, limits)?;
        let pos = match index.get(&id) {
            Some((s, pos)) if s == split && pos < split_len => pos,
            Some((other, _)) if other != split => {
                return Err(PlanFileError::WrongSplit {
                    line,
                    id,
                    split,
                    other,
                });
            }
            _ => return Err(PlanFileError::UnknownId { line, id, split }),
        };
        if plans[pos].is_some() {
            return Err(PlanFileError::DuplicateId {
                line,
                id,
                first: first_line[pos],
            });
        }
        plans[pos] = Some(plan);
        first_line[pos] = line;
        order.push(pos);
    }
    if order.is_empty() {
        return Err(PlanFileError::Empty);
    }
    Ok(PlanFile { plans, order })
}

fn parse_line(text: &str, line: usize, limits: &PlanLimits) -> Result<(String, Vec<String>), PlanFileError> {
    let value: Value = serde_json::from_str(text).map_err(|e| PlanFileError::NotJson {
        line,
        message: e.to_string(),
    })?;
    let Value::Object(mut obj) = value else {
        return Err(PlanFileError::NotObject { line });
    };
    let Some(Value::String(id)) = obj.remove("id") else {
        return Err(PlanFileError::MissingId { line });
    };
    let Some(Value::Array(items)) = obj.remove("plan") else {
        return Err(PlanFileError::PlanNotList { line });
    };
    if items.len() > limits.max_steps {
        return Err(PlanFileError::TooManySteps {
            line,
            steps: items.len(),
            limit: limits.max_steps,
        });
    }
    let mut plan = Vec::with_capacity(items.len());
    for (i, item) in items.into_iter().enumerate() {
        let Value::String(step) = item else {
            return Err(PlanFileError::StepNotString { line, step: i + 1 });
        };
        let chars = step.chars().count();
        if chars > limits.max_step_chars {
            return Err(PlanFileError::StepTooLong {
                line,
                step: i + 1,
                chars,
                limit: limits.max_step_chars,
            });
        }
        plan.push(step);
    }
    Ok((id, plan))
}

/// Per-instruction outcome of scoring a file.
#[derive(Debug, Clone, PartialEq)]
pub struct InstructionScore {
    pub id: String,
    pub present: bool,
    pub correct: usize,
    pub total: usize,
}

impl InstructionScore {
    pub(crate) fn em(&self) -> f64 {
        PlanMatch {
            correct: self.correct,
            total: self.total,
        }
        .accuracy()
    }
}

/// A scored plan file.
#[derive(Debug, Clone, PartialEq)]
pub struct PlanScore {
    pub em: f64,
    pub instructions: Vec<InstructionScore>,
    pub missing: usize,
}

/// EM of `file` against the split's ground truth (`ground_truth[i]` ↔ `file.plans[i]`).
pub fn score(file: &PlanFile, ground_truth: &[Instruction]) -> PlanScore {
    let instructions: Vec<InstructionScore> = ground_truth
        .iter()
        .zip(&file.plans)
        .map(|(gt, pred)| {
            let m = PlanMatch::of(pred.as_deref(), &gt.plan);
            InstructionScore {
                id: gt.id.clone(),
                present: pred.is_some(),
                correct: m.correct,
                total: m.total,
            }
        })
        .collect();
    let missing = instructions.iter().filter(|i| !i.present).count();
    let em = kitchen_r_core::metrics::mean(instructions.iter().map(InstructionScore::em));
    PlanScore {
        em,
        instructions,
        missing,
    }
}

/// Warnings to show with an accepted file.
pub(crate) fn warnings(score: &PlanScore) -> Vec<String> {
    if score.missing == 0 {
        return Vec::new();
    }
    vec![format!(
        "{} of {} instructions had no plan in the file and score 0",
        score.missing,
        score.instructions.len()
    )]
}

#[cfg(test)]
mod tests;
