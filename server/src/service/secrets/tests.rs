use kitchen_r_core::dataset::Split;

use crate::testutil::{FakeProbe, Fixture, fixture};

const OLD: &str = "old-plain-token-77";

/// A dev run of one instruction whose endpoint has a token; the submission id.
async fn registered(f: &Fixture, token: &str) -> i64 {
    let team = f.team("alpha").await;
    let mut req = f.request(Split::Dev);
    req.token = Some(token.into());
    (f.state)
        .register_policy(&f.caller(&team).await, req)
        .await
        .unwrap()
        .id
}

/// Every raw `submissions.body` and `jobs.spec`.
async fn raw_rows(f: &Fixture) -> Vec<String> {
    let pool = f.state.pool();
    let mut rows: Vec<String> = sqlx::query_scalar("SELECT body FROM submissions")
        .fetch_all(pool)
        .await
        .unwrap();
    rows.extend(
        sqlx::query_scalar::<_, String>("SELECT spec FROM jobs")
            .fetch_all(pool)
            .await
            .unwrap(),
    );
    rows
}

/// Rewrite the stored rows the way servers before 20261126000200 wrote them: the token in
/// plain text in the body and in every job's spec, and the sealing step still to do.
async fn make_old_format(f: &Fixture) {
    let pool = f.state.pool();
    for sql in [
        "UPDATE submissions SET body = json_set(json_remove(body, '$.token_sealed'), '$.token', ?)",
        "UPDATE jobs SET spec = json_set(json_remove(spec, '$.endpoint.bearer_token_sealed'), '$.endpoint.bearer_token', ?)",
    ] {
        sqlx::query(sql).bind(OLD).execute(pool).await.unwrap();
    }
    sqlx::query("INSERT INTO pending_token_sealing (id) VALUES (1)")
        .execute(pool)
        .await
        .unwrap();
}

#[tokio::test]
async fn plain_tokens_stored_before_are_sealed_at_start_and_still_reach_the_worker() {
    let f = fixture(FakeProbe::ok(2), |c| c.control.dev_episodes = 1).await;
    let id = registered(&f, "new-token").await;
    make_old_format(&f).await;
    assert!(raw_rows(&f).await.iter().all(|r| r.contains(OLD)));

    // A restart seals them; nothing else changes.
    let state = f.reopen(FakeProbe::ok(2)).await;
    let rows = raw_rows(&f).await;
    assert_eq!(rows.len(), 3);
    for r in &rows {
        assert!(!r.contains(OLD) && r.contains("kr1."), "{r}");
    }
    let again = f.reopen(FakeProbe::ok(2)).await;
    assert_eq!(raw_rows(&f).await, rows, "the step is idempotent");
    drop(again);
    let body = crate::store::submission_body(state.pool(), id)
        .await
        .unwrap()
        .body;
    let info = crate::service::policies::policy_info(&body).unwrap();
    assert!(info.has_token && info.endpoint == "http://127.0.0.1:50099");
    let jobs = state.lease(f.worker().await, "w1", 8, 0).await.unwrap();
    assert_eq!(jobs.len(), 2);
    assert!(jobs.iter().all(|j| j.spec.endpoint.bearer_token == OLD));
}

#[tokio::test]
async fn a_wrong_key_stops_the_server_and_a_damaged_token_is_never_sent_empty() {
    let f = fixture(FakeProbe::ok(2), |c| c.control.dev_episodes = 1).await;
    registered(&f, "the-token").await;
    let config = f.state.config().clone();
    let key_file = config.secrets.key_path(&config.db).unwrap();
    assert!(key_file.is_file());
    let original = std::fs::read(&key_file).unwrap();
    std::fs::remove_file(&key_file).unwrap();
    crate::secrets::SecretKey::load_or_create(&key_file).unwrap();
    // Metrics off: this test process must not install the global recorder.
    let no_metrics = crate::Config {
        metrics: false,
        ..config.clone()
    };
    let e = crate::build(no_metrics).await.unwrap_err();
    let e = format!("{e:#}");
    assert!(e.contains("secret key") && e.contains("key_file"), "{e}");
    std::fs::write(&key_file, original).unwrap();

    // A damaged sealed value: the job is not handed out, its attempt fails with the reason.
    sqlx::query(
        "UPDATE jobs SET spec = json_set(spec, '$.endpoint.bearer_token_sealed', 'kr1.' || ? || '.00ff')",
    )
    .bind(crate::secret_key(&config).unwrap().fingerprint().to_string())
    .execute(f.state.pool())
    .await
    .unwrap();
    assert!(f.lease("w1", 8).await.is_empty());
    let errors: Vec<(String, Option<String>)> =
        sqlx::query_as("SELECT state, last_error FROM jobs ORDER BY id")
            .fetch_all(f.state.pool())
            .await
            .unwrap();
    for (state, error) in errors {
        assert_eq!(state, "queued");
        assert!(error.unwrap().contains("cannot be opened"));
    }
}
