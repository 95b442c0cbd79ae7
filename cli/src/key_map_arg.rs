//! `--key-map JSON|FILE` of `submit policy`, `check-policy` and `eval`: an openpi endpoint's key
//! map (manual: "openpi WebSocket endpoints"), inline when it starts with `{`, else read from the
//! file it names. Checked here for being a JSON object; its fields are checked where it is used
//! (`kitchen_r_contract::KeyMap`, at registration by the server's probe).

use anyhow::Context;

/// The key map's JSON text, or `None` when no `--key-map` was given.
pub(crate) fn read(arg: Option<&str>) -> anyhow::Result<Option<serde_json::Value>> {
    let Some(arg) = arg else {
        return Ok(None);
    };
    let text = if arg.trim_start().starts_with('{') {
        arg.to_string()
    } else {
        std::fs::read_to_string(arg).with_context(|| format!("reading the key map {arg}"))?
    };
    let v: serde_json::Value = serde_json::from_str(&text).context("--key-map is not JSON")?;
    anyhow::ensure!(v.is_object(), "--key-map must be a JSON object");
    Ok(Some(v))
}

/// As [`read`], as the text the contract crate parses (empty: the convention).
pub(crate) fn text(arg: Option<&str>) -> anyhow::Result<String> {
    Ok(read(arg)?.map_or_else(String::new, |v| v.to_string()))
}
