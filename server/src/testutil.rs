//! Test support: a server state over a temporary SQLite file and the real assets, a scriptable
//! policy probe, and helpers that play a worker.

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

use kitchen_r_core::dataset::Split;

use crate::config::Config;
use crate::content::Content;
use crate::episodes::TaskOutcome;
use crate::probe::{BoxFuture, PolicyProbe, ProbeError, ProbedSpec};
use crate::service::jobs::{LeasedJob, Report};
use crate::service::{AppState, Caller, Organiser, RegisterPolicy, Tokens, WorkerCred};
use crate::store::Team;

pub(crate) const ADMIN: &str = "admin-token-for-tests-0123456789";
pub(crate) const WORKER: &str = "worker-token-for-tests-012345678";

/// A probe answering whatever the test set, counting its calls.
#[derive(Debug)]
pub(crate) struct FakeProbe {
    pub answer: Result<ProbedSpec, ProbeError>,
    pub calls: AtomicUsize,
}

impl FakeProbe {
    pub(crate) fn ok(max_concurrency: u32) -> Arc<FakeProbe> {
        Arc::new(FakeProbe {
            answer: Ok(ProbedSpec {
                protocol_version: kitchen_r_proto::POLICY_PROTOCOL_VERSION,
                max_concurrency,
                summary: "fake-policy 1.0".into(),
                observation_history: 0,
                actions_executed_per_chunk: 0,
                privileged_observations: false,
                key_map: None,
            }),
            calls: AtomicUsize::new(0),
        })
    }

    /// A policy whose GetSpec asks for privileged observations (the privileged track).
    pub(crate) fn privileged(max_concurrency: u32) -> Arc<FakeProbe> {
        let mut answer = FakeProbe::ok(max_concurrency).answer.clone();
        if let Ok(spec) = &mut answer {
            spec.privileged_observations = true;
        }
        Arc::new(FakeProbe {
            answer,
            calls: AtomicUsize::new(0),
        })
    }

    pub(crate) fn err(e: ProbeError) -> Arc<FakeProbe> {
        Arc::new(FakeProbe {
            answer: Err(e),
            calls: AtomicUsize::new(0),
        })
    }

    pub(crate) fn calls(&self) -> usize {
        self.calls.load(Ordering::SeqCst)
    }
}

impl PolicyProbe for FakeProbe {
    fn probe(
        &self,
        _url: &str,
        _bearer: Option<&str>,
        _key_map: Option<&str>,
    ) -> BoxFuture<'static, Result<ProbedSpec, ProbeError>> {
        self.calls.fetch_add(1, Ordering::SeqCst);
        let answer = self.answer.clone();
        Box::pin(async move { answer })
    }
}

pub(crate) struct Fixture {
    pub state: AppState,
    pub _dir: tempfile::TempDir,
}

/// A state with `control.dev_episodes = 3` (tweak further with `tweak`).
pub(crate) async fn fixture(probe: Arc<dyn PolicyProbe>, tweak: impl FnOnce(&mut Config)) -> Fixture {
    let dir = tempfile::tempdir().unwrap();
    let mut config = Config {
        db: format!("sqlite://{}", dir.path().join("t.db").display()),
        ..Config::default()
    };
    config.control.dev_episodes = 3;
    tweak(&mut config);
    config.validate().unwrap();
    let content = Content::load(&config.assets_dir(), config.test_set_dir()).unwrap();
    let pool = crate::store::connect(&config.db, config.db_pool.into())
        .await
        .unwrap();
    let key = crate::secret_key(&config).unwrap();
    let tokens = Tokens {
        admin: ADMIN,
        worker: WORKER,
        secret_key: &key,
    };
    let state = AppState::new(pool, config, content, tokens, probe);
    state.seal_stored_tokens().await.unwrap();
    Fixture { state, _dir: dir }
}

impl Fixture {
    /// The real gRPC routes on 127.0.0.1:0; a connected worker-service client.
    pub(crate) async fn worker_client(
        &self,
    ) -> kitchen_r_proto::worker::v1::worker_client::WorkerClient<tonic::transport::Channel> {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        let routes = crate::grpc_routes(self.state.clone()).await.unwrap();
        let incoming = tokio_stream::wrappers::TcpListenerStream::new(listener);
        tokio::spawn(routes.serve_with_incoming(incoming));
        let url = format!("http://{addr}");
        kitchen_r_proto::worker::v1::worker_client::WorkerClient::connect(url)
            .await
            .unwrap()
    }

    /// A second server process on the same database file (a restart).
    pub(crate) async fn reopen(&self, probe: Arc<dyn PolicyProbe>) -> AppState {
        let config = self.state.config().clone();
        let content = Content::load(&config.assets_dir(), config.test_set_dir()).unwrap();
        let pool = crate::store::connect(&config.db, config.db_pool.into())
            .await
            .unwrap();
        let key = crate::secret_key(&config).unwrap();
        let tokens = Tokens {
            admin: ADMIN,
            worker: WORKER,
            secret_key: &key,
        };
        let state = AppState::new(pool, config, content, tokens, probe);
        state.seal_stored_tokens().await.unwrap();
        state
    }

    pub(crate) async fn team(&self, name: &str) -> String {
        self.state
            .create_team(self.admin().await, name)
            .await
            .unwrap()
            .token
    }

    /// The caller a request with this bearer token resolves to (the adapters' path).
    pub(crate) async fn caller(&self, token: &str) -> Caller {
        self.state.caller(Some(token)).await.unwrap()
    }

    pub(crate) async fn admin(&self) -> Organiser {
        self.caller(ADMIN).await.organiser().unwrap()
    }

    pub(crate) async fn worker(&self) -> WorkerCred {
        self.caller(WORKER).await.worker().unwrap()
    }

    /// The team a team token belongs to.
    pub(crate) async fn team_of(&self, token: &str) -> Team {
        self.caller(token).await.team().unwrap().clone()
    }

    pub(crate) fn request(&self, split: Split) -> RegisterPolicy {
        RegisterPolicy {
            endpoint: "http://127.0.0.1:50099".into(),
            split,
            token: None,
            plans: None,
            episodes: None,
            reference: false,
            key_map: None,
        }
    }

    pub(crate) async fn lease(&self, worker: &str, max: u32) -> Vec<LeasedJob> {
        self.state
            .lease(self.worker().await, worker, max, 0)
            .await
            .unwrap()
    }

    /// A report of `job` where task j succeeds when `success(j)`, with MSE `mse` on 2 samples
    /// per task for offline episodes.
    pub(crate) fn report(
        &self,
        worker: &str,
        job: &LeasedJob,
        success: impl Fn(usize) -> bool,
        mse: f64,
    ) -> Report {
        let offline = job.spec.mode == crate::episodes::Mode::Offline;
        let tasks = (0..job.spec.task_count())
            .map(|j| TaskOutcome {
                index: j as u32,
                step: job.spec.plan[j].clone(),
                success: !offline && success(j),
                completion_time_s: 0.0,
                failure_reason: if offline || success(j) {
                    String::new()
                } else {
                    "timeout".into()
                },
                mse: if offline { mse } else { 0.0 },
                mse_samples: if offline { 2 } else { 0 },
            })
            .collect();
        Report {
            worker_id: worker.into(),
            job_id: job.id,
            attempt: job.attempt,
            run_id: job.run_id,
            episode_key: job.episode_key.clone(),
            tasks,
            platform_error: String::new(),
            log_tail: "ok".into(),
            wall_ms: 10,
            path: None,
        }
    }

    /// Teams `alpha` and `bravo`; alpha registers a policy run on dev and one on test, and every
    /// episode of both is reported (task 0 succeeds) with the path `path(report)` gives. Returns
    /// the two tokens and the dev and test submission ids.
    pub(crate) async fn runs_with_paths(
        &self,
        path: impl Fn(&Report) -> kitchen_r_core::topdown::PathPlot,
    ) -> (String, String, i64, i64) {
        let (alpha, bravo) = (self.team("alpha").await, self.team("bravo").await);
        let caller = self.caller(&alpha).await;
        let mut ids = Vec::new();
        for split in [Split::Dev, Split::Test] {
            let id = self
                .state
                .register_policy(&caller, self.request(split))
                .await
                .unwrap()
                .id;
            ids.push(id);
        }
        let worker = self.worker().await;
        loop {
            let jobs = self.lease("w1", 16).await;
            if jobs.is_empty() {
                break;
            }
            for job in jobs {
                let mut report = self.report("w1", &job, |j| j == 0, 0.0);
                report.path = Some(path(&report));
                self.state.report_result(worker, report).await.unwrap();
            }
        }
        (alpha, bravo, ids[0], ids[1])
    }
}
