//! End-to-end tests of the `kitchen-r` binary, one test binary with a module per area:
//! `cargo test -p kitchen-r --test e2e [MODULE]`, e.g. `--test e2e control`.
//!
//! The tests share a process and run on parallel threads; each starts its own server processes
//! on 127.0.0.1:0 with its own temporary directory and sets no process-wide state (environment
//! variables go to the spawned commands only).

mod support;
// The worker crate's scripted policies served over real sockets (`TestServer`, `factory`).
#[path = "../../worker/tests/it/remote_support/scripted.rs"]
mod remote_support;

mod admin;
mod archive;
mod audit;
mod baseline_diffusion;
mod baseline_planner;
mod batched;
mod browser;
mod cli;
mod control;
mod episodes;
mod grasp;
mod grpc;
mod integrity;
mod leaderboard_ties;
mod live;
mod load_bench;
mod metrics;
mod openapi;
mod openpi;
mod pages;
mod participant_client;
mod planning;
mod privileged;
mod replay;
mod ros2_live;
mod secrets;
mod submission;
mod video;
mod video_files;
mod video_limits;
mod workers;
