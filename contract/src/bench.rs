//! Worker-side overhead of one policy call on loopback (docs/measured/performance.md: ≤ 1 ms
//! p50 with two 128×128 raw images): everything between the runner handing over an
//! observation and getting a chunk back — encoding, gRPC over a real socket, decoding — with a
//! trivial policy on the other end, so the figure is the transport's cost alone.

use std::sync::Arc;
use std::time::{Duration, Instant};

use kitchen_r_sim::Observation;
use kitchen_r_sim::sensors::CameraImage;
use kitchen_r_sim::types::Odometry;
use serde::Serialize;

use crate::server::{PolicyFactory, ServeOptions, serve_policy};
use crate::{Credentials, RemoteConfig, RemoteError, RemotePolicy, SimCamera};
use kitchen_r_episode::policy::{ACTION_DIM, HORIZON, Policy, PolicyError, PolicyInput, PolicySpec};

/// Answers every call with the same valid chunk.
struct Trivial(PolicySpec);

impl Policy for Trivial {
    fn spec(&self) -> &PolicySpec {
        &self.0
    }
    fn reset(&mut self, _: &str, _: usize, _: &str) -> Result<(), PolicyError> {
        Ok(())
    }
    fn act(&mut self, _: &PolicyInput<'_>) -> Result<Vec<[f64; ACTION_DIM]>, PolicyError> {
        Ok(vec![
            [0.0, 0.0, 0.35, 0.0, 0.95, 0.0, 1.0, 0.0, 0.0, 1.0];
            HORIZON
        ])
    }
}

/// Latency of `calls` Act round trips, microseconds.
#[derive(Debug, Clone, Serialize)]
pub struct CallOverhead {
    pub calls: usize,
    pub p50_us: f64,
    pub p99_us: f64,
    pub mean_us: f64,
}

/// Serve a trivial policy on 127.0.0.1:0 and time `calls` Act calls (after a warm-up) made
/// by a [`RemotePolicy`] with two 128×128 RAW_RGB8 cameras.
pub fn call_overhead(calls: usize) -> Result<CallOverhead, RemoteError> {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .map_err(|e| RemoteError::Runtime(e.to_string()))?;
    let listener = rt
        .block_on(tokio::net::TcpListener::bind("127.0.0.1:0"))
        .map_err(|e| RemoteError::Runtime(e.to_string()))?;
    let addr = listener
        .local_addr()
        .map_err(|e| RemoteError::Runtime(e.to_string()))?;
    let spec = PolicySpec {
        name: "trivial".into(),
        ..PolicySpec::default()
    };
    let factory: PolicyFactory = Arc::new(move || Box::new(Trivial(spec.clone())) as Box<dyn Policy>);
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    rt.spawn(serve_policy(listener, factory, ServeOptions::default(), async {
        let _ = stopped.await;
    }));
    let cameras: Vec<SimCamera> = ["base", "gripper"]
        .map(|n| SimCamera {
            name: n.into(),
            width: 128,
            height: 128,
        })
        .to_vec();
    let mut p = RemotePolicy::connect(
        &format!("http://{addr}"),
        &Credentials::default(),
        &RemoteConfig::default(),
        &cameras,
    )?;
    let obs = observation(&cameras);
    p.reset("bench", 0, "move to the blue zone")
        .map_err(|e| RemoteError::Runtime(e.to_string()))?;
    let mut times = Vec::with_capacity(calls);
    for i in 0..(calls + calls / 10 + 10) {
        let input = PolicyInput {
            episode_id: "bench",
            step: i as u64,
            task_index: 0,
            sub_task: "move to the blue zone",
            observation: &obs,
            ee_pose: [0.35, 0.0, 0.95, 0.0, 1.0, 0.0, 0.0],
            previous_action: None,
            history: &[],
            privileged: None,
            privileged_observation: None,
        };
        let t = Instant::now();
        p.act(&input).map_err(|e| RemoteError::Runtime(e.to_string()))?;
        if i >= calls / 10 + 10 {
            times.push(t.elapsed());
        }
    }
    let _ = stop.send(());
    drop(p);
    rt.shutdown_timeout(Duration::from_secs(1));
    times.sort();
    let us = |d: Duration| d.as_secs_f64() * 1e6;
    let pick = |q: f64| us(times[((times.len() - 1) as f64 * q).round() as usize]);
    Ok(CallOverhead {
        calls: times.len(),
        p50_us: pick(0.5),
        p99_us: pick(0.99),
        mean_us: times.iter().map(|d| us(*d)).sum::<f64>() / times.len().max(1) as f64,
    })
}

fn observation(cameras: &[SimCamera]) -> Observation {
    Observation {
        time: 0.0,
        images: cameras
            .iter()
            .map(|c| CameraImage {
                name: c.name.clone(),
                width: c.width,
                height: c.height,
                rgb: (0..(c.width * c.height * 3) as usize)
                    .map(|i| (i % 251) as u8)
                    .collect(),
                depth: vec![1.0; (c.width * c.height) as usize],
            })
            .collect(),
        lidar: None,
        odometry: Odometry {
            pose: [0.0; 3],
            velocity: [0.0; 2],
        },
        joints: [0.0; 6],
        gripper: 1.0,
        task: None,
    }
}
