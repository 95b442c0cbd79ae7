//! `kitchen-r replay TRACE`: an episode reproduced from its trace (`eval --trace`), checked
//! against the outcome its evaluation recorded, and its video written as `eval --record`
//! writes it (the workers' recorder, as a hook on the replay). A replay that disagrees with the
//! recorded outcome writes nothing and exits non-zero: a video is shown only of the episode
//! that was scored. A gzipped trace (as the server stores and serves it) is read as it is. The
//! work is in `kitchen_r_episode::trace`.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use clap::Args;
use kitchen_r_episode::eval::summarize;
use kitchen_r_episode::runner::EpisodeOutcome;
use kitchen_r_episode::trace::{Trace, replay as replay_trace};
use kitchen_r_record::video::episode::{EpisodeVideo, VideoHook};

#[derive(Args, Debug)]
pub(crate) struct ReplayArgs {
    /// The trace of one episode: `DIR/<episode key>.trace.json` written by `eval --trace`, or a
    /// server's gzipped trace (`kitchen-r submission trace`, `.trace.json.gz`).
    #[arg(value_name = "TRACE")]
    trace: PathBuf,
    /// Where to write the episode video (both cameras at the control rate with the caption
    /// bar; AV1 MP4, as `eval --record` writes it) [default: the trace's path with
    /// `.trace.json` or `.trace.json.gz` replaced by `.mp4`].
    #[arg(long, value_name = "OUT.mp4", conflicts_with = "check_only")]
    video: Option<PathBuf>,
    /// Only check that the replay reproduces the recorded outcome bit for bit; render and
    /// write nothing (no camera frame is rendered, so this is the cheapest check).
    #[arg(long)]
    check_only: bool,
}

pub(crate) fn replay(args: ReplayArgs) -> anyhow::Result<()> {
    let trace = Trace::load(&args.trace)?;
    let started = Instant::now();
    let refused = |e| anyhow::anyhow!("replay refused, nothing written: {e}");
    if args.check_only {
        let out = replay_trace(&trace, &mut ()).map_err(refused)?;
        print(&trace, &out, started);
        return Ok(());
    }
    let path = args.video.unwrap_or_else(|| default_video(&args.trace));
    let n_tasks = trace
        .run
        .max_tasks
        .map_or(trace.episode.plan.len(), |m| m.min(trace.episode.plan.len()));
    let mut nothing_else = ();
    let video = EpisodeVideo::new(&trace.episode.plan, n_tasks, 0);
    let mut recorder = VideoHook::new(&mut nothing_else, video);
    let out = replay_trace(&trace, &mut recorder).map_err(refused)?;
    print(&trace, &out, started);
    let video = recorder.into_video().finish().map_err(anyhow::Error::msg)?;
    std::fs::write(&path, &video.mp4).with_context(|| format!("writing {}", path.display()))?;
    println!(
        "video {}: {} frames, {} bytes, composed and encoded in {:.2} s",
        path.display(),
        video.frames,
        video.mp4.len(),
        video.encode_time.as_secs_f64()
    );
    Ok(())
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
