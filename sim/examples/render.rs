//! Same as `kitchen-r sim render --scene ID --out DIR [--seed S]`, without building the whole CLI:
//! `cargo run -p kitchen-r-sim --example render -- kitchen_a /tmp/render 0`.

fn main() -> Result<(), kitchen_r_sim::SimError> {
    let args: Vec<String> = std::env::args().collect();
    let scene = args.get(1).map_or("kitchen_a", String::as_str);
    let out = args.get(2).map_or("render", String::as_str);
    let seed = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(0);
    for p in kitchen_r_sim::render::render_scene(scene, std::path::Path::new(out), seed)? {
        println!("{}", p.display());
    }
    Ok(())
}
