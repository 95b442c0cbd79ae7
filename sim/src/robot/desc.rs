//! The robot description (docs/twin/robot.md): read from a URDF or MJCF file and its sidecar by
//! kitchen-r-core (`kitchen_r_core::robot`, where the mapping and the frame conventions are
//! documented), so the dataset generator's reach rule and the twin read the same numbers.

pub use kitchen_r_core::robot::*;
