//! `check-policy ws://…`: the checks a worker makes of an openpi endpoint, in the order it makes
//! them: the key map, the address, `/healthz`, the metadata sent on connect, then two decisions
//! on synthetic observations at the key map's image size, each chunk checked as a run checks it.

use std::time::Instant;

use super::report::Report;
use super::synthetic::synthetic;
use crate::openpi::{self, KeyMap, camera_plans};
use crate::{Credentials, RemoteConfig, RemoteError, SimCamera, endpoint};
use kitchen_r_episode::policy::{ChunkTolerance, HORIZON, PolicyInput, check_chunk};

/// Check names, in the order they run.
pub(crate) const NAMES: [&str; 6] = ["keys", "reachable", "health", "metadata", "act", "act-again"];

pub(super) async fn probe(
    report: &mut Report,
    url: &str,
    creds: &Credentials,
    cfg: &RemoteConfig,
    sim: &[SimCamera],
    key_map: &str,
) {
    let keys = KeyMap::parse(key_map).and_then(|k| k.check(sim, cfg).map(|()| k));
    let keys = match keys {
        Ok(k) => {
            report.push(NAMES[0], Ok(k.describe(cfg)));
            k
        }
        Err(e) => {
            report.push(NAMES[0], Err(e));
            return report.skip(&NAMES[1..], "the key map is not usable");
        }
    };
    let ep = match endpoint::resolve(url, &cfg.allowed_networks) {
        Ok(ep) => ep,
        Err(e) => {
            report.push(NAMES[1], Err(e.to_string()));
            return report.skip(&NAMES[2..], "the endpoint is not usable");
        }
    };
    let uri = ep.uri.clone();
    let mut h = match openpi::handshake(ep, creds, cfg, sim, key_map).await {
        Ok(h) => h,
        Err(e @ (RemoteError::Unreachable { .. } | RemoteError::Endpoint(_) | RemoteError::Runtime(_))) => {
            report.push(NAMES[1], Err(e.to_string()));
            return report.skip(&NAMES[2..], "the endpoint is unreachable");
        }
        Err(e @ (RemoteError::Health { .. } | RemoteError::Tls { .. })) => {
            report.push(NAMES[1], Ok(format!("{uri} answered")));
            report.push(NAMES[2], Err(e.to_string()));
            return report.skip(&NAMES[3..], "the health check failed");
        }
        Err(e @ RemoteError::Handshake { .. }) => {
            report.push(NAMES[1], Ok(format!("{uri} answered")));
            report.push(NAMES[2], Ok("GET /healthz answered 200".into()));
            report.push(NAMES[3], Err(e.to_string()));
            return report.skip(&NAMES[4..], "no connection with metadata");
        }
    };
    report.push(NAMES[1], Ok(format!("{uri} answered")));
    report.push(NAMES[2], Ok("GET /healthz answered 200".into()));
    report.push(NAMES[3], Ok(h.summary(cfg)));
    let deadline = cfg.call_deadline().as_secs_f64();
    let k = keys
        .actions_executed_per_chunk
        .unwrap_or(cfg.actions_executed_per_chunk) as u64;
    for (name, step) in [(NAMES[4], 0), (NAMES[5], k)] {
        let r = one_act(&mut h, &keys, step).await;
        let ok = report.push(
            name,
            r.map(|(ms, note)| {
                format!("valid chunk for step {step} in {ms:.1} ms (deadline {deadline} s){note}")
            }),
        );
        if !ok && name == NAMES[4] {
            report.skip(&NAMES[5..], "the first decision failed");
            break;
        }
    }
    h.close().await;
}

/// One decision on a synthetic observation; the elapsed milliseconds when the chunk is valid,
/// and a note when values had to be corrected within the default tolerances.
async fn one_act(h: &mut openpi::Handshake, keys: &KeyMap, step: u64) -> Result<(f64, String), String> {
    let obs = synthetic(&camera_plans(keys), step);
    let input = PolicyInput {
        episode_id: "check-policy",
        step,
        task_index: 0,
        sub_task: "move to the blue zone",
        observation: &obs,
        ee_pose: [0.35, 0.0, 0.95, 0.0, 1.0, 0.0, 0.0],
        previous_action: (step > 0).then_some([0.0, 0.0, 0.35, 0.0, 0.95, 0.0, 1.0, 0.0, 0.0, 1.0]),
        history: &[],
        privileged: None,
        privileged_observation: None,
    };
    let t = Instant::now();
    let mut chunk = h.act(&input).await.map_err(|e| e.to_string())?;
    let ms = t.elapsed().as_secs_f64() * 1e3;
    let fixed = check_chunk(&mut chunk, HORIZON, &ChunkTolerance::default()).map_err(|e| e.to_string())?;
    let note = fixed
        .warning()
        .map_or_else(String::new, |w| format!("; warning: {w} (within tolerance)"));
    Ok((ms, note))
}
