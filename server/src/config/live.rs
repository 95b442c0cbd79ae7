//! `[live]`: episodes published live while workers run them (docs/twin/live.md). The organiser
//! decides centrally: the setting travels to the workers with every leased job
//! (`EpisodeSpec.live_ros2`), and only with dev-split jobs: a test-split episode is never
//! published, whatever this says, since its plan and goals are the hidden answers.

use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LiveConfig {
    /// Workers publish every online dev-split episode as live ROS 2 topics over DDS (the
    /// topics of `kitchen-r eval --ros2`), with the domain, network and QoS of their own
    /// `configs/live.toml` `[ros2]`. Off by default.
    pub ros2: bool,
}
