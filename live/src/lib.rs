//! Watching an episode live: the transports that carry the ROS 2 messages kitchen-r-record's
//! live publisher produces (`kitchen_r_record::live`) to the tools robotics people use.
//!
//! - [`foxglove`]: a WebSocket server speaking the Foxglove WebSocket protocol (v1), so the
//!   Foxglove app or Lichtblick connects to a running `eval` or `replay` and shows
//!   the cameras, the robot's path and TF as the episode runs. It listens on loopback unless
//!   told otherwise.
//! - [`ros2`]: the same messages as live ROS 2 topics over DDS (RustDDS), named and typed as a
//!   ROS 2 node names them, so a stock node, `ros2 topic echo` or `ros2 bag record` subscribes
//!   with no bridge. Discovery stays on loopback unless `configs/live.toml` says otherwise.
//!
//! It owns the network side of live publishing only: which messages exist and how they are
//! encoded is kitchen-r-record's (the MCAP recordings hold the same bytes), and the episode is
//! never waited for: every queue on the way drops rather than blocks.
//!
//! The protocol is implemented here on axum's WebSocket rather than with the Foxglove SDK
//! crate: the SDK's server negotiates only its own `foxglove.sdk.v1*` subprotocols, which
//! Lichtblick does not offer, and would bring a second WebSocket, SHA and protobuf stack into
//! the build, where this is a few hundred lines on what the HTTP API already builds.

pub mod foxglove;
pub mod ros2;
