//! `kitchen-r submission trace ID EPISODE_KEY [-o FILE]`: download one episode's trace (gzipped
//! JSON) from `GET /api/v1/submissions/{id}/episodes/{key}/trace`, for `kitchen-r replay FILE`
//! to reproduce the episode locally, bit for bit, and write its video. The team gets its dev
//! episodes' traces; the organiser every trace (test split too).

use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Context, bail};

use crate::server_client::{Auth, error_message, runtime, url};

/// Download the trace and write it to `out` (default `<episode key>.trace.json.gz`).
pub(crate) fn download(id: i64, key: &str, out: Option<PathBuf>, auth: &Auth) -> anyhow::Result<()> {
    let path =
        out.unwrap_or_else(|| PathBuf::from(format!("{}.trace.json.gz", key.replace(['/', '\\'], "_"))));
    let bytes = runtime()?.block_on(async {
        let resp = reqwest::Client::new()
            .get(url(
                &auth.server,
                &format!("/api/v1/submissions/{id}/episodes/{key}/trace"),
            ))
            .bearer_auth(&auth.token)
            .timeout(Duration::from_secs(120))
            .send()
            .await
            .context("cannot reach the server")?;
        let status = resp.status();
        if !status.is_success() {
            let text = resp.text().await.unwrap_or_default();
            bail!("{}", error_message(status.as_u16(), &text));
        }
        resp.bytes().await.context("reading the trace")
    })?;
    std::fs::write(&path, &bytes).with_context(|| format!("writing {}", path.display()))?;
    println!(
        "trace of episode {key} of submission {id}: {} ({} bytes); `kitchen-r replay {}` reproduces it",
        path.display(),
        bytes.len(),
        path.display()
    );
    Ok(())
}
