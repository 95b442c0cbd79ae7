//! A policy served over TLS is called over `https://` with the endpoint's CA and the bearer
//! token; a client that does not trust the certificate is refused with a TLS reason.

use crate::remote_support;

use kitchen_r_contract::server::{ServeOptions, TlsIdentity};
use kitchen_r_contract::{Credentials, RemoteConfig, RemotePolicy};
use kitchen_r_episode::policy::Policy;
use remote_support::*;

/// A self-signed certificate for `localhost`: (cert PEM, key PEM).
fn self_signed() -> (String, String) {
    let c = rcgen::generate_simple_self_signed(vec!["localhost".to_string()]).unwrap();
    (c.cert.pem(), c.signing_key.serialize_pem())
}

fn tls_server() -> (TestServer, String) {
    let (cert, key) = self_signed();
    let opts = ServeOptions {
        tls: Some(TlsIdentity {
            cert_pem: cert.clone().into_bytes(),
            key_pem: key.into_bytes(),
        }),
        ..ServeOptions::default()
    };
    (TestServer::start(still(), opts), cert)
}

fn cfg() -> RemoteConfig {
    RemoteConfig {
        startup_deadline_s: 10.0,
        ..RemoteConfig::default()
    }
}

#[test]
fn a_tls_endpoint_is_called_over_https_with_its_ca() {
    let (server, cert) = tls_server();
    let url = format!("https://localhost:{}", server.addr.port());
    let creds = Credentials {
        token: Some("s3cret-token".into()),
        ca_pem: Some(cert.into_bytes()),
    };
    let mut p = RemotePolicy::connect(&url, &creds, &cfg(), &cameras()).unwrap();
    assert_eq!(p.spec().horizon, 16);
    let mut sim = sim();
    p.set_scene(&sim.episode().scene.clone());
    let opts = kitchen_r_episode::runner::RunOptions {
        task_time_limit: 1.0,
        max_tasks: Some(1),
        ..Default::default()
    };
    let out = kitchen_r_episode::runner::run_episode(&mut sim, &mut p, &opts, None, &mut ()).unwrap();
    // The still policy never succeeds, but every call went through: the task ran to its limit.
    let f = out.tasks[0].failure.as_deref().unwrap_or_default();
    assert!(f.starts_with("time limit of 1 s reached"), "{f}");
    assert!(out.policy_calls >= 2);
}

#[test]
fn an_untrusted_certificate_is_refused_with_a_tls_reason() {
    let (server, _) = tls_server();
    let url = format!("https://localhost:{}", server.addr.port());
    let err = match RemotePolicy::connect(&url, &Credentials::default(), &cfg(), &cameras()) {
        Ok(_) => panic!("an untrusted self-signed certificate must be refused"),
        Err(e) => e.to_string(),
    };
    assert!(
        err.to_lowercase().contains("certificate") || err.to_lowercase().contains("tls"),
        "{err}"
    );
}
