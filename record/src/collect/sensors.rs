//! What a collection run records: the sensors (less the cameras `--cameras` leaves out), their
//! camera specs, and the recording-rate monitor over the topics actually written.

use kitchen_r_sim::SensorsConfig;

use crate::frame::keep_cameras;

use super::{CollectError, CollectOptions};
use crate::lerobot::CameraSpec;
use crate::rate::RateMonitor;

/// The sensors to simulate: the configured ones, less the cameras `opts.cameras` leaves out.
pub(super) fn sensors(opts: &CollectOptions) -> Result<SensorsConfig, CollectError> {
    let mut s = match &opts.sensors {
        Some(s) => s.clone(),
        None => SensorsConfig::load_default()?,
    };
    if let Some(names) = &opts.cameras {
        if names.is_empty() {
            return Err(CollectError::Config("--cameras: name at least one camera".into()));
        }
        keep_cameras(&mut s, names).map_err(|e| CollectError::Config(format!("--cameras: {e}")))?;
    }
    Ok(s)
}

pub(super) fn camera_specs(s: &SensorsConfig) -> Vec<CameraSpec> {
    s.cameras
        .iter()
        .map(|c| CameraSpec {
            name: c.name.clone(),
            width: c.width,
            height: c.height,
        })
        .collect()
}

/// The recording-rate monitor over the topics this run writes: a camera left out by
/// `--cameras` has no rate to keep.
pub(super) fn rate_monitor(opts: &CollectOptions) -> Result<RateMonitor, CollectError> {
    let cameras: Vec<String> = sensors(opts)?.cameras.into_iter().map(|c| c.name).collect();
    let min_hz = opts
        .config
        .rates
        .min_hz
        .iter()
        .filter(|(topic, _)| {
            topic
                .strip_prefix("/camera/")
                .and_then(|t| t.split('/').next())
                .is_none_or(|cam| cameras.iter().any(|c| c == cam))
        })
        .map(|(t, hz)| (t.clone(), *hz))
        .collect();
    Ok(RateMonitor::new(min_hz, opts.config.rates.window_s))
}
