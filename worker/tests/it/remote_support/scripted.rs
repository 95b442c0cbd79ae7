//! Scripted policies served over real loopback sockets: shared by the worker's remote tests
//! and the workspace end-to-end tests (`tests/e2e`, which include this file by path).

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use kitchen_r_contract::server::{PolicyFactory, ServeOptions, serve_policy};
use kitchen_r_episode::policy::{Policy, PolicyError, PolicyInput, PolicySpec};

/// Stand still with the gripper open: valid, never succeeds.
pub(crate) const STILL: [f64; 10] = [0.0, 0.0, 0.35, 0.0, 0.95, 0.0, 1.0, 0.0, 0.0, 1.0];

pub(crate) type Answer = Arc<dyn Fn(&PolicyInput<'_>) -> Result<Vec<[f64; 10]>, PolicyError> + Send + Sync>;

/// A policy answering with a closure.
pub(crate) struct Scripted {
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

pub(crate) fn spec(horizon: usize) -> PolicySpec {
    PolicySpec {
        name: "scripted".into(),
        horizon,
        ..PolicySpec::default()
    }
}

pub(crate) fn factory(horizon: usize, answer: Answer) -> PolicyFactory {
    Arc::new(move || {
        Box::new(Scripted {
            spec: spec(horizon),
            answer: answer.clone(),
        }) as Box<dyn Policy>
    })
}

/// A policy server on 127.0.0.1:0 in its own runtime; stopped on drop.
pub(crate) struct TestServer {
    pub addr: SocketAddr,
    rt: Option<tokio::runtime::Runtime>,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
}

impl TestServer {
    pub(crate) fn start(factory: PolicyFactory, opts: ServeOptions) -> TestServer {
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

    pub(crate) fn url(&self) -> String {
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
