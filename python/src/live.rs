//! `KitchenREnv(ros2=True)`: the environment's episodes published live as ROS 2 topics, the
//! topics, types and frames of `kitchen-r eval --ros2` (kitchen-r-live's `Ros2Episodes`, the
//! hook `eval` uses), with the domain, network and QoS of `configs/live.toml` `[ros2]` or of the
//! file given. Best effort: the hook never changes an episode, and a slow subscriber costs
//! messages, never steps.
//!
//! One publisher per process, shared by every environment that asks for one (a vector
//! environment's too): one episode at a time holds the topics, so a subscriber never sees two
//! robots mixed. It stops when the last environment holding it is closed or dropped.

use std::path::Path;
use std::sync::{Arc, Mutex, PoisonError, Weak};
use std::time::Duration;

use kitchen_r_episode::hooks::WrapHook;
use kitchen_r_live::ros2::{Ros2Config, Ros2Episodes};
use kitchen_r_sim::SensorsConfig;
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;

/// The process's publisher and the settings it started with, while an environment holds it.
static SHARED: Mutex<Option<(Ros2Config, Weak<Ros2Episodes>)>> = Mutex::new(None);

/// What an environment asked for and, while it holds it, the publisher.
pub(crate) struct Live {
    config: Ros2Config,
    sensors: SensorsConfig,
    held: Option<Arc<Ros2Episodes>>,
}

/// The publisher of `ros2=True` (settings from `file`, else `configs/live.toml`), started or
/// joined with the GIL released; with `wait_s` > 0, once a subscriber is there.
pub(crate) fn start(
    py: Python<'_>,
    file: Option<&Path>,
    sensors: &SensorsConfig,
    wait_s: f64,
) -> PyResult<Live> {
    if !(wait_s.is_finite() && (0.0..=600.0).contains(&wait_s)) {
        return Err(PyValueError::new_err("ros2_wait must be 0 to 600 seconds"));
    }
    let config = config(file).map_err(PyValueError::new_err)?;
    let wait = Duration::from_secs_f64(wait_s);
    (py.detach(|| Live::start(config, sensors, wait))).map_err(PyRuntimeError::new_err)
}

/// `[ros2]` of `file`, else of `configs/live.toml` (its defaults when there is none); then
/// `ROS_DOMAIN_ID`.
fn config(file: Option<&Path>) -> Result<Ros2Config, String> {
    match file {
        Some(f) => Ros2Config::load(f),
        None => Ros2Config::load_default(&kitchen_r_sim::config::configs_dir()),
    }
    .map_err(|e| format!("ros2: {e}"))
}

impl Live {
    /// Start (or join) the process's publisher; `wait` > 0: then wait up to that long for a
    /// subscriber, as `eval --ros2-wait` does.
    fn start(config: Ros2Config, sensors: &SensorsConfig, wait: Duration) -> Result<Live, String> {
        let mut live = Live {
            config,
            sensors: sensors.clone(),
            held: None,
        };
        live.hold()?;
        if !wait.is_zero()
            && let Some(p) = &live.held
            && !p.wait_for_subscriber(wait)
        {
            return Err(format!(
                "ros2_wait: no ROS 2 subscriber in domain {} in {:.1} s",
                p.domain_id(),
                wait.as_secs_f64()
            ));
        }
        Ok(live)
    }

    /// The publisher, started again after [`Live::release`].
    fn hold(&mut self) -> Result<&Arc<Ros2Episodes>, String> {
        if self.held.is_none() {
            let mut shared = SHARED.lock().unwrap_or_else(PoisonError::into_inner);
            let running = (shared.as_ref()).and_then(|(c, w)| Some((c, w.upgrade()?)));
            let p = match running {
                Some((c, _)) if *c != self.config => {
                    return Err(format!(
                        "ros2: this process already publishes with other [ros2] settings ({c:?}); \
                         every environment of a process shares one publisher, so give them the same"
                    ));
                }
                Some((_, p)) => p,
                None => {
                    let p =
                        Ros2Episodes::start(&self.config, &self.sensors).map_err(|e| format!("ros2: {e}"))?;
                    let p = Arc::new(p);
                    *shared = Some((self.config.clone(), Arc::downgrade(&p)));
                    p
                }
            };
            self.held = Some(p);
        }
        Ok(self.held.as_ref().expect("held"))
    }

    /// The hook wrapper for the next episode.
    pub(crate) fn watch(&mut self) -> Result<WrapHook, String> {
        Ok(self.hold()?.wrap())
    }

    /// Let go of the publisher (`close()`); it stops once no environment or episode holds it.
    pub(crate) fn release(&mut self) {
        self.held = None;
    }

    /// `(domain id, samples written, samples dropped by DDS)` while held.
    pub(crate) fn counts(&self) -> Option<(u16, u64, u64)> {
        let p = self.held.as_ref()?;
        let (written, dropped) = p.counts();
        Some((p.domain_id(), written, dropped))
    }
}
