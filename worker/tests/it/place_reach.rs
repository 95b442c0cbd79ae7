//! The dataset generator's reach rule (`kitchen_r_core::reach`) against the twin: for every key
//! object in every zone of every committed scene, the place spot the rule accepts with the
//! least reach to spare is placed by the privileged oracle, through the same runner
//! participants are scored by, with the base standing the rule's whole `BASE_SLACK` further
//! from the target than the approach pose and the grasp point on the object's far side (the
//! worst the rule allows for). The rule must also leave most of every zone usable: the test
//! prints, per zone and object, how many spots of a 1 cm grid it refuses.
//!
//! `PLACE_REACH_SWEEP=N` tries the N hardest accepted spots (at least 5 cm apart) of each zone
//! and object instead of one.

use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use kitchen_r_core::dataset::symbolic::{Placed, fits_in_zone};
use kitchen_r_core::reach::{ArmReach, BASE_SLACK};
use kitchen_r_episode::oracle::OraclePolicy;
use kitchen_r_episode::runner::{RunOptions, run_episode};
use kitchen_r_sim::world::Style;
use kitchen_r_sim::{Assets, EpisodeConfig, ObjectPlacement, SensorsConfig, Sim, SimConfig};

/// The place tolerance of the paper's success criterion, m.
const PLACE_TOLERANCE: f64 = 0.05;
/// Grid step of the spots counted and searched, m.
const GRID: f64 = 0.01;

/// One pick-then-place episode in a single zone.
#[derive(Debug, Clone)]
struct Case {
    label: String,
    episode: EpisodeConfig,
    target: [f64; 3],
}

/// Spots of `zone` on a `GRID` lattice where the object's footprint fits.
fn grid_spots(zone: &kitchen_r_core::scene::Zone, radius: f64) -> Vec<[f64; 2]> {
    let n = |i: usize| (zone.size[i] / 2.0 / GRID).floor() as i64;
    let mut out = Vec::new();
    for i in -n(0)..=n(0) {
        for j in -n(1)..=n(1) {
            let xy = [zone.center[0] + i as f64 * GRID, zone.center[1] + j as f64 * GRID];
            if fits_in_zone(zone, radius, xy) {
                out.push(xy);
            }
        }
    }
    out
}

fn cases(assets: &Assets, arm: &ArmReach, per_zone: usize) -> (Vec<Case>, Vec<String>, Vec<String>) {
    let (mut cases, mut table, mut mostly_refused) = (Vec::new(), Vec::new(), Vec::new());
    for scene in &assets.scenes {
        for zone in &scene.zones {
            let waist = arm.waist_at(zone.approach);
            let mut row = format!("{:<10} {:<7}", scene.id, zone.color);
            for model in assets.catalogue.key_models() {
                let placed = Placed::of(model);
                let spots = grid_spots(zone, placed.radius);
                let room =
                    |xy: [f64; 2]| arm.place_headroom(zone, placed.half_height, placed.grasp_offset, xy);
                let mut accepted: Vec<([f64; 2], f64)> = spots
                    .iter()
                    .map(|&xy| (xy, room(xy)))
                    .filter(|s| s.1 >= 0.0)
                    .collect();
                let refused = spots.len() - accepted.len();
                row += &format!("  {}: {:>3}/{:<4} refused", model.id, refused, spots.len());
                if 2 * refused > spots.len() {
                    mostly_refused.push(format!("{} {} {}", scene.id, zone.color, model.id));
                }
                accepted.sort_by(|a, b| a.1.total_cmp(&b.1));
                let Some(&(start, _)) = accepted.last() else {
                    continue;
                };
                let mut chosen: Vec<[f64; 2]> = Vec::new();
                for &(xy, _) in &accepted {
                    if chosen.len() == per_zone {
                        break;
                    }
                    if chosen.iter().all(|c| (c[0] - xy[0]).hypot(c[1] - xy[1]) >= 0.05) {
                        chosen.push(xy);
                    }
                }
                for target in chosen {
                    // Base moved `BASE_SLACK` away from the target; grasp point on the far side.
                    let (dx, dy) = (target[0] - waist[0], target[1] - waist[1]);
                    let (ux, uy) = (dx / dx.hypot(dy), dy / dx.hypot(dy));
                    let [gx, gy, _] = model.grasp_offset;
                    let yaw = if gx.hypot(gy) > 1e-9 {
                        uy.atan2(ux) - gy.atan2(gx)
                    } else {
                        0.0
                    };
                    let [ax, ay, ayaw] = zone.approach;
                    let z = zone.height + placed.half_height;
                    let name = model.id.clone();
                    let episode = EpisodeConfig {
                        id: format!("reach-{}-{}-{}", scene.id, zone.color, model.id),
                        scene: scene.id.clone(),
                        seed: 0,
                        robot_start: [ax - BASE_SLACK * ux, ay - BASE_SLACK * uy, ayaw],
                        objects: vec![ObjectPlacement {
                            name: name.clone(),
                            model: model.id.clone(),
                            color: model.color,
                            position: [start[0], start[1], z],
                            yaw,
                        }],
                        background: Vec::new(),
                        style: Style::of(scene),
                        plan: vec![format!("pick the {name}"), format!("place the {name}")],
                        place_targets: vec![[target[0], target[1], z]],
                    };
                    cases.push(Case {
                        label: format!(
                            "{} {} {} at [{:.3}, {:.3}]",
                            scene.id, zone.color, model.id, target[0], target[1]
                        ),
                        episode,
                        target: [target[0], target[1], z],
                    });
                }
            }
            table.push(row);
        }
    }
    (cases, table, mostly_refused)
}

/// Runs each case with the oracle; `Err` describes a miss.
fn run_cases(assets: &Assets, cases: &[Case]) -> Vec<Result<String, String>> {
    let sensors = SensorsConfig {
        cameras: Vec::new(),
        lidar: None,
        ..SensorsConfig::default()
    };
    let sim_cfg = SimConfig::load_default().unwrap();
    let run = RunOptions {
        privileged: true,
        ..RunOptions::default()
    };
    let next = AtomicUsize::new(0);
    let out = Mutex::new(vec![Err(String::from("not run")); cases.len()]);
    let jobs = std::thread::available_parallelism().map_or(1, |n| n.get());
    std::thread::scope(|scope| {
        for _ in 0..jobs.min(cases.len()) {
            scope.spawn(|| {
                let mut oracle = OraclePolicy::new(assets).without_images();
                loop {
                    let i = next.fetch_add(1, Ordering::SeqCst);
                    let Some(c) = cases.get(i) else { break };
                    let (mut sim, _) =
                        Sim::new(assets.clone(), sim_cfg.clone(), sensors.clone(), &c.episode).unwrap();
                    let o = run_episode(&mut sim, &mut oracle, &run, None, &mut ()).unwrap();
                    let p = sim.object_poses()[0].1.translation.vector;
                    let [tx, ty, tz] = c.target;
                    let d = ((p.x - tx).powi(2) + (p.y - ty).powi(2) + (p.z - tz).powi(2)).sqrt();
                    let failed: Vec<String> = (o.tasks.iter().filter(|t| !t.success))
                        .map(|t| format!("{:?}: {}", t.step, t.failure.as_deref().unwrap_or("")))
                        .collect();
                    let r = if failed.is_empty() && d <= PLACE_TOLERANCE {
                        Ok(format!("{}: placed {d:.3} m off", c.label))
                    } else {
                        Err(format!("{}: ends {d:.3} m off; {}", c.label, failed.join("; ")))
                    };
                    out.lock().unwrap()[i] = r;
                }
            });
        }
    });
    out.into_inner().unwrap()
}

#[test]
fn every_place_spot_the_rule_accepts_is_placed_by_the_oracle() {
    let assets = Assets::load_default().unwrap();
    let arm = ArmReach::committed().unwrap();
    let per_zone = std::env::var("PLACE_REACH_SWEEP")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1);
    let (cases, table, mostly_refused) = cases(&assets, arm, per_zone);
    eprintln!("spots of a {GRID} m grid the reach rule refuses, per zone and object:");
    for row in &table {
        eprintln!("{row}");
    }
    let started = std::time::Instant::now();
    let results = run_cases(&assets, &cases);
    for r in &results {
        match r {
            Ok(m) => eprintln!("ok   {m}"),
            Err(m) => eprintln!("MISS {m}"),
        }
    }
    eprintln!(
        "{} hardest accepted spots in {:.1} s",
        cases.len(),
        started.elapsed().as_secs_f64()
    );
    assert!(
        mostly_refused.is_empty(),
        "the rule refuses most of: {mostly_refused:?}"
    );
    let misses: Vec<&String> = results.iter().filter_map(|r| r.as_ref().err()).collect();
    assert!(misses.is_empty(), "accepted but not placed:\n{misses:#?}");
}
