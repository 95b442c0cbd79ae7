use kitchen_r_core::GraspMode;
use kitchen_r_core::observations::ObservationTrack;

use super::intervals::{Interval, Intervals};
use super::render::csv;
use super::*;
use crate::testutil::{FakeProbe, fixture};

pub(crate) fn board(team: &str) -> Leaderboard {
    Leaderboard {
        track: Track::Planning,
        observations: None,
        grasp_mode: None,
        split: Split::Test,
        interval_ties: true,
        ties: TIES_BY_INTERVAL,
        rows: vec![Row {
            rank: Some(1),
            team: team.into(),
            submission_id: 7,
            scores: Scores::em(Some(0.5)),
            submitted_at: "2026-01-01T00:00:00Z".into(),
            state: None,
            baseline: false,
            observations: None,
            grasp_mode: None,
            intervals: Intervals {
                em: Some(Interval { low: 0.2, high: 0.8 }),
                ..Intervals::default()
            },
            card: None,
        }],
    }
}

#[test]
fn csv_quotes_and_formats() {
    assert_eq!(
        csv(&board("a,b")),
        "rank,team,submission_id,em,submitted_at,em_low,em_high\n\
         1,\"a,b\",7,0.500000,2026-01-01T00:00:00Z,0.200000,0.800000\n"
    );
}

/// Issue 23: a team named `-1-1` was a formula in a spreadsheet opening the CSV export.
#[test]
fn csv_neutralises_cells_a_spreadsheet_would_evaluate() {
    for (team, cell) in [
        ("-1-1", "\"'-1-1\""),
        ("+1", "\"'+1\""),
        ("@SUM(A1)", "\"'@SUM(A1)\""),
        ("\tx", "\"'\tx\""),
        ("\rx", "\"'\rx\""),
        (
            "=HYPERLINK(\"http://evil.example\",\"x\")",
            "\"'=HYPERLINK(\"\"http://evil.example\"\",\"\"x\"\")\"",
        ),
        ("team-1", "team-1"),
    ] {
        let csv = csv(&board(team));
        let row = csv.split_once('\n').unwrap().1;
        assert_eq!(
            row,
            format!("1,{cell},7,0.500000,2026-01-01T00:00:00Z,0.200000,0.800000\n"),
            "{team:?}"
        );
    }
    assert_eq!(super::render::text_cell(""), "");
}

/// A control board of `observations` with one finished row.
pub(crate) fn control_board(observations: ObservationTrack) -> Leaderboard {
    let mut b = board("team");
    b.track = Track::Control;
    b.observations = Some(observations);
    b.rows[0].scores = Scores {
        em: None,
        sr: Some(0.25),
        mse: Some(0.5),
        m: None,
        p: None,
    };
    b.rows[0].state = Some("finished".into());
    b.rows[0].observations = Some(observations);
    b.grasp_mode = Some(GraspMode::Abstract);
    b.rows[0].grasp_mode = Some(GraspMode::Abstract);
    b.rows[0].intervals = Intervals {
        sr: Some(Interval { low: 0.1, high: 0.5 }),
        ..Intervals::default()
    };
    b
}

/// Issue 25: every rendering names the board a policy row is ranked on.
#[test]
fn policy_boards_name_their_observation_track_in_csv_and_html() {
    let privileged = control_board(ObservationTrack::Privileged);
    assert_eq!(
        csv(&privileged),
        "rank,team,submission_id,sr,mse,state,baseline,submitted_at,observations,grasp_mode,\
         sr_low,sr_high,mse_low,mse_high,\
         sr_navigation,sr_navigation_low,sr_navigation_high,\
         sr_manipulation,sr_manipulation_low,sr_manipulation_high,\
         sr_pick,sr_pick_low,sr_pick_high,sr_place,sr_place_low,sr_place_high\n\
         1,team,7,0.250000,0.500000,finished,false,2026-01-01T00:00:00Z,privileged,abstract,\
         0.100000,0.500000,,,,,,,,,,,,,,\n"
    );
    assert!(csv(&control_board(ObservationTrack::Standard)).contains(",standard,abstract,"));
    // The page's headings and links: `http/leaderboard/tests.rs`.
    // Planning keeps its CSV exactly.
    assert!(!csv(&board("a")).contains("observations"));
    assert!(!csv(&board("a")).contains("grasp"));
}

/// Issue 27: every policy rendering names the grasp mode; a board of another mode than the
/// contest's is labelled as such, row by row, and its links ask for its mode.
#[test]
fn policy_boards_name_their_grasp_mode_and_another_mode_than_the_contests_is_labelled() {
    let mut physical = control_board(ObservationTrack::Standard);
    physical.grasp_mode = Some(GraspMode::Physical);
    physical.rows[0].grasp_mode = Some(GraspMode::Physical);
    assert!(
        csv(&physical).contains(",standard,physical,"),
        "{}",
        csv(&physical)
    );
    // The page's labels for another mode than the contest's: `http/leaderboard/tests.rs`.
}

#[test]
fn tracks_parse() {
    assert_eq!("".parse::<Track>().unwrap(), Track::Planning);
    assert_eq!("control".parse::<Track>().unwrap(), Track::Control);
    assert_eq!("integrated".parse::<Track>().unwrap(), Track::Integrated);
    assert!("nope".parse::<Track>().is_err());
}

/// The dev split's standard-observation board of `track` as CSV bytes.
async fn dev_csv(f: &crate::testutil::Fixture, track: Track) -> bytes::Bytes {
    (f.state.leaderboard_rendered(
        track,
        ObservationTrack::Standard,
        None,
        Split::Dev,
        Format::Csv,
        crate::http::leaderboard_page,
    ))
    .await
    .unwrap()
}

/// A policy submission with a finished (or active) run carrying exactly these scores.
#[allow(clippy::too_many_arguments)]
async fn policy(
    pool: &sqlx::SqlitePool,
    team: i64,
    at: i64,
    reference: bool,
    plans: bool,
    state: &str,
    sr: Option<f64>,
    mse: Option<f64>,
    m: Option<f64>,
    p: Option<f64>,
) -> i64 {
    let body = serde_json::json!({"reference": reference, "plans": if plans { Some(1) } else { None }});
    let sub: i64 = sqlx::query_scalar(
        "INSERT INTO submissions (team_id, split, kind, body, created_at) VALUES (?, 'dev', 'policy', ?, ?) RETURNING id",
    )
    .bind(team)
    .bind(body.to_string())
    .bind(at)
    .fetch_one(pool)
    .await
    .unwrap();
    sqlx::query(
        "INSERT INTO scoring_runs (submission_id, scorer_version, created_at, state, sr, mse, m, p)
         VALUES (?, 'test', ?, ?, ?, ?, ?, ?)",
    )
    .bind(sub)
    .bind(at)
    .bind(state)
    .bind(sr)
    .bind(mse)
    .bind(m)
    .bind(p)
    .execute(pool)
    .await
    .unwrap();
    sub
}

#[tokio::test]
async fn control_and_integrated_order_with_baselines_and_infinite_p() {
    let f = fixture(FakeProbe::ok(1), |_| {}).await;
    for name in ["a", "b", "c", "d"] {
        f.team(name).await;
    }
    let base = crate::store::runs::baseline_team(f.state.pool(), 0)
        .await
        .unwrap()
        .id;
    let pool = f.state.pool();
    let fin = "finished";
    // Team a: SR 0.5 then 0.8 (best counts). b: 0.8 with lower MSE than a's → b first.
    policy(
        pool,
        1,
        10,
        false,
        true,
        fin,
        Some(0.5),
        Some(0.1),
        Some(1.0),
        Some(2.0),
    )
    .await;
    let a_best = policy(
        pool,
        1,
        20,
        false,
        true,
        fin,
        Some(0.8),
        Some(0.3),
        Some(1.5),
        Some(f64::INFINITY),
    )
    .await;
    let b = policy(
        pool,
        2,
        30,
        false,
        true,
        fin,
        Some(0.8),
        Some(0.2),
        Some(1.5),
        Some(3.0),
    )
    .await;
    // c: still evaluating → last, never first. d: no plans → not on the integrated track.
    let c = policy(pool, 3, 5, false, true, "active", None, None, None, None).await;
    let d = policy(pool, 4, 40, false, false, fin, Some(0.1), None, None, None).await;
    // Two baseline runs: both shown, ranked among teams by score, without a rank number.
    let b1 = policy(
        pool,
        base,
        1,
        true,
        true,
        fin,
        Some(1.0),
        Some(0.0),
        Some(2.0),
        Some(1.0),
    )
    .await;
    let b2 = policy(
        pool,
        base,
        2,
        true,
        true,
        fin,
        Some(0.0),
        Some(9.0),
        Some(0.0),
        Some(f64::INFINITY),
    )
    .await;
    // The rows above were written by hand, past the store's writers: rebuild the maintained
    // entries as the server does at start-up.
    crate::store::board::rebuild(pool).await.unwrap();
    f.state.leaderboard_cache().invalidate();

    let control = f.state.leaderboard(Track::Control, Split::Dev).await.unwrap();
    let order: Vec<(i64, Option<usize>, bool)> = control
        .rows
        .iter()
        .map(|r| (r.submission_id, r.rank, r.baseline))
        .collect();
    // These runs were written without episodes: each SR's interval is [0, 1], so every finished
    // entry shares rank 1 (docs/reference/leaderboard.md#ties); the evaluating run c never ties.
    assert_eq!(
        order,
        vec![
            (b1, None, true),
            (b, Some(1), false),
            (a_best, Some(1), false),
            (d, Some(1), false),
            (b2, None, true),
            (c, Some(4), false),
        ]
    );
    let strict = ranked(control.rows.clone(), Track::Control, false);
    let ranks: Vec<Option<usize>> = strict.iter().map(|r| r.rank).collect();
    assert_eq!(ranks, [None, Some(1), Some(2), Some(3), None, Some(4)]);
    let integrated = f.state.leaderboard(Track::Integrated, Split::Dev).await.unwrap();
    let order: Vec<i64> = integrated.rows.iter().map(|r| r.submission_id).collect();
    // M ties 1.5: b's P 3.0 beats a's +inf.
    assert_eq!(order, vec![b1, b, a_best, b2, c]);

    let json = String::from_utf8(
        f.state
            .leaderboard_rendered(
                Track::Integrated,
                ObservationTrack::Standard,
                None,
                Split::Dev,
                Format::Json,
                crate::http::leaderboard_page,
            )
            .await
            .unwrap()
            .to_vec(),
    )
    .unwrap();
    assert!(
        json.contains(r#""p":"inf""#) && json.contains(r#""baseline":true"#),
        "{json}"
    );
    let text = String::from_utf8(dev_csv(&f, Track::Integrated).await.to_vec()).unwrap();
    let mut lines = text.lines();
    assert!((lines.next().unwrap()).starts_with(
        "rank,team,submission_id,m,p,sr,mse,state,baseline,submitted_at,observations,grasp_mode,"
    ));
    let a_line = lines.nth(2).unwrap();
    assert!(
        a_line.starts_with(&format!(
            "1,a,{a_best},1.500000,inf,0.800000,0.300000,finished,false,"
        )),
        "{text}"
    );
    let html = String::from_utf8(
        f.state
            .leaderboard_page(Split::Dev, crate::http::leaderboard_page)
            .await
            .unwrap()
            .to_vec(),
    )
    .unwrap();
    for needle in [
        "Planning track",
        "Control track",
        "Integrated track",
        "<td>a</td>",
        "(baseline)",
        ">inf<",
    ] {
        assert!(html.contains(needle), "{needle}");
    }
}

#[tokio::test]
async fn the_cache_is_dropped_when_a_run_finishes() {
    let f = fixture(FakeProbe::ok(8), |c| {
        c.control.dev_episodes = 1;
        c.control.offline_mse = false;
    })
    .await;
    let token = f.team("alpha").await;
    f.state
        .register_policy(&f.caller(&token).await, f.request(Split::Dev))
        .await
        .unwrap();
    let before = dev_csv(&f, Track::Control).await;
    assert!(
        String::from_utf8_lossy(&before).contains(",active,"),
        "{before:?}"
    );
    let job = f.lease("w", 1).await.remove(0);
    f.state
        .report_result(f.worker().await, f.report("w", &job, |_| true, 0.0))
        .await
        .unwrap();
    let after = dev_csv(&f, Track::Control).await;
    assert!(
        String::from_utf8_lossy(&after).contains("1,alpha,1,1.000000,,finished,false,"),
        "{after:?}"
    );
}

/// Issue: a policy that refused its offline (MSE) episodes at the handshake got no MSE and an
/// integrated P of 1/EM alone, ranking above an honest policy with the same M. Refusing now
/// costs the failure penalty, so it ranks below on both boards.
#[tokio::test]
async fn a_policy_dodging_its_mse_episodes_ranks_below_an_honest_one() {
    let f = fixture(FakeProbe::ok(8), |c| {
        c.control.dev_episodes = 2;
        c.quota.concurrent_runs = 0;
    })
    .await;
    let gt = f.state.content().ground_truth(Split::Dev)[..2].to_vec();
    let plans: String = (gt.iter())
        .map(|i| serde_json::json!({"id": i.id, "plan": i.plan}).to_string() + "\n")
        .collect();
    let mut runs = Vec::new();
    for name in ["honest", "dodger"] {
        let token = f.team(name).await;
        let sub = f
            .state
            .submit_plans(&f.team_of(&token).await, Split::Dev, plans.as_bytes())
            .await
            .unwrap();
        let mut req = f.request(Split::Dev);
        req.plans = Some(sub.id);
        let reg = f
            .state
            .register_policy(&f.caller(&token).await, req)
            .await
            .unwrap();
        runs.push((name, reg.run_id));
    }
    loop {
        let jobs = f.lease("w", 16).await;
        if jobs.is_empty() {
            break;
        }
        for job in jobs {
            let dodger = runs.iter().any(|(n, r)| *n == "dodger" && *r == job.run_id);
            let mut report = f.report("w", &job, |_| true, 3.0);
            if dodger && job.spec.mode == crate::episodes::Mode::Offline {
                for t in &mut report.tasks {
                    (t.mse, t.mse_samples) = (0.0, 0);
                    t.failure_reason = "policy unreachable: GetSpec: UNAVAILABLE".into();
                }
            }
            f.state.report_result(f.worker().await, report).await.unwrap();
        }
    }
    for track in [Track::Control, Track::Integrated] {
        let board = f.state.leaderboard(track, Split::Dev).await.unwrap();
        let order: Vec<&str> = board.rows.iter().map(|r| r.team.as_str()).collect();
        assert_eq!(order, vec!["honest", "dodger"], "{track:?}: {:?}", board.rows);
        let dodger = &board.rows[1].scores;
        assert_eq!(dodger.mse, Some(kitchen_r_core::metrics::FAILED_PREDICTION_MSE));
    }
}

/// The boards are maintained by each write (docs/measured/load-benchmark.md: a read after a write
/// must not recompute from every submission). After plan uploads on both splits, a test policy run
/// that makes later test plans unranked, finished and active runs and a rescore, every board read
/// equals what a rebuild from all submissions gives.
#[tokio::test]
async fn maintained_boards_equal_a_rebuild_after_every_kind_of_write() {
    let f = fixture(FakeProbe::ok(8), |c| {
        c.control.dev_episodes = 1;
        c.control.offline_mse = false;
        c.quota.concurrent_runs = 0;
        c.quota.dev_per_day = 0;
        c.quota.test_per_day = 0;
    })
    .await;
    let file = |split: Split, keep: usize| -> String {
        (f.state.content().ground_truth(split).iter().take(6).enumerate())
            .map(|(n, i)| {
                let plan = if n < keep {
                    i.plan.clone()
                } else {
                    vec!["pick(x)".into()]
                };
                serde_json::json!({"id": i.id, "plan": plan}).to_string() + "\n"
            })
            .collect()
    };
    let boards = async || {
        let mut all = Vec::new();
        for split in [Split::Dev, Split::Test] {
            for track in Track::ALL {
                let rows = f.state.leaderboard(track, split).await.unwrap().rows;
                all.push(serde_json::to_string(&rows).unwrap());
            }
        }
        all
    };
    let check = async |what: &str| {
        let maintained = boards().await;
        crate::store::board::rebuild(f.state.pool()).await.unwrap();
        assert_eq!(maintained, boards().await, "after {what}");
    };
    let mut tokens = Vec::new();
    for (n, name) in ["alpha", "beta", "gamma"].into_iter().enumerate() {
        let token = f.team(name).await;
        let team = f.team_of(&token).await;
        for keep in [n, 6 - n, 3] {
            for split in [Split::Dev, Split::Test] {
                let body = file(split, keep);
                f.state.submit_plans(&team, split, body.as_bytes()).await.unwrap();
            }
        }
        tokens.push(token);
    }
    check("plan uploads").await;
    let dev = (f
        .state
        .register_policy(&f.caller(&tokens[1]).await, f.request(Split::Dev)))
    .await
    .unwrap();
    check("an active dev run").await;
    (f.state
        .register_policy(&f.caller(&tokens[0]).await, f.request(Split::Test)))
    .await
    .unwrap();
    let late = file(Split::Test, 6);
    let late_id = (f
        .state
        .submit_plans(&f.team_of(&tokens[0]).await, Split::Test, late.as_bytes()))
    .await
    .unwrap()
    .id;
    check("a test policy run and a later test plan file").await;
    for job in f.lease("w", 64).await {
        if job.run_id == dev.run_id {
            let report = f.report("w", &job, |j| j % 2 == 0, 0.0);
            f.state.report_result(f.worker().await, report).await.unwrap();
        }
    }
    check("finished runs").await;
    let control = f.state.leaderboard(Track::Control, Split::Dev).await.unwrap();
    assert_eq!(control.rows[0].state.as_deref(), Some("finished"));
    let planning = f.state.leaderboard(Track::Planning, Split::Test).await.unwrap();
    assert_eq!(planning.rows.len(), 3);
    assert!(planning.rows.iter().all(|r| r.submission_id < late_id));
    f.state.rescore_all(f.admin().await).await.unwrap();
    check("a rescore").await;
}

/// Issue 27: a contest run in the physical grasp mode sends it with every job, ranks its runs on
/// the physical board (the default one), and ranks a run of the abstract mode (from before the
/// organiser changed the setting) apart, on a board the page labels; planning is unaffected.
#[tokio::test]
async fn runs_are_ranked_with_their_own_grasp_mode_and_the_contests_is_the_default_board() {
    let f = fixture(FakeProbe::ok(1), |c| {
        c.control.dev_episodes = 1;
        c.control.offline_mse = false;
        c.control.grasp = GraspMode::Physical;
    })
    .await;
    let token = f.team("alpha").await;
    let team = f.team_of(&token).await;
    let gt = f.state.content().ground_truth(Split::Dev)[0].clone();
    let plan = serde_json::json!({"id": gt.id, "plan": gt.plan}).to_string() + "\n";
    f.state
        .submit_plans(&team, Split::Dev, plan.as_bytes())
        .await
        .unwrap();
    let run = (f
        .state
        .register_policy(&f.caller(&token).await, f.request(Split::Dev)))
    .await
    .unwrap();
    let job = f.lease("w", 1).await.remove(0);
    assert_eq!(job.spec.grasp, GraspMode::Physical);
    assert_eq!(
        job.spec.episode_proto("ep").grasp_mode,
        kitchen_r_proto::worker::v1::GraspMode::Physical as i32
    );
    f.state
        .report_result(f.worker().await, f.report("w", &job, |_| true, 0.0))
        .await
        .unwrap();
    // A rescore keeps the run's mode.
    f.state.rescore_all(f.admin().await).await.unwrap();
    // A run of the abstract mode, from before the organiser chose the physical one (written by
    // hand, so the maintained boards are rebuilt).
    let old = policy(
        f.state.pool(),
        team.id,
        1,
        false,
        false,
        "finished",
        Some(0.5),
        None,
        None,
        None,
    )
    .await;
    crate::store::board::rebuild(f.state.pool()).await.unwrap();

    let contest = f.state.leaderboard(Track::Control, Split::Dev).await.unwrap();
    assert_eq!(contest.grasp_mode, Some(GraspMode::Physical));
    let ids: Vec<(i64, Option<GraspMode>)> = contest
        .rows
        .iter()
        .map(|r| (r.submission_id, r.grasp_mode))
        .collect();
    assert_eq!(ids, [(run.id, Some(GraspMode::Physical))]);
    let earlier = (f.state)
        .board(
            Track::Control,
            ObservationTrack::Standard,
            Some(GraspMode::Abstract),
            Split::Dev,
        )
        .await
        .unwrap();
    assert_eq!(earlier.rows[0].submission_id, old);
    assert_eq!(earlier.rows[0].grasp_mode, Some(GraspMode::Abstract));
    // Planning has no grasp mode: its board is the same whatever the contest's mode.
    let planning = f.state.leaderboard(Track::Planning, Split::Dev).await.unwrap();
    assert_eq!((planning.rows.len(), planning.grasp_mode), (1, None));
    assert!(
        (f.state)
            .board(
                Track::Planning,
                ObservationTrack::Standard,
                Some(GraspMode::Physical),
                Split::Dev
            )
            .await
            .is_err()
    );
    let view = f
        .state
        .get_submission(&f.caller(&token).await, run.id)
        .await
        .unwrap();
    let evaluation = view.latest_run.unwrap().evaluation.unwrap();
    assert_eq!(evaluation.grasp_mode, GraspMode::Physical);

    let page = String::from_utf8(
        f.state
            .leaderboard_page(Split::Dev, crate::http::leaderboard_page)
            .await
            .unwrap()
            .to_vec(),
    )
    .unwrap();
    assert!(
        page.contains("Grasp mode of this contest: <b>physical</b>"),
        "{page}"
    );
    assert!(
        page.contains("<h2 id=\"control\">Control track — standard observations — physical grasp</h2>"),
        "{page}"
    );
    assert!(page.contains("<h2 id=\"control-abstract\">"), "{page}");
    assert!(
        page.contains(&format!(">{old}</a> (abstract grasp)</td>")),
        "{page}"
    );
    let csv = String::from_utf8(dev_csv(&f, Track::Control).await.to_vec()).unwrap();
    assert!(
        csv.lines().nth(1).unwrap().contains(",standard,physical,"),
        "{csv}"
    );
}

#[tokio::test]
async fn an_organiser_reference_plan_file_is_a_baseline_row_without_quota() {
    let f = fixture(FakeProbe::ok(8), |c| c.quota.dev_per_day = 1).await;
    let gt = f.state.content().ground_truth(Split::Dev).to_vec();
    let perfect: String = (gt.iter())
        .map(|i| serde_json::json!({"id": i.id, "plan": i.plan}).to_string() + "\n")
        .collect();
    let half: String = (gt.iter().take(gt.len() / 2))
        .map(|i| serde_json::json!({"id": i.id, "plan": i.plan}).to_string() + "\n")
        .collect();
    let token = f.team("alpha").await;
    let alpha = f.team_of(&token).await;
    let team = f
        .state
        .submit_plans(&alpha, Split::Dev, half.as_bytes())
        .await
        .unwrap();
    // A team cannot file a reference row.
    let refused = f
        .state
        .submit_reference_plans(&f.caller(&token).await, Split::Dev, perfect.as_bytes())
        .await;
    assert!(refused.is_err(), "a team token filed a reference plan file");
    // The organiser can, twice, past the daily quota of 1.
    let admin = f.caller(crate::testutil::ADMIN).await;
    for _ in 0..2 {
        f.state
            .submit_reference_plans(&admin, Split::Dev, perfect.as_bytes())
            .await
            .unwrap();
    }
    let board = f.state.leaderboard(Track::Planning, Split::Dev).await.unwrap();
    let rows: Vec<(String, Option<usize>, bool)> = (board.rows.iter())
        .map(|r| (r.team.clone(), r.rank, r.baseline))
        .collect();
    assert_eq!(
        rows,
        vec![
            ("(baseline)".to_string(), None, true),
            ("alpha".to_string(), Some(1), false)
        ],
        "team {} ranks first among teams; the baseline is marked and unranked",
        team.id
    );
}
