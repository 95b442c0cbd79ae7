//! Simulation worker: the job loop that leases `kitchen_r.worker.v1.Job`s from the server, runs
//! each through the episode runner with the job's policy, heartbeats and reports the result
//! ([`job`]), and local evaluation of an endpoint the way those jobs run it.
//!
//! Episodes, policies and the oracle live in kitchen-r-episode, the policy transport in
//! kitchen-r-contract, trajectory recording in kitchen-r-record. This crate must not score
//! submissions or touch the database: results go back to the server, which owns scoring and
//! storage.

pub mod job;
mod metrics;
