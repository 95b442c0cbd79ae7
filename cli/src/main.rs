//! The `kitchen-r` binary: parses arguments and calls into the crates. Nothing else lives here.
//!
//! Each area's subcommands live in their own module (`serve_cmd` for the server, `client_cmd`
//! for the participant and organiser commands that talk to a server over HTTP, `sim_cmd` for
//! the twin's tools); `main` only dispatches. Without a subcommand the binary serves, so
//! `cargo run --release` starts the server.

// The doc comments of this crate's argument structs are clap's `--help` texts, written for a
// terminal (`[default: …]`, `DIR/<episode key>.mp4`): escaping them for rustdoc would print the
// escapes in `--help`, so rustdoc's link and HTML checks do not apply here.
#![allow(rustdoc::broken_intra_doc_links, rustdoc::invalid_html_tags)]

mod admin_cmd;
mod archive_cmd;
mod check_policy_cmd;
mod client_cmd;
mod clock_parse;
mod collect_cmd;
mod dataset_cmd;
mod episodes_cmd;
mod eval_cmd;
mod eval_record;
mod key_map_arg;
mod leaderboard_table;
mod live_view;
mod load_bench;
mod policy_cmd;
mod policy_submit;
mod probe_glue;
mod reevaluate_cmd;
mod replay_cmd;
mod serve_cmd;
mod server_client;
mod sim_cmd;
mod submission_cmd;
mod submission_trace;
mod submission_view;
mod verify_cmd;
mod worker_cmd;

use clap::{Parser, Subcommand};

#[derive(Parser, Debug)]
#[command(
    name = "kitchen-r",
    version,
    about = "Kitchen-R evaluation server, simulation worker and tools"
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Run the evaluation server (HTTP + gRPC on SQLite). The default command.
    Serve(serve_cmd::ServeArgs),
    /// A standalone simulation worker leasing episodes from a server's gRPC port.
    Worker(worker_cmd::WorkerArgs),
    /// Organiser: manage teams.
    Team(client_cmd::TeamArgs),
    /// Upload a submission and print its scores.
    Submit(client_cmd::SubmitArgs),
    /// A submission's progress and results: `show ID [--json]`, `wait ID [--timeout S]`.
    Submission(submission_cmd::SubmissionArgs),
    /// Print the ranking.
    Leaderboard(client_cmd::LeaderboardArgs),
    /// Organiser: add a new scoring run to every submission.
    Rescore(client_cmd::RescoreArgs),
    /// Organiser's console: queue, workers, runs; cancel or requeue a run; back up the database.
    Admin(admin_cmd::AdminArgs),
    /// Benchmark content: regenerate the instruction dataset.
    Dataset(dataset_cmd::DatasetArgs),
    /// Saved batches of validation episodes: generate one, show one.
    Episodes(episodes_cmd::EpisodesArgs),
    /// Kitchen twin tools (render what the robot sees).
    Sim(sim_cmd::SimArgs),
    /// Performance figures.
    Bench(sim_cmd::BenchArgs),
    /// Evaluate a policy locally on a split, through the workers' episode runner.
    Eval(eval_cmd::EvalArgs),
    /// Replay an episode from its trace (`eval --trace`), bit-identical to its evaluation,
    /// into its video; refused when the replay disagrees with the recorded outcome.
    Replay(replay_cmd::ReplayArgs),
    /// Collect expert trajectories into MCAP and/or HDF5.
    Collect(collect_cmd::CollectArgs),
    /// Serve a reference policy over the participant gRPC contract.
    Policy(policy_cmd::PolicyArgs),
    /// Conformance probe of a policy endpoint: one PASS/FAIL line per check.
    CheckPolicy(check_policy_cmd::CheckPolicyArgs),
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {
        None => serve_cmd::serve(serve_cmd::ServeArgs::default()),
        Some(Command::Serve(args)) => serve_cmd::serve(args),
        Some(Command::Worker(args)) => worker_cmd::worker(args),
        Some(Command::Team(args)) => client_cmd::team(args),
        Some(Command::Submit(args)) => client_cmd::submit(args),
        Some(Command::Submission(args)) => submission_cmd::submission(args),
        Some(Command::Leaderboard(args)) => client_cmd::leaderboard(args),
        Some(Command::Rescore(args)) => client_cmd::rescore(args),
        Some(Command::Admin(args)) => admin_cmd::admin(args),
        Some(Command::Dataset(args)) => dataset_cmd::dataset(args),
        Some(Command::Episodes(args)) => episodes_cmd::episodes(args),
        Some(Command::Sim(args)) => sim_cmd::sim(args),
        Some(Command::Bench(args)) => sim_cmd::bench(args),
        Some(Command::Eval(args)) => eval_cmd::eval(args),
        Some(Command::Replay(args)) => replay_cmd::replay(args),
        Some(Command::Collect(args)) => collect_cmd::collect_cmd(args),
        Some(Command::Policy(args)) => policy_cmd::policy(args),
        Some(Command::CheckPolicy(args)) => check_policy_cmd::check_policy(args),
    }
}
