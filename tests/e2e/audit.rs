//! `kitchen-r dataset audit` as an organiser runs it: a public sample fails with the reasons and
//! a non-zero exit code; a set generated with private phrasings (composed with the language
//! features, the default) passes, the starter kit's parser included; `--oracle` runs the
//! privileged oracle over the set's instructions with progress on stderr.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::Value;

fn root() -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
}

fn kitchen_r(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_kitchen-r"))
        .args(args)
        .current_dir(root())
        .env_remove("KITCHEN_R_ASSETS")
        .env("RUST_BACKTRACE", "0")
        .output()
        .expect("run kitchen-r")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn path(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn a_public_sample_fails_the_audit_with_reasons() {
    let dir = tempfile::tempdir().unwrap();
    let set = dir.path().join("sample");
    let out = kitchen_r(&["dataset", "generate", "--seed", "5", "--out", path(&set)]);
    assert!(out.status.success(), "{}", text(&out.stderr));

    let out = kitchen_r(&["dataset", "audit", path(&set)]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out.stdout));
    let stdout = text(&out.stdout);
    assert!(stdout.contains("FAIL  attack EM"), "{stdout}");
    assert!(stdout.contains("the set FAILS the audit"), "{stdout}");
    assert!(stdout.contains("note: this is a public sample"), "{stdout}");
    assert!(
        text(&out.stderr).contains("audit failed: attack EM"),
        "{}",
        text(&out.stderr)
    );

    let out = kitchen_r(&["dataset", "audit", path(&set), "--json"]);
    assert_eq!(out.status.code(), Some(1));
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["passed"], false);
    assert_eq!(v["report"]["attack"]["em"], 1.0);
    assert_eq!(v["report"]["kind"], "public_sample");
    assert_eq!(v["report"]["public_phrasing_share"], 1.0);

    // Thresholds are the organiser's: loose enough, the same set passes.
    let out = kitchen_r(&[
        "dataset",
        "audit",
        path(&set),
        "--max-attack-em",
        "1",
        "--max-public-phrasing-share",
        "1",
        "--max-bag-of-mentions-em",
        "1",
        "--max-parser-em",
        "1",
    ]);
    assert!(out.status.success(), "{}", text(&out.stdout));
    assert!(text(&out.stdout).contains("the set passes the audit"));
}

#[test]
fn a_private_set_passes_and_the_oracle_completes_it() {
    let dir = tempfile::tempdir().unwrap();
    // The documented example: private phrasings for every template that also vary the order in
    // which objects and places are mentioned (what the audit's 0.3 attack limit asks for).
    let phrasings = root().join("docs/examples/private-phrasings.example.toml");
    let set = dir.path().join("private");
    let out = kitchen_r(&[
        "dataset",
        "generate",
        "--seed",
        "913577",
        "--phrasings",
        path(&phrasings),
        "--out",
        path(&set),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));

    let out = kitchen_r(&["dataset", "audit", path(&set), "--json"]);
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["report"]["kind"], "private");
    assert_eq!(v["report"]["public_phrasing"], 0);
    assert_eq!(v["report"]["attack"]["inverted"], 0);
    assert!(v["report"]["attack"]["em"].as_f64().unwrap() <= 0.3, "{v:#}");
    assert!(
        v["report"]["attack"]["fallback_em"].as_f64().unwrap() <= 0.3,
        "{v:#}"
    );
    assert_eq!(v["passed"], true, "{v:#}");
    assert!(out.status.success());
    // Composed with every language feature (the default for private sets), each instruction
    // kept only with exactly one plan; the checker's refusals are counted by reason.
    let language = &v["report"]["language"];
    assert_eq!(language["features"].as_array().unwrap().len(), 5, "{v:#}");
    assert_eq!(language["composed"], 400, "{v:#}");
    assert!(
        language["rejected"]["ambiguous reference"].as_u64().unwrap() > 0,
        "{v:#}"
    );
    // The starter kit's parser ran through python3 (or the report says why not).
    let note = v["report"]["parser_note"].as_str().unwrap();
    if note.starts_with("ran python3") {
        assert!(v["report"]["parser"]["em"].as_f64().unwrap() <= 0.6, "{v:#}");
    } else {
        assert!(note.contains("python3"), "{note}");
    }

    // The oracle over the first three instructions (a whole set takes minutes).
    let gt = std::fs::read_to_string(set.join("test_ground_truth.jsonl")).unwrap();
    let head: String = gt.lines().take(3).map(|l| format!("{l}\n")).collect();
    let small = dir.path().join("small");
    std::fs::create_dir(&small).unwrap();
    std::fs::write(small.join("test_ground_truth.jsonl"), head).unwrap();
    std::fs::copy(set.join("manifest.json"), small.join("manifest.json")).unwrap();
    let out = kitchen_r(&[
        "dataset",
        "audit",
        path(&small),
        "--oracle",
        "--jobs",
        "1",
        "--max-attack-em",
        "1",
        "--max-bag-of-mentions-em",
        "1",
        "--no-parser",
    ]);
    let (stdout, stderr) = (text(&out.stdout), text(&out.stderr));
    assert!(out.status.success(), "{stdout}\n{stderr}");
    assert!(
        stdout.contains("oracle: 0 of 3 instructions not completed"),
        "{stdout}"
    );
    assert!(stdout.contains("PASS  oracle failures"), "{stdout}");
    assert!(stderr.contains("[3] test-"), "{stderr}");
}
