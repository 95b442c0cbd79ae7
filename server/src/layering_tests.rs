//! The crate doc's import rule, checked on the source text (docs/contributing.md): adapters →
//! service → store → leaf types. Textual on purpose: `crate::` paths are how this crate names its
//! modules, so a string search finds every import a reviewer would, without a parser.
//!
//! Tests are exempt (a test of the service may drive the HTTP router): test files (`tests.rs`,
//! `*_tests.rs`, `tests/`, `testutil.rs`, this file) and inline `#[cfg(test)] mod … { … }`
//! blocks. Comments are skipped: doc links to an adapter are not imports.

use std::path::{Path, PathBuf};

/// The adapters: the only files that may name an adapter module.
const ADAPTERS: [&str; 3] = ["http", "grpc", "grpc_worker"];

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

fn is_test_file(rel: &str) -> bool {
    let name = rel.rsplit('/').next().unwrap_or(rel);
    name == "tests.rs"
        || name.ends_with("_tests.rs")
        || name == "testutil.rs"
        || rel.split('/').any(|part| part == "tests")
}

/// The module a file belongs to at the crate's top (`http/pages.rs` → `http`).
fn top_module(rel: &str) -> &str {
    let first = rel.split('/').next().unwrap_or(rel);
    first.strip_suffix(".rs").unwrap_or(first)
}

/// The file's non-test, non-comment lines with their numbers.
fn code_lines(text: &str) -> Vec<(usize, &str)> {
    let mut out = Vec::new();
    let mut lines = text.lines().enumerate().peekable();
    while let Some((n, line)) = lines.next() {
        let trimmed = line.trim_start();
        if trimmed.starts_with("//") {
            continue;
        }
        if trimmed == "#[cfg(test)]" {
            // An inline test module runs to the first `}` at column 0; a `mod x;` line is a
            // test file, scanned (or exempted) on its own.
            if let Some((_, next)) = lines.peek()
                && next.contains("mod ")
                && next.trim_end().ends_with('{')
            {
                for (_, inner) in lines.by_ref() {
                    if inner == "}" {
                        break;
                    }
                }
            }
            continue;
        }
        out.push((n + 1, line));
    }
    out
}

/// Whether `line` names `crate::<module>` as a whole path segment (so `crate::grpc` does not
/// match `crate::grpc_routes`, a function of lib.rs).
fn names_module(line: &str, module: &str) -> bool {
    let needle = format!("crate::{module}");
    line.match_indices(&needle).any(|(at, _)| {
        let after = line[at + needle.len()..].chars().next();
        !after.is_some_and(|c| c.is_alphanumeric() || c == '_')
    })
}

#[test]
fn no_file_outside_an_adapter_imports_one_and_the_store_never_imports_the_service() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    assert!(files.len() > 50, "found only {} files", files.len());
    let mut wrong = Vec::new();
    for path in files {
        let rel = path
            .strip_prefix(&src)
            .unwrap()
            .to_string_lossy()
            .replace('\\', "/");
        if is_test_file(&rel) || rel == "layering_tests.rs" {
            continue;
        }
        let top = top_module(&rel);
        let text = std::fs::read_to_string(&path).unwrap();
        for (n, line) in code_lines(&text) {
            for adapter in ADAPTERS {
                if !ADAPTERS.contains(&top) && names_module(line, adapter) {
                    wrong.push(format!("{rel}:{n}: imports the adapter `{adapter}`: {line}"));
                }
            }
            if top == "store" && names_module(line, "service") {
                wrong.push(format!("{rel}:{n}: the store imports the service: {line}"));
            }
        }
    }
    assert!(
        wrong.is_empty(),
        "imports against the rule in the crate doc:\n{}",
        wrong.join("\n")
    );
}

#[test]
fn the_check_sees_an_import_and_skips_comments_and_test_modules() {
    let text = "use crate::http::openapi;\n// crate::http in a comment\n#[cfg(test)]\nmod tests {\n    use crate::http;\n}\nfn f() {}\n";
    let lines = code_lines(text);
    assert_eq!(lines.len(), 2, "{lines:?}");
    assert!(names_module(lines[0].1, "http"));
    assert!(!names_module("crate::grpc_routes(x)", "grpc"));
    assert!(names_module("crate::grpc::Caller", "grpc"));
}
