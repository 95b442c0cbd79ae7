//! Planning track end to end: the real `kitchen-r serve` process on a temporary database,
//! driven over HTTP (and gRPC for the submission service).

use crate::support;

use serde_json::Value;
use support::*;

fn dev_ground_truth_file() -> String {
    dev_plans().iter().map(|(id, p)| line(id, p) + "\n").collect()
}

/// dev-0001: 3 of 4 steps right (index 1 wrong, one extra step); dev-0002: 2 of 5 (short);
/// dev-0003: missing. EM = (3/4 + 2/5 + 0) / 3.
fn known_wrong_file() -> (String, f64) {
    let body = [
        line(
            "dev-0001",
            &[
                "move to the blue zone",
                "pick the cup",
                "move to the red zone",
                "place the bowl",
                "pick the bowl",
            ],
        ),
        line("dev-0002", &["move to the green zone", "pick the cup"]),
    ]
    .join("\n");
    (body, (0.75 + 0.4) / 3.0)
}

fn em(v: &Value) -> f64 {
    v["scores"]["em"].as_f64().unwrap()
}

#[tokio::test]
async fn scores_persist_across_restart_and_rescore_adds_a_run() {
    let fx = Fixture::new("");
    let server = fx.serve();
    let token = team(&server, "alpha").await;

    let (status, gt) = submit(&server, Some(&token), "dev", dev_ground_truth_file()).await;
    assert_eq!(status, 201, "{gt}");
    assert_eq!(em(&gt), 1.0);
    assert_eq!(gt["warnings"].as_array().unwrap().len(), 0);

    let (body, expected) = known_wrong_file();
    let (status, wrong) = submit(&server, Some(&token), "dev", body).await;
    assert_eq!(status, 201, "{wrong}");
    assert!((em(&wrong) - expected).abs() < 1e-12, "{wrong}");
    assert!(
        wrong["warnings"][0]
            .as_str()
            .unwrap()
            .starts_with("1 of 3 instructions")
    );

    // The submission page shows per-instruction results.
    let (_, sub) = get_json(
        &server,
        &format!("/api/v1/submissions/{}", wrong["id"]),
        Some(&token),
    )
    .await;
    let inst = sub["latest_run"]["instructions"].as_array().unwrap();
    let summary: Vec<(bool, u64, u64)> = inst
        .iter()
        .map(|i| {
            (
                i["present"].as_bool().unwrap(),
                i["correct_steps"].as_u64().unwrap(),
                i["total_steps"].as_u64().unwrap(),
            )
        })
        .collect();
    assert_eq!(summary, vec![(true, 3, 4), (true, 2, 5), (false, 0, 8)]);

    // Restart on the same database: everything is still there.
    drop(server);
    let server = fx.serve();
    let mut first_runs = Vec::new();
    for (sub, want) in [(&gt, 1.0), (&wrong, expected)] {
        let (status, v) = get_json(
            &server,
            &format!("/api/v1/submissions/{}", sub["id"]),
            Some(&token),
        )
        .await;
        assert_eq!(status, 200, "{v}");
        assert_eq!(v["runs"], 1);
        assert!((v["latest_run"]["scores"]["em"].as_f64().unwrap() - want).abs() < 1e-12);
        first_runs.push(v["latest_run"]["id"].clone());
    }
    let (_, board) = get_json(&server, "/api/v1/leaderboard?track=planning&split=dev", None).await;
    assert_eq!(board["rows"][0]["team"], "alpha");
    assert_eq!(board["rows"][0]["submission_id"], gt["id"]);

    // Rescore adds a second run with the same score to each submission.
    let r = client()
        .post(server.url("/api/v1/admin/rescore"))
        .bearer_auth(ADMIN)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    let report: Value = r.json().await.unwrap();
    assert_eq!(report["rescored"], 2);
    for ((sub, want), first_run) in [(&gt, 1.0), (&wrong, expected)].into_iter().zip(first_runs) {
        let (_, v) = get_json(
            &server,
            &format!("/api/v1/submissions/{}", sub["id"]),
            Some(&token),
        )
        .await;
        assert_eq!(v["runs"], 2);
        assert!((v["latest_run"]["scores"]["em"].as_f64().unwrap() - want).abs() < 1e-12);
        assert_ne!(
            v["latest_run"]["id"], first_run,
            "rescoring must add a run, not reuse one"
        );
    }
}

/// (token, split, body, status, error code, line).
type Case<'a> = (Option<&'a str>, &'a str, String, u16, &'a str, Option<u64>);

#[tokio::test]
async fn bad_inputs_are_refused_with_line_numbers_and_store_nothing() {
    let fx = Fixture::new("max_body_bytes = 2048\n[quota]\ntest_per_day = 1\n");
    let server = fx.serve();
    let token = team(&server, "beta").await;
    let ok = line("dev-0001", &["move to the blue zone"]);
    let cases: Vec<Case> = vec![
        (
            Some(&token),
            "dev",
            format!("{ok}\n{{oops"),
            400,
            "not_json",
            Some(2),
        ),
        (
            Some(&token),
            "dev",
            format!("\n{ok}\n\"just a string\""),
            400,
            "not_an_object",
            Some(3),
        ),
        (
            Some(&token),
            "dev",
            r#"{"plan": []}"#.into(),
            400,
            "missing_id",
            Some(1),
        ),
        (
            Some(&token),
            "dev",
            line("dev-0404", &[]),
            400,
            "unknown_id",
            Some(1),
        ),
        (
            Some(&token),
            "dev",
            format!("{ok}\n{ok}"),
            400,
            "duplicate_id",
            Some(2),
        ),
        (
            Some(&token),
            "dev",
            line("test-0001", &[]),
            400,
            "wrong_split",
            Some(1),
        ),
        (
            Some(&token),
            "test",
            line("dev-0001", &[]),
            400,
            "wrong_split",
            Some(1),
        ),
        (
            Some(&token),
            "dev",
            r#"{"id": "dev-0001", "plan": "pick the cup"}"#.into(),
            400,
            "plan_not_a_list",
            Some(1),
        ),
        (
            Some(&token),
            "dev",
            r#"{"id": "dev-0001", "plan": [1]}"#.into(),
            400,
            "step_not_a_string",
            Some(1),
        ),
        (
            Some(&token),
            "dev",
            line("dev-0001", &[&"x".repeat(201)]),
            400,
            "step_too_long",
            Some(1),
        ),
        (Some(&token), "dev", "\n \n".into(), 400, "empty_file", None),
        (
            Some(&token),
            "dev",
            format!("{ok}\n").repeat(60),
            413,
            "body_too_large",
            Some(41),
        ),
        (None, "dev", ok.clone(), 401, "missing_token", None),
        (Some("kr_wrong"), "dev", ok.clone(), 401, "bad_token", None),
        (Some(&token), "train", ok.clone(), 400, "bad_request", None),
    ];
    for (tok, split, body, status, code, line_no) in cases {
        let (got, v) = submit(&server, tok, split, body).await;
        assert_eq!((got, v["code"].as_str().unwrap()), (status, code), "{v}");
        assert!(!v["error"].as_str().unwrap().is_empty());
        assert_eq!(v["line"].as_u64(), line_no, "{v}");
    }
    // Nothing was stored and no quota was used: the first accepted file is submission 1, and
    // the one test submission of the day is still available.
    let (status, v) = submit(&server, Some(&token), "dev", ok.clone()).await;
    assert_eq!((status, v["id"].as_i64()), (201, Some(1)), "{v}");
    let (status, v) = submit(&server, Some(&token), "test", line("test-0001", &[])).await;
    assert_eq!(status, 201, "{v}");
}

#[tokio::test]
async fn quota_answers_429_with_the_reset_time() {
    let fx = Fixture::new("[quota]\ntest_per_day = 2\ndev_per_day = 0\n");
    let server = fx.serve();
    let token = team(&server, "gamma").await;
    let body = line("test-0001", &["move to the red zone"]);
    for _ in 0..2 {
        assert_eq!(submit(&server, Some(&token), "test", body.clone()).await.0, 201);
    }
    let (status, v) = submit(&server, Some(&token), "test", body.clone()).await;
    assert_eq!(status, 429, "{v}");
    assert_eq!(v["code"], "quota_exceeded");
    let resets = v["resets_at"].as_str().unwrap();
    assert!(resets.ends_with("T00:00:00Z"), "{resets}");
    assert!(v["error"].as_str().unwrap().contains(resets));
    // A file refused for its content is still told what is wrong, and dev stays unlimited.
    assert_eq!(submit(&server, Some(&token), "test", "{").await.0, 400);
    for _ in 0..3 {
        assert_eq!(
            submit(&server, Some(&token), "dev", line("dev-0001", &[]))
                .await
                .0,
            201
        );
    }
    // Another team has its own quota.
    let other = team(&server, "delta").await;
    assert_eq!(submit(&server, Some(&other), "test", body).await.0, 201);
}

#[tokio::test]
async fn leaderboard_orders_by_em_then_time_and_hides_test_ground_truth() {
    let fx = Fixture::new("");
    let server = fx.serve();
    let (a, b, c) = (
        team(&server, "a-team").await,
        team(&server, "b-team").await,
        team(&server, "c-team").await,
    );
    let half = line(
        "test-0001",
        &[
            "move to the red zone",
            "pick the fork",
            "move to the blue zone",
            "place the fork",
        ],
    );
    let full = [
        half.clone(),
        line(
            "test-0002",
            &[
                "move to the green zone",
                "pick the bowl",
                "move to the red zone",
                "place the bowl",
            ],
        ),
    ]
    .join("\n");
    // b: 0.5 then 1.0 (best counts); c: 0.5 before a's 0.5 (earlier wins the tie).
    submit(&server, Some(&b), "test", half.clone()).await;
    submit(&server, Some(&c), "test", half.clone()).await;
    submit(&server, Some(&a), "test", half.clone()).await;
    submit(&server, Some(&b), "test", full).await;
    let (_, board) = get_json(&server, "/api/v1/leaderboard?track=planning&split=test", None).await;
    let order: Vec<(&str, f64)> = board["rows"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| (r["team"].as_str().unwrap(), r["scores"]["em"].as_f64().unwrap()))
        .collect();
    assert_eq!(order, vec![("b-team", 1.0), ("c-team", 0.5), ("a-team", 0.5)]);

    let csv = client()
        .get(server.url("/api/v1/leaderboard?split=test&format=csv"))
        .send()
        .await
        .unwrap()
        .text()
        .await
        .unwrap();
    assert!(
        csv.starts_with("rank,team,submission_id,em,submitted_at,em_low,em_high\n1,b-team,4,1.000000,"),
        "{csv}"
    );
    let page = client()
        .get(server.url("/"))
        .send()
        .await
        .unwrap()
        .text()
        .await
        .unwrap();
    assert!(page.contains("<td>c-team</td>"), "{page}");

    let test = client()
        .get(server.url("/api/v1/dataset/test"))
        .send()
        .await
        .unwrap()
        .text()
        .await
        .unwrap();
    assert_eq!(test.lines().count(), 2);
    for l in test.lines() {
        let v: Value = serde_json::from_str(l).unwrap();
        assert!(v.get("plan").is_none() && v.get("place_targets").is_none(), "{l}");
    }
    let dev = client()
        .get(server.url("/api/v1/dataset/dev"))
        .send()
        .await
        .unwrap()
        .text()
        .await
        .unwrap();
    assert!(
        dev.lines()
            .all(|l| serde_json::from_str::<Value>(l).unwrap()["plan"].is_array())
    );

    // Another team's submission is not visible; the organiser sees everything.
    assert_eq!(get_json(&server, "/api/v1/submissions/1", Some(&a)).await.0, 404);
    let (status, sub) = get_json(&server, "/api/v1/submissions/1", Some(ADMIN)).await;
    assert_eq!(status, 200);
    // Test split: aggregate feedback only, no row per instruction.
    let run = &sub["latest_run"];
    assert_eq!(run["instructions"], serde_json::json!([]), "{sub:#}");
    assert_eq!(run["instructions_total"], 2, "{sub:#}");
    assert!(!sub.to_string().contains("test-0001"), "{sub:#}");
    let (_, scenes) = get_json(&server, "/api/v1/scenes", None).await;
    assert_eq!(scenes[0]["id"], "kitchen_a");
    assert_eq!(get_json(&server, "/api/v1/scenes/kitchen_a", None).await.0, 200);
    assert_eq!(get_json(&server, "/api/v1/scenes/nowhere", None).await.0, 404);
    assert_eq!(get_json(&server, "/healthz", None).await.0, 200);
}
