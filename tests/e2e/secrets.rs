//! Issue 23 through the real binary: a policy endpoint's bearer token is kept sealed at rest,
//! yet the workers present it to the endpoint.

use crate::support;

use std::process::Command;

use serde_json::json;
use support::*;

const SECRET: &str = "kit-token-Sealed-9137";

#[tokio::test(flavor = "multi_thread")]
async fn a_token_protected_policy_is_called_with_its_token_while_no_database_file_holds_it() {
    let python = Command::new("python3")
        .args(["-c", "import grpc, grpc_tools, grpc_health"])
        .status()
        .is_ok_and(|s| s.success());
    if !python {
        assert!(
            std::env::var("CI").is_err(),
            "python3 with grpcio is required in CI"
        );
        eprintln!("skipped: the starter kit's Python modules are not installed");
        return;
    }
    let fx = ControlFixture::new("[control]\nmax_plan_steps = 1\ntask_time_limit_s = 5.0\n");
    let server = fx.serve(2);
    let kit = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../starter-kit/policy_server.py");
    let (child, line) = spawn_ready(
        Command::new("python3")
            .arg(kit)
            .args(["--listen", "127.0.0.1:0", "--token", SECRET]),
        "listening grpc=",
    );
    let _kit = Proc(child);
    let url = format!("http://{}", line.trim_start_matches("listening grpc=").trim());
    let token = team(&server, "sealed").await;
    let body = json!({"endpoint": url, "split": "dev", "episodes": 1, "token": SECRET});
    let (status, reg) = register_policy(&server, &token, body).await;
    assert_eq!(status, 201, "{reg}");
    let id = reg["id"].as_i64().unwrap();
    let view = wait_for(&server, id, &token, "the token-protected run", finished).await;
    assert_eq!(view["latest_run"]["evaluation"]["state"], "finished", "{view:#}");
    // The kit refuses calls without its token: every task ran to its time limit instead.
    let text = view.to_string();
    assert!(
        !text.contains("Unauthenticated") && !text.contains("bearer"),
        "{view:#}"
    );
    assert!(text.contains("time limit"), "{view:#}");
    assert!(!text.contains(SECRET));
    // No file of the database (WAL included) holds the token in plain text.
    let db_dir = fx.dir.path().join("db");
    let mut seen = 0;
    for entry in std::fs::read_dir(&db_dir).unwrap() {
        let path = entry.unwrap().path();
        if !path.is_file() {
            continue; // `videos/`
        }
        let bytes = std::fs::read(&path).unwrap();
        assert!(
            !bytes.windows(SECRET.len()).any(|w| w == SECRET.as_bytes()),
            "{} holds the token",
            path.display()
        );
        seen += 1;
    }
    assert!(seen >= 2, "the database and its key file");
    assert!(db_dir.join("secret.key").is_file());
}
