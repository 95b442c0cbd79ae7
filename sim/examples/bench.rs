//! Same as `kitchen-r bench sim --json`, without building the whole CLI:
//! `cargo run --release -p kitchen-r-sim --example bench -- 600 8`.

fn main() -> Result<(), kitchen_r_sim::SimError> {
    let args: Vec<String> = std::env::args().collect();
    let steps = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(600);
    let every = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(8);
    println!("{}", kitchen_r_sim::bench::run(steps, every, None)?.to_json());
    Ok(())
}
