//! Simulation worker: runs episodes on the kitchen twin, talks to policies and the server, and
//! records expert trajectories.
//!
//! It owns everything that turns simulator output into artefacts (trajectory files), the oracle
//! expert ([`oracle`]), local evaluation ([`eval`]), trajectory collection ([`collect`]) and, in
//! later issues, job leasing and policy calls. It must not score submissions or touch the
//! database: results go back to the server, which owns scoring and storage.

pub mod bench;
pub mod collect;
pub mod eval;
pub mod job;
pub mod offline;
pub mod oracle;
pub mod policy;
pub mod record;
pub mod remote;
pub mod runner;
