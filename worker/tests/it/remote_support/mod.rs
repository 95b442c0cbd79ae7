//! Shared by the remote tests: policies served over real loopback sockets (`scripted`, also
//! used by the workspace end-to-end tests), a proxy that drops connections, and the simulator
//! set-up of the runner tests.

mod scripted;

use std::io::{Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::sync::Arc;

use kitchen_r_contract::server::PolicyFactory;
use kitchen_r_contract::{Credentials, RemoteConfig, RemotePolicy, SimCamera};
use kitchen_r_core::dataset::Dataset;
use kitchen_r_episode::policy::HORIZON;
use kitchen_r_sim::{Assets, EpisodeConfig, EpisodeParams, SensorsConfig, Sim, SimConfig};

pub(crate) use scripted::*;

pub(crate) fn still() -> PolicyFactory {
    factory(HORIZON, Arc::new(|_| Ok(vec![STILL; HORIZON])))
}

/// Forwards connections to `upstream` and cuts each one (both directions) once the client
/// has sent more than `limit` bytes on it: the handshake passes, an Act with images does not.
pub(crate) fn dropping_proxy(upstream: SocketAddr, limit: usize) -> SocketAddr {
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

pub(crate) fn cameras() -> Vec<SimCamera> {
    SimCamera::from_sensors(&SensorsConfig::load_default().unwrap())
}

/// Connect with short deadlines so misbehaviour shows quickly.
pub(crate) fn connect(url: &str, call_deadline_s: f64) -> RemotePolicy {
    let cfg = RemoteConfig {
        call_deadline_s,
        startup_deadline_s: 20.0,
        ..RemoteConfig::default()
    };
    RemotePolicy::connect(url, &Credentials::default(), &cfg, &cameras()).unwrap()
}

/// The first dev instruction's episode.
pub(crate) fn sim() -> Sim {
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
