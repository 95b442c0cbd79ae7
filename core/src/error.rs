use std::path::PathBuf;

/// Everything that can go wrong reading or validating benchmark content.
#[derive(Debug, thiserror::Error)]
pub enum ContentError {
    #[error("cannot read {path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path} is not valid TOML for this schema: {message}")]
    Parse { path: PathBuf, message: String },
    #[error("{path}: {message}")]
    Invalid { path: PathBuf, message: String },
    #[error(
        "not a plan step: {0:?} (expected `move to the <colour> zone`, `pick the <object>` or `place the <object>`)"
    )]
    BadStep(String),
}
