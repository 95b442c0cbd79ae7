//! The worker's integration tests, one binary (one link of rapier and tonic) with a module per
//! area: `cargo test -p kitchen-r-worker --test it [MODULE]`, e.g. `--test it remote_transport`.
//! It covers the crates the worker is built from too (kitchen-r-episode: `runner`, `oracle`,
//! `offline`, `place_reach`; kitchen-r-contract: `remote_*`; kitchen-r-record: `record_roundtrip`,
//! `collect`), so the workspace links those heavy dependencies once.
//!
//! The tests share a process and run on parallel threads: none of them sets process-wide state
//! (environment, current directory); the only `static` (the job context of `job_execute`) is
//! read-only once built.

mod remote_support;

mod collect;
mod driven;
mod job_execute;
mod job_worker;
mod lerobot_export;
mod live_ros2;
mod offline;
mod oracle;
mod place_reach;
mod record_roundtrip;
mod remote_bench;
mod remote_check;
mod remote_history;
mod remote_oracle;
mod remote_probe;
mod remote_starter_kit;
mod remote_tls;
mod remote_transport;
mod runner;
