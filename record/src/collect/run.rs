//! The collection loop: a work queue over threads (each owns a simulator and an oracle), files
//! written as `*.partial` and renamed, the manifest and the summary on the calling thread.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use kitchen_r_core::GraspMode;
use kitchen_r_core::dataset::{Instruction, Split};
use kitchen_r_sim::{Assets, EpisodeConfig, EpisodeParams, Sim, SimConfig, SimError};

use super::hook::{Recorder, Trip};
use super::sensors::{camera_specs, rate_monitor, sensors};
use super::{CollectError, CollectOptions, CollectSummary, ManifestEntry};
use crate::EpisodeMeta;
use crate::frame::mounts;
use crate::hdf5_aloha::{Hdf5Options, Hdf5Recorder};
use crate::lerobot::{EpisodeRecorder, LeRobotDataset};
use crate::live_hook::LiveHook;
use crate::mcap_ros2::McapRecorder;
use crate::video::VideoSettings;
use kitchen_r_episode::batch::run_batch;
use kitchen_r_episode::oracle::{OraclePolicy, expert_options};
use kitchen_r_episode::runner::run_episode;
use kitchen_r_episode::samples::collection_episode;

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> CollectError + '_ {
    move |source| CollectError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// The configuration of episode `index`, its instruction text and instruction id.
fn episode(
    assets: &Assets,
    params: &EpisodeParams,
    ins: &[Instruction],
    opts: &CollectOptions,
    index: usize,
) -> Result<(EpisodeConfig, String, String), CollectError> {
    if let Some(batch) = &opts.batch {
        // Run exactly as saved (ids and seeds included); a batch episode has no dataset
        // instruction, so its plan stands in for the text.
        let cfg = batch[index].clone();
        let text = cfg.plan.join("; ");
        return Ok((cfg, text, String::new()));
    }
    // The paper's randomisation when configured, each aspect as switched in
    // configs/episodes.toml `[randomise]`; the same seed gives the same episode (and the same
    // as the Python package's streamed expert samples).
    let cfg = collection_episode(assets, params, ins, opts.seed, index, opts.config.randomise)?;
    let instruction = &ins[index % ins.len()];
    Ok((cfg, instruction.instruction.clone(), instruction.id.clone()))
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

/// Run, record and judge episode `index`; returns its manifest entry. A kept episode is staged
/// for the LeRobotDataset under `staging`, encoding its videos with the given settings (when
/// that format is on).
#[allow(clippy::too_many_arguments)]
fn one(
    assets: &Assets,
    sim: &mut Option<Sim>,
    oracle: &mut OraclePolicy,
    cfg: &EpisodeConfig,
    instruction: &str,
    opts: &CollectOptions,
    index: usize,
    staging: Option<(&Path, VideoSettings)>,
) -> Result<ManifestEntry, CollectError> {
    let started = Instant::now();
    let finals = final_paths(opts, index);
    let mut entry = ManifestEntry {
        index,
        episode_id: cfg.id.clone(),
        instruction_id: String::new(),
        seed: cfg.seed,
        grasp_mode: GraspMode::Abstract,
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
            if let Some(mode) = opts.grasp {
                sim_cfg.grasp.mode = mode;
            }
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
    entry.grasp_mode = s.config().grasp.mode;
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
    let hdf5_options = Hdf5Options {
        depth: opts.depth.unwrap_or_default(),
        ..Hdf5Options::default()
    };
    let hdf5 = opts
        .formats
        .hdf5
        .then(|| Hdf5Recorder::new(meta.clone(), hdf5_options));
    let lerobot = match staging {
        Some((_, video)) => Some(EpisodeRecorder::new(
            index,
            meta.clone(),
            &camera_specs(&sensors(opts)?),
            video,
        )?),
        None => None,
    };
    let mut rec = Recorder::new(
        mcap,
        hdf5,
        lerobot,
        rate_monitor(opts)?,
        opts.config.monitors.clone(),
    );
    rec.depth = opts.depth.is_some();
    let outcome = match &opts.live {
        Some(queue) => {
            let mut live = LiveHook::new(&mut rec, queue.clone(), &sensors(opts)?);
            run_episode(s, oracle, &expert_options(), None, &mut live)
        }
        None => run_episode(s, oracle, &expert_options(), None, &mut rec),
    }
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
    let mut written = finish(&mut rec, opts, &finals, mcap_path.as_deref());
    if let (None, Ok(()), Some(l), Some(dir)) = (&trip, &written, rec.lerobot.take(), staging.map(|s| s.0)) {
        written = l.finish(dir).map_err(|e| Trip::new("write_error", e.to_string()));
    }
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

/// Collect `opts.episodes` episodes (or the batch's) into `opts.out`.
pub fn collect(opts: &CollectOptions) -> Result<CollectSummary, CollectError> {
    opts.config.validate()?;
    let f = opts.formats;
    if !(f.mcap || f.hdf5 || f.lerobot) {
        return Err(CollectError::Config("--format: name at least one format".into()));
    }
    sensors(opts)?;
    std::fs::create_dir_all(&opts.out).map_err(io(&opts.out))?;
    let started = Instant::now();
    let assets = Assets::load_default()?;
    let params = EpisodeParams::load_default()?;
    let ins = kitchen_r_episode::eval::instructions(Split::Dev, None)?;
    let count = opts.count();
    let mut summary = CollectSummary {
        requested: count,
        ..CollectSummary::default()
    };
    let mut dataset = match f.lerobot {
        true => Some(
            LeRobotDataset::open(&opts.out.join("lerobot"))?
                .with_episodes_per_file(opts.lerobot_episodes_per_file),
        ),
        false => None,
    };
    let mut video = VideoSettings::default();
    if let Some(d) = &dataset {
        d.check_cameras(&camera_specs(&sensors(opts)?))?;
        video = video.with_codec(d.resolve_codec(opts.video_codec)?);
    }
    let staging = dataset.as_ref().map(LeRobotDataset::staging_dir);
    let todo: Vec<usize> = (0..count)
        .filter(|i| {
            let files = final_paths(opts, *i).iter().all(|p| p.is_file());
            !(files && dataset.as_ref().is_none_or(|d| d.has(*i)))
        })
        .collect();
    summary.skipped = count - todo.len();
    let manifest_path = opts.out.join("manifest.jsonl");
    let mut manifest = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&manifest_path)
        .map_err(io(&manifest_path))?;
    let pb = bar(opts, todo.len());
    let staging = staging.as_deref().map(|s| (s, video));
    let oracle = || match opts.grasp {
        Some(mode) => OraclePolicy::new(&assets).with_grasp_mode(mode),
        None => OraclePolicy::new(&assets),
    };
    run_batch(
        todo.len(),
        opts.jobs,
        || (oracle(), None::<Sim>),
        |(oracle, sim), k| {
            let i = todo[k];
            episode(&assets, &params, &ins, opts, i).and_then(|(cfg, text, id)| {
                let mut e = one(&assets, sim, oracle, &cfg, &text, opts, i, staging)?;
                e.instruction_id = id;
                Ok(e)
            })
        },
        |_, r| {
            let e = r?;
            let line = serde_json::to_string(&e).unwrap_or_default();
            writeln!(manifest, "{line}").map_err(io(&manifest_path))?;
            summary.frames += e.frames;
            match (&e.kept, &e.reason_kind) {
                (true, _) => {
                    summary.kept += 1;
                    if let Some(d) = &mut dataset {
                        d.staged(e.index)?;
                    }
                }
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
            Ok::<(), CollectError>(())
        },
    )?;
    pb.finish_and_clear();
    if let Some(d) = &mut dataset {
        d.finish()?;
    }
    summary.wall_s = started.elapsed().as_secs_f64();
    let ran = summary.kept + summary.discarded.values().sum::<usize>();
    summary.episodes_per_min = if summary.wall_s > 0.0 {
        ran as f64 * 60.0 / summary.wall_s
    } else {
        0.0
    };
    Ok(summary)
}
