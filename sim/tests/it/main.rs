//! The twin's integration tests, one binary with a module per area:
//! `cargo test -p kitchen-r-sim --test it [MODULE]`, e.g. `--test it arm_grasp`.

mod common;

mod arm_grasp;
mod episodes;
mod physical;
mod randomise;
mod twin;
mod usd;
