//! `kitchen-r check-policy ENDPOINT`: the conformance probe a participant runs against their
//! own policy server before registering it; one PASS/FAIL/SKIP line per check and a non-zero
//! exit status when any check fails.
//!
//! It runs on the participant's side, so every address range is allowed here; the server
//! applies its `[policy.allowed_networks]` rules when the endpoint is registered.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use kitchen_r_contract::check::{self, Verdict};
use kitchen_r_contract::{AllowedNetworks, Credentials, RemoteConfig, SimCamera};
use kitchen_r_sim::SensorsConfig;

#[derive(Args, Debug)]
pub(crate) struct CheckPolicyArgs {
    /// The policy server: gRPC at `http://HOST:PORT` or `https://HOST:PORT`, or an openpi
    /// WebSocket server at `ws://HOST:PORT` or `wss://HOST:PORT`.
    pub endpoint: String,
    /// openpi (`ws://`) endpoints: the key map you will register, inline JSON or a JSON file;
    /// without it the default keys.
    #[arg(long, value_name = "JSON|FILE")]
    pub key_map: Option<String>,
    /// Bearer token the policy server expects (sent as `authorization: Bearer <T>`).
    #[arg(long, env = "KITCHEN_R_POLICY_TOKEN", value_name = "T")]
    pub token: Option<String>,
    /// PEM file of the CA that signed the server's certificate (https endpoints, private CA).
    #[arg(long, value_name = "FILE")]
    pub ca: Option<PathBuf>,
    /// Per-call deadline in seconds, as the workers apply it.
    #[arg(long, value_name = "S", default_value_t = 10.0)]
    pub deadline: f64,
    /// Seconds the server may take to start answering.
    #[arg(long, value_name = "S", default_value_t = 30.0)]
    pub startup_deadline: f64,
    /// The organiser's default actions executed per chunk (server `control.actions_executed_per_chunk`),
    /// announced in GetSpec and used when the policy does not choose its own count.
    #[arg(long, value_name = "K", default_value_t = 8, value_parser = clap::value_parser!(u32).range(1..=16))]
    pub execute: u32,
    /// The organiser's smallest count a policy may choose (server
    /// `control.min_actions_executed_per_chunk`), to check a GetSpec against a stricter server.
    #[arg(long, value_name = "K", default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=16))]
    pub min_execute: u32,
    /// Check against a server that does not run the privileged track (`control.privileged_track
    /// = false`, the default there): a policy asking for privileged observations then fails.
    /// Without it the check announces the track, and a privileged policy's Acts carry a
    /// synthetic privileged observation.
    #[arg(long)]
    pub standard_only: bool,
}

pub(crate) fn check_policy(args: CheckPolicyArgs) -> anyhow::Result<()> {
    if args.min_execute > args.execute {
        anyhow::bail!(
            "--min-execute {} exceeds --execute {}",
            args.min_execute,
            args.execute
        );
    }
    let sensors = SensorsConfig::load_default().context("loading configs/sensors.toml")?;
    let ca_pem = match &args.ca {
        Some(p) => Some(std::fs::read(p).with_context(|| format!("reading {}", p.display()))?),
        None => None,
    };
    let creds = Credentials {
        token: args.token,
        ca_pem,
    };
    let cfg = RemoteConfig {
        call_deadline_s: args.deadline,
        startup_deadline_s: args.startup_deadline,
        actions_executed_per_chunk: args.execute,
        min_actions_executed_per_chunk: args.min_execute,
        allowed_networks: AllowedNetworks::ALL,
        privileged_track: !args.standard_only,
        ..RemoteConfig::default()
    };
    let key_map = crate::key_map_arg::text(args.key_map.as_deref())?;
    let cameras = SimCamera::from_sensors(&sensors);
    let report = check::check_policy(&args.endpoint, &creds, &cfg, &cameras, &key_map);
    for c in &report.checks {
        println!("{c}");
    }
    let failed = report
        .checks
        .iter()
        .filter(|c| c.verdict == Verdict::Fail)
        .count();
    if failed > 0 {
        anyhow::bail!("{failed} of {} checks failed", report.checks.len());
    }
    println!("all checks passed");
    Ok(())
}
