//! The crate's one error type.

use std::path::PathBuf;

/// Everything that can go wrong loading, configuring or running the twin.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    #[error(transparent)]
    Content(#[from] kitchen_r_core::ContentError),
    #[error("cannot read {path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path} is not valid for its schema: {message}")]
    Parse { path: PathBuf, message: String },
    #[error("invalid configuration: {0}")]
    Config(String),
    #[error("unknown scene {0:?}")]
    UnknownScene(String),
    #[error("unknown object {0:?}")]
    UnknownObject(String),
    #[error("episode config does not fit the scene: {0}")]
    Episode(String),
    #[error("preflight check failed: {0}")]
    Preflight(String),
    #[error("bad action: {0}")]
    BadAction(String),
    #[error("mesh {path}: {message}")]
    Mesh { path: PathBuf, message: String },
    #[error("cannot write image {path}: {message}")]
    Image { path: PathBuf, message: String },
}

/// Read a TOML file into `T`, mapping errors to [`SimError`].
pub(crate) fn read_toml<T: serde::de::DeserializeOwned>(path: &std::path::Path) -> Result<T, SimError> {
    let text = std::fs::read_to_string(path).map_err(|source| SimError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    toml::from_str(&text).map_err(|e| SimError::Parse {
        path: path.to_path_buf(),
        message: e.to_string(),
    })
}
