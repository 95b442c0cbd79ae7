//! The grasp mode an episode runs in (docs/twin/robot.md): part of what a score means, so the
//! server, the workers, the simulator and every page that shows a score name it the same way.

use serde::{Deserialize, Serialize};

/// How the twin decides that the gripper holds an object.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum GraspMode {
    /// An object whose grasp point lies between the closing fingers is carried rigidly at its
    /// offset from the tool centre point (Habitat's "magic grasp" has the same kind of rule).
    #[default]
    Abstract,
    /// Fingers are force-limited joints and only friction contacts hold an object.
    Physical,
}

impl GraspMode {
    pub const ALL: [GraspMode; 2] = [GraspMode::Abstract, GraspMode::Physical];

    pub fn as_str(self) -> &'static str {
        match self {
            GraspMode::Abstract => "abstract",
            GraspMode::Physical => "physical",
        }
    }
}

impl std::fmt::Display for GraspMode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl std::str::FromStr for GraspMode {
    type Err = String;

    fn from_str(s: &str) -> Result<GraspMode, String> {
        GraspMode::ALL
            .into_iter()
            .find(|m| m.as_str() == s)
            .ok_or_else(|| format!("unknown grasp mode {s:?}: expected \"abstract\" or \"physical\""))
    }
}

/// For stores that read the mode back from a TEXT column (`#[sqlx(try_from = "String")]`).
impl TryFrom<String> for GraspMode {
    type Error = String;

    fn try_from(s: String) -> Result<GraspMode, String> {
        s.parse()
    }
}

#[cfg(test)]
mod tests {
    use super::GraspMode;

    #[test]
    fn a_grasp_mode_reads_back_what_it_prints_and_an_unknown_one_names_the_choices() {
        for m in GraspMode::ALL {
            assert_eq!(m.to_string().parse::<GraspMode>(), Ok(m));
        }
        let err = "magic".parse::<GraspMode>().unwrap_err();
        assert!(err.contains("\"abstract\" or \"physical\""), "{err}");
    }
}
