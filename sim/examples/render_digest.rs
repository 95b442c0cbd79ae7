//! Render digests: steps every scene under the benchmark's varied actions and prints one hash of
//! all camera images, depth maps and LiDAR points per episode, then the mean observation time.
//! Compare the digests of two builds to check that a renderer change keeps images bit-identical:
//! `cargo run --release -p kitchen-r-sim --example render_digest`. With `REPEAT=1` it also renders
//! 100 more observations per episode, for profiling the renderer alone.

use kitchen_r_sim::bench::wobble_action;
use kitchen_r_sim::config::{SensorsConfig, SimConfig};
use kitchen_r_sim::generator::{EpisodeParams, generate};
use kitchen_r_sim::sim::{Assets, Sim};
use std::hash::{Hash, Hasher};

fn main() {
    let assets = Assets::load_default().unwrap();
    let config = SimConfig::load_default().unwrap();
    let sensors = SensorsConfig::load_default().unwrap();
    let params = EpisodeParams::load_default().unwrap();
    let mut total = std::time::Duration::ZERO;
    let mut n = 0;
    for scene in assets.scenes.clone() {
        for seed in 0..3u64 {
            let ep = generate(&scene, &assets.catalogue, &params, seed, 0).unwrap();
            let (mut sim, _) = Sim::new(assets.clone(), config.clone(), sensors.clone(), &ep).unwrap();
            let mut h = std::collections::hash_map::DefaultHasher::new();
            let steps = if std::env::var("REPEAT").is_ok() { 21 } else { 400 };
            for k in 0..steps {
                let (obs, _) = sim.step(&wobble_action(k), false).unwrap();
                let _ = obs;
                if k % 20 == 0 {
                    let t = std::time::Instant::now();
                    let o = sim.observe();
                    total += t.elapsed();
                    n += 1;
                    for im in &o.images {
                        im.rgb.hash(&mut h);
                        for d in &im.depth {
                            d.to_bits().hash(&mut h);
                        }
                    }
                    if let Some(l) = &o.lidar {
                        for p in &l.points {
                            for c in p {
                                c.to_bits().hash(&mut h);
                            }
                        }
                    }
                }
            }
            println!("{} {} {:016x}", scene.id, seed, h.finish());
            if std::env::var("REPEAT").is_ok() {
                let t = std::time::Instant::now();
                for _ in 0..100 {
                    std::hint::black_box(sim.observe());
                }
                total += t.elapsed();
                n += 100;
            }
        }
    }
    println!(
        "obs mean {:.3} ms over {}",
        total.as_secs_f64() * 1e3 / n as f64,
        n
    );
}
