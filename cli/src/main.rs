//! The `kitchen-r` binary: parses arguments and calls into the crates. Nothing else lives here.

fn main() -> anyhow::Result<()> {
    Ok(())
}
