//! The episode video (docs/contest/video.md): every camera of every control step (0.1 s, the
//! control rate), side by side with a caption bar ([`super::caption`]), encoded as the episode runs
//! into one H.264 MP4 that browsers play inline.
//!
//! Frames are encoded as they come, with one second held back: when a task ends, its held
//! frames are captioned with the outcome (`SUCCESS at 14.2 s`, `FAILED: <reason>`), so a viewer
//! sees how the task ended without a frame being added (one frame per control step).
//!
//! Recording never decides anything about the episode: an encoder error stops the recording,
//! is kept, and is returned by [`EpisodeVideo::finish`]; the episode and its scores go on.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use kitchen_r_episode::runner::{StepHook, TaskRecord};
use kitchen_r_sim::{Action, Observation, Sim, StepInfo};

use super::caption::{Caption, FrameLayout, Outcome};
use super::{Codec, VideoEncoder, VideoSettings};

/// The control rate: one frame per control step.
pub const FPS: u32 = 10;

/// Encoder settings of episode videos: H.264 at 60 kbit/s, a key frame every 5 s for seeking.
/// H.264 because a failing policy's episode runs every task to its time limit (6,000–7,200
/// frames), which AV1 took 78–121 s to encode here and H.264 encodes about twelve times faster
/// (docs/measured/video.md), so a requested video plays within the 30 s a viewer waits. 60 kbit/s:
/// measured on 888 oracle frames, about 0.74 KB a frame with the caption sharp (the AV1 videos'
/// size:
/// 0.66 KB), where the base QP takes 1.3 KB; a still scene takes 0.14 KB a frame. The AV1 knobs
/// stay as they were measured (quantizer 160) for a build that switches back.
pub const SETTINGS: VideoSettings = VideoSettings {
    codec: Codec::H264,
    speed: 10,
    quantizer: 160,
    h264_kbps: 60,
    key_interval: 50,
};

/// A frame waiting for its task's outcome.
struct Held {
    images: Vec<Vec<u8>>,
    task: usize,
    time: f64,
}

/// Records one episode; see the module doc. Use it through [`VideoHook`].
pub struct EpisodeVideo {
    plan: Vec<String>,
    tasks: usize,
    task: usize,
    layout: Option<FrameLayout>,
    encoder: Option<VideoEncoder>,
    held: VecDeque<Held>,
    frame: Vec<u8>,
    max_bytes: usize,
    error: Option<String>,
    /// Time spent composing and encoding frames.
    busy: Duration,
    frames: usize,
}

/// A finished recording.
#[derive(Debug, Clone)]
pub struct RecordedVideo {
    /// The MP4 file.
    pub mp4: Vec<u8>,
    pub frames: usize,
    /// Composing and encoding time (rendering the cameras is the simulator's, not counted).
    pub encode_time: Duration,
}

impl EpisodeVideo {
    /// A recorder for an episode of `plan` running its first `tasks` steps; a file larger than
    /// `max_bytes` is refused at the end (0: no limit).
    pub fn new(plan: &[String], tasks: usize, max_bytes: usize) -> EpisodeVideo {
        EpisodeVideo {
            plan: plan.to_vec(),
            tasks,
            task: 0,
            layout: None,
            encoder: None,
            held: VecDeque::new(),
            frame: Vec::new(),
            max_bytes,
            error: None,
            busy: Duration::ZERO,
            frames: 0,
        }
    }

    fn observe(&mut self, obs: &Observation) {
        if self.error.is_some() {
            return;
        }
        let started = Instant::now();
        self.held.push_back(Held {
            images: obs.images.iter().map(|i| i.rgb.clone()).collect(),
            task: self.task,
            time: obs.time,
        });
        if self.layout.is_none() {
            let sizes: Vec<(u32, u32)> = obs.images.iter().map(|i| (i.width, i.height)).collect();
            let layout = FrameLayout::new(&sizes);
            match VideoEncoder::new(layout.width, layout.height, FPS, SETTINGS) {
                Ok(e) => self.encoder = Some(e),
                Err(e) => self.error = Some(e.to_string()),
            }
            self.layout = Some(layout);
        }
        while self.held.len() > FPS as usize {
            if let Some(h) = self.held.pop_front() {
                self.encode(&h, None);
            }
        }
        self.busy += started.elapsed();
    }

    fn task_ended(&mut self, task: &TaskRecord, sim: &Sim) {
        let outcome = match &task.failure {
            None => Outcome::Success(sim.time()),
            Some(why) => Outcome::Failed(why.clone()),
        };
        let started = Instant::now();
        while let Some(h) = self.held.pop_front() {
            let mine = h.task == task.index;
            self.encode(&h, mine.then_some(&outcome));
        }
        self.busy += started.elapsed();
    }

    fn encode(&mut self, h: &Held, outcome: Option<&Outcome>) {
        let (Some(layout), Some(encoder)) = (&self.layout, &mut self.encoder) else {
            return;
        };
        if self.error.is_some() {
            return;
        }
        let caption = Caption {
            task: h.task,
            tasks: self.tasks,
            step: self.plan.get(h.task).map_or("", String::as_str),
            sim_time: h.time,
            outcome,
        };
        let images: Vec<&[u8]> = h.images.iter().map(Vec::as_slice).collect();
        layout.compose(&images, &caption, &mut self.frame);
        match encoder.push_rgb(&self.frame) {
            Ok(()) => self.frames += 1,
            Err(e) => self.error = Some(e.to_string()),
        }
    }

    /// The MP4, or why there is none (no frame, an encoder error, over the size limit).
    pub fn finish(mut self) -> Result<RecordedVideo, String> {
        let started = Instant::now();
        while let Some(h) = self.held.pop_front() {
            self.encode(&h, None);
        }
        if let Some(e) = self.error {
            return Err(format!("episode video: {e}"));
        }
        let Some(encoder) = self.encoder.take() else {
            return Err("episode video: no frame was recorded".into());
        };
        let mp4 = encoder
            .finish()
            .map_err(|e| format!("episode video: {e}"))?
            .to_mp4();
        if self.max_bytes > 0 && mp4.len() > self.max_bytes {
            return Err(format!(
                "episode video: {} bytes, over the limit of {}",
                mp4.len(),
                self.max_bytes
            ));
        }
        Ok(RecordedVideo {
            mp4,
            frames: self.frames,
            encode_time: self.busy + started.elapsed(),
        })
    }
}

/// Passes every call on to `inner` and records the episode video on the way.
pub struct VideoHook<'a> {
    inner: &'a mut dyn StepHook,
    video: EpisodeVideo,
}

impl<'a> VideoHook<'a> {
    pub fn new(inner: &'a mut dyn StepHook, video: EpisodeVideo) -> VideoHook<'a> {
        VideoHook { inner, video }
    }

    pub fn into_video(self) -> EpisodeVideo {
        self.video
    }
}

impl StepHook for VideoHook<'_> {
    fn on_step(&mut self, sim: &Sim, action: &Action, info: &StepInfo) -> Result<(), String> {
        self.inner.on_step(sim, action, info)
    }

    fn wants_observation(&self) -> bool {
        true
    }

    fn observation(&mut self, obs: &Observation) {
        self.video.observe(obs);
        if self.inner.wants_observation() {
            self.inner.observation(obs);
        }
    }

    fn on_task_start(&mut self, sim: &Sim, index: usize) {
        self.video.task = index;
        self.inner.on_task_start(sim, index);
    }

    fn on_task_end(&mut self, sim: &Sim, task: &TaskRecord) {
        self.video.task_ended(task, sim);
        self.inner.on_task_end(sim, task);
    }

    /// Composing and encoding frames is the platform's time, not the policy's.
    fn overhead(&self) -> Duration {
        self.video.busy + self.inner.overhead()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use kitchen_r_episode::oracle::OraclePolicy;
    use kitchen_r_episode::runner::{RunOptions, run_episode};

    /// Counts the steps the runner executed, beside the recorder.
    struct Steps(usize);

    impl StepHook for Steps {
        fn on_step(&mut self, _: &Sim, _: &Action, _: &StepInfo) -> Result<(), String> {
            self.0 += 1;
            Ok(())
        }
    }

    #[test]
    fn an_oracle_episode_records_one_frame_per_control_step_into_a_fast_start_mp4() {
        let (assets, mut sim) = crate::test_sim::first_dev_sim();
        let run = RunOptions {
            privileged: true,
            max_tasks: Some(1),
            ..RunOptions::default()
        };
        let mut steps = Steps(0);
        let mut hook = VideoHook::new(&mut steps, EpisodeVideo::new(&sim.episode().plan, 1, 0));
        let out = run_episode(&mut sim, &mut OraclePolicy::new(&assets), &run, None, &mut hook).unwrap();
        assert!(out.tasks[0].success, "{:?}", out.tasks);
        // The encoding time is reported, so the episode's wall budget can leave it out.
        assert!(hook.overhead() > Duration::ZERO);
        let video = hook.into_video().finish().unwrap();
        assert!(steps.0 > 10, "{} steps", steps.0);
        assert_eq!(video.frames, steps.0);
        let b = &video.mp4;
        assert_eq!(&b[4..8], b"ftyp");
        let moov = b.windows(4).position(|w| w == b"moov").unwrap();
        let mdat = b.windows(4).position(|w| w == b"mdat").unwrap();
        assert!(moov < mdat, "moov must come first for inline play");
        assert!(b.windows(4).any(|w| w == b"avcC"));
    }

    #[test]
    fn a_size_limit_refuses_the_file_instead_of_truncating_it() {
        let mut v = EpisodeVideo::new(&["pick the bowl".to_string()], 1, 10);
        let obs = Observation {
            time: 0.1,
            images: vec![kitchen_r_sim::sensors::camera::CameraImage {
                name: "base".into(),
                width: 32,
                height: 32,
                rgb: vec![90; 32 * 32 * 3],
                depth: vec![],
            }],
            lidar: None,
            odometry: kitchen_r_sim::types::Odometry {
                pose: [0.0; 3],
                velocity: [0.0; 2],
            },
            joints: [0.0; 6],
            gripper: 0.0,
            task: None,
        };
        v.observe(&obs);
        let err = v.finish().unwrap_err();
        assert!(err.contains("over the limit of 10"), "{err}");
        assert!(
            EpisodeVideo::new(&[], 1, 0)
                .finish()
                .unwrap_err()
                .contains("no frame")
        );
    }
}
