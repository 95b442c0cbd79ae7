//! Shared by the `remote_*` tests: policies served over real loopback sockets, a proxy that
//! drops connections, and the simulator set-up of the runner tests.
#![allow(dead_code)]

use std::io::{Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::sync::Arc;
use std::time::Duration;

use kitchen_r_core::dataset::Dataset;
use kitchen_r_sim::{Assets, EpisodeConfig, EpisodeParams, SensorsConfig, Sim, SimConfig};
use kitchen_r_worker::policy::{HORIZON, Policy, PolicyError, PolicyInput, PolicySpec};
use kitchen_r_worker::remote::server::{PolicyFactory, ServeOptions, serve_policy};
use kitchen_r_worker::remote::{Credentials, RemoteConfig, RemotePolicy, SimCamera};

/// Stand still with the gripper open: valid, never succeeds.
pub const STILL: [f64; 10] = [0.0, 0.0, 0.35, 0.0, 0.95, 0.0, 1.0, 0.0, 0.0, 1.0];

pub type Answer = Arc<dyn Fn(&PolicyInput<'_>) -> Result<Vec<[f64; 10]>, PolicyError> + Send + Sync>;

/// A policy answering with a closure.
pub struct Scripted {
    pub spec: PolicySpec,
    pub answer: Answer,
}

impl Policy for Scripted {
    fn spec(&self) -> &PolicySpec {
        &self.spec
    }
    fn reset(&mut self, _: &str, _: usize, _: &str) -> Result<(), PolicyError> {
        Ok(())
    }
    fn act(&mut self, input: &PolicyInput<'_>) -> Result<Vec<[f64; 10]>, PolicyError> {
        (self.answer)(input)
    }
}

pub fn spec(horizon: usize) -> PolicySpec {
    PolicySpec {
        name: "scripted".into(),
        horizon,
        action_dim: 10,
        cameras: vec![],
        max_concurrency: 1,
    }
}

pub fn factory(horizon: usize, answer: Answer) -> PolicyFactory {
    Arc::new(move || {
        Box::new(Scripted {
            spec: spec(horizon),
            answer: answer.clone(),
        }) as Box<dyn Policy>
    })
}

pub fn still() -> PolicyFactory {
    factory(HORIZON, Arc::new(|_| Ok(vec![STILL; HORIZON])))
}

/// A policy server on 127.0.0.1:0 in its own runtime; stopped on drop.
pub struct TestServer {
    pub addr: SocketAddr,
    rt: Option<tokio::runtime::Runtime>,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
}

impl TestServer {
    pub fn start(factory: PolicyFactory, opts: ServeOptions) -> TestServer {
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
            .unwrap();
        let listener = rt.block_on(tokio::net::TcpListener::bind("127.0.0.1:0")).unwrap();
        let addr = listener.local_addr().unwrap();
        let (tx, rx) = tokio::sync::oneshot::channel::<()>();
        rt.spawn(serve_policy(listener, factory, opts, async {
            let _ = rx.await;
        }));
        TestServer {
            addr,
            rt: Some(rt),
            stop: Some(tx),
        }
    }

    pub fn url(&self) -> String {
        format!("http://{}", self.addr)
    }
}

impl Drop for TestServer {
    fn drop(&mut self) {
        if let Some(tx) = self.stop.take() {
            let _ = tx.send(());
        }
        if let Some(rt) = self.rt.take() {
            rt.shutdown_timeout(Duration::from_secs(2));
        }
    }
}

/// Forwards connections to `upstream` and cuts each one (both directions) once the client
/// has sent more than `limit` bytes on it: the handshake passes, an Act with images does not.
pub fn dropping_proxy(upstream: SocketAddr, limit: usize) -> SocketAddr {
    let l = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = l.local_addr().unwrap();
    std::thread::spawn(move || {
        for client in l.incoming() {
            let Ok(client) = client else { return };
            let Ok(server) = TcpStream::connect(upstream) else {
                return;
            };
            let (c2, s2) = (client.try_clone().unwrap(), server.try_clone().unwrap());
            std::thread::spawn(move || pump(s2, c2, usize::MAX));
            std::thread::spawn(move || pump(client, server, limit));
        }
    });
    addr
}

fn pump(mut from: TcpStream, mut to: TcpStream, limit: usize) {
    let mut buf = [0u8; 16 << 10];
    let mut total = 0usize;
    loop {
        let n = match from.read(&mut buf) {
            Ok(0) | Err(_) => break,
            Ok(n) => n,
        };
        total += n;
        if total > limit || to.write_all(&buf[..n]).is_err() {
            break;
        }
    }
    let _ = from.shutdown(Shutdown::Both);
    let _ = to.shutdown(Shutdown::Both);
}

pub fn cameras() -> Vec<SimCamera> {
    SimCamera::from_sensors(&SensorsConfig::load_default().unwrap())
}

/// Connect with short deadlines so misbehaviour shows quickly.
pub fn connect(url: &str, call_deadline_s: f64) -> RemotePolicy {
    let cfg = RemoteConfig {
        call_deadline_s,
        startup_deadline_s: 20.0,
        ..RemoteConfig::default()
    };
    RemotePolicy::connect(url, &Credentials::default(), &cfg, &cameras()).unwrap()
}

/// The first dev instruction's episode.
pub fn sim() -> Sim {
    let assets = Assets::load_default().unwrap();
    let data = Dataset::load(&kitchen_r_core::assets::assets_dir().join("dataset")).unwrap();
    let ins = &data.dev[0];
    let scene = assets.scene(&ins.scene).unwrap().clone();
    let params = EpisodeParams::load_default().unwrap();
    let cfg = EpisodeConfig::from_instruction(ins, &scene, &assets.catalogue, &params, 1).unwrap();
    let sensors = SensorsConfig::load_default().unwrap();
    Sim::new(assets, SimConfig::load_default().unwrap(), sensors, &cfg)
        .unwrap()
        .0
}
