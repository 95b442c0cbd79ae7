use std::collections::BTreeSet;
use std::path::Path;

use super::*;

/// The route paths the HTTP adapter's source files declare with `.route("...", ...)`, read
/// from `src/http.rs` and every file under `src/http/` (the router is assembled from those).
fn declared_routes() -> BTreeSet<String> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = vec![root.join("http.rs")];
    let mut dirs = vec![root.join("http")];
    while let Some(dir) = dirs.pop() {
        for entry in std::fs::read_dir(&dir).expect("src/http is readable") {
            let path = entry.expect("a directory entry").path();
            if path.is_dir() {
                dirs.push(path);
            } else if path.extension().is_some_and(|e| e == "rs") {
                files.push(path);
            }
        }
    }
    let mut routes = BTreeSet::new();
    for file in files {
        let text = std::fs::read_to_string(&file).expect("a source file is readable");
        // `.route(` then, maybe after a line break, the path literal.
        for piece in text.split(".route(").skip(1) {
            let rest = piece.trim_start();
            if let Some(lit) = rest.strip_prefix('"')
                && let Some(end) = lit.find('"')
            {
                routes.insert(lit[..end].to_string());
            }
        }
    }
    routes
}

fn documented() -> serde_json::Value {
    serde_json::from_str(document_json()).expect("the document is JSON")
}

#[test]
fn the_document_is_openapi_3_1() {
    let doc = documented();
    let version = doc["openapi"].as_str().expect("an `openapi` field");
    assert!(version.starts_with("3.1."), "openapi is {version}");
    let schemes = &doc["components"]["securitySchemes"];
    assert_eq!(schemes[TEAM]["scheme"], "bearer");
    assert_eq!(schemes[ORGANISER]["scheme"], "bearer");
}

#[test]
fn every_api_route_the_router_serves_is_documented_and_nothing_else() {
    let declared: BTreeSet<String> = declared_routes()
        .into_iter()
        .filter(|r| r.starts_with("/api/v1/") || r == "/healthz" || r == "/metrics")
        .collect();
    // Sanity: the scan found the router (a refactor that hides routes from it must fail here).
    assert!(declared.contains("/api/v1/submissions/{id}"), "{declared:?}");
    assert!(declared.contains("/api/v1/admin/queue"), "{declared:?}");
    let doc = documented();
    let paths: BTreeSet<String> = doc["paths"].as_object().expect("paths").keys().cloned().collect();
    let missing: Vec<_> = declared.difference(&paths).collect();
    assert!(
        missing.is_empty(),
        "routes without a #[utoipa::path] in http/openapi.rs's list: {missing:?}"
    );
    let extra: Vec<_> = paths.difference(&declared).collect();
    assert!(extra.is_empty(), "documented paths no route serves: {extra:?}");
}

#[test]
fn every_operation_documents_its_errors_and_they_have_the_error_shape() {
    let doc = documented();
    for (path, item) in doc["paths"].as_object().expect("paths") {
        for (method, op) in item.as_object().expect("a path item") {
            let responses = op["responses"].as_object().expect("responses");
            assert!(responses.contains_key("500"), "{method} {path} lacks 500");
            let secured = op
                .get("security")
                .is_some_and(|s| !s.as_array().is_some_and(Vec::is_empty));
            assert_eq!(
                responses.contains_key("401"),
                secured,
                "{method} {path}: 401 iff a token is needed"
            );
            // Error answers with a body (a 416 to a byte range has none) carry the error shape.
            for (status, r) in responses {
                if (status.starts_with('4') || status.starts_with('5')) && r.get("content").is_some() {
                    assert_eq!(
                        r["content"]["application/json"]["schema"]["$ref"], "#/components/schemas/ErrorBody",
                        "{method} {path} {status}"
                    );
                }
            }
        }
    }
}

#[test]
fn every_schema_reference_resolves() {
    fn refs<'a>(v: &'a serde_json::Value, out: &mut Vec<&'a str>) {
        match v {
            serde_json::Value::Object(o) => {
                if let Some(r) = o.get("$ref").and_then(|r| r.as_str()) {
                    out.push(r);
                }
                o.values().for_each(|v| refs(v, out));
            }
            serde_json::Value::Array(a) => a.iter().for_each(|v| refs(v, out)),
            _ => {}
        }
    }
    let doc = documented();
    let mut found = Vec::new();
    refs(&doc, &mut found);
    assert!(!found.is_empty());
    for r in found {
        let name = r
            .strip_prefix("#/components/schemas/")
            .expect("a schema reference");
        assert!(
            doc["components"]["schemas"].get(name).is_some(),
            "{r} is not defined"
        );
    }
}

#[test]
fn an_admin_run_names_its_observation_track() {
    let doc = documented();
    let run = &doc["components"]["schemas"]["AdminRunView"];
    let required = run["required"].as_array().expect("required fields");
    assert!(required.iter().any(|f| f == "observations"), "{run:#}");
    assert_eq!(
        run["properties"]["observations"]["$ref"], "#/components/schemas/ObservationsName",
        "{run:#}"
    );
    let values = &doc["components"]["schemas"]["ObservationsName"]["enum"];
    assert_eq!(values, &serde_json::json!(["standard", "privileged"]));
}
