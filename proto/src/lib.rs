//! Wire contracts (protobuf/gRPC) of Kitchen-R, generated at build time from `proto/kitchen_r/**`.
//!
//! This crate owns the `.proto` files and the conversions between wire messages and the domain
//! types of `kitchen-r-core` ([`convert`]), and nothing else: no business rules, no I/O. The three
//! packages are
//! - [`policy::v1`]: what a participant's policy server implements (control track);
//! - [`worker::v1`]: how simulation workers lease jobs from the server and report results;
//! - [`submission::v1`]: the participant API (plans, policies, submissions, leaderboard), the
//!   gRPC twin of the HTTP API.
//!
//! Generated code carries the `.proto` comments as docs; read the `.proto` files for the field
//! by field contract.

pub mod convert;

/// Encoded `FileDescriptorSet` of all three packages, for gRPC server reflection.
pub const FILE_DESCRIPTOR_SET: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/kitchen_r_descriptor.bin"));

/// The policy protocol version this build speaks (see `policy.proto`).
pub const POLICY_PROTOCOL_VERSION: u32 = 1;

/// The minor version of protocol 1 this build's workers speak, announced in GetSpec: 1 is
/// contract v1.1 (observation history, chosen execution count, hand pose and previous action in
/// every observation); 2 adds the privileged-information track (`PolicySpec.
/// privileged_observations`, `GetSpecRequest.privileged_track`, `Observation.
/// privileged_observation`). Compatible: a v1.0 policy is driven exactly as before.
pub const POLICY_MINOR_VERSION: u32 = 2;

pub mod policy {
    pub mod v1 {
        #![allow(clippy::all, missing_docs)]
        tonic::include_proto!("kitchen_r.policy.v1");
    }
}

pub mod worker {
    pub mod v1 {
        #![allow(clippy::all, missing_docs)]
        tonic::include_proto!("kitchen_r.worker.v1");
    }
}

pub mod submission {
    pub mod v1 {
        #![allow(clippy::all, missing_docs)]
        tonic::include_proto!("kitchen_r.submission.v1");
    }
}
