//! The typed rows against a real SQLite file: JSON columns keep the text earlier builds wrote,
//! and read back as typed values.

use kitchen_r_core::dataset::Split;

use super::queue::{self, NewResult};
use super::runs::{self, NewPolicyRun};
use crate::episodes::{EndpointSpec, JobSpec, Mode, TaskOutcome};
use crate::states::{JobState, RunState, SubmissionKind};

fn spec() -> JobSpec {
    JobSpec {
        mode: Mode::Online,
        scene_id: "kitchen_a".into(),
        instruction_id: "dev-0001".into(),
        plan: vec!["pick the bowl".into(), "place the bowl on the table".into()],
        seed: 7,
        task_time_limit_s: 120.0,
        actions_executed_per_chunk: 8,
        teleport_on_failure: true,
        max_plan_steps: 0,
        privileged: false,
        privileged_observations: None,
        endpoint: EndpointSpec {
            url: "http://127.0.0.1:1".into(),
            bearer_token: String::new(),
            bearer_token_sealed: None,
            call_deadline_ms: 1,
            startup_deadline_ms: 1,
            episode_budget_ms: 1,
            max_successive_timeouts: 1,
            min_actions_executed_per_chunk: 0,
            quat_norm_tolerance: None,
            gripper_margin: None,
            key_map: None,
        },
        place_targets: vec![[0.5, -0.25, 0.9]],
        grasp: kitchen_r_core::GraspMode::Physical,
    }
}

/// A fresh database at `url` (its write pool) with team "a" (token hash "hash"), its id and keys.
async fn with_team(url: &str) -> (sqlx::SqlitePool, i64, super::NameKeys) {
    let pool = super::connect(url, super::PoolLimits::default())
        .await
        .unwrap()
        .write;
    let keys = super::NameKeys {
        skeleton: "a".into(),
        skeleton_folded: "a".into(),
    };
    let team = super::insert_team(&pool, "a", &keys, "hash", 1)
        .await
        .unwrap()
        .unwrap();
    (pool, team, keys)
}

#[tokio::test]
async fn json_columns_round_trip_as_typed_values_in_the_stored_text() {
    let dir = tempfile::tempdir().unwrap();
    let url = format!("sqlite://{}", dir.path().join("t.db").display());
    let (pool, team, keys) = with_team(&url).await;
    assert_eq!(
        super::insert_team(&pool, "a", &keys, "other", 1).await.unwrap(),
        None
    );
    let spec = spec();
    // A spec written before `place_targets` existed still reads.
    let mut legacy = serde_json::to_value(&spec).unwrap();
    legacy.as_object_mut().unwrap().remove("place_targets");
    // ... and one written before `grasp`: it ran the abstract grasp.
    legacy.as_object_mut().unwrap().remove("grasp");
    let jobs = [
        ("dev-0001".to_string(), serde_json::to_string(&spec).unwrap()),
        ("dev-0002".to_string(), legacy.to_string()),
    ];
    let new = NewPolicyRun {
        team,
        split: Split::Dev,
        body: "{}",
        scorer_version: "v",
        max_concurrency: 0,
        max_attempts: 3,
        grasp: kitchen_r_core::GraspMode::Physical,
        jobs: &jobs,
    };
    let (sub, run) = runs::insert_policy_submission(&pool, &new, 10).await.unwrap();

    let row = super::submission(&pool, sub).await.unwrap().unwrap();
    assert_eq!(
        (row.team.as_str(), row.kind, row.runs),
        ("a", SubmissionKind::Policy, 1)
    );
    let latest = super::latest_run(&pool, sub).await.unwrap().unwrap();
    assert_eq!(
        (latest.id, latest.state, latest.scores.em),
        (run, RunState::Active, None)
    );
    assert!(!latest.needs_resimulation);

    let claimed = queue::claim(&pool, "w", 20, 1000, 2, 0).await.unwrap();
    assert_eq!(claimed.len(), 2);
    assert_eq!(claimed[0].spec, spec);
    assert!(claimed[1].spec.place_targets.is_empty());
    assert_eq!(claimed[1].spec.grasp, kitchen_r_core::GraspMode::Abstract);
    let counts = runs::job_counts(&pool, run).await.unwrap();
    assert_eq!((counts.queued, counts.leased, counts.started), (0, 2, 2));

    let mut conn = pool.acquire().await.unwrap();
    let job = queue::job(&mut conn, claimed[0].id).await.unwrap().unwrap();
    assert_eq!((job.state, job.attempt, &job.spec), (JobState::Leased, 1, &spec));
    let tasks = vec![TaskOutcome {
        index: 0,
        step: "pick the bowl".into(),
        success: true,
        completion_time_s: 3.5,
        ..TaskOutcome::default()
    }];
    let result = NewResult {
        job: &job,
        mode: "online",
        tasks: &tasks,
        failure: None,
        wall_ms: 5,
        log_tail: "",
        worker_id: "w",
        path: None,
    };
    assert!(queue::insert_result(&mut conn, &result, 30).await.unwrap());
    let text: String = sqlx::query_scalar("SELECT tasks FROM episode_results")
        .fetch_one(&mut *conn)
        .await
        .unwrap();
    assert_eq!(text, serde_json::to_string(&tasks).unwrap());

    let episodes = queue::episodes(&mut conn, run).await.unwrap();
    assert_eq!(episodes.len(), 1);
    assert_eq!((&episodes[0].spec, &episodes[0].tasks), (&spec, &tasks));
    drop(conn); // the write pool has one connection
    let results = runs::results(&pool, run).await.unwrap();
    assert_eq!(
        (results[0].episode_key.as_str(), &results[0].tasks),
        ("dev-0001", &tasks)
    );
}

/// Databases from before compressed plan storage keep every plan file and result: the next
/// start converts them, and they read back the same.
#[tokio::test]
async fn rows_stored_before_compression_are_converted_at_start_and_read_the_same() {
    let dir = tempfile::tempdir().unwrap();
    let url = format!("sqlite://{}", dir.path().join("t.db").display());
    let (pool, team, _) = with_team(&url).await;
    let body = "{\"id\": \"dev-0001\", \"plan\": [\"pick(cup)\"]}\n".repeat(20);
    // Written as the server did before 20261122250000: text body, one row per instruction.
    let sub: i64 = sqlx::query_scalar(
        "INSERT INTO submissions (team_id, split, kind, body, created_at) VALUES (?, 'dev', 'plans', ?, 1) RETURNING id",
    )
    .bind(team)
    .bind(&body)
    .fetch_one(&pool)
    .await
    .unwrap();
    let run: i64 = sqlx::query_scalar(
        "INSERT INTO scoring_runs (submission_id, scorer_version, created_at, em) VALUES (?, 'v', 1, 0.5) RETURNING id",
    )
    .bind(sub)
    .fetch_one(&pool)
    .await
    .unwrap();
    sqlx::query(
        "INSERT INTO instruction_results (run_id, instruction_id, present, correct_steps, total_steps)
         VALUES (?1, 'dev-0002', 0, 0, 4), (?1, 'dev-0001', 1, 3, 4)",
    )
    .bind(run)
    .execute(&pool)
    .await
    .unwrap();
    pool.close().await;

    let db = super::connect(&url, super::PoolLimits::default()).await.unwrap();
    assert_eq!(super::submission_body(&db.read, sub).await.unwrap().body, body);
    let results = super::instruction_results(&db.read, run).await.unwrap();
    let got: Vec<(&str, bool, usize, usize)> = (results.iter())
        .map(|i| (i.id.as_str(), i.present, i.correct, i.total))
        .collect();
    assert_eq!(got, [("dev-0001", true, 3, 4), ("dev-0002", false, 0, 4)]);
    let left: i64 = sqlx::query_scalar("SELECT COUNT(*) FROM instruction_results")
        .fetch_one(&db.read)
        .await
        .unwrap();
    let text: String = sqlx::query_scalar("SELECT body FROM submissions WHERE id = ?")
        .bind(sub)
        .fetch_one(&db.read)
        .await
        .unwrap();
    assert_eq!((left, text.as_str()), (0, ""));
}

/// An in-memory database has one connection; reads must see what was written through it.
#[tokio::test]
async fn an_in_memory_database_reads_what_it_wrote() {
    let db = super::connect("sqlite::memory:", super::PoolLimits::default())
        .await
        .unwrap();
    let keys = super::NameKeys {
        skeleton: "a".into(),
        skeleton_folded: "a".into(),
    };
    super::insert_team(&db.write, "a", &keys, "hash", 1)
        .await
        .unwrap()
        .unwrap();
    let team = super::team_by_token_hash(&db.read, "hash").await.unwrap();
    assert_eq!(team.map(|t| t.name).as_deref(), Some("a"));
}
