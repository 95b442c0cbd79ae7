//! `GET /api/docs`: the API reference, rendered on the server from the same OpenAPI document
//! that `GET /api/v1/openapi.json` serves ([`crate::http::openapi`]), so the page cannot drift
//! from the code. Plain HTML in the pages' frame: no script, nothing fetched.
//!
//! It walks the document as JSON (not utoipa's model) because that is the shape a reader of
//! the document sees too; the HTML is built once and kept.

use std::fmt::Write as _;
use std::sync::OnceLock;

use axum::extract::State;
use axum::http::{HeaderMap, StatusCode};
use axum::response::Response;
use serde_json::Value;

use super::layout::escape;
use crate::error::ServiceError;
use crate::http::openapi;
use crate::service::{AppState, Caller};

const METHODS: [&str; 6] = ["get", "post", "put", "patch", "delete", "head"];

pub(super) async fn page(
    State(s): State<AppState>,
    caller: Caller,
    headers: HeaderMap,
) -> Result<Response, ServiceError> {
    let who = super::who(&s, caller, &headers).await?;
    Ok(super::respond(
        &headers,
        &who,
        StatusCode::OK,
        "API reference",
        None,
        body(),
    ))
}

/// The page's body, rendered once from the document.
fn body() -> &'static str {
    static BODY: OnceLock<String> = OnceLock::new();
    BODY.get_or_init(|| {
        let doc: Value = serde_json::from_str(openapi::document_json()).expect("the document is JSON");
        render(&doc)
    })
}

/// Markdown-ish text of the document (backticks) as HTML: escaped, `code` spans kept.
fn prose(text: &str) -> String {
    let mut out = String::new();
    for (i, part) in text.split('`').enumerate() {
        match i % 2 {
            0 => out.push_str(&escape(part)),
            _ => {
                let _ = write!(out, "<code>{}</code>", escape(part));
            }
        }
    }
    out
}

fn anchor(method: &str, path: &str) -> String {
    let slug: String = path
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '-' })
        .collect();
    format!("{method}{slug}")
}

pub(super) fn render(doc: &Value) -> String {
    let mut out = String::new();
    let info = &doc["info"];
    let _ = write!(
        out,
        "<p>{}</p><p>The machine-readable document: <a href=\"/api/v1/openapi.json\">/api/v1/openapi.json</a> \
(OpenAPI {}, version {}). This page is rendered from it.</p>",
        prose(info["description"].as_str().unwrap_or("")),
        escape(doc["openapi"].as_str().unwrap_or("")),
        escape(info["version"].as_str().unwrap_or("")),
    );
    security_section(&mut out, doc);
    let ops = operations(doc);
    // Contents, by tag.
    let tags: Vec<(String, String)> = (doc["tags"].as_array().into_iter().flatten())
        .map(|t| {
            (
                t["name"].as_str().unwrap_or("").to_string(),
                t["description"].as_str().unwrap_or("").to_string(),
            )
        })
        .collect();
    out.push_str("<h2 id=contents>Operations</h2><table class=stack><tr><th>Method</th><th>Path</th><th>What</th></tr>");
    for (tag, _) in &tags {
        for (method, path, op) in ops.iter().filter(|(_, _, op)| first_tag(op) == tag) {
            let _ = write!(
                out,
                "<tr><td><code>{}</code></td><td><a href=\"#{}\"><code>{}</code></a></td><td>{}</td></tr>",
                method.to_uppercase(),
                anchor(method, path),
                escape(path),
                prose(op["summary"].as_str().unwrap_or("")),
            );
        }
    }
    out.push_str("</table>");
    for (tag, description) in &tags {
        let _ = write!(
            out,
            "<h2 id=\"tag-{0}\">{0}</h2><p>{1}</p>",
            escape(tag),
            prose(description)
        );
        for (method, path, op) in ops.iter().filter(|(_, _, op)| first_tag(op) == tag) {
            operation(&mut out, method, path, op);
        }
    }
    schemas_section(&mut out, doc);
    out
}

fn first_tag(op: &Value) -> &str {
    op["tags"][0].as_str().unwrap_or("")
}

/// `(method, path, operation)` in the document's path order.
fn operations(doc: &Value) -> Vec<(&'static str, &str, &Value)> {
    let mut ops = Vec::new();
    for (path, item) in doc["paths"].as_object().into_iter().flatten() {
        for method in METHODS {
            if let Some(op) = item.get(method) {
                ops.push((method, path.as_str(), op));
            }
        }
    }
    ops
}

fn security_section(out: &mut String, doc: &Value) {
    out.push_str("<h2 id=auth>Authentication</h2><table><tr><th>Scheme</th><th>How</th><th>What</th></tr>");
    for (name, s) in doc["components"]["securitySchemes"]
        .as_object()
        .into_iter()
        .flatten()
    {
        let _ = write!(
            out,
            "<tr><td><code>{}</code></td><td><code>Authorization: Bearer TOKEN</code></td><td>{}</td></tr>",
            escape(name),
            prose(s["description"].as_str().unwrap_or("")),
        );
    }
    out.push_str("</table>");
}

fn operation(out: &mut String, method: &str, path: &str, op: &Value) {
    let _ = write!(
        out,
        "<h3 id=\"{}\"><code>{} {}</code></h3><p><b>{}</b></p>",
        anchor(method, path),
        method.to_uppercase(),
        escape(path),
        prose(op["summary"].as_str().unwrap_or("")),
    );
    if let Some(d) = op["description"].as_str() {
        let _ = write!(out, "<p>{}</p>", prose(d));
    }
    let schemes: Vec<String> = (op["security"].as_array().into_iter().flatten())
        .filter_map(|req| req.as_object())
        .flat_map(|o| o.keys().map(|k| format!("<code>{}</code>", escape(k))))
        .collect();
    let _ = write!(
        out,
        "<p>Token: {}</p>",
        match schemes.is_empty() {
            true => "none".to_string(),
            false => schemes.join(" or "),
        }
    );
    if let Some(params) = op["parameters"].as_array().filter(|p| !p.is_empty()) {
        out.push_str("<div class=scroll><table><tr><th>Parameter</th><th>In</th><th>Type</th><th>Required</th><th>What</th></tr>");
        for p in params {
            let _ = write!(
                out,
                "<tr><td><code>{}</code></td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
                escape(p["name"].as_str().unwrap_or("")),
                escape(p["in"].as_str().unwrap_or("")),
                type_of(&p["schema"]),
                if p["required"].as_bool() == Some(true) {
                    "yes"
                } else {
                    "no"
                },
                prose(p["description"].as_str().unwrap_or("")),
            );
        }
        out.push_str("</table></div>");
    }
    if let Some(body) = op.get("requestBody") {
        let _ = write!(
            out,
            "<p>Request body{}: {}</p>",
            if body["required"].as_bool() == Some(true) {
                " (required)"
            } else {
                ""
            },
            content(&body["content"]),
        );
        if let Some(d) = body["description"].as_str() {
            let _ = write!(out, "<p class=muted>{}</p>", prose(d));
        }
    }
    out.push_str("<div class=scroll><table><tr><th>Status</th><th>Meaning</th><th>Body</th></tr>");
    for (status, r) in op["responses"].as_object().into_iter().flatten() {
        let _ = write!(
            out,
            "<tr><td>{}</td><td>{}</td><td>{}</td></tr>",
            escape(status),
            prose(r["description"].as_str().unwrap_or("")),
            content(&r["content"]),
        );
    }
    out.push_str("</table></div>");
}

/// `media type: schema` per content entry.
fn content(content: &Value) -> String {
    let parts: Vec<String> = (content.as_object().into_iter().flatten())
        .map(|(media, c)| format!("<code>{}</code> {}", escape(media), type_of(&c["schema"])))
        .collect();
    match parts.is_empty() {
        true => "–".into(),
        false => parts.join("<br>"),
    }
}

/// A schema in a few words: a link to a named schema, `array of …`, a type, or its variants.
fn type_of(schema: &Value) -> String {
    if let Some(r) = schema["$ref"].as_str() {
        let name = r.rsplit('/').next().unwrap_or(r);
        return format!("<a href=\"#schema-{0}\">{0}</a>", escape(name));
    }
    for key in ["oneOf", "anyOf", "allOf"] {
        if let Some(items) = schema[key].as_array() {
            let join = if key == "allOf" { " and " } else { " or " };
            return items.iter().map(type_of).collect::<Vec<_>>().join(join);
        }
    }
    if let Some(values) = schema["enum"].as_array() {
        return values
            .iter()
            .map(|v| format!("<code>{}</code>", escape(&v.to_string())))
            .collect::<Vec<_>>()
            .join(" | ");
    }
    let types: Vec<&str> = match &schema["type"] {
        Value::String(t) => vec![t.as_str()],
        Value::Array(ts) => ts.iter().filter_map(Value::as_str).collect(),
        _ => vec![],
    };
    let words: Vec<String> = types
        .iter()
        .map(|t| match *t {
            "array" => format!("array of {}", type_of(&schema["items"])),
            "object" if schema["additionalProperties"].is_object() => {
                format!("map of {}", type_of(&schema["additionalProperties"]))
            }
            "string" if schema["format"] == "binary" => "bytes".into(),
            t => escape(t),
        })
        .collect();
    match words.is_empty() {
        true => "any".into(),
        false => words.join(" or "),
    }
}

fn schemas_section(out: &mut String, doc: &Value) {
    out.push_str("<h2 id=schemas>Schemas</h2>");
    for (name, s) in doc["components"]["schemas"].as_object().into_iter().flatten() {
        let _ = write!(out, "<h3 id=\"schema-{0}\">{0}</h3>", escape(name));
        if let Some(d) = s["description"].as_str() {
            let _ = write!(out, "<p>{}</p>", prose(d));
        }
        let Some(props) = s["properties"].as_object() else {
            let _ = write!(out, "<p>{}</p>", type_of(s));
            continue;
        };
        let required: Vec<&str> = (s["required"].as_array().into_iter().flatten())
            .filter_map(Value::as_str)
            .collect();
        out.push_str(
            "<div class=scroll><table><tr><th>Field</th><th>Type</th><th>Always there</th><th>What</th></tr>",
        );
        for (field, p) in props {
            let _ = write!(
                out,
                "<tr><td><code>{}</code></td><td>{}</td><td>{}</td><td>{}</td></tr>",
                escape(field),
                type_of(p),
                if required.contains(&field.as_str()) {
                    "yes"
                } else {
                    "no"
                },
                prose(p["description"].as_str().unwrap_or("")),
            );
        }
        out.push_str("</table></div>");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_page_lists_every_operation_of_the_document_with_its_responses() {
        let doc: Value = serde_json::from_str(openapi::document_json()).unwrap();
        let html = render(&doc);
        for (method, path, op) in operations(&doc) {
            assert!(
                html.contains(&format!("id=\"{}\"", anchor(method, path))),
                "{method} {path}"
            );
            for status in op["responses"].as_object().unwrap().keys() {
                assert!(
                    html.contains(&format!("<td>{status}</td>")),
                    "{method} {path} {status}"
                );
            }
        }
        assert!(html.contains("id=\"schema-ErrorBody\""));
        assert!(!html.contains("<script"), "no script on the pages");
    }

    #[test]
    fn a_schema_is_named_in_a_few_words() {
        let t = |v: Value| type_of(&v);
        assert_eq!(
            t(serde_json::json!({"type": ["integer", "null"]})),
            "integer or null"
        );
        assert_eq!(
            t(serde_json::json!({"type": "array", "items": {"$ref": "#/components/schemas/Row"}})),
            "array of <a href=\"#schema-Row\">Row</a>"
        );
        assert_eq!(
            t(serde_json::json!({"enum": ["dev", "test"]})),
            "<code>&quot;dev&quot;</code> | <code>&quot;test&quot;</code>"
        );
    }
}
