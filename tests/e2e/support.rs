//! Shared harness of the end-to-end tests: a hand-made benchmark fixture in a temporary
//! directory and the real `kitchen-r` binary started on it on 127.0.0.1:0.
//!
//! The fixture is small and hand-made so expected scores can be computed by hand; its scenes and
//! catalogue are the committed ones, so it validates against the real schemas.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

use serde_json::{Value, json};

pub(crate) const ADMIN: &str = "test-admin-token-0123456789";
/// How long a server may take to print its readiness line (a debug build migrating a new DB).
const STARTUP: Duration = Duration::from_secs(60);

pub(crate) fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_kitchen-r")
}

/// Dev ground truth of the fixture: (id, plan).
pub(crate) fn dev_plans() -> Vec<(&'static str, Vec<&'static str>)> {
    vec![
        (
            "dev-0001",
            vec![
                "move to the blue zone",
                "pick the bowl",
                "move to the red zone",
                "place the bowl",
            ],
        ),
        (
            "dev-0002",
            vec![
                "move to the green zone",
                "pick the cup",
                "move to the red zone",
                "place the cup",
                "move to the blue zone",
            ],
        ),
        (
            "dev-0003",
            vec![
                "move to the red zone",
                "pick the apple",
                "move to the green zone",
                "place the apple",
                "move to the blue zone",
                "pick the plate",
                "move to the red zone",
                "place the plate",
            ],
        ),
    ]
}

pub(crate) fn test_plans() -> Vec<(&'static str, Vec<&'static str>)> {
    vec![
        (
            "test-0001",
            vec![
                "move to the red zone",
                "pick the fork",
                "move to the blue zone",
                "place the fork",
            ],
        ),
        (
            "test-0002",
            vec![
                "move to the green zone",
                "pick the bowl",
                "move to the red zone",
                "place the bowl",
            ],
        ),
    ]
}

fn instruction(id: &str, plan: &[&str]) -> Value {
    json!({
        "id": id,
        "scene": "kitchen_a",
        "instruction": format!("instruction {id}"),
        "plan": plan,
        "template": "t01",
        "place_targets": [],
    })
}

fn jsonl(items: &[(&str, Vec<&str>)]) -> String {
    items
        .iter()
        .map(|(id, plan)| instruction(id, plan).to_string() + "\n")
        .collect()
}

/// A plan file line.
pub(crate) fn line(id: &str, plan: &[&str]) -> String {
    json!({ "id": id, "plan": plan }).to_string()
}

/// A temporary benchmark: assets (committed scenes and catalogue, fixture dataset) and a config.
/// Planning content only (no robot), so the server runs without simulation slots.
pub(crate) struct Fixture {
    pub dir: tempfile::TempDir,
}

impl Fixture {
    /// `config` is appended to the generated server.toml (e.g. `[quota]` settings).
    pub(crate) fn new(config: &str) -> Fixture {
        let dir = tempfile::tempdir().unwrap();
        let repo_assets = Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets");
        let assets = dir.path().join("assets");
        std::fs::create_dir_all(assets.join("scenes")).unwrap();
        std::fs::create_dir_all(assets.join("dataset")).unwrap();
        std::fs::copy(repo_assets.join("objects.toml"), assets.join("objects.toml")).unwrap();
        std::fs::copy(
            repo_assets.join("scenes/kitchen_a.toml"),
            assets.join("scenes/kitchen_a.toml"),
        )
        .unwrap();
        let ds = assets.join("dataset");
        std::fs::write(ds.join("dev.jsonl"), jsonl(&dev_plans())).unwrap();
        std::fs::write(ds.join("test_ground_truth.jsonl"), jsonl(&test_plans())).unwrap();
        let manifest = json!({"seed": 7, "generator_version": 1, "templates": 1, "dev": 3, "test": 2});
        std::fs::write(ds.join("manifest.json"), manifest.to_string()).unwrap();
        let db = dir.path().join("db/kitchen-r.db");
        let toml = format!(
            "http = \"127.0.0.1:0\"\ngrpc = \"127.0.0.1:0\"\ndb = \"sqlite://{}\"\nassets = \"{}\"\nworkers = 0\n{config}\n",
            db.display(),
            assets.display()
        );
        std::fs::write(dir.path().join("server.toml"), toml).unwrap();
        Fixture { dir }
    }

    pub(crate) fn config_path(&self) -> PathBuf {
        self.dir.path().join("server.toml")
    }

    /// Start `kitchen-r serve` on this fixture.
    pub(crate) fn serve(&self) -> Server {
        Server::start(&self.config_path(), self.dir.path())
    }
}

/// A running server process, killed when dropped.
pub(crate) struct Server {
    child: Child,
    pub http: String,
    pub grpc: String,
}

impl Server {
    fn start(config: &Path, cwd: &Path) -> Server {
        let mut cmd = Command::new(bin());
        cmd.args(["serve", "--config"])
            .arg(config)
            .current_dir(cwd)
            .env("KITCHEN_R_ADMIN_TOKEN", ADMIN)
            .env("RUST_LOG", "warn");
        Server::spawn(&mut cmd)
    }

    /// Spawn a prepared `kitchen-r serve` command and read its `listening` line.
    fn spawn(cmd: &mut Command) -> Server {
        let (child, ready) = spawn_ready(cmd, "listening ");
        let field = |k: &str| {
            ready
                .split_whitespace()
                .find_map(|w| w.strip_prefix(k))
                .unwrap()
                .to_string()
        };
        Server {
            child,
            http: format!("http://{}", field("http=")),
            grpc: format!("http://{}", field("grpc=")),
        }
    }

    pub(crate) fn url(&self, path: &str) -> String {
        format!("{}{path}", self.http)
    }

    /// The server process (to signal it).
    pub(crate) fn child(&mut self) -> &mut Child {
        &mut self.child
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A blocking HTTP client for the tests (bounded timeouts so a hung server fails the test).
pub(crate) fn client() -> reqwest::Client {
    reqwest::Client::builder()
        .timeout(Duration::from_secs(30))
        .build()
        .unwrap()
}

/// Create a team and return its token.
pub(crate) async fn team(server: &Server, name: &str) -> String {
    let r = client()
        .post(server.url("/api/v1/teams"))
        .bearer_auth(ADMIN)
        .json(&json!({ "name": name }))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 201);
    let v: Value = r.json().await.unwrap();
    v["token"].as_str().unwrap().to_string()
}

/// Log `token`'s team in through the page's login form, as a browser does; returns the
/// `Cookie` header a browser would then send (CSRF nonce and the session).
pub(crate) async fn page_session(server: &Server, token: &str) -> String {
    let c = reqwest::Client::builder()
        .redirect(reqwest::redirect::Policy::none())
        .timeout(Duration::from_secs(30))
        .build()
        .unwrap();
    let pair = |r: &reqwest::Response, name: &str| {
        (r.headers().get_all("set-cookie").iter())
            .map(|v| v.to_str().unwrap().split(';').next().unwrap().to_string())
            .find(|p| p.starts_with(&format!("{name}=")))
            .unwrap_or_else(|| panic!("no {name} cookie"))
    };
    let form = c.get(server.url("/team/login")).send().await.unwrap();
    let nonce = pair(&form, "kitchen_r_csrf");
    let page = form.text().await.unwrap();
    let csrf = page
        .split("name=csrf value=\"")
        .nth(1)
        .unwrap()
        .split('"')
        .next()
        .unwrap();
    let r = c
        .post(server.url("/team/login"))
        .header("cookie", &nonce)
        .header("content-type", "application/x-www-form-urlencoded")
        .body(format!("token={token}&csrf={csrf}&next=/team"))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 303, "login refused");
    format!("{nonce}; {}", pair(&r, "kitchen_r_team"))
}

/// POST a plan file; returns (status, JSON body).
pub(crate) async fn submit(
    server: &Server,
    token: Option<&str>,
    split: &str,
    body: impl Into<String>,
) -> (u16, Value) {
    let mut req = client()
        .post(server.url(&format!("/api/v1/submissions/plans?split={split}")))
        .body(body.into());
    if let Some(t) = token {
        req = req.bearer_auth(t);
    }
    let r = req.send().await.unwrap();
    let status = r.status().as_u16();
    (status, r.json().await.unwrap())
}

/// The body of a GET that must answer 200 (pages, CSV, metrics).
pub(crate) async fn get_text(server: &Server, path: &str) -> String {
    let r = client().get(server.url(path)).send().await.unwrap();
    assert_eq!(r.status(), 200, "{path}");
    r.text().await.unwrap()
}

pub(crate) async fn get_json(server: &Server, path: &str, token: Option<&str>) -> (u16, Value) {
    let mut req = client().get(server.url(path));
    if let Some(t) = token {
        req = req.bearer_auth(t);
    }
    let r = req.send().await.unwrap();
    let status = r.status().as_u16();
    (status, r.json().await.unwrap())
}

/// Worker token the control-track tests configure.
pub(crate) const WORKER_TOKEN: &str = "test-worker-token-0123456789";
/// Upper bound on how long one test waits for a run to finish (debug build, shared machine).
pub(crate) const RUN_DEADLINE: Duration = Duration::from_secs(900);

/// Start `cmd` with piped stdout and wait for its first line starting with `prefix`; the rest of
/// stdout is drained in the background. Returns the child and that line.
pub(crate) fn spawn_ready(cmd: &mut Command, prefix: &str) -> (Child, String) {
    let mut child = cmd
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("spawn process");
    let stdout = child.stdout.take().unwrap();
    let (tx, rx) = mpsc::channel();
    let prefix = prefix.to_string();
    std::thread::spawn(move || {
        for l in BufReader::new(stdout).lines().map_while(Result::ok) {
            if l.starts_with(&prefix) {
                let _ = tx.send(l);
            }
        }
    });
    match rx.recv_timeout(STARTUP) {
        Ok(l) => (child, l),
        Err(_) => {
            let _ = child.kill();
            panic!("{cmd:?} printed no line starting with the readiness prefix");
        }
    }
}

/// The starter kit's Python policy server (`starter-kit/policy_server.py --listen 127.0.0.1:0`
/// and `args`), killed on drop, and its `http://` URL; `None` (skipped, said on stderr) when
/// python3 lacks its modules, which CI always has (scripts/test.sh installs them).
pub(crate) fn starter_kit(args: &[&str]) -> Option<(Proc, String)> {
    let ready = Command::new("python3")
        .args(["-c", "import grpc, grpc_tools, grpc_health"])
        .status()
        .is_ok_and(|s| s.success());
    if !ready {
        assert!(
            std::env::var("CI").is_err(),
            "python3 with grpcio, grpcio-tools and grpcio-health-checking is required in CI"
        );
        eprintln!("skipped: the starter kit's Python modules are not installed");
        return None;
    }
    let kit = Path::new(env!("CARGO_MANIFEST_DIR")).join("../starter-kit/policy_server.py");
    let (child, line) = spawn_ready(
        Command::new("python3")
            .arg(kit)
            .args(["--listen", "127.0.0.1:0"])
            .args(args),
        "listening grpc=",
    );
    let url = format!("http://{}", line.trim_start_matches("listening grpc=").trim());
    Some((Proc(child), url))
}

/// A process killed (SIGKILL) when dropped.
pub(crate) struct Proc(pub Child);

impl Proc {
    /// SIGKILL now and reap.
    pub(crate) fn kill(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        self.kill();
    }
}

/// The reference oracle served over gRPC (`kitchen-r policy oracle --listen 127.0.0.1:0`);
/// returns the process and its `http://` URL.
pub(crate) fn oracle_policy() -> (Proc, String) {
    oracle_policy_with(&[])
}

/// The oracle served with extra `kitchen-r policy oracle` flags (e.g. `--max-batch 4`).
pub(crate) fn oracle_policy_with(flags: &[&str]) -> (Proc, String) {
    let (child, line) = spawn_ready(
        Command::new(bin())
            .args(["policy", "oracle", "--listen", "127.0.0.1:0"])
            .args(flags)
            .env("RUST_LOG", "warn"),
        "listening grpc=",
    );
    let addr = line.trim_start_matches("listening grpc=").trim().to_string();
    (Proc(child), format!("http://{addr}"))
}

/// A server on the committed benchmark (real scenes and dataset) with a temporary database;
/// `config` is appended to its server.toml.
pub(crate) struct ControlFixture {
    pub dir: tempfile::TempDir,
}

impl ControlFixture {
    pub(crate) fn new(config: &str) -> ControlFixture {
        let dir = tempfile::tempdir().unwrap();
        let db = dir.path().join("db/kitchen-r.db");
        let toml = format!(
            "http = \"127.0.0.1:0\"\ngrpc = \"127.0.0.1:0\"\ndb = \"sqlite://{}\"\nworker_token = \"{WORKER_TOKEN}\"\n{config}\n",
            db.display(),
        );
        std::fs::write(dir.path().join("server.toml"), toml).unwrap();
        ControlFixture { dir }
    }

    /// `kitchen-r serve --workers N` on this fixture (N = 0: no in-process workers).
    pub(crate) fn serve(&self, workers: usize) -> Server {
        let mut cmd = Command::new(bin());
        cmd.args(["serve", "--workers", &workers.to_string(), "--config"])
            .arg(self.dir.path().join("server.toml"))
            .env("KITCHEN_R_ADMIN_TOKEN", ADMIN)
            .env("RUST_LOG", "warn");
        Server::spawn(&mut cmd)
    }
}

/// `kitchen-r worker --server GRPC --slots N` with the test worker token, started and ready.
pub(crate) fn worker(server: &Server, slots: usize, id: &str) -> Proc {
    let (child, _) = spawn_ready(
        Command::new(bin())
            .args(["worker", "--server", &server.grpc, "--slots", &slots.to_string()])
            .args(["--worker-id", id])
            .env("KITCHEN_R_WORKER_TOKEN", WORKER_TOKEN)
            .env("RUST_LOG", "warn"),
        "worker ready",
    );
    Proc(child)
}

/// Register a policy endpoint; returns (status, JSON body).
pub(crate) async fn register_policy(server: &Server, token: &str, body: Value) -> (u16, Value) {
    let r = client()
        .post(server.url("/api/v1/submissions/policies"))
        .bearer_auth(token)
        .json(&body)
        .send()
        .await
        .unwrap();
    let status = r.status().as_u16();
    (status, r.json().await.unwrap())
}

/// Poll a submission until `done(evaluation)` holds; returns the submission view.
pub(crate) async fn wait_for(
    server: &Server,
    id: i64,
    token: &str,
    what: &str,
    done: impl Fn(&Value) -> bool,
) -> Value {
    let start = std::time::Instant::now();
    loop {
        let (status, v) = get_json(server, &format!("/api/v1/submissions/{id}"), Some(token)).await;
        assert_eq!(status, 200, "{v}");
        if done(&v["latest_run"]["evaluation"]) {
            return v;
        }
        assert!(
            start.elapsed() < RUN_DEADLINE,
            "gave up waiting for {what}; last view: {v:#}"
        );
        tokio::time::sleep(Duration::from_millis(300)).await;
    }
}

/// Whether a run's evaluation has finished.
pub(crate) fn finished(e: &Value) -> bool {
    e["state"] == "finished" || e["state"] == "platform_failed"
}

/// A command's stdout as text.
pub(crate) fn out(o: &std::process::Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// A command's stderr as text.
pub(crate) fn err(o: &std::process::Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// `o`, after asserting the command succeeded (both streams shown when not).
pub(crate) fn ok(o: std::process::Output) -> std::process::Output {
    assert!(o.status.success(), "stdout:\n{}\nstderr:\n{}", out(&o), err(&o));
    o
}

/// Text with every run of spaces made one, so column widths do not matter.
pub(crate) fn squash(s: &str) -> String {
    s.split(' ')
        .filter(|w| !w.is_empty())
        .collect::<Vec<_>>()
        .join(" ")
}
