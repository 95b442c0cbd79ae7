//! The benchmark's side of the wire: one pooled HTTP client, the few API calls it makes, the
//! plan files it uploads, and a bounded-concurrency driver.

use std::future::Future;
use std::time::Duration;

use anyhow::{Context, bail};
use serde_json::{Value, json};
use tokio::task::JoinSet;

use super::stats::classify;

/// The server under load and one client whose connections are reused by every task.
#[derive(Debug, Clone)]
pub(super) struct Api {
    client: reqwest::Client,
    base: String,
}

/// A team the benchmark created.
#[derive(Debug, Clone)]
pub(super) struct Team {
    pub name: String,
    pub token: String,
}

/// An upload the server acknowledged: its team (index), submission id and EM.
#[derive(Debug, Clone, Copy)]
pub(super) struct Ack {
    pub team: usize,
    pub id: i64,
    pub em: f64,
}

/// Why a request did not succeed: a non-2xx status, or how the transport failed.
#[derive(Debug, Clone)]
pub(super) struct Failure {
    pub what: String,
    /// The server's `Retry-After`, seconds, on a refusal that carries one.
    pub retry_after_s: Option<u64>,
}

impl Failure {
    fn transport(e: &reqwest::Error) -> Failure {
        Failure {
            what: classify(e),
            retry_after_s: None,
        }
    }
}

impl Api {
    /// Loopback only, so no proxy; every request bounded by `timeout`.
    pub(super) fn new(base: &str, timeout: Duration) -> anyhow::Result<Api> {
        let client = reqwest::Client::builder()
            .no_proxy()
            .timeout(timeout)
            .connect_timeout(timeout.min(Duration::from_secs(5)))
            .tcp_nodelay(true)
            .build()
            .context("building the HTTP client")?;
        Ok(Api {
            client,
            base: base.trim_end_matches('/').to_string(),
        })
    }

    fn url(&self, path: &str) -> String {
        format!("{}{path}", self.base)
    }

    /// A GET whose body is read and dropped (a leaderboard read); the body's size on success.
    pub(super) async fn read(&self, path: &str) -> Result<usize, Failure> {
        let resp = self.client.get(self.url(path)).send().await;
        let resp = checked(resp.map_err(|e| Failure::transport(&e))?)?;
        let body = resp.bytes().await.map_err(|e| Failure::transport(&e))?;
        Ok(body.len())
    }

    /// A GET answered with JSON.
    pub(super) async fn get_json(&self, path: &str, token: Option<&str>) -> Result<Value, Failure> {
        let mut req = self.client.get(self.url(path));
        if let Some(t) = token {
            req = req.bearer_auth(t);
        }
        let resp = checked(req.send().await.map_err(|e| Failure::transport(&e))?)?;
        resp.json().await.map_err(|e| Failure::transport(&e))
    }

    /// Upload a dev plan file; the submission id and EM the server answered.
    pub(super) async fn upload(&self, token: &str, body: String) -> Result<(i64, f64), Failure> {
        let resp = self
            .client
            .post(self.url("/api/v1/submissions/plans?split=dev"))
            .bearer_auth(token)
            .header(reqwest::header::CONTENT_TYPE, "application/x-ndjson")
            .body(body)
            .send()
            .await
            .map_err(|e| Failure::transport(&e))?;
        let v: Value = checked(resp)?.json().await.map_err(|e| Failure::transport(&e))?;
        match (v["id"].as_i64(), v["scores"]["em"].as_f64()) {
            (Some(id), Some(em)) => Ok((id, em)),
            _ => Err(Failure {
                what: "bad answer".into(),
                retry_after_s: None,
            }),
        }
    }

    /// Organiser: create a team.
    pub(super) async fn create_team(&self, admin: &str, name: &str) -> anyhow::Result<Team> {
        let resp = self
            .client
            .post(self.url("/api/v1/teams"))
            .bearer_auth(admin)
            .json(&json!({ "name": name }))
            .send()
            .await
            .context("creating a team")?;
        let status = resp.status();
        let v: Value = resp.json().await.unwrap_or(Value::Null);
        if !status.is_success() {
            bail!("creating team {name:?}: HTTP {} {v}", status.as_u16());
        }
        match (v["name"].as_str(), v["token"].as_str()) {
            (Some(name), Some(token)) => Ok(Team {
                name: name.into(),
                token: token.into(),
            }),
            _ => bail!("creating team {name:?}: unexpected answer {v}"),
        }
    }

    /// The dev split as the server serves it (with its ground-truth plans).
    pub(super) async fn dev_split(&self) -> anyhow::Result<Vec<(String, Vec<String>)>> {
        let resp = self
            .client
            .get(self.url("/api/v1/dataset/dev"))
            .send()
            .await
            .context("downloading the dev split")?;
        let text = checked(resp)
            .map_err(|f| anyhow::anyhow!("downloading the dev split: {}", f.what))?
            .text()
            .await?;
        text.lines()
            .filter(|l| !l.trim().is_empty())
            .map(|l| {
                let v: Value = serde_json::from_str(l).context("a dev split line")?;
                let id = v["id"].as_str().context("a dev line without id")?.to_string();
                let plan = v["plan"]
                    .as_array()
                    .context("a dev line without plan")?
                    .iter()
                    .map(|s| s.as_str().unwrap_or_default().to_string())
                    .collect();
                Ok((id, plan))
            })
            .collect()
    }
}

/// A 2xx response, or the failure its status says (with `Retry-After` when present).
fn checked(resp: reqwest::Response) -> Result<reqwest::Response, Failure> {
    if resp.status().is_success() {
        return Ok(resp);
    }
    let retry_after_s = resp
        .headers()
        .get(reqwest::header::RETRY_AFTER)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.trim().parse().ok());
    Err(Failure {
        what: resp.status().as_u16().to_string(),
        retry_after_s,
    })
}

/// The plan files the benchmark uploads: the first `lines` dev instructions, each either with
/// its true plan or with one step dropped. Which lines are wrong is drawn per file, with a
/// per-file error rate, so EMs spread over the whole range and the ranking is not a tie.
#[derive(Debug)]
pub(super) struct PlanFiles {
    good: Vec<String>,
    bad: Vec<String>,
}

impl PlanFiles {
    pub(super) fn new(dev: &[(String, Vec<String>)], lines: usize) -> PlanFiles {
        let mut rng = Rng(0x5eed);
        let (mut good, mut bad) = (Vec::new(), Vec::new());
        for (id, plan) in dev.iter().take(lines) {
            good.push(json!({ "id": id, "plan": plan }).to_string());
            let mut wrong = plan.clone();
            if wrong.len() > 1 {
                wrong.remove(rng.below(wrong.len()));
            }
            bad.push(json!({ "id": id, "plan": wrong }).to_string());
        }
        PlanFiles { good, bad }
    }

    pub(super) fn lines(&self) -> usize {
        self.good.len()
    }

    /// The `k`-th file of a run seeded with `seed`: the same for the same (seed, k) whatever
    /// the order uploads happen in.
    pub(super) fn file(&self, seed: u64, k: u64) -> String {
        let mut rng = Rng(seed ^ k.wrapping_mul(0x9E37_79B9_7F4A_7C15));
        let error_rate = rng.unit() * 0.6;
        let mut out = String::with_capacity(self.good.iter().map(|l| l.len() + 1).sum());
        for (good, bad) in self.good.iter().zip(&self.bad) {
            out.push_str(if rng.unit() < error_rate { bad } else { good });
            out.push('\n');
        }
        out
    }
}

/// SplitMix64: small, deterministic, good enough to pick which lines are wrong.
#[derive(Debug)]
pub(super) struct Rng(pub u64);

impl Rng {
    pub(super) fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }
}

/// Run `task(0..n)` with at most `concurrency` in flight; results in completion order.
/// `progress` is called with the number done after each one.
pub(super) async fn bounded<T, F, Fut>(
    n: usize,
    concurrency: usize,
    mut task: F,
    mut progress: impl FnMut(usize),
) -> anyhow::Result<Vec<T>>
where
    F: FnMut(usize) -> Fut,
    Fut: Future<Output = T> + Send + 'static,
    T: Send + 'static,
{
    let mut set = JoinSet::new();
    let mut out = Vec::with_capacity(n);
    for k in 0..n {
        if set.len() >= concurrency.max(1)
            && let Some(r) = set.join_next().await
        {
            out.push(r.context("a benchmark task panicked")?);
            progress(out.len());
        }
        set.spawn(task(k));
    }
    while let Some(r) = set.join_next().await {
        out.push(r.context("a benchmark task panicked")?);
        progress(out.len());
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dev() -> Vec<(String, Vec<String>)> {
        (0..50)
            .map(|i| (format!("dev-{i:04}"), vec!["a".into(), "b".into(), "c".into()]))
            .collect()
    }

    #[test]
    fn plan_files_are_deterministic_and_varied() {
        let files = PlanFiles::new(&dev(), 40);
        assert_eq!(files.lines(), 40);
        assert_eq!(files.file(7, 3), files.file(7, 3));
        let f = files.file(7, 3);
        assert_eq!(f.lines().count(), 40);
        let wrong = |f: &str| f.lines().filter(|l| !l.contains("\"a\",\"b\",\"c\"")).count();
        let counts: std::collections::BTreeSet<usize> = (0..20).map(|k| wrong(&files.file(7, k))).collect();
        assert!(counts.len() > 5, "{counts:?}");
    }

    #[tokio::test]
    async fn bounded_runs_every_task_once() {
        let mut seen = 0;
        let mut out = bounded(25, 4, |k| async move { k * 2 }, |n| seen = n)
            .await
            .unwrap();
        out.sort_unstable();
        assert_eq!(out, (0..25).map(|k| k * 2).collect::<Vec<_>>());
        assert_eq!(seen, 25);
    }
}
