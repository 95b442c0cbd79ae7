//! The key map of an openpi endpoint: under which keys the observation goes out, at what image
//! size, under which key the actions come back, how many actions of each chunk run and how many
//! episodes may run at once. A team gives it as JSON when it registers a `ws://` endpoint; every
//! field is optional and the defaults are our documented convention (the manual's "openpi
//! WebSocket endpoints" chapter), so a policy written for them needs none.
//!
//! The map only renames and resizes: what an endpoint may receive (the standard track's cameras,
//! state and sub-task sentence) is fixed here, whatever the map says.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::{RemoteConfig, SimCamera};
use kitchen_r_episode::policy::HORIZON;

/// Largest image side sent (as `policy.proto` allows gRPC policies).
const MAX_SIDE: u32 = 1024;
/// Longest key, characters.
const MAX_KEY: usize = 128;
/// Most episodes a key map may ask to run at once.
const MAX_CONCURRENCY: u32 = 64;

/// An openpi endpoint's key map; [`KeyMap::default`] is the convention.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct KeyMap {
    /// Simulator camera → the key its image goes under (uint8, `image_size` × 3). Only the
    /// cameras named are sent. Default: `base` → `observation/base_image`, `gripper` →
    /// `observation/gripper_image`.
    pub cameras: BTreeMap<String, String>,
    /// `[height, width]` of every image sent, pixels (resized from the render). Default
    /// `[224, 224]`, the input size of openpi's models.
    pub image_size: [u32; 2],
    /// Key of the standard state vector (float32, 29 values in `STATE_FIELDS` order); `""`
    /// sends none.
    pub state: String,
    /// Key of the current sub-task's sentence (`pick the bowl`); `""` sends none.
    pub prompt: String,
    /// Key of the reply's `(H, 10)` action array, H ≥ 16.
    pub actions: String,
    /// Actions of each chunk executed before asking again (the organiser's minimum to 16);
    /// absent: the organiser's default.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub actions_executed_per_chunk: Option<u32>,
    /// Episodes evaluated at once, each over its own connection. Default 1.
    pub max_concurrency: u32,
}

impl Default for KeyMap {
    fn default() -> Self {
        KeyMap {
            cameras: [
                ("base", "observation/base_image"),
                ("gripper", "observation/gripper_image"),
            ]
            .into_iter()
            .map(|(c, k)| (c.to_string(), k.to_string()))
            .collect(),
            image_size: [224, 224],
            state: "observation/state".into(),
            prompt: "prompt".into(),
            actions: "actions".into(),
            actions_executed_per_chunk: None,
            max_concurrency: 1,
        }
    }
}

impl KeyMap {
    /// A key map from its JSON text; empty (or blank) text is the default. Not yet checked
    /// against a simulator: see [`KeyMap::check`].
    pub fn parse(json: &str) -> Result<KeyMap, String> {
        if json.trim().is_empty() {
            return Ok(KeyMap::default());
        }
        serde_json::from_str(json).map_err(|e| format!("the key map is not valid: {e}"))
    }

    /// The normalised JSON text stored with the endpoint (every field spelt out).
    pub fn to_json(&self) -> String {
        serde_json::to_string(self).unwrap_or_default()
    }

    /// The map is usable with these simulator cameras and this organiser's limits; the reason
    /// names the field.
    pub fn check(&self, sim: &[SimCamera], cfg: &RemoteConfig) -> Result<(), String> {
        let names: Vec<&str> = sim.iter().map(|c| c.name.as_str()).collect();
        for cam in self.cameras.keys() {
            if !names.contains(&cam.as_str()) {
                return Err(format!(
                    "key map: camera {cam:?} is not one of the simulator's cameras {names:?}"
                ));
            }
        }
        let [h, w] = self.image_size;
        if !(1..=MAX_SIDE).contains(&h) || !(1..=MAX_SIDE).contains(&w) {
            return Err(format!(
                "key map: image_size [{h}, {w}] must be [height, width] within 1..={MAX_SIDE}"
            ));
        }
        let mut sent: Vec<&str> = self.cameras.values().map(String::as_str).collect();
        sent.extend(
            [self.state.as_str(), self.prompt.as_str()]
                .into_iter()
                .filter(|k| !k.is_empty()),
        );
        for k in sent.iter().chain([&self.actions.as_str()]) {
            if k.is_empty() || k.chars().count() > MAX_KEY || k.chars().any(char::is_control) {
                return Err(format!(
                    "key map: key {k:?} must be 1 to {MAX_KEY} printable characters"
                ));
            }
        }
        let mut unique = sent.clone();
        unique.sort_unstable();
        unique.dedup();
        if unique.len() != sent.len() {
            return Err(format!("key map: two values are sent under one key ({sent:?})"));
        }
        if sent.is_empty() {
            return Err("key map: nothing would be sent (no camera, no state, no prompt)".into());
        }
        let min = cfg.min_actions_executed_per_chunk.clamp(1, HORIZON as u32);
        if let Some(n) = self.actions_executed_per_chunk
            && !(min..=HORIZON as u32).contains(&n)
        {
            return Err(format!(
                "key map: actions_executed_per_chunk is {n}, must be between {min} (this \
                 organiser's minimum) and {HORIZON}, or absent for the organiser's default {}",
                cfg.actions_executed_per_chunk
            ));
        }
        if !(1..=MAX_CONCURRENCY).contains(&self.max_concurrency) {
            return Err(format!(
                "key map: max_concurrency is {}, must be between 1 and {MAX_CONCURRENCY}",
                self.max_concurrency
            ));
        }
        Ok(())
    }

    /// One line for the participant: what goes out under which key, and what comes back.
    pub fn describe(&self, cfg: &RemoteConfig) -> String {
        let [h, w] = self.image_size;
        let mut parts: Vec<String> = self
            .cameras
            .iter()
            .map(|(c, k)| format!("{c} {h}x{w} uint8 as {k:?}"))
            .collect();
        if !self.state.is_empty() {
            parts.push(format!("state (29 float32) as {:?}", self.state));
        }
        if !self.prompt.is_empty() {
            parts.push(format!("sub-task as {:?}", self.prompt));
        }
        let execute = self.actions_executed_per_chunk.map_or_else(
            || format!("the organiser's {}", cfg.actions_executed_per_chunk),
            |n| n.to_string(),
        );
        format!(
            "sends {}; reads {:?} (H x 10, H >= {HORIZON}); executes {execute} actions per chunk; \
             max concurrency {}",
            parts.join(", "),
            self.actions,
            self.max_concurrency
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sim() -> Vec<SimCamera> {
        ["base", "gripper"]
            .map(|n| SimCamera {
                name: n.into(),
                width: 128,
                height: 128,
            })
            .to_vec()
    }

    #[test]
    fn empty_text_is_the_convention_and_round_trips() {
        let d = KeyMap::parse(" ").unwrap();
        assert_eq!(d, KeyMap::default());
        assert_eq!(d.cameras["base"], "observation/base_image");
        assert_eq!(KeyMap::parse(&d.to_json()).unwrap(), d);
        d.check(&sim(), &RemoteConfig::default()).unwrap();
    }

    #[test]
    fn a_partial_map_keeps_the_other_defaults() {
        let k = KeyMap::parse(
            r#"{"cameras": {"base": "image"}, "image_size": [96, 128], "actions_executed_per_chunk": 4}"#,
        )
        .unwrap();
        assert_eq!(k.cameras.len(), 1);
        assert_eq!(k.image_size, [96, 128]);
        assert_eq!(k.state, "observation/state");
        assert_eq!(k.actions_executed_per_chunk, Some(4));
        k.check(&sim(), &RemoteConfig::default()).unwrap();
        assert!(
            k.describe(&RemoteConfig::default())
                .contains("base 96x128 uint8 as \"image\"")
        );
    }

    #[test]
    fn bad_maps_say_which_field() {
        let cfg = RemoteConfig::default();
        let err = |json: &str| match KeyMap::parse(json) {
            Ok(k) => k.check(&sim(), &cfg).unwrap_err(),
            Err(e) => e,
        };
        assert!(err(r#"{"camera": {}}"#).contains("unknown field `camera`"));
        assert!(err(r#"{"cameras": {"thermal": "t"}}"#).contains("\"thermal\""));
        assert!(err(r#"{"image_size": [0, 8]}"#).contains("image_size"));
        assert!(err(r#"{"prompt": "observation/state"}"#).contains("one key"));
        assert!(err(r#"{"actions": ""}"#).contains("1 to 128"));
        assert!(err(r#"{"actions_executed_per_chunk": 17}"#).contains("between 1"));
        assert!(err(r#"{"max_concurrency": 0}"#).contains("max_concurrency"));
        assert!(err(r#"{"cameras": {}, "state": "", "prompt": ""}"#).contains("nothing"));
    }
}
