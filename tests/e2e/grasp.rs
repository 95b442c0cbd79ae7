//! The grasp mode end to end (docs/twin/robot.md): the organiser's `[control] grasp` reaches every
//! episode a real `kitchen-r serve` hands its workers, and every place that shows the run's
//! control score names the mode: the registration and submission answers, the leaderboard's
//! JSON, CSV and page, and the entry's public summary. An unknown mode stops the server at start,
//! naming the two there are.

use crate::support;

use std::process::Command;

use serde_json::json;
use support::*;

/// One dev instruction, online only, under the physical grasp.
const CONFIG: &str =
    "[control]\ngrasp = \"physical\"\noffline_mse = false\nlease_s = 4\nreaper_interval_s = 1\n";

#[tokio::test(flavor = "multi_thread")]
async fn a_physical_grasp_contest_names_its_mode_wherever_the_score_shows() {
    let fx = ControlFixture::new(CONFIG);
    let server = fx.serve(1);
    let (_oracle, url) = oracle_policy();
    let body = json!({"endpoint": url, "split": "dev", "episodes": 1, "reference": true});
    let (status, reg) = register_policy(&server, ADMIN, body).await;
    assert_eq!(status, 201, "{reg}");
    assert_eq!(reg["grasp_mode"], "physical", "{reg}");
    let id = reg["id"].as_i64().unwrap();
    let view = wait_for(&server, id, ADMIN, "the physical run", finished).await;
    let evaluation = &view["latest_run"]["evaluation"];
    assert_eq!(evaluation["state"], "finished", "{view:#}");
    assert_eq!(evaluation["grasp_mode"], "physical", "{view:#}");
    assert!(view["latest_run"]["scores"]["sr"].is_number(), "{view:#}");
    // The worker ran the episode in the job's mode (its log names it).
    let log = evaluation["episodes"][0]["log_tail"].as_str().unwrap_or_default();
    assert!(log.contains("grasp physical"), "{view:#}");

    // The contest's mode is the board answered by default, and every row names it.
    let (status, board) = get_json(&server, "/api/v1/leaderboard?track=control&split=dev", None).await;
    assert_eq!(status, 200);
    assert_eq!(board["grasp_mode"], "physical", "{board:#}");
    let row = (board["rows"].as_array().unwrap().iter())
        .find(|r| r["submission_id"] == id)
        .unwrap_or_else(|| panic!("run {id} not on the board: {board:#}"));
    assert_eq!(row["grasp_mode"], "physical", "{board:#}");
    let (_, other) = get_json(
        &server,
        "/api/v1/leaderboard?track=control&split=dev&grasp_mode=abstract",
        None,
    )
    .await;
    assert_eq!(
        (&other["grasp_mode"], &other["rows"]),
        (&json!("abstract"), &json!([]))
    );
    let (status, bad) = get_json(
        &server,
        "/api/v1/leaderboard?track=control&grasp_mode=magic",
        None,
    )
    .await;
    assert_eq!(status, 400, "{bad}");

    let csv = get_text(&server, "/api/v1/leaderboard?track=control&split=dev&format=csv").await;
    let mut lines = csv.lines();
    assert!(
        lines.next().unwrap().contains(",observations,grasp_mode,"),
        "{csv}"
    );
    assert!(
        lines.any(|l| l.contains(&format!(",{id},")) && l.contains(",standard,physical,")),
        "{csv}"
    );

    let page = get_text(&server, "/?split=dev").await;
    assert!(
        page.contains("Grasp mode of this contest: <b>physical</b>"),
        "{page}"
    );
    assert!(
        page.contains("<h2 id=\"control\">Control track — standard observations — physical grasp</h2>"),
        "{page}"
    );
    let entry = get_text(&server, &format!("/leaderboard/control/dev/{id}")).await;
    assert!(entry.contains("<th>Grasp mode</th><td>physical</td>"), "{entry}");
}

#[test]
fn an_unknown_grasp_mode_stops_the_server_naming_the_choices() {
    let fx = ControlFixture::new("[control]\ngrasp = \"magic\"\n");
    let out = Command::new(bin())
        .args(["serve", "--workers", "0", "--config"])
        .arg(fx.dir.path().join("server.toml"))
        .env("KITCHEN_R_ADMIN_TOKEN", ADMIN)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let e = err(&out);
    for needed in ["grasp", "magic", "abstract", "physical"] {
        assert!(e.contains(needed), "{needed:?} not in: {e}");
    }
}
