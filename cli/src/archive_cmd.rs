//! `kitchen-r admin export --out FILE [--videos]` and `kitchen-r admin import FILE`: the contest
//! archive (docs/contest/archive.md) over the server's organiser routes. The archive holds the
//! hidden test answers: both commands say so.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use serde_json::Value;

use crate::server_client::{ServerArgs, runtime, send, url};

const WARNING: &str = "warning: the archive holds the contest's hidden answers (the private test set's \
ground truth) and every team's results. Keep it as you keep the test set; never give it to a participant.";

pub(crate) fn export(
    server: &ServerArgs,
    token: &str,
    out: &Path,
    videos: bool,
    force: bool,
) -> anyhow::Result<()> {
    if out.exists() && !force {
        bail!("{} exists: pass --force to replace it", out.display());
    }
    let path = format!("/api/v1/admin/export?videos={videos}");
    let mut partial = out.as_os_str().to_owned();
    partial.push(".partial");
    let partial = PathBuf::from(partial);
    let written = runtime()?.block_on(async {
        let mut resp = send(reqwest::Client::new().post(url(server, &path)).bearer_auth(token)).await?;
        let expected = resp.content_length();
        let mut file = std::fs::File::create(&partial)
            .with_context(|| format!("cannot create {}", partial.display()))?;
        let mut written = 0u64;
        while let Some(chunk) = resp.chunk().await.context("the export broke off")? {
            file.write_all(&chunk)?;
            written += chunk.len() as u64;
        }
        if let Some(n) = expected
            && n != written
        {
            bail!("the export broke off: {written} of {n} bytes");
        }
        file.sync_all()?;
        anyhow::Ok(written)
    });
    let written = match written {
        Ok(n) => n,
        Err(e) => {
            let _ = std::fs::remove_file(&partial);
            return Err(e);
        }
    };
    std::fs::rename(&partial, out).with_context(|| format!("cannot write {}", out.display()))?;
    println!(
        "contest archive written to {} ({written} bytes{}); `kitchen-r admin import {}` loads it into an empty server",
        out.display(),
        if videos { ", videos included" } else { "" },
        out.display()
    );
    eprintln!("{WARNING}");
    Ok(())
}

pub(crate) fn import(server: &ServerArgs, token: &str, file: &Path, raw: bool) -> anyhow::Result<()> {
    let bytes = std::fs::read(file).with_context(|| format!("cannot read {}", file.display()))?;
    let v: Value = runtime()?.block_on(async {
        let req = reqwest::Client::new()
            .post(url(server, "/api/v1/admin/import"))
            .bearer_auth(token)
            .header("content-type", "application/zstd")
            .body(bytes);
        let resp = send(req).await?;
        resp.json::<Value>().await.context("reading the server's answer")
    })?;
    if raw {
        println!("{v}");
        return Ok(());
    }
    let rows: Vec<String> = (v["rows"].as_object().into_iter().flatten())
        .map(|(table, n)| format!("{table} {n}"))
        .collect();
    println!(
        "imported {} (made by kitchen-r {}, archive format {}, {}): {}; {} trace/video file(s)",
        file.display(),
        v["binary_version"].as_str().unwrap_or("-"),
        v["format_version"],
        v["dataset"].as_str().unwrap_or("-"),
        rows.join(", "),
        v["files"]
    );
    let teams: Vec<&str> = (v["teams_without_token"].as_array().into_iter().flatten())
        .filter_map(Value::as_str)
        .collect();
    if !teams.is_empty() {
        println!(
            "teams have no token after an import ({}): issue new ones with `kitchen-r team rotate-token ID`",
            teams.join(", ")
        );
    }
    eprintln!("{WARNING}");
    Ok(())
}
