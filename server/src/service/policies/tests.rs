use std::sync::Arc;

use kitchen_r_core::dataset::Split;

use super::*;
use crate::probe::{NoProbe, ProbeError, ProbedSpec};
use crate::testutil::{ADMIN, FakeProbe, fixture};

#[tokio::test]
async fn accepted_registration_queues_online_and_offline_jobs_in_one_go() {
    let probe = FakeProbe::ok(4);
    let f = fixture(probe.clone(), |_| {}).await;
    let token = f.team("alpha").await;
    let done = f
        .state
        .register_policy(&f.caller(&token).await, f.request(Split::Dev))
        .await
        .unwrap();
    assert_eq!(
        (done.instructions, done.episodes, done.max_concurrency),
        (3, 6, 4)
    );
    assert_eq!(probe.calls(), 1);
    let view = f
        .state
        .get_submission(&f.caller(&token).await, done.id)
        .await
        .unwrap();
    assert_eq!(view.kind, "policy");
    let info = view.policy.unwrap();
    assert_eq!(
        (info.endpoint.as_str(), info.has_token),
        ("http://127.0.0.1:50099", false)
    );
    let eval = view.latest_run.unwrap().evaluation.unwrap();
    assert_eq!(
        (eval.state, eval.episodes_total, eval.episodes_done),
        ("queued", 6, 0)
    );
    // The request may ask for fewer dev episodes, never more than the configured cap.
    let mut fewer = f.request(Split::Dev);
    fewer.episodes = Some(1);
    fewer.token = Some("secret".into());
    let fewer = f
        .state
        .register_policy(&f.caller(&token).await, fewer)
        .await
        .unwrap();
    assert_eq!((fewer.instructions, fewer.episodes), (1, 2));
}

#[tokio::test]
async fn offline_jobs_can_be_switched_off_and_the_test_split_runs_whole() {
    let f = fixture(FakeProbe::ok(0), |c| {
        c.control.offline_mse = false;
        c.quota.test_per_day = 0;
    })
    .await;
    let token = f.team("alpha").await;
    let done = f
        .state
        .register_policy(&f.caller(&token).await, f.request(Split::Test))
        .await
        .unwrap();
    let n = f.state.content().ground_truth(Split::Test).len();
    assert_eq!(
        (done.instructions, done.episodes, done.max_concurrency),
        (n, n, 1)
    );
    let mut bad = f.request(Split::Test);
    bad.episodes = Some(2);
    let e = f
        .state
        .register_policy(&f.caller(&token).await, bad)
        .await
        .unwrap_err();
    assert_eq!(e.code(), "bad_request", "{e}");
}

async fn refused(probe: Arc<dyn crate::probe::PolicyProbe>) -> ServiceError {
    let f = fixture(probe, |_| {}).await;
    let token = f.team("alpha").await;
    let e = f
        .state
        .register_policy(&f.caller(&token).await, f.request(Split::Dev))
        .await
        .unwrap_err();
    // Nothing was stored, so a refusal never uses quota.
    let n: i64 = sqlx::query_scalar("SELECT COUNT(*) FROM submissions")
        .fetch_one(f.state.pool())
        .await
        .unwrap();
    assert_eq!(n, 0);
    e
}

/// Contract v1.1: GetSpec's execution count and history must be within this server's ranges.
#[tokio::test]
async fn a_spec_outside_the_contract_ranges_is_refused_naming_field_and_range() {
    let asks = |history: u32, execute: u32| {
        Arc::new(FakeProbe {
            answer: Ok(ProbedSpec {
                protocol_version: 1,
                max_concurrency: 1,
                summary: String::new(),
                observation_history: history,
                actions_executed_per_chunk: execute,
                privileged_observations: false,
                key_map: None,
            }),
            calls: Default::default(),
        })
    };
    let f = fixture(asks(2, 2), |c| c.control.min_actions_executed_per_chunk = 4).await;
    let token = f.team("alpha").await;
    let e = (f.state)
        .register_policy(&f.caller(&token).await, f.request(Split::Dev))
        .await
        .unwrap_err();
    assert_eq!(e.code(), "policy_probe_failed");
    assert!(
        e.to_string().contains(
            "actions_executed_per_chunk 2, which must be between 4 (this server's \
             control.min_actions_executed_per_chunk) and 16"
        ),
        "{e}"
    );
    let e = refused(asks(9, 0)).await;
    assert!(
        e.to_string()
            .contains("observation_history 9, which must be between 1 and 8"),
        "{e}"
    );
    let f = fixture(asks(2, 4), |c| c.control.min_actions_executed_per_chunk = 4).await;
    let token = f.team("alpha").await;
    (f.state)
        .register_policy(&f.caller(&token).await, f.request(Split::Dev))
        .await
        .unwrap();
}

#[tokio::test]
async fn probe_failures_are_clear_4xx_naming_what_failed() {
    let e = refused(FakeProbe::err(ProbeError::Refused(
        "10.0.0.5 is a private address".into(),
    )))
    .await;
    assert_eq!(e.code(), "endpoint_refused");
    assert!(e.to_string().contains("private address"), "{e}");
    assert_eq!(
        e.body()["error"],
        "policy endpoint refused: 10.0.0.5 is a private address"
    );

    let e = refused(FakeProbe::err(ProbeError::Failed("health: NOT_SERVING".into()))).await;
    assert_eq!(e.code(), "policy_probe_failed");
    assert!(e.to_string().contains("NOT_SERVING"));

    let e = refused(Arc::new(NoProbe)).await;
    assert_eq!(e.code(), "policy_evaluation_disabled");

    let wrong = Arc::new(FakeProbe {
        answer: Ok(ProbedSpec {
            protocol_version: 99,
            max_concurrency: 1,
            summary: String::new(),
            observation_history: 0,
            actions_executed_per_chunk: 0,
            privileged_observations: false,
            key_map: None,
        }),
        calls: Default::default(),
    });
    let e = refused(wrong).await;
    assert_eq!(e.code(), "policy_probe_failed");
    assert!(e.to_string().contains("protocol version 99"), "{e}");
}

#[tokio::test]
async fn bad_requests_are_refused_before_probing() {
    let probe = FakeProbe::ok(1);
    let f = fixture(probe.clone(), |_| {}).await;
    let alpha = f.team("alpha").await;
    let beta = f.team("beta").await;
    let dev = f.state.content().ground_truth(Split::Dev);
    let line = format!("{{\"id\": \"{}\", \"plan\": []}}\n", dev[0].id);
    let plans = f
        .state
        .submit_plans(&f.team_of(&beta).await, Split::Dev, line.as_bytes())
        .await
        .unwrap()
        .id;

    let with = |edit: &dyn Fn(&mut RegisterPolicy)| {
        let mut r = f.request(Split::Dev);
        edit(&mut r);
        r
    };
    let cases: Vec<(RegisterPolicy, &str)> = vec![
        (with(&|r| r.endpoint = "ftp://x:1".into()), "endpoint_refused"),
        (with(&|r| r.endpoint = "http://a b:1".into()), "endpoint_refused"),
        (with(&|r| r.endpoint = String::new()), "bad_request"),
        (with(&|r| r.token = Some("bad\ntoken".into())), "bad_request"),
        (with(&|r| r.episodes = Some(0)), "bad_request"),
        // Another team's plans are not even acknowledged to exist.
        (with(&|r| r.plans = Some(plans)), "not_found"),
        (with(&|r| r.plans = Some(9999)), "not_found"),
        (with(&|r| r.reference = true), "not_admin"),
    ];
    for (req, code) in cases {
        let e = f
            .state
            .register_policy(&f.caller(&alpha).await, req.clone())
            .await
            .unwrap_err();
        assert_eq!(e.code(), code, "{req:?}: {e}");
    }
    // The linked plans must be of the same split.
    let test_line = format!(
        "{{\"id\": \"{}\", \"plan\": []}}\n",
        f.state.content().ground_truth(Split::Test)[0].id
    );
    let test_plans = f
        .state
        .submit_plans(&f.team_of(&alpha).await, Split::Test, test_line.as_bytes())
        .await
        .unwrap()
        .id;
    let e = f
        .state
        .register_policy(&f.caller(&alpha).await, with(&|r| r.plans = Some(test_plans)))
        .await
        .unwrap_err();
    assert!(e.to_string().contains("test split"), "{e}");
    assert_eq!(
        f.state
            .register_policy(&f.state.caller(None).await.unwrap(), f.request(Split::Dev))
            .await
            .unwrap_err()
            .code(),
        "missing_token"
    );
    assert_eq!(probe.calls(), 0);
}

#[tokio::test]
async fn concurrent_runs_and_daily_quota_are_enforced_but_reference_runs_are_exempt() {
    let f = fixture(FakeProbe::ok(1), |c| {
        c.quota.concurrent_runs = 2;
        c.quota.dev_per_day = 3;
    })
    .await;
    let token = f.team("alpha").await;
    for _ in 0..2 {
        f.state
            .register_policy(&f.caller(&token).await, f.request(Split::Dev))
            .await
            .unwrap();
    }
    let e = f
        .state
        .register_policy(&f.caller(&token).await, f.request(Split::Dev))
        .await
        .unwrap_err();
    assert_eq!(e.code(), "concurrent_runs_exceeded");
    assert!(e.body()["error"].as_str().unwrap().contains("at most 2"));
    // Plans count against the same daily quota: 2 policies + 1 plan file = 3.
    let line = format!(
        "{{\"id\": \"{}\", \"plan\": []}}\n",
        f.state.content().ground_truth(Split::Dev)[0].id
    );
    f.state
        .submit_plans(&f.team_of(&token).await, Split::Dev, line.as_bytes())
        .await
        .unwrap();
    let e = f
        .state
        .submit_plans(&f.team_of(&token).await, Split::Dev, line.as_bytes())
        .await
        .unwrap_err();
    assert_eq!(e.code(), "quota_exceeded");

    let mut reference = f.request(Split::Dev);
    reference.reference = true;
    for _ in 0..3 {
        let done = f
            .state
            .register_policy(&f.caller(ADMIN).await, reference.clone())
            .await
            .unwrap();
        let view = f
            .state
            .get_submission(&f.caller(ADMIN).await, done.id)
            .await
            .unwrap();
        assert_eq!(view.team, crate::store::runs::BASELINE_TEAM);
        assert!(view.policy.unwrap().reference);
    }
}
