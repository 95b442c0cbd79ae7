//! The two observation tracks of the control and integrated boards
//! (docs/participant/privileged.md): **standard** (the paper's observation: cameras, sub-task,
//! robot state relative to the episode start) and
//! **privileged** (a run whose policy asked for, and received, privileged observations: the
//! robot's pose in the scene frame, the current task's goal, key objects' poses). Runs of the
//! two are ranked apart and every place that shows a policy's score names its track.

use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ObservationTrack {
    #[default]
    Standard,
    Privileged,
}

impl ObservationTrack {
    pub const ALL: [ObservationTrack; 2] = [ObservationTrack::Standard, ObservationTrack::Privileged];

    /// The track of a run that did (`true`) or did not receive privileged observations.
    pub fn of(privileged: bool) -> ObservationTrack {
        if privileged {
            ObservationTrack::Privileged
        } else {
            ObservationTrack::Standard
        }
    }

    pub fn as_str(self) -> &'static str {
        match self {
            ObservationTrack::Standard => "standard",
            ObservationTrack::Privileged => "privileged",
        }
    }
}

impl std::fmt::Display for ObservationTrack {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl std::str::FromStr for ObservationTrack {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "" | "standard" => Ok(ObservationTrack::Standard),
            "privileged" => Ok(ObservationTrack::Privileged),
            other => Err(format!(
                "unknown observations {other:?} (expected `standard` or `privileged`)"
            )),
        }
    }
}

/// How much a privileged observation shows (the rule is in
/// `kitchen_r_episode::policy::privileged`); the server picks it from the split.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PrivilegedScope {
    /// Dev split: the robot, the current goal and every key object of the episode.
    Episode,
    /// Test split: the robot and what the current sub-task names (its goal, its object).
    SubTask,
}

impl PrivilegedScope {
    /// The scope a run on `split` gets: only the dev split's ground truth is public.
    pub fn for_split(split: crate::dataset::Split) -> PrivilegedScope {
        match split {
            crate::dataset::Split::Dev => PrivilegedScope::Episode,
            crate::dataset::Split::Test => PrivilegedScope::SubTask,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_empty_is_standard() {
        for t in ObservationTrack::ALL {
            assert_eq!(t.as_str().parse::<ObservationTrack>(), Ok(t));
            assert_eq!(serde_json::to_string(&t).unwrap(), format!("\"{t}\""));
        }
        assert_eq!("".parse(), Ok(ObservationTrack::Standard));
        assert!(
            "Privileged"
                .parse::<ObservationTrack>()
                .unwrap_err()
                .contains("`privileged`")
        );
        assert_eq!(ObservationTrack::of(true), ObservationTrack::Privileged);
    }

    #[test]
    fn the_scope_follows_the_split() {
        use crate::dataset::Split;
        assert_eq!(PrivilegedScope::for_split(Split::Dev), PrivilegedScope::Episode);
        assert_eq!(PrivilegedScope::for_split(Split::Test), PrivilegedScope::SubTask);
    }
}
