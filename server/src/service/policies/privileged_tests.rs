//! The privileged track at registration: refused with the config key when off; when on, the
//! submission is stored as privileged and its jobs grant the split's scope.

use kitchen_r_core::dataset::Split;
use kitchen_r_core::observations::ObservationTrack;

use crate::testutil::{FakeProbe, fixture};

/// The `privileged_observations` of every job of run `run`, as stored.
async fn scopes(pool: &sqlx::SqlitePool, run: i64) -> Vec<Option<String>> {
    sqlx::query_scalar("SELECT json_extract(spec, '$.privileged_observations') FROM jobs WHERE run_id = ?")
        .bind(run)
        .fetch_all(pool)
        .await
        .unwrap()
}

#[tokio::test]
async fn asking_for_privileged_observations_is_refused_naming_the_key_when_the_track_is_off() {
    let f = fixture(FakeProbe::privileged(1), |_| {}).await;
    let token = f.team("alpha").await;
    let e = (f.state)
        .register_policy(&f.caller(&token).await, f.request(Split::Dev))
        .await
        .unwrap_err();
    assert_eq!(e.code(), "privileged_track_disabled");
    assert_eq!(e.body()["code"], "privileged_track_disabled");
    let text = e.to_string();
    assert!(text.contains("control.privileged_track"), "{text}");
    assert!(text.contains("privileged_track = true"), "{text}");
    let n: i64 = sqlx::query_scalar("SELECT COUNT(*) FROM submissions")
        .fetch_one(f.state.pool())
        .await
        .unwrap();
    assert_eq!(n, 0, "a refusal stores nothing");
}

#[tokio::test]
async fn with_the_track_on_the_run_is_privileged_and_its_jobs_grant_the_splits_scope() {
    let f = fixture(FakeProbe::privileged(2), |c| {
        c.control.privileged_track = true;
        c.quota.test_per_day = 0;
    })
    .await;
    let token = f.team("alpha").await;
    let caller = f.caller(&token).await;
    let dev = (f.state)
        .register_policy(&caller, f.request(Split::Dev))
        .await
        .unwrap();
    assert_eq!(dev.observations, ObservationTrack::Privileged);
    let all = scopes(f.state.pool(), dev.run_id).await;
    assert!(
        !all.is_empty() && all.iter().all(|s| s.as_deref() == Some("episode")),
        "{all:?}"
    );
    let view = f.state.get_submission(&caller, dev.id).await.unwrap();
    assert_eq!(view.policy.unwrap().observations, ObservationTrack::Privileged);

    let test = (f.state)
        .register_policy(&caller, f.request(Split::Test))
        .await
        .unwrap();
    let all = scopes(f.state.pool(), test.run_id).await;
    assert!(all.iter().all(|s| s.as_deref() == Some("sub_task")), "{all:?}");
}

#[tokio::test]
async fn a_standard_policy_on_a_server_with_the_track_on_stays_standard() {
    let f = fixture(FakeProbe::ok(1), |c| c.control.privileged_track = true).await;
    let token = f.team("alpha").await;
    let done = (f.state)
        .register_policy(&f.caller(&token).await, f.request(Split::Dev))
        .await
        .unwrap();
    assert_eq!(done.observations, ObservationTrack::Standard);
    let all = scopes(f.state.pool(), done.run_id).await;
    assert!(all.iter().all(Option::is_none), "{all:?}");
    let body: String = sqlx::query_scalar("SELECT body FROM submissions WHERE id = ?")
        .bind(done.id)
        .fetch_one(f.state.pool())
        .await
        .unwrap();
    // Standard bodies are stored exactly as before the track existed.
    assert!(!body.contains("privileged_observations"), "{body}");
}
