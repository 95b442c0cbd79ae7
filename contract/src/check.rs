//! The conformance probe behind `kitchen-r check-policy ENDPOINT`: the checks a worker makes of
//! a participant's endpoint, each reported PASS or FAIL with what is wrong, so a participant
//! finds out before registering rather than from a failed run.
//!
//! Checks run in order; one whose prerequisite failed is reported SKIP (it cannot be judged),
//! and the probe fails when any check fails.

use std::time::Instant;

use kitchen_r_proto::POLICY_PROTOCOL_VERSION;
use kitchen_r_proto::policy::v1 as pb;
use tonic_health::pb::health_check_response::ServingStatus;

mod openpi;
mod report;
mod synthetic;

pub use report::{Check, Report, Verdict};
use synthetic::synthetic;

use crate::conn::{Conn, describe};
use crate::convert::{self, CameraPlan, MAX_SIDE};
use crate::endpoint::Transport;
use crate::{Credentials, RemoteConfig, SimCamera, client, endpoint};
use kitchen_r_episode::policy::{
    ChunkTolerance, Goal, HORIZON, PolicyInput, PolicySpec, PrivilegedObservation, check_chunk,
};

/// Check names, in the order they run.
pub(crate) const NAMES: [&str; 12] = [
    "reachable",
    "health",
    "protocol",
    "shape",
    "cameras",
    "v1.1",
    "privileged",
    "reset",
    "act",
    "act-again",
    "large-image",
    "act-batch",
];

/// Probe `endpoint`; never panics on what the endpoint does. `key_map` (JSON, empty for the
/// convention) configures an openpi endpoint (`ws://`), whose checks are [`openpi::NAMES`].
pub fn check_policy(
    endpoint: &str,
    creds: &Credentials,
    cfg: &RemoteConfig,
    sim: &[SimCamera],
    key_map: &str,
) -> Report {
    let mut report = Report::default();
    let rt = match tokio::runtime::Builder::new_current_thread().enable_all().build() {
        Ok(rt) => rt,
        Err(e) => {
            report.push(NAMES[0], Err(format!("cannot start a runtime: {e}")));
            return report;
        }
    };
    match Transport::of(endpoint) {
        Some(Transport::Openpi) => {
            rt.block_on(openpi::probe(&mut report, endpoint, creds, cfg, sim, key_map))
        }
        _ if !key_map.trim().is_empty() => {
            report.push(
                NAMES[0],
                Err("a key map applies to ws:// and wss:// (openpi) endpoints only".into()),
            );
            report.skip(&NAMES[1..], "the endpoint is not usable");
        }
        _ => rt.block_on(probe(&mut report, endpoint, creds, cfg, sim)),
    }
    report
}

async fn probe(
    report: &mut Report,
    endpoint: &str,
    creds: &Credentials,
    cfg: &RemoteConfig,
    sim: &[SimCamera],
) {
    let conn = endpoint::resolve(endpoint, &cfg.allowed_networks)
        .map_err(|e| e.to_string())
        .and_then(|ep| Conn::new(ep, creds, cfg).map_err(|e| e.to_string()));
    let mut conn = match conn {
        Ok(c) => c,
        Err(e) => {
            report.push(NAMES[0], Err(e));
            return report.skip(&NAMES[1..], "the endpoint is not usable");
        }
    };
    // Reachable: anything answered (even an error status), within the startup deadline.
    let started = Instant::now();
    let mut health = conn.health().await;
    while health.as_ref().is_err_and(is_unreachable) && started.elapsed() < cfg.startup_deadline() {
        tokio::time::sleep(std::time::Duration::from_millis(100)).await;
        health = conn.health().await;
    }
    let reachable = match &health {
        Err(s) if is_unreachable(s) => Err(describe("connect", s, cfg.max_answer_bytes)),
        _ => Ok(format!("{} answered", conn.endpoint.uri)),
    };
    if !report.push(NAMES[0], reachable) {
        return report.skip(&NAMES[1..], "the endpoint is unreachable");
    }
    report.push(
        NAMES[1],
        match health {
            Ok(ServingStatus::Serving) => Ok("grpc.health.v1 reports SERVING".into()),
            Ok(s) => Err(format!("grpc.health.v1 reports {}, not SERVING", s.as_str_name())),
            Err(s) => Err(describe("grpc.health.v1 Check", &s, cfg.max_answer_bytes)),
        },
    );
    let spec = match conn.get_spec(cfg).await {
        Ok(s) => s,
        Err(e) => {
            report.push(NAMES[2], Err(e.to_string()));
            return report.skip(&NAMES[3..], "GetSpec failed");
        }
    };
    let version = spec.protocol_version;
    report.push(
        NAMES[2],
        if version == POLICY_PROTOCOL_VERSION {
            Ok(format!("protocol version {version}; policy {:?}", spec.name))
        } else {
            Err(format!(
                "protocol version {version}, this worker speaks {POLICY_PROTOCOL_VERSION}"
            ))
        },
    );
    let shape = (spec.horizon, spec.action_dim);
    report.push(
        NAMES[3],
        if shape == (HORIZON as u32, 10) {
            Ok(format!(
                "horizon 16, action_dim 10, max_concurrency {}",
                spec.max_concurrency.max(1)
            ))
        } else {
            Err(format!(
                "horizon {} and action_dim {}, must be 16 and 10",
                shape.0, shape.1
            ))
        },
    );
    let plans = match convert::plan_cameras(&spec, sim) {
        Ok(p) => p,
        Err(e) => {
            report.push(NAMES[4], Err(e));
            return report.skip(&NAMES[5..], "the camera request is invalid");
        }
    };
    report.push(NAMES[4], Ok(describe_cameras(&plans)));
    let v1_1 = client::check_v1_1(&spec, cfg);
    let v1_1_ok = v1_1.is_ok();
    report.push(NAMES[5], v1_1.map(|(h, k)| describe_v1_1(h, k, cfg)));
    let track_ok = report.push(NAMES[6], describe_track(spec.privileged_observations, cfg));
    match client::check_spec(&spec, sim, cfg) {
        Ok(_) if !track_ok => report.skip(&NAMES[7..], "this server would refuse the registration"),
        Ok((checked, _)) => acts(report, &mut conn, cfg, &plans, &checked, &spec).await,
        Err(_) if !v1_1_ok => report.skip(&NAMES[7..], "the v1.1 fields are out of range"),
        Err(_) => report.skip(&NAMES[7..], "the handshake failed"),
    }
}

/// Which observation track the policy asked for, and whether the server described by `cfg`
/// (`privileged_track`: `control.privileged_track` there) accepts it.
fn describe_track(asks: bool, cfg: &RemoteConfig) -> Result<String, String> {
    match (asks, cfg.privileged_track) {
        (false, _) => Ok("standard track: the policy does not ask for privileged observations".into()),
        (true, true) => Ok("privileged track: the policy asks for privileged observations \
             (PolicySpec.privileged_observations); a server runs it only where the organiser set \
             `control.privileged_track = true`, and ranks it on the privileged boards; every Act \
             of this check carries a synthetic privileged observation"
            .into()),
        (true, false) => Err("the policy asks for privileged observations \
             (PolicySpec.privileged_observations), which a server refuses unless its organiser \
             set `control.privileged_track = true`; leave the field false for the standard track"
            .into()),
    }
}

/// What the policy chose of contract v1.1 (history, execution count), and what it gets.
fn describe_v1_1(history: usize, execute: Option<usize>, cfg: &RemoteConfig) -> String {
    let execute = match execute {
        Some(n) => format!("executes {n} actions per chunk (its choice)"),
        None => format!(
            "executes the organiser's {} actions per chunk",
            cfg.actions_executed_per_chunk
        ),
    };
    format!(
        "observation history {history} frame(s); {execute}; every observation carries the hand pose and the previous action"
    )
}

async fn acts(
    report: &mut Report,
    conn: &mut Conn,
    cfg: &RemoteConfig,
    plans: &[CameraPlan],
    spec: &PolicySpec,
    wire_spec: &pb::PolicySpec,
) {
    let episode = "check-policy";
    let reset = pb::ResetRequest {
        episode_id: episode.into(),
        task_index: 0,
        sub_task: "move to the blue zone".into(),
        scene_id: "kitchen_a".into(),
    };
    if !report.push(
        NAMES[7],
        conn.reset(reset)
            .await
            .map(|()| "Reset accepted".into())
            .map_err(|e| e.to_string()),
    ) {
        return report.skip(&NAMES[8..], "Reset failed");
    }
    let deadline = cfg.call_deadline().as_secs_f64();
    let k = spec
        .actions_executed_per_chunk
        .unwrap_or(cfg.actions_executed_per_chunk as usize) as u64;
    let history = spec.observation_history;
    let privileged = spec.privileged_observations.then(synthetic_privileged);
    let privileged = privileged.as_ref();
    for (name, step) in [(NAMES[8], 0), (NAMES[9], k)] {
        let r = one_act(conn, episode, step, plans, history, privileged).await;
        report.push(
            name,
            r.map(|(ms, note)| {
                format!(
                    "valid 16x10 chunk for step {step} ({history} frame(s)) in {ms:.1} ms (deadline {deadline} s){note}"
                )
            }),
        );
    }
    let large: Vec<CameraPlan> = plans
        .iter()
        .map(|p| CameraPlan {
            width: MAX_SIDE,
            height: MAX_SIDE,
            ..p.clone()
        })
        .collect();
    let r = one_act(conn, episode, 2 * k, &large, history, privileged).await;
    report.push(
        NAMES[10],
        r.map(|(ms, _)| format!("{} camera(s) at {MAX_SIDE}x{MAX_SIDE} accepted in {ms:.1} ms", large.len()))
            .map_err(|e| format!("{e} (the worker may send images up to {MAX_SIDE}x{MAX_SIDE}: raise the server's receive limit)")),
    );
    let batch = act_batch(conn, cfg, plans, wire_spec, 3 * k, privileged).await;
    report.push(NAMES[11], batch);
}

/// Batched decisions: with `max_batch` > 1, episodes of their own (Reset each) get one Act each
/// and then the same observations in one ActBatch, whose answer must hold one valid chunk per
/// observation. A chunk unlike its Act's is noted, not failed: a policy with memory may answer
/// a repeated step differently.
async fn act_batch(
    conn: &Conn,
    cfg: &RemoteConfig,
    plans: &[CameraPlan],
    spec: &pb::PolicySpec,
    step: u64,
    privileged: Option<&PrivilegedObservation>,
) -> Result<String, String> {
    let declared = spec.max_batch;
    if declared <= 1 {
        return Ok(format!(
            "max_batch {declared}: no batching, every decision is its own Act (declare max_batch > 1 \
             in GetSpec and answer ActBatch to have workers batch decisions across episodes)"
        ));
    }
    let n = declared.min(4) as usize;
    let mut conn = conn.clone().for_batch(n, cfg);
    let mut singles = Vec::new();
    let mut observations = Vec::new();
    for i in 0..n {
        let episode = format!("check-policy-batch-{i}");
        let reset = pb::ResetRequest {
            episode_id: episode.clone(),
            task_index: 0,
            sub_task: "move to the blue zone".into(),
            scene_id: "kitchen_a".into(),
        };
        conn.reset(reset).await.map_err(|e| e.to_string())?;
        let wire = wire_observation(
            &episode,
            step,
            plans,
            spec.observation_history.max(1) as usize,
            privileged,
        )?;
        let single = conn.act(wire.clone()).await.map_err(|e| e.to_string())?;
        singles.push(single);
        observations.push(wire);
    }
    let t = Instant::now();
    let answer = conn
        .act_batch(pb::ObservationBatch { observations }, cfg.call_deadline())
        .await
        .map_err(|e| format!("{e} (a policy declaring max_batch > 1 must answer ActBatch)"))?;
    let ms = t.elapsed().as_secs_f64() * 1e3;
    if answer.chunks.len() != n {
        return Err(format!(
            "ActBatch of {n} observations answered {} chunks: one chunk per observation, in the same order",
            answer.chunks.len()
        ));
    }
    let mut differ = 0;
    for (i, (c, single)) in answer.chunks.iter().zip(&singles).enumerate() {
        let mut chunk = convert::chunk_from_wire(c, HORIZON).map_err(|e| format!("chunk {i}: {e}"))?;
        check_chunk(&mut chunk, HORIZON, &ChunkTolerance::default())
            .map_err(|e| format!("chunk {i}: {e}"))?;
        differ += usize::from(c != single);
    }
    let note = match differ {
        0 => "each equal to its Act's answer".to_string(),
        d => format!(
            "{d} unlike the Act answer to the same observation (fine for a policy with memory; \
             a stateless policy should answer alike)"
        ),
    };
    Ok(format!(
        "max_batch {declared}: {n} valid chunks for {n} observations of {n} episodes in {ms:.1} ms; {note}"
    ))
}

/// One Act on a synthetic observation (with `history - 1` earlier frames, padded as at the
/// start of a task); the elapsed milliseconds when the chunk is valid, and a note when values
/// had to be corrected within the default tolerances (a warning in a real run).
async fn one_act(
    conn: &mut Conn,
    episode: &str,
    step: u64,
    plans: &[CameraPlan],
    history: usize,
    privileged: Option<&PrivilegedObservation>,
) -> Result<(f64, String), String> {
    let wire = wire_observation(episode, step, plans, history, privileged)?;
    let t = Instant::now();
    let answer = conn.act(wire).await.map_err(|e| e.to_string())?;
    let ms = t.elapsed().as_secs_f64() * 1e3;
    let mut chunk = convert::chunk_from_wire(&answer, HORIZON).map_err(|e| e.to_string())?;
    let fixed = check_chunk(&mut chunk, HORIZON, &ChunkTolerance::default()).map_err(|e| e.to_string())?;
    let note = fixed
        .warning()
        .map_or_else(String::new, |w| format!("; warning: {w} (within tolerance)"));
    Ok((ms, note))
}

/// The synthetic observation of `episode` at `step`, as a worker would send it.
fn wire_observation(
    episode: &str,
    step: u64,
    plans: &[CameraPlan],
    history: usize,
    privileged: Option<&PrivilegedObservation>,
) -> Result<pb::Observation, String> {
    let obs = synthetic(plans, step);
    let input = PolicyInput {
        episode_id: episode,
        step,
        task_index: 0,
        sub_task: "move to the blue zone",
        observation: &obs,
        ee_pose: [0.35, 0.0, 0.95, 0.0, 1.0, 0.0, 0.0],
        previous_action: (step > 0).then_some([0.0, 0.0, 0.35, 0.0, 0.95, 0.0, 1.0, 0.0, 0.0, 1.0]),
        history: &[],
        privileged: None,
        privileged_observation: privileged,
    };
    convert::observation(&input, plans, history).map_err(|e| e.to_string())
}

/// What a privileged run would show for the check's sub-task, `move to the blue zone`: the
/// robot's scene pose and the zone's approach pose in the robot frame; a move names no object,
/// so (as on the test split) no object.
fn synthetic_privileged() -> PrivilegedObservation {
    PrivilegedObservation {
        base_pose: [1.0, 0.5, 0.0],
        goal: Goal::Approach {
            x: 1.2,
            y: -0.4,
            yaw: 1.5,
        },
        objects: Vec::new(),
    }
}

fn describe_cameras(plans: &[CameraPlan]) -> String {
    plans
        .iter()
        .map(|p| {
            let enc = if p.encoding == pb::ImageEncoding::Jpeg {
                "JPEG"
            } else {
                "RAW_RGB8"
            };
            let depth = if p.depth { " + depth" } else { "" };
            format!("{} {}x{} {enc}{depth}", p.name, p.width, p.height)
        })
        .collect::<Vec<_>>()
        .join(", ")
}

fn is_unreachable(s: &tonic::Status) -> bool {
    s.code() == tonic::Code::Unavailable
        || s.code() == tonic::Code::Unknown && s.message().contains("transport")
}
