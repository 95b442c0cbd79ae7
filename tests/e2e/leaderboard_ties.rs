//! Intervals and ties on the boards (docs/reference/leaderboard.md), end to end: the real
//! `kitchen-r serve` on the committed dataset (163 dev instructions), plan files planted so that
//! two pairs of entries have overlapping EM intervals and the pairs do not; every rendering
//! shows the intervals, the board says how ties are decided, and each row carries its results
//! card. The organiser's switch (`[leaderboard] interval_ties = false`) gives every entry its
//! own rank again.

use crate::support;

use kitchen_r_proto::submission::v1 as pb;
use serde_json::Value;
use support::*;

/// The committed dev split's lines, as a plan file would hold them.
fn dev_lines() -> Vec<String> {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/dataset/dev.jsonl");
    (std::fs::read_to_string(path).unwrap().lines())
        .map(|l| {
            let v: Value = serde_json::from_str(l).unwrap();
            serde_json::json!({"id": v["id"], "plan": v["plan"]}).to_string()
        })
        .collect()
}

fn ranks(board: &Value) -> Vec<(String, u64)> {
    (board["rows"].as_array().unwrap().iter())
        .map(|r| {
            (
                r["team"].as_str().unwrap().to_string(),
                r["rank"].as_u64().unwrap(),
            )
        })
        .collect()
}

fn pairs(names: [(&str, u64); 4]) -> Vec<(String, u64)> {
    names.iter().map(|(t, r)| (t.to_string(), *r)).collect()
}

#[tokio::test]
async fn overlapping_intervals_share_a_rank_and_every_rendering_shows_them() {
    let fx = ControlFixture::new("");
    let server = fx.serve(0);
    let lines = dev_lines();
    assert_eq!(lines.len(), 163);
    // EM 1 ([0.977, 1]) and 162/163 overlap; 82/163 ([0.43, 0.58]) and 80/163 overlap; the two
    // pairs do not.
    for (team_name, kept) in [
        ("full", 163),
        ("all-but-one", 162),
        ("half", 82),
        ("under-half", 80),
    ] {
        let token = team(&server, team_name).await;
        let (status, body) = submit(&server, Some(&token), "dev", lines[..kept].join("\n")).await;
        assert_eq!(status, 201, "{body}");
    }

    let (status, board) = get_json(&server, "/api/v1/leaderboard?track=planning&split=dev", None).await;
    assert_eq!(status, 200, "{board}");
    let expected = pairs([("full", 1), ("all-but-one", 1), ("half", 3), ("under-half", 3)]);
    assert_eq!(ranks(&board), expected, "{board:#}");
    assert_eq!(board["interval_ties"], true, "{board:#}");
    assert!(
        board["ties"].as_str().unwrap().contains("1, 2, 2, 4"),
        "{board:#}"
    );
    let first = &board["rows"][0];
    let em = first["intervals"]["em"].as_array().unwrap();
    let (low, high) = (em[0].as_f64().unwrap(), em[1].as_f64().unwrap());
    assert!(low > 0.97 && low < 0.98 && high == 1.0, "{first}");
    let card = &first["card"];
    assert_eq!(card["episodes"], 163, "{card}");
    assert_ne!(card["dataset"], "unknown", "{card}");
    assert_eq!(card["binary_version"], env!("CARGO_PKG_VERSION"), "{card}");

    grpc_board_matches(&server, &board).await;

    let csv = get_text(&server, "/api/v1/leaderboard?track=planning&split=dev&format=csv").await;
    let mut csv_lines = csv.lines();
    assert_eq!(
        csv_lines.next(),
        Some("rank,team,submission_id,em,submitted_at,em_low,em_high"),
        "{csv}"
    );
    let row = csv_lines.nth(1).unwrap();
    assert!(row.starts_with("1,all-but-one,"), "{csv}");
    let cells: Vec<f64> = (row.split(',').enumerate())
        .filter(|(i, _)| [3, 5, 6].contains(i))
        .map(|(_, c)| c.parse().unwrap())
        .collect();
    assert!(cells[1] < cells[0] && cells[0] < cells[2], "{csv}");

    let page = get_text(&server, "/?split=dev").await;
    assert!(page.contains("<b>Ties: </b>Ranks are shared"), "{page}");
    assert!(page.contains("<small class=\"ci\">[0.97"), "{page}");
    assert!(page.contains("<summary>card</summary>"), "{page}");
    let html = get_text(
        &server,
        "/api/v1/leaderboard?track=planning&split=dev&format=html",
    )
    .await;
    assert!(html.contains("<small class=\"ci\">["), "{html}");
    drop(server);

    // The organiser switches ties off: one rank each, and the boards say so.
    let config = fx.dir.path().join("server.toml");
    let mut toml = std::fs::read_to_string(&config).unwrap();
    toml.push_str("\n[leaderboard]\ninterval_ties = false\n");
    std::fs::write(&config, toml).unwrap();
    let server = fx.serve(0);
    let (_, board) = get_json(&server, "/api/v1/leaderboard?track=planning&split=dev", None).await;
    let expected = pairs([("full", 1), ("all-but-one", 2), ("half", 3), ("under-half", 4)]);
    assert_eq!(ranks(&board), expected, "{board:#}");
    assert_eq!(board["interval_ties"], false, "{board:#}");
    let page = get_text(&server, "/?split=dev").await;
    assert!(page.contains("a rank of its own"), "{page}");
}

/// The gRPC twin of the board (`GetLeaderboard`) carries what the HTTP board carries: the same
/// shared ranks, intervals, ties sentence and results cards.
async fn grpc_board_matches(server: &Server, http: &Value) {
    let mut client = pb::submissions_client::SubmissionsClient::connect(server.grpc.clone())
        .await
        .unwrap();
    let board = (client.get_leaderboard(pb::GetLeaderboardRequest {
        track: "planning".into(),
        split: "dev".into(),
        ..Default::default()
    }))
    .await
    .unwrap()
    .into_inner();
    assert_eq!(board.interval_ties, http["interval_ties"].as_bool().unwrap());
    assert_eq!(board.ties, http["ties"].as_str().unwrap());
    let rows = http["rows"].as_array().unwrap();
    assert_eq!(board.rows.len(), rows.len());
    for (g, h) in board.rows.iter().zip(rows) {
        assert_eq!(g.team, h["team"].as_str().unwrap());
        assert_eq!(u64::from(g.rank), h["rank"].as_u64().unwrap(), "{h}");
        let em = g.intervals.as_ref().and_then(|i| i.em).unwrap();
        let want = h["intervals"]["em"].as_array().unwrap();
        assert_eq!(
            (em.low, em.high),
            (want[0].as_f64().unwrap(), want[1].as_f64().unwrap()),
            "{h}"
        );
        let card = g.card.as_ref().unwrap();
        assert_eq!(card.run_id, h["card"]["run_id"].as_i64().unwrap(), "{h}");
        assert_eq!(card.episodes, h["card"]["episodes"].as_u64().unwrap(), "{h}");
        assert_eq!(card.dataset, h["card"]["dataset"].as_str().unwrap(), "{h}");
    }
}
