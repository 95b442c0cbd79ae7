//! The Foxglove WebSocket live view (see the crate doc).

mod protocol;
mod server;

pub use server::{FoxgloveServer, LiveError};

/// The port Foxglove and Lichtblick suggest for a WebSocket connection.
pub const DEFAULT_ADDR: &str = "127.0.0.1:8765";
