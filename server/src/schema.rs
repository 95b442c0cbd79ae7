//! Schema stand-ins for domain values the OpenAPI document names: a split or an observation
//! track is held as a core type (or a string) that has no `ToSchema`, so the fields that carry
//! one point their derive here (`#[schema(value_type = crate::schema::SplitName)]`).
//!
//! Why here and not in `http::openapi`: the domain types (leaderboard, service answers) derive
//! their schemas, and the domain must not import the HTTP adapter (the rule is in the
//! crate doc). A leaf module: it imports nothing of this crate.

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

/// A dataset split as named in paths, queries and bodies.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub(crate) enum SplitName {
    Dev,
    Test,
}

/// The observation track of a policy run (`kitchen_r_core::observations::ObservationTrack`).
#[derive(Debug, Clone, Copy, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub(crate) enum ObservationsName {
    Standard,
    Privileged,
}

/// The grasp mode a policy run's episodes ran in (`kitchen_r_core::GraspMode`, docs/twin/robot.md):
/// part of what a control score means.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub(crate) enum GraspModeName {
    Abstract,
    Physical,
}
