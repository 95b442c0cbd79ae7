//! Recording a replayed episode (`kitchen-r replay --mcap/--frames`): a step hook that writes
//! each control step of a trace's replay as `collect` writes its MCAP, and/or the rendered
//! camera images as PNG files, so a participant can study a failure without running their
//! policy again.
//!
//! It must not change the episode: it runs no monitor and never stops a step (a write error is
//! kept and reported by [`ReplayRecorder::finish`]), because the replay has to reproduce the
//! scored episode bit for bit. Whether what it wrote may be kept is the replay's outcome check:
//! the caller deletes the files when the replay disagrees.

use std::path::{Path, PathBuf};

use kitchen_r_episode::runner::{StepHook, TaskRecord};
use kitchen_r_sim::{Action, EpisodeConfig, Observation, SensorsConfig, Sim, StepInfo};

use crate::frame::{frame_of, mounts};
use crate::mcap_ros2::McapRecorder;
use crate::{EpisodeMeta, Frame, RecordError, TaskSpan};

/// The MCAP metadata of a replayed episode. A trace holds the episode, not its instruction's
/// sentence, so `instruction` is empty; `sensors` are those the replay renders.
pub fn episode_meta(episode: &EpisodeConfig, sensors: &SensorsConfig) -> EpisodeMeta {
    EpisodeMeta {
        episode_id: episode.id.clone(),
        scene: episode.scene.clone(),
        instruction: String::new(),
        plan: episode.plan.clone(),
        seed: episode.seed,
        sensor_mounts: mounts(sensors),
    }
}

/// PNG frames: every `every`-th control step's images, one file per camera.
#[derive(Debug, Clone)]
pub struct FramesOut {
    pub dir: PathBuf,
    pub every: usize,
}

/// What a recorded replay wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct ReplayFiles {
    /// Control steps recorded.
    pub steps: usize,
    pub mcap: Option<PathBuf>,
    /// PNG files written (each camera of each kept step).
    pub pngs: usize,
}

/// The step hook; see the module doc.
pub struct ReplayRecorder {
    mcap: Option<McapRecorder>,
    frames: Option<FramesOut>,
    pngs: usize,
    steps: usize,
    spans: Vec<TaskSpan>,
    /// First step and sim time of the running task.
    task_start: (usize, f64),
    latest: Option<Observation>,
    error: Option<RecordError>,
}

impl ReplayRecorder {
    /// `mcap`: where to write the MCAP (created now) and the episode it shows; `frames`: where
    /// to write PNG images (the directory is created now).
    pub fn new(
        mcap: Option<(&Path, &EpisodeMeta)>,
        frames: Option<FramesOut>,
    ) -> Result<ReplayRecorder, RecordError> {
        let mcap = match mcap {
            Some((path, meta)) => Some(McapRecorder::create(path, meta)?),
            None => None,
        };
        if let Some(f) = &frames {
            std::fs::create_dir_all(&f.dir).map_err(|source| RecordError::Io {
                path: f.dir.clone(),
                source,
            })?;
        }
        Ok(ReplayRecorder {
            mcap,
            frames,
            pngs: 0,
            steps: 0,
            spans: Vec::new(),
            task_start: (0, 0.0),
            latest: None,
            error: None,
        })
    }

    /// Close the MCAP (its task spans in the metadata, as `collect` writes them); the first
    /// write error of the replay, if any.
    pub fn finish(self) -> Result<ReplayFiles, RecordError> {
        if let Some(e) = self.error {
            return Err(e);
        }
        let mcap = match self.mcap {
            Some(m) => Some(m.finish(&self.spans)?),
            None => None,
        };
        Ok(ReplayFiles {
            steps: self.steps,
            mcap,
            pngs: self.pngs,
        })
    }

    /// Whether this step's images go to PNG files.
    fn keeps_png(&self) -> bool {
        self.frames
            .as_ref()
            .is_some_and(|f| self.steps.is_multiple_of(f.every.max(1)))
    }

    fn write(&mut self, frame: &Frame) -> Result<(), RecordError> {
        if let Some(m) = &mut self.mcap {
            m.write_frame(frame, None)?;
        }
        if let Some(f) = self.frames.as_ref().filter(|_| self.keeps_png()) {
            for c in &frame.cameras {
                let path = f.dir.join(format!("{:06}_{}.png", self.steps, c.name));
                image::save_buffer(&path, &c.rgb, c.width, c.height, image::ExtendedColorType::Rgb8)
                    .map_err(|e| RecordError::Io {
                        path: path.clone(),
                        source: std::io::Error::other(e),
                    })?;
                self.pngs += 1;
            }
        }
        Ok(())
    }
}

impl StepHook for ReplayRecorder {
    /// Every step's rendering for an MCAP; PNG frames alone render only the steps they keep.
    fn wants_observation(&self) -> bool {
        self.mcap.is_some()
    }

    fn observation(&mut self, obs: &Observation) {
        self.latest = Some(obs.clone());
    }

    fn on_task_start(&mut self, sim: &Sim, _index: usize) {
        self.task_start = (self.steps, sim.time());
    }

    fn on_task_end(&mut self, _sim: &Sim, task: &TaskRecord) {
        self.spans.push(TaskSpan {
            step: task.step.clone(),
            start: self.task_start.0,
            end: self.steps,
            success: task.success,
            duration: task.sim_time,
        });
    }

    fn on_step(&mut self, sim: &Sim, action: &Action, info: &StepInfo) -> Result<(), String> {
        let latest = self.latest.take();
        if self.mcap.is_some() || self.keeps_png() {
            let obs = latest.unwrap_or_else(|| sim.observe());
            let task = info.task.as_ref().map_or(0, |t| t.index);
            let frame = frame_of(sim, obs, action, info, task, true);
            if self.error.is_none()
                && let Err(e) = self.write(&frame)
            {
                self.error = Some(e);
            }
        }
        self.steps += 1;
        Ok(())
    }
}
