//! `GET /api/docs`: the API reference, rendered on the server from the same OpenAPI document
//! that `GET /api/v1/openapi.json` serves ([`crate::http::openapi`]), so the page cannot drift
//! from the code. Plain HTML in the pages' frame: no script, nothing fetched.
//!
//! It walks the document as JSON (not utoipa's model) because that is the shape a reader of
//! the document sees too; the HTML is built once and kept.

use std::sync::OnceLock;

use axum::extract::State;
use axum::http::{HeaderMap, StatusCode};
use axum::response::Response;
use maud::{Markup, PreEscaped, html};
use serde_json::Value;

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
        PreEscaped(body().to_string()),
    ))
}

/// The page's body, rendered once from the document (and kept as markup maud built).
fn body() -> &'static str {
    static BODY: OnceLock<String> = OnceLock::new();
    BODY.get_or_init(|| {
        let doc: Value = serde_json::from_str(openapi::document_json()).expect("the document is JSON");
        render(&doc).into_string()
    })
}

/// Markdown-ish text of the document (backticks) as HTML: the text escaped, `code` spans kept.
fn prose(text: &str) -> Markup {
    html! {
        @for (i, part) in text.split('`').enumerate() {
            @if i % 2 == 0 { (part) } @else { code { (part) } }
        }
    }
}

/// The text of `v`'s string field `key`, empty when absent.
fn text<'a>(v: &'a Value, key: &str) -> &'a str {
    v[key].as_str().unwrap_or("")
}

fn anchor(method: &str, path: &str) -> String {
    let slug: String = path
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '-' })
        .collect();
    format!("{method}{slug}")
}

pub(super) fn render(doc: &Value) -> Markup {
    let info = &doc["info"];
    let ops = operations(doc);
    // Contents, by tag.
    let tags: Vec<(&str, &str)> = (doc["tags"].as_array().into_iter().flatten())
        .map(|t| (text(t, "name"), text(t, "description")))
        .collect();
    let tagged = |tag: &str| {
        let tag = tag.to_string();
        ops.iter().filter(move |(_, _, op)| first_tag(op) == tag)
    };
    html! {
        p { (prose(text(info, "description"))) }
        p {
            "The machine-readable document: " a href="/api/v1/openapi.json" { "/api/v1/openapi.json" }
            " (OpenAPI " (text(doc, "openapi")) ", version " (text(info, "version")) "). This page is rendered from it."
        }
        (security_section(doc))
        h2 id="contents" { "Operations" }
        table.stack {
            tr { th { "Method" } th { "Path" } th { "What" } }
            @for (tag, _) in &tags {
                @for (method, path, op) in tagged(tag) {
                    tr {
                        td { code { (method.to_uppercase()) } }
                        td { a href={ "#" (anchor(method, path)) } { code { (path) } } }
                        td { (prose(text(op, "summary"))) }
                    }
                }
            }
        }
        @for (tag, description) in &tags {
            h2 id={ "tag-" (tag) } { (tag) }
            p { (prose(description)) }
            @for (method, path, op) in tagged(tag) { (operation(method, path, op)) }
        }
        (schemas_section(doc))
    }
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

fn security_section(doc: &Value) -> Markup {
    let schemes = doc["components"]["securitySchemes"]
        .as_object()
        .into_iter()
        .flatten();
    html! {
        h2 id="auth" { "Authentication" }
        table {
            tr { th { "Scheme" } th { "How" } th { "What" } }
            @for (name, s) in schemes {
                tr { td { code { (name) } } td { code { "Authorization: Bearer TOKEN" } } td { (prose(text(s, "description"))) } }
            }
        }
    }
}

fn yes_no(v: &Value) -> &'static str {
    match v.as_bool() {
        Some(true) => "yes",
        _ => "no",
    }
}

fn operation(method: &str, path: &str, op: &Value) -> Markup {
    let schemes: Vec<&String> = (op["security"].as_array().into_iter().flatten())
        .filter_map(|req| req.as_object())
        .flat_map(|o| o.keys())
        .collect();
    html! {
        h3 id=(anchor(method, path)) { code { (method.to_uppercase()) " " (path) } }
        p { b { (prose(text(op, "summary"))) } }
        @if let Some(d) = op["description"].as_str() { p { (prose(d)) } }
        p {
            "Token: "
            @if schemes.is_empty() { "none" }
            @for (i, k) in schemes.iter().enumerate() { @if i > 0 { " or " } code { (k) } }
        }
        @if let Some(params) = op["parameters"].as_array().filter(|p| !p.is_empty()) {
            div.scroll {
                table {
                    tr { th { "Parameter" } th { "In" } th { "Type" } th { "Required" } th { "What" } }
                    @for p in params {
                        tr {
                            td { code { (text(p, "name")) } } td { (text(p, "in")) } td { (type_of(&p["schema"])) }
                            td { (yes_no(&p["required"])) } td { (prose(text(p, "description"))) }
                        }
                    }
                }
            }
        }
        @if let Some(body) = op.get("requestBody") {
            p {
                "Request body" @if body["required"].as_bool() == Some(true) { " (required)" } ": "
                (content(&body["content"]))
            }
            @if let Some(d) = body["description"].as_str() { p.muted { (prose(d)) } }
        }
        div.scroll {
            table {
                tr { th { "Status" } th { "Meaning" } th { "Body" } }
                @for (status, r) in op["responses"].as_object().into_iter().flatten() {
                    tr { td { (status) } td { (prose(text(r, "description"))) } td { (content(&r["content"])) } }
                }
            }
        }
    }
}

/// `media type: schema` per content entry.
fn content(content: &Value) -> Markup {
    let parts: Vec<(&String, &Value)> = content.as_object().into_iter().flatten().collect();
    html! {
        @if parts.is_empty() { "–" }
        @for (i, (media, c)) in parts.iter().enumerate() {
            @if i > 0 { br; }
            code { (media) } " " (type_of(&c["schema"]))
        }
    }
}

/// `items` joined by `sep`.
fn joined(items: impl IntoIterator<Item = Markup>, sep: &str) -> Markup {
    html! {
        @for (i, item) in items.into_iter().enumerate() { @if i > 0 { (sep) } (item) }
    }
}

/// A schema in a few words: a link to a named schema, `array of …`, a type, or its variants.
fn type_of(schema: &Value) -> Markup {
    if let Some(r) = schema["$ref"].as_str() {
        let name = r.rsplit('/').next().unwrap_or(r);
        return html! { a href={ "#schema-" (name) } { (name) } };
    }
    for key in ["oneOf", "anyOf", "allOf"] {
        if let Some(items) = schema[key].as_array() {
            let join = if key == "allOf" { " and " } else { " or " };
            return joined(items.iter().map(type_of), join);
        }
    }
    if let Some(values) = schema["enum"].as_array() {
        return joined(values.iter().map(|v| html! { code { (v.to_string()) } }), " | ");
    }
    let types: Vec<&str> = match &schema["type"] {
        Value::String(t) => vec![t.as_str()],
        Value::Array(ts) => ts.iter().filter_map(Value::as_str).collect(),
        _ => vec![],
    };
    if types.is_empty() {
        return html! { "any" };
    }
    let words = types.into_iter().map(|t| match t {
        "array" => html! { "array of " (type_of(&schema["items"])) },
        "object" if schema["additionalProperties"].is_object() => {
            html! { "map of " (type_of(&schema["additionalProperties"])) }
        }
        "string" if schema["format"] == "binary" => html! { "bytes" },
        t => html! { (t) },
    });
    joined(words, " or ")
}

fn schemas_section(doc: &Value) -> Markup {
    let schemas = doc["components"]["schemas"].as_object().into_iter().flatten();
    html! {
        h2 id="schemas" { "Schemas" }
        @for (name, s) in schemas {
            h3 id={ "schema-" (name) } { (name) }
            @if let Some(d) = s["description"].as_str() { p { (prose(d)) } }
            @match s["properties"].as_object() {
                None => { p { (type_of(s)) } }
                Some(props) => {
                    @let required: Vec<&str> = (s["required"].as_array().into_iter().flatten()).filter_map(Value::as_str).collect();
                    div.scroll {
                        table {
                            tr { th { "Field" } th { "Type" } th { "Always there" } th { "What" } }
                            @for (field, p) in props {
                                tr {
                                    td { code { (field) } } td { (type_of(p)) }
                                    td { (if required.contains(&field.as_str()) { "yes" } else { "no" }) }
                                    td { (prose(text(p, "description"))) }
                                }
                            }
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_page_lists_every_operation_of_the_document_with_its_responses() {
        let doc: Value = serde_json::from_str(openapi::document_json()).unwrap();
        let html = render(&doc).into_string();
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
        let t = |v: Value| type_of(&v).into_string();
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
