//! The gRPC twin of the submission API: same service layer, same scores and refusals as HTTP,
//! plus the standard health service.

use crate::support;

use kitchen_r_proto::submission::v1 as pb;
use pb::submissions_client::SubmissionsClient;
use support::*;
use tonic::Code;
use tonic::metadata::MetadataValue;

fn authed<T>(msg: T, token: &str) -> tonic::Request<T> {
    let mut req = tonic::Request::new(msg);
    let value: MetadataValue<_> = format!("Bearer {token}").parse().unwrap();
    req.metadata_mut().insert("authorization", value);
    req
}

#[tokio::test]
async fn submit_and_read_back_over_grpc() {
    let fx = Fixture::new("");
    let server = fx.serve();
    let token = team(&server, "grpc team").await;
    let mut client = SubmissionsClient::connect(server.grpc.clone()).await.unwrap();

    let body = line("dev-0001", &["move to the blue zone", "pick the bowl"]);
    let done = client
        .submit_plans(authed(
            pb::SubmitPlansRequest {
                split: "dev".into(),
                body: body.into_bytes(),
            },
            &token,
        ))
        .await
        .unwrap()
        .into_inner();
    // dev-0001: 2/4; dev-0002 and dev-0003 missing.
    assert_eq!(done.scores.unwrap().em, Some(0.5 / 3.0));
    assert_eq!(done.warnings.len(), 1);

    let sub = client
        .get_submission(authed(pb::GetSubmissionRequest { id: done.id }, &token))
        .await
        .unwrap()
        .into_inner();
    assert_eq!(sub.latest_run.unwrap().instructions.len(), 3);

    let bad = client
        .submit_plans(authed(
            pb::SubmitPlansRequest {
                split: "dev".into(),
                body: b"{\"id\": \"dev-0001\", \"plan\": [1]}".to_vec(),
            },
            &token,
        ))
        .await
        .unwrap_err();
    assert_eq!(bad.code(), Code::InvalidArgument);
    assert!(bad.message().contains("line 1"), "{}", bad.message());
    let anon = client
        .submit_plans(pb::SubmitPlansRequest {
            split: "dev".into(),
            body: b"x".to_vec(),
        })
        .await
        .unwrap_err();
    assert_eq!(anon.code(), Code::Unauthenticated);

    let board = client
        .get_leaderboard(pb::GetLeaderboardRequest {
            track: String::new(),
            split: "dev".into(),
            ..Default::default()
        })
        .await
        .unwrap()
        .into_inner();
    assert_eq!(board.rows[0].team, "grpc team");

    let channel = tonic::transport::Endpoint::from_shared(server.grpc.clone())
        .unwrap()
        .connect()
        .await
        .unwrap();
    let mut health = tonic_health::pb::health_client::HealthClient::new(channel);
    let status = health
        .check(tonic_health::pb::HealthCheckRequest {
            service: "kitchen_r.submission.v1.Submissions".into(),
        })
        .await
        .unwrap()
        .into_inner();
    assert_eq!(
        status.status(),
        tonic_health::pb::health_check_response::ServingStatus::Serving
    );
}
