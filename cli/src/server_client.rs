//! How the client commands reach a server: the `--server` flag, the runtime, URLs, and a
//! request whose refusal becomes an error in the server's own words (message, status, code,
//! request id).
//!
//! A file of its own because every client command file (`client_cmd`, `policy_submit`,
//! `submission_cmd`, `submission_view`, `submission_trace`, `admin_cmd`) needs it: held in
//! `client_cmd` and `submission_view`, it made those files import each other (docs/contributing.md,
//! import circles).

use anyhow::{Context, bail};
use clap::Args;
use serde_json::Value;

#[derive(Args, Debug)]
pub(crate) struct ServerArgs {
    /// Server base URL.
    #[arg(long, env = "KITCHEN_R_SERVER", default_value = "http://127.0.0.1:8080")]
    pub server: String,
}

// A server and the token a submission command acts with (a plain comment: clap would read a
// doc comment as help text).
#[derive(Args, Debug)]
pub(crate) struct Auth {
    #[command(flatten)]
    pub server: ServerArgs,
    /// Team token (or the organiser token, which sees every submission).
    #[arg(long, env = "KITCHEN_R_TOKEN", hide_env_values = true)]
    pub token: String,
}

pub(crate) fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")
}

pub(crate) fn url(server: &ServerArgs, path: &str) -> String {
    format!("{}{path}", server.server.trim_end_matches('/'))
}

/// Send, and turn a non-2xx answer into an error carrying the server's message, error code and
/// request id.
pub(crate) async fn send(req: reqwest::RequestBuilder) -> anyhow::Result<reqwest::Response> {
    let resp = req.send().await.context("cannot reach the server")?;
    if resp.status().is_success() {
        return Ok(resp);
    }
    let status = resp.status();
    let text = resp.text().await.unwrap_or_default();
    bail!(error_message(status.as_u16(), &text))
}

pub(crate) async fn json(req: reqwest::RequestBuilder) -> anyhow::Result<Value> {
    send(req)
        .await?
        .json()
        .await
        .context("the server's answer is not JSON")
}

/// A refused request in words: the server's message, status, error code and request id (to
/// quote when reporting a problem).
pub(crate) fn error_message(status: u16, body: &str) -> String {
    let v: Value = serde_json::from_str(body).unwrap_or(Value::Null);
    let Some(msg) = v["error"].as_str() else {
        let body = body.trim();
        return match body.is_empty() {
            true => format!("the server answered HTTP {status}"),
            false => format!("{body} (HTTP {status})"),
        };
    };
    let mut extra = Vec::new();
    if let Some(c) = v["code"].as_str() {
        extra.push(format!("code {c}"));
    }
    if let Some(r) = v["request_id"].as_str() {
        extra.push(format!("request id {r}"));
    }
    match extra.is_empty() {
        true => format!("{msg} (HTTP {status})"),
        false => format!("{msg} (HTTP {status}) [{}]", extra.join(", ")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errors_quote_code_and_request_id() {
        let body = r#"{"error":"submission 9 not found","code":"not_found","request_id":"abc"}"#;
        assert_eq!(
            error_message(404, body),
            "submission 9 not found (HTTP 404) [code not_found, request id abc]"
        );
        assert_eq!(error_message(502, ""), "the server answered HTTP 502");
    }
}
