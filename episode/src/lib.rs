//! Episodes on the kitchen twin: the policy interface ([`policy`]), the single episode runner
//! every evaluation uses ([`runner`]), the oracle expert ([`oracle`]), offline MSE ([`offline`])
//! local evaluation of a split ([`eval`]), teleport-on-failure's expert states ([`teleport`])
//! an episode driven one action at a time from outside ([`driven`], the Python environment) and
//! expert training samples from parallel simulators ([`samples`]) and the traces that
//! reproduce an episode for its video on demand ([`trace`]).
//!
//! It owns how a policy drives the simulator and what an episode's outcome is. It must not touch
//! the network, a database or an async runtime (no tokio, tonic, prost or kitchen-r-proto):
//! transports wrap a policy from outside (kitchen-r-contract), the job loop leases and reports
//! (kitchen-r-worker), and scoring and storage belong to the server.

pub mod batch;
#[cfg(test)]
mod closed_loop_tests;
pub mod driven;
pub mod eval;
pub mod hooks;
#[cfg(test)]
mod mesh_object_tests;
pub mod offline;
pub mod oracle;
#[cfg(test)]
mod physical_plate_tests;
pub mod policy;
#[cfg(test)]
mod robosuite_object_tests;
#[cfg(test)]
mod robot_file_tests;
pub mod runner;
pub mod samples;
pub mod sim_slot;
pub mod teleport;
#[cfg(test)]
mod test_oracle;
pub mod trace;
#[cfg(test)]
mod usd_scene_tests;
