//! Where the benchmark content lives on disk.
//!
//! The `assets/` directory is found, in order, from `KITCHEN_R_ASSETS`, from `./assets` in the
//! working directory, and from the workspace the binary was built in (so `cargo run` and tests
//! work from any directory of the checkout).

use std::path::PathBuf;

/// Environment variable that overrides the assets directory.
pub const ASSETS_ENV: &str = "KITCHEN_R_ASSETS";

/// The assets directory to read scenes, the catalogue and the dataset from.
pub fn assets_dir() -> PathBuf {
    if let Some(dir) = std::env::var_os(ASSETS_ENV) {
        return PathBuf::from(dir);
    }
    let local = PathBuf::from("assets");
    if local.join("scenes").is_dir() {
        return local;
    }
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../assets"))
}
