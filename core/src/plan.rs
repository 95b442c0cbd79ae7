//! Canonical plan steps.
//!
//! A plan is a list of lower-case English steps, exactly one of
//! `move to the <colour> zone`, `pick the <object>` and `place the <object>`, where `<object>` is
//! a catalogue model name optionally preceded by a colour variant (`the red cup`). These strings
//! are what EM compares character by character, so they are produced only by [`Step`]'s
//! `Display` and never assembled by hand elsewhere.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::ContentError;

/// One step of a plan; each ground-truth step is also one task of an episode.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(tag = "action", rename_all = "snake_case")]
pub enum Step {
    /// Drive the base to the approach point of the zone with this colour name.
    MoveTo { zone: String },
    /// Grasp this object (e.g. `"red cup"`, `"bowl"`) and lift it clear of its support.
    Pick { object: String },
    /// Put the held object down in the zone the robot is at.
    Place { object: String },
}

/// Which success criterion a task is judged by (paper, METRICS).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TaskKind {
    /// Base centre within 10 cm of the target.
    Navigation,
    /// Object centre within 5 cm of its target.
    Manipulation,
}

impl Step {
    pub fn kind(&self) -> TaskKind {
        match self {
            Step::MoveTo { .. } => TaskKind::Navigation,
            Step::Pick { .. } | Step::Place { .. } => TaskKind::Manipulation,
        }
    }

    /// The object a manipulation step is about.
    pub fn object(&self) -> Option<&str> {
        match self {
            Step::MoveTo { .. } => None,
            Step::Pick { object } | Step::Place { object } => Some(object),
        }
    }
}

/// How many steps of `plan` are canonical `place` steps: each has one place target, in order.
pub fn place_steps<S: AsRef<str>>(plan: &[S]) -> usize {
    (plan.iter())
        .filter(|s| matches!(s.as_ref().parse::<Step>(), Ok(Step::Place { .. })))
        .count()
}

impl fmt::Display for Step {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Step::MoveTo { zone } => write!(f, "move to the {zone} zone"),
            Step::Pick { object } => write!(f, "pick the {object}"),
            Step::Place { object } => write!(f, "place the {object}"),
        }
    }
}

impl FromStr for Step {
    type Err = ContentError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = || ContentError::BadStep(s.to_string());
        let word = |w: &str| !w.is_empty() && w.bytes().all(|b| b.is_ascii_lowercase() || b == b' ');
        if let Some(rest) = s.strip_prefix("move to the ") {
            let zone = rest.strip_suffix(" zone").ok_or_else(bad)?;
            return (word(zone) && !zone.contains(' '))
                .then(|| Step::MoveTo {
                    zone: zone.to_string(),
                })
                .ok_or_else(bad);
        }
        let (object, pick) = if let Some(o) = s.strip_prefix("pick the ") {
            (o, true)
        } else if let Some(o) = s.strip_prefix("place the ") {
            (o, false)
        } else {
            return Err(bad());
        };
        if !word(object) || object.starts_with(' ') || object.ends_with(' ') || object.contains("  ") {
            return Err(bad());
        }
        let object = object.to_string();
        Ok(if pick {
            Step::Pick { object }
        } else {
            Step::Place { object }
        })
    }
}

/// Parse a whole plan; the first bad step is reported.
pub fn parse_plan<S: AsRef<str>>(steps: &[S]) -> Result<Vec<Step>, ContentError> {
    steps.iter().map(|s| s.as_ref().parse()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn canonical_strings_round_trip() {
        for s in ["move to the blue zone", "pick the red cup", "place the bowl"] {
            let step: Step = s.parse().unwrap();
            assert_eq!(step.to_string(), s);
        }
    }

    #[test]
    fn near_misses_are_not_steps() {
        for s in [
            "Move to the blue zone",
            "move to blue zone",
            "move to the light blue zone",
            "pick the  cup",
            "pick the cup ",
            "pick up the cup",
            "place the",
            "",
        ] {
            assert!(s.parse::<Step>().is_err(), "{s:?} parsed");
        }
    }

    #[test]
    fn kinds_follow_the_paper() {
        assert_eq!(
            "move to the red zone".parse::<Step>().unwrap().kind(),
            TaskKind::Navigation
        );
        assert_eq!(
            "pick the fork".parse::<Step>().unwrap().kind(),
            TaskKind::Manipulation
        );
    }
}
