//! `kitchen-r replay TRACE`: an episode reproduced from its trace (`eval --trace`), checked
//! against the outcome its evaluation recorded, and its video written as `eval --record`
//! writes it (the workers' recorder, as a hook on the replay). A replay that disagrees with the
//! recorded outcome writes nothing and exits non-zero: a video is shown only of the episode
//! that was scored. A gzipped trace (as the server stores and serves it) is read as it is. The
//! work is in `kitchen_r_episode::trace`.
//!
//! `--mcap` and `--frames` record the replay as `collect` records an episode, at any of the
//! configured cameras and any resolution (`--camera`, `--size`): rendering reads the world
//! without changing it, so the replay's physics, and its check, are the same whatever is
//! rendered. Files are staged beside their destination and moved into place only after the
//! check passed.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use clap::Args;
use kitchen_r_episode::eval::summarize;
use kitchen_r_episode::runner::{EpisodeOutcome, StepHook};
use kitchen_r_episode::trace::{Trace, replay_with};
use kitchen_r_record::keep_cameras;
use kitchen_r_record::live_hook::LiveHook;
use kitchen_r_record::replay::{FramesOut, ReplayRecorder, episode_meta};
use kitchen_r_record::video::episode::{EpisodeVideo, VideoHook};
use kitchen_r_sim::{Assets, SensorsConfig, SimConfig};

use crate::live_view::LiveView;

#[derive(Args, Debug)]
pub(crate) struct ReplayArgs {
    /// The trace of one episode: `DIR/<episode key>.trace.json` written by `eval --trace`, or a
    /// server's gzipped trace (`kitchen-r submission trace`, `.trace.json.gz`).
    #[arg(value_name = "TRACE")]
    trace: PathBuf,
    /// Where to write the episode video (the cameras at the control rate with the caption
    /// bar; H.264 MP4, as `eval --record` writes it) [default, when neither `--mcap` nor
    /// `--frames` is given: the trace's path with `.trace.json` or `.trace.json.gz` replaced by
    /// `.mp4`].
    #[arg(long, value_name = "OUT.mp4", conflicts_with = "check_only")]
    video: Option<PathBuf>,
    /// Write the replay as `collect` writes an episode's MCAP (ROS 2 messages: both cameras'
    /// images and depth, LiDAR, /tf, /odom, the action; the task spans in its metadata).
    #[arg(long, value_name = "OUT.mcap", conflicts_with = "check_only")]
    mcap: Option<PathBuf>,
    /// Write each camera's image of every `--every`-th control step as
    /// `DIR/<step>_<camera>.png` (DIR must be new or empty).
    #[arg(long, value_name = "DIR", conflicts_with = "check_only")]
    frames: Option<PathBuf>,
    /// With `--frames`: keep every N-th control step (1: all, 10 control steps a second).
    #[arg(long, value_name = "N", default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
    every: u32,
    /// Render only these configured cameras (comma-separated, e.g. `gripper`) [default: all of
    /// `configs/sensors.toml`].
    #[arg(
        long,
        value_name = "NAMES",
        value_delimiter = ',',
        conflicts_with = "check_only"
    )]
    camera: Vec<String>,
    /// Render the cameras at this resolution (e.g. `640x480`; the field of view is kept)
    /// [default: the configured one, 128x128].
    #[arg(long, value_name = "WxH", value_parser = parse_size, conflicts_with = "check_only")]
    size: Option<(u32, u32)>,
    /// Only check that the replay reproduces the recorded outcome bit for bit; render and
    /// write nothing (no camera frame is rendered, so this is the cheapest check).
    #[arg(long, conflicts_with_all = ["foxglove", "foxglove_wait", "ros2", "ros2_wait"])]
    check_only: bool,
    #[command(flatten)]
    live: crate::live_view::LiveArgs,
    /// With --foxglove or --ros2: sim seconds replayed per wall second (1: real time; 0: as
    /// fast as it runs). The outcome does not depend on it.
    #[arg(long, value_name = "X", default_value_t = 1.0)]
    speed: f64,
}

fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let bad = || format!("{s:?}: give the size as WIDTHxHEIGHT, each 16 to 4096 (e.g. 640x480)");
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(bad)?;
    let (w, h): (u32, u32) = (
        w.trim().parse().map_err(|_| bad())?,
        h.trim().parse().map_err(|_| bad())?,
    );
    match (16..=4096).contains(&w) && (16..=4096).contains(&h) {
        true => Ok((w, h)),
        false => Err(bad()),
    }
}

/// The sensors the replay renders: the configured ones, less the cameras `--camera` leaves
/// out, at `--size`.
fn sensors(names: &[String], size: Option<(u32, u32)>) -> anyhow::Result<SensorsConfig> {
    let mut s = SensorsConfig::load_default()?;
    if !names.is_empty() {
        keep_cameras(&mut s, names).map_err(|e| anyhow::anyhow!("--camera: {e}"))?;
    }
    if let Some((w, h)) = size {
        for c in &mut s.cameras {
            (c.width, c.height) = (w, h);
        }
    }
    Ok(s)
}

pub(crate) fn replay(args: ReplayArgs) -> anyhow::Result<()> {
    let trace = Trace::load(&args.trace)?;
    let started = Instant::now();
    let assets = Assets::load_default()?;
    let sim_cfg = SimConfig::load_default()?;
    let sensors = sensors(&args.camera, args.size)?;
    let refused = |e| anyhow::anyhow!("replay refused, nothing written: {e}");
    if args.check_only {
        let out = replay_with(&trace, &assets, &sim_cfg, &sensors, &mut ()).map_err(refused)?;
        print(&trace, &out, started);
        return Ok(());
    }
    // Watching it live is a reason to replay of its own: no video unless asked for then.
    let video_path = match (&args.video, &args.mcap, &args.frames, args.live.any()) {
        (Some(v), _, _, _) => Some(v.clone()),
        (None, None, None, false) => Some(default_video(&args.trace)),
        _ => None,
    };
    let staged = Staged::new(args.mcap.as_deref(), args.frames.as_deref())?;
    let meta = episode_meta(&trace.episode, &sensors);
    let mut recorder = ReplayRecorder::new(
        staged.mcap.as_deref().map(|p| (p, &meta)),
        staged.frames.clone().map(|dir| FramesOut {
            dir,
            every: args.every as usize,
        }),
    )?;
    let n_tasks = trace
        .run
        .max_tasks
        .map_or(trace.episode.plan.len(), |m| m.min(trace.episode.plan.len()));
    let view = LiveView::start(&args.live, &sensors)?;
    // The live view, when watched, wraps whatever else records the replay.
    let live = |inner: &mut dyn StepHook, replay: &mut dyn FnMut(&mut dyn StepHook)| match &view {
        Some(v) => replay(&mut LiveHook::new(inner, v.queue(), v.sensors()).paced(args.speed)),
        None => replay(inner),
    };
    let mut replayed = None;
    let video = match video_path.is_some() {
        true => {
            let video = EpisodeVideo::new(&trace.episode.plan, n_tasks, 0);
            let mut hook = VideoHook::new(&mut recorder, video);
            live(&mut hook, &mut |h| {
                replayed = Some(replay_with(&trace, &assets, &sim_cfg, &sensors, h))
            });
            Some(hook.into_video())
        }
        false => {
            live(&mut recorder, &mut |h| {
                replayed = Some(replay_with(&trace, &assets, &sim_cfg, &sensors, h))
            });
            None
        }
    };
    if let Some(v) = view {
        v.finish()?;
    }
    let replayed = replayed.expect("the replay ran");
    let out = match replayed {
        Ok(out) => out,
        Err(e) => {
            staged.discard();
            return Err(refused(e));
        }
    };
    print(&trace, &out, started);
    let files = match recorder.finish() {
        Ok(f) => f,
        Err(e) => {
            staged.discard();
            return Err(e).context("recording the replay");
        }
    };
    staged.commit(args.mcap.as_deref(), args.frames.as_deref())?;
    if let Some(m) = &args.mcap {
        println!("mcap {}: {} control steps", m.display(), files.steps);
    }
    if let Some(d) = &args.frames {
        println!("frames {}: {} PNG files", d.display(), files.pngs);
    }
    if let (Some(path), Some(video)) = (video_path, video) {
        let video = video.finish().map_err(anyhow::Error::msg)?;
        std::fs::write(&path, &video.mp4).with_context(|| format!("writing {}", path.display()))?;
        println!(
            "video {}: {} frames, {} bytes, composed and encoded in {:.2} s",
            path.display(),
            video.frames,
            video.mp4.len(),
            video.encode_time.as_secs_f64()
        );
    }
    Ok(())
}

/// The MCAP and the frames folder written beside their destinations (`*.partial`), moved into
/// place once the replay agreed with the recorded outcome, removed otherwise.
struct Staged {
    mcap: Option<PathBuf>,
    frames: Option<PathBuf>,
}

impl Staged {
    fn new(mcap: Option<&Path>, frames: Option<&Path>) -> anyhow::Result<Staged> {
        if let Some(d) = frames
            && d.exists()
            && std::fs::read_dir(d)
                .with_context(|| format!("--frames {}", d.display()))?
                .next()
                .is_some()
        {
            anyhow::bail!(
                "--frames {}: the folder is not empty; name a new or empty one",
                d.display()
            );
        }
        let partial = |p: &Path| {
            let mut s = p.as_os_str().to_owned();
            s.push(".partial");
            PathBuf::from(s)
        };
        let staged = Staged {
            mcap: mcap.map(partial),
            frames: frames.map(partial),
        };
        if let Some(d) = &staged.frames {
            // A folder a killed replay left behind.
            let _ = std::fs::remove_dir_all(d);
        }
        Ok(staged)
    }

    fn discard(&self) {
        if let Some(m) = &self.mcap {
            let _ = std::fs::remove_file(m);
        }
        if let Some(d) = &self.frames {
            let _ = std::fs::remove_dir_all(d);
        }
    }

    fn commit(&self, mcap: Option<&Path>, frames: Option<&Path>) -> anyhow::Result<()> {
        if let (Some(from), Some(to)) = (&self.mcap, mcap) {
            std::fs::rename(from, to).with_context(|| format!("moving the MCAP to {}", to.display()))?;
        }
        if let (Some(from), Some(to)) = (&self.frames, frames) {
            if to.exists() {
                std::fs::remove_dir(to)
                    .with_context(|| format!("replacing the empty folder {}", to.display()))?;
            }
            std::fs::rename(from, to).with_context(|| format!("moving the frames to {}", to.display()))?;
        }
        Ok(())
    }
}

/// `DIR/<key>.trace.json` (or `.trace.json.gz`) → `DIR/<key>.mp4`.
fn default_video(trace: &Path) -> PathBuf {
    let name = trace.file_name().and_then(|n| n.to_str()).unwrap_or("episode");
    let name = name.strip_suffix(".gz").unwrap_or(name);
    let stem = name
        .strip_suffix(".trace.json")
        .or_else(|| name.strip_suffix(".json"))
        .unwrap_or(name);
    trace.with_file_name(format!("{stem}.mp4"))
}

/// The replayed episode's tasks and `eval`'s table of SR per task kind.
fn print(trace: &Trace, out: &EpisodeOutcome, started: Instant) {
    println!(
        "episode {}  scene {}  policy {}  tasks {}  calls {}",
        out.episode_id,
        out.scene,
        trace.policy.name,
        out.tasks.len(),
        trace.calls.len()
    );
    for t in &out.tasks {
        let result = if t.success { "success" } else { "failed" };
        let why = t.failure.as_deref().map_or(String::new(), |f| format!("  {f}"));
        println!(
            "  task {} {:<28} {result:<7} {:>7.1} s sim  {:>4} calls{why}",
            t.index,
            format!("{:?}", t.step),
            t.sim_time,
            t.policy_calls
        );
    }
    let (overall, by_kind) = summarize(std::slice::from_ref(out));
    crate::eval_cmd::print_kinds(&by_kind, &overall);
    println!(
        "the replay agrees with the recorded outcome bit for bit (sim {:.1} s, replayed in {:.2} s wall)",
        out.sim_time,
        started.elapsed().as_secs_f64()
    );
}

#[cfg(test)]
mod tests {
    use super::parse_size;

    #[test]
    fn a_size_is_width_x_height_within_16_to_4096() {
        assert_eq!(parse_size("640x480"), Ok((640, 480)));
        assert_eq!(parse_size("16X4096"), Ok((16, 4096)));
        for bad in ["640", "640x", "x480", "15x480", "640x5000", "-1x20", "axb"] {
            let e = parse_size(bad).unwrap_err();
            assert!(e.contains("WIDTHxHEIGHT"), "{bad}: {e}");
        }
    }
}
