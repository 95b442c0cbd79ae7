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

/// Environment variable naming robosuite 1.5.2's unpacked assets (the wheel's
/// `robosuite/models/assets`, fetched by `scripts/robosuite-assets.sh`), which the robosuite
/// sidecars and catalogue entries name their files relative to.
pub const ROBOSUITE_ENV: &str = "ROBOSUITE_ASSETS";

/// robosuite's assets for a test of its arms or objects, from [`ROBOSUITE_ENV`]. Without it the
/// test skips (`None`, saying how to fetch them), except in CI (`CI=true`), which must have them:
/// there this panics. For the workspace's tests; nothing else calls it.
pub fn robosuite_assets_for_tests() -> Option<PathBuf> {
    if let Some(dir) = std::env::var_os(ROBOSUITE_ENV) {
        return Some(PathBuf::from(dir));
    }
    assert_ne!(
        std::env::var("CI").as_deref(),
        Ok("true"),
        "CI needs {ROBOSUITE_ENV}: scripts/test.sh exports it (scripts/robosuite-assets.sh)"
    );
    eprintln!("skipped: export {ROBOSUITE_ENV}=\"$(scripts/robosuite-assets.sh)\"");
    None
}
