//! Compiles the `.proto` contracts in-process with `protox` (no `protoc` needed), generates the
//! prost messages and tonic clients/servers, and writes the encoded file descriptor set that
//! the server hands to gRPC reflection.

use std::path::PathBuf;

use prost::Message;

const PROTOS: [&str; 3] = [
    "kitchen_r/policy/v1/policy.proto",
    "kitchen_r/worker/v1/worker.proto",
    "kitchen_r/submission/v1/submission.proto",
];

fn main() -> Result<(), Box<dyn std::error::Error>> {
    for p in PROTOS {
        println!("cargo:rerun-if-changed={p}");
    }
    let fds = protox::compile(PROTOS, ["."])?;
    let out_dir = PathBuf::from(std::env::var("OUT_DIR")?);
    std::fs::write(out_dir.join("kitchen_r_descriptor.bin"), fds.encode_to_vec())?;
    tonic_prost_build::configure()
        .build_client(true)
        .build_server(true)
        .compile_fds(fds)?;
    Ok(())
}
