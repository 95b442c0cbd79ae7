//! Language that tells planners apart (private sets): a template's plan said with relational
//! references, pronouns, implicit steps, order words and distractors, and kept only when the
//! uniqueness checker finds exactly one plan for it.
//!
//! - [`lexicon`]: the switchable [`Feature`]s and the phrase book (`assets/language.toml`, or a
//!   private `[language]` table that replaces its lists).
//! - [`meaning`]: what a composed instruction says, as references and acts.
//! - [`compose`](fn@compose): one seeded rendering of a plan, with its meaning.
//! - [`unique`]: the checker that enumerates the plans a meaning allows in a scene.
//!
//! The generator ([`crate::dataset::generate_with`]) composes the test split's instructions when
//! features are on, draws again when the checker refuses a rendering (counting why), and falls
//! back to the template's phrasing when no rendering in [`ATTEMPTS`] passes. The dev split never
//! uses these features, so the public dev split is the same with or without them.

mod compose;
pub mod lexicon;
pub mod meaning;
#[cfg(test)]
mod tests;
pub mod unique;

pub use compose::compose;
pub use lexicon::{Feature, Lexicon, load_lexicon, parse_features};
pub use unique::{Rejection, check};

/// Renderings drawn per instruction before it falls back to its template phrasing.
pub const ATTEMPTS: usize = 40;
