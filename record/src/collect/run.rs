//! The collection loop: a work queue over threads (each owns a simulator and an oracle), files
//! written as `*.partial` and renamed, the manifest and the summary on the calling thread.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc;
use std::time::Instant;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use kitchen_r_core::dataset::{Instruction, Split};
use kitchen_r_sim::generator::splitmix;
use kitchen_r_sim::{Assets, EpisodeConfig, EpisodeParams, SensorsConfig, Sim, SimConfig, SimError};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::hook::{Recorder, Trip};
use super::{CollectError, CollectOptions, CollectSummary, ManifestEntry};
use crate::hdf5_aloha::Hdf5Recorder;
use crate::mcap_ros2::McapRecorder;
use crate::rate::RateMonitor;
use crate::{EpisodeMeta, StaticTransform};
use kitchen_r_episode::oracle::{OraclePolicy, expert_options};
use kitchen_r_episode::runner::run_episode;

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> CollectError + '_ {
    move |source| CollectError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// The configuration of episode `index`.
fn episode(
    assets: &Assets,
    params: &EpisodeParams,
    ins: &[Instruction],
    opts: &CollectOptions,
    index: usize,
) -> Result<(EpisodeConfig, String), CollectError> {
    let instruction = &ins[index % ins.len()];
    let seed = splitmix(opts.seed ^ splitmix(index as u64));
    let scene = assets.scene(&instruction.scene)?;
    let mut cfg = EpisodeConfig::from_instruction(instruction, scene, &assets.catalogue, params, seed)?;
    cfg.id = format!("ep{index:05}");
    if opts.config.randomize_style {
        // A separate stream, so style draws never shift the robot start or background objects.
        let mut rng = ChaCha8Rng::seed_from_u64(splitmix(seed ^ 0x53_5459_4c45));
        let j = params.color_jitter;
        let s = &mut cfg.style;
        for c in s.floor_color.iter_mut().chain(s.wall_color.iter_mut()) {
            *c = (*c + rng.random_range(-j..=j)).clamp(0.0, 1.0);
        }
        if !params.floor_tiles.is_empty() {
            s.floor_tile = params.floor_tiles[rng.random_range(0..params.floor_tiles.len())];
        }
    }
    Ok((cfg, instruction.instruction.clone()))
}

fn final_paths(opts: &CollectOptions, index: usize) -> Vec<PathBuf> {
    let ext = opts.formats.extensions();
    ext.iter()
        .map(|e| opts.out.join(format!("ep{index:05}.{e}")))
        .collect()
}

fn partial(p: &Path) -> PathBuf {
    let mut s = p.as_os_str().to_owned();
    s.push(".partial");
    PathBuf::from(s)
}

/// Run, record and judge episode `index`; returns its manifest entry.
fn one(
    assets: &Assets,
    sim: &mut Option<Sim>,
    oracle: &mut OraclePolicy,
    cfg: &EpisodeConfig,
    instruction: &str,
    opts: &CollectOptions,
    index: usize,
) -> Result<ManifestEntry, CollectError> {
    let started = Instant::now();
    let finals = final_paths(opts, index);
    let mut entry = ManifestEntry {
        index,
        episode_id: cfg.id.clone(),
        instruction_id: String::new(),
        seed: cfg.seed,
        kept: false,
        reason: None,
        reason_kind: None,
        frames: 0,
        sim_time: 0.0,
        wall_s: 0.0,
        files: Vec::new(),
    };
    let reset = match sim {
        Some(s) => s.reset(cfg).map(|_| ()),
        None => {
            let mut sim_cfg = SimConfig::load_default()?;
            sim_cfg.monitors = opts.config.monitors.clone();
            Sim::new(assets.clone(), sim_cfg, sensors(opts)?, cfg).map(|(s, _)| *sim = Some(s))
        }
    };
    let discard = |entry: &mut ManifestEntry, t: Trip| {
        entry.reason_kind = Some(t.kind);
        entry.reason = Some(t.message);
    };
    match reset {
        Err(SimError::Preflight(m)) => {
            discard(&mut entry, Trip::new("preflight", m));
            return Ok(entry);
        }
        Err(e) => return Err(e.into()),
        Ok(()) => {}
    }
    let s = sim.as_mut().ok_or(CollectError::Panicked)?;
    let meta = EpisodeMeta {
        episode_id: cfg.id.clone(),
        scene: cfg.scene.clone(),
        instruction: instruction.to_string(),
        plan: cfg.plan.clone(),
        seed: cfg.seed,
        sensor_mounts: mounts(&sensors(opts)?),
    };
    let mcap_path = opts.formats.mcap.then(|| partial(&finals[0]));
    let mcap = match &mcap_path {
        Some(p) => Some(McapRecorder::create(p, &meta).map_err(|e| CollectError::Config(e.to_string()))?),
        None => None,
    };
    let hdf5 = opts.formats.hdf5.then(|| Hdf5Recorder::new(meta.clone()));
    let rate = RateMonitor::new(opts.config.rates.min_hz.clone(), opts.config.rates.window_s);
    let mut rec = Recorder::new(mcap, hdf5, rate, opts.config.monitors.clone());
    let outcome = run_episode(s, oracle, &expert_options(), None, &mut rec)
        .map_err(|e| CollectError::Config(e.to_string()))?;
    entry.frames = rec.frames;
    entry.sim_time = outcome.sim_time;
    let failed = outcome.tasks.iter().find(|t| !t.success);
    let trip = rec.trip.take().or_else(|| {
        failed.map(|t| {
            Trip::new(
                "task_failed",
                format!("{}: {}", t.step, t.failure.clone().unwrap_or_default()),
            )
        })
    });
    let written = finish(&mut rec, opts, &finals, mcap_path.as_deref());
    match (trip, written) {
        (Some(t), _) | (None, Err(t)) => {
            for p in &finals {
                let _ = std::fs::remove_file(partial(p));
                let _ = std::fs::remove_file(p);
            }
            discard(&mut entry, t);
        }
        (None, Ok(())) => {
            for p in &finals {
                std::fs::rename(partial(p), p).map_err(io(p))?;
            }
            entry.kept = true;
            entry.files = finals
                .iter()
                .filter_map(|p| p.file_name())
                .map(|n| n.to_string_lossy().into())
                .collect();
        }
    }
    entry.wall_s = started.elapsed().as_secs_f64();
    Ok(entry)
}

/// Close the recorders into their `.partial` files.
fn finish(
    rec: &mut Recorder,
    opts: &CollectOptions,
    finals: &[PathBuf],
    mcap: Option<&Path>,
) -> Result<(), Trip> {
    let err = |e: crate::RecordError| Trip::new("write_error", e.to_string());
    if let Some(m) = rec.mcap.take() {
        m.finish(&rec.spans).map_err(err)?;
        debug_assert!(mcap.is_some());
    }
    if let Some(h) = rec.hdf5.take() {
        let path = partial(&finals[usize::from(opts.formats.mcap)]);
        h.finish(&path, &rec.spans).map_err(err)?;
    }
    Ok(())
}

fn sensors(opts: &CollectOptions) -> Result<SensorsConfig, CollectError> {
    Ok(match &opts.sensors {
        Some(s) => s.clone(),
        None => SensorsConfig::load_default()?,
    })
}

/// Static transforms of the sensor mounts (`/tf_static`).
fn mounts(sensors: &SensorsConfig) -> Vec<StaticTransform> {
    use kitchen_r_sim::config::Mount;
    let parent = |m: Mount| match m {
        Mount::Base => "base_link",
        Mount::Gripper => "ee_link",
        Mount::World => "odom",
    };
    let mut out: Vec<StaticTransform> = sensors
        .cameras
        .iter()
        .map(|c| {
            let q = nalgebra::UnitQuaternion::from_euler_angles(c.rpy[0], c.rpy[1], c.rpy[2]);
            StaticTransform {
                parent: parent(c.mount).into(),
                child: format!("{}_optical_frame", c.name),
                translation: c.position,
                rotation: [q.w, q.i, q.j, q.k],
            }
        })
        .collect();
    if let Some(l) = &sensors.lidar {
        out.push(StaticTransform {
            parent: parent(l.mount).into(),
            child: "lidar".into(),
            translation: l.position,
            rotation: [1.0, 0.0, 0.0, 0.0],
        });
    }
    out
}

fn bar(opts: &CollectOptions, n: usize) -> ProgressBar {
    let pb = ProgressBar::new(n as u64);
    if !opts.progress {
        pb.set_draw_target(ProgressDrawTarget::hidden());
    }
    if let Ok(style) =
        ProgressStyle::with_template("{bar:30} {pos}/{len} episodes {elapsed} (eta {eta}) {msg}")
    {
        pb.set_style(style);
    }
    pb
}

/// Collect `opts.episodes` episodes into `opts.out`.
pub fn collect(opts: &CollectOptions) -> Result<CollectSummary, CollectError> {
    opts.config.validate()?;
    std::fs::create_dir_all(&opts.out).map_err(io(&opts.out))?;
    let started = Instant::now();
    let assets = Assets::load_default()?;
    let params = EpisodeParams::load_default()?;
    let ins = kitchen_r_episode::eval::instructions(Split::Dev, None)?;
    let mut summary = CollectSummary {
        requested: opts.episodes,
        ..CollectSummary::default()
    };
    let todo: Vec<usize> = (0..opts.episodes)
        .filter(|i| !final_paths(opts, *i).iter().all(|p| p.is_file()))
        .collect();
    summary.skipped = opts.episodes - todo.len();
    let manifest_path = opts.out.join("manifest.jsonl");
    let mut manifest = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&manifest_path)
        .map_err(io(&manifest_path))?;
    let pb = bar(opts, todo.len());
    let next = AtomicUsize::new(0);
    let (tx, rx) = mpsc::channel::<Result<ManifestEntry, CollectError>>();
    std::thread::scope(|scope| -> Result<(), CollectError> {
        for _ in 0..opts.jobs.clamp(1, todo.len().max(1)) {
            let (tx, next, todo, assets, params, ins) = (tx.clone(), &next, &todo, &assets, &params, &ins);
            scope.spawn(move || {
                let mut oracle = OraclePolicy::new(assets);
                let mut sim = None;
                while let Some(&i) = todo.get(next.fetch_add(1, Ordering::SeqCst)) {
                    let r = episode(assets, params, ins, opts, i).and_then(|(cfg, text)| {
                        let mut e = one(assets, &mut sim, &mut oracle, &cfg, &text, opts, i)?;
                        e.instruction_id = ins[i % ins.len()].id.clone();
                        Ok(e)
                    });
                    if tx.send(r).is_err() {
                        break;
                    }
                }
            });
        }
        drop(tx);
        for r in rx {
            let e = r?;
            let line = serde_json::to_string(&e).unwrap_or_default();
            writeln!(manifest, "{line}").map_err(io(&manifest_path))?;
            summary.frames += e.frames;
            match (&e.kept, &e.reason_kind) {
                (true, _) => summary.kept += 1,
                (false, kind) => {
                    let kind = kind.clone().unwrap_or_else(|| "unknown".into());
                    pb.println(format!(
                        "discarded {} ({}): {}",
                        e.episode_id,
                        e.instruction_id,
                        e.reason.clone().unwrap_or_default()
                    ));
                    *summary.discarded.entry(kind).or_default() += 1;
                }
            }
            pb.inc(1);
            pb.set_message(format!("kept {}", summary.kept));
        }
        Ok(())
    })?;
    pb.finish_and_clear();
    summary.wall_s = started.elapsed().as_secs_f64();
    let ran = summary.kept + summary.discarded.values().sum::<usize>();
    summary.episodes_per_min = if summary.wall_s > 0.0 {
        ran as f64 * 60.0 / summary.wall_s
    } else {
        0.0
    };
    Ok(summary)
}
