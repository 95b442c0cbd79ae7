//! The server's registration probe (`kitchen_r_server::PolicyProbe`) implemented with the
//! worker crate's endpoint check, so registration contacts an endpoint exactly as a worker will.
//! It lives in the binary because the server must not depend on the worker crate.

use kitchen_r_contract::probe::{ProbeFailure, probe_for_registration};
use kitchen_r_contract::{AllowedNetworks, RemoteConfig};
use kitchen_r_server::{BoxFuture, PolicyProbe, ProbeError, ProbedSpec};

pub(crate) struct WorkerProbe {
    pub allow: AllowedNetworks,
    pub remote: RemoteConfig,
}

impl PolicyProbe for WorkerProbe {
    fn probe(
        &self,
        url: &str,
        bearer: Option<&str>,
        key_map: Option<&str>,
    ) -> BoxFuture<'static, Result<ProbedSpec, ProbeError>> {
        let (url, bearer) = (url.to_string(), bearer.map(str::to_string));
        let key_map = key_map.unwrap_or_default().to_string();
        let (allow, remote) = (self.allow, self.remote.clone());
        Box::pin(async move {
            match probe_for_registration(&url, bearer.as_deref(), &key_map, &allow, &remote).await {
                Ok(s) => Ok(ProbedSpec {
                    protocol_version: s.protocol_version,
                    max_concurrency: s.max_concurrency,
                    summary: s.summary,
                    observation_history: s.observation_history,
                    actions_executed_per_chunk: s.actions_executed_per_chunk,
                    privileged_observations: s.privileged_observations,
                    key_map: s.key_map,
                }),
                Err(
                    e
                    @ (ProbeFailure::Malformed(_) | ProbeFailure::Resolve(_) | ProbeFailure::Refused { .. }),
                ) => Err(ProbeError::Refused(e.to_string())),
                Err(e @ ProbeFailure::Internal(_)) => Err(ProbeError::Unavailable(e.to_string())),
                Err(e) => Err(ProbeError::Failed(e.to_string())),
            }
        })
    }
}
