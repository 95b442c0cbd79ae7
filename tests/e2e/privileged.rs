//! The privileged-information track end to end (docs/participant/privileged.md): `kitchen-r serve`
//! with
//! `control.privileged_track = true`, a participant's policy whose GetSpec asks for privileged
//! observations and logs what it receives, a standard policy beside it, and the boards.
//!
//! Online and offline (MSE) episodes both run. Checked: the endpoint really receives the
//! privileged observation at every Act (its robot pose, a goal in
//! the robot frame that matches the scene's zone); on the dev split every key object of the
//! episode, on the test split nothing beyond what the current sub-task names; the standard
//! policy receives none; the control and integrated boards keep standard and privileged entries
//! apart, labelled in JSON, CSV and on the pages (the dev runs link a plan file, so they rank on
//! both; the test run links none, so it ranks on control only); the organiser's runs API names
//! each run's track; and a server with the track off refuses the registration, naming the config
//! key.

use crate::remote_support;
use crate::support;

use std::sync::{Arc, Mutex};

use kitchen_r_contract::server::ServeOptions;
use kitchen_r_core::dataset::Instruction;
use kitchen_r_episode::policy::{Goal, HORIZON, PolicyInput, PrivilegedObservation};
use remote_support::{Answer, STILL, Scripted, TestServer, spec};
use serde_json::{Value, json};
use support::*;

/// What one Act carried: the sub-task, the reference state (never for participants) and the
/// privileged observation.
#[derive(Debug, Clone)]
struct Seen {
    sub_task: String,
    reference_state: bool,
    shown: Option<PrivilegedObservation>,
}

type Log = Arc<Mutex<Vec<Seen>>>;

/// A policy server that stands still and logs every Act; `privileged` is what its GetSpec asks.
fn logging_policy(privileged: bool) -> (TestServer, Log) {
    let log: Log = Arc::default();
    let seen = log.clone();
    let answer: Answer = Arc::new(move |input: &PolicyInput<'_>| {
        seen.lock().unwrap().push(Seen {
            sub_task: input.sub_task.to_string(),
            reference_state: input.privileged.is_some(),
            shown: input.privileged_observation.cloned(),
        });
        Ok(vec![STILL; HORIZON])
    });
    let factory: kitchen_r_contract::server::PolicyFactory = Arc::new(move || {
        let mut spec = spec(HORIZON);
        spec.privileged_observations = privileged;
        Box::new(Scripted {
            spec,
            answer: answer.clone(),
        }) as Box<dyn kitchen_r_episode::policy::Policy>
    });
    (TestServer::start(factory, ServeOptions::default()), log)
}

/// The committed public sample's first instruction (two key objects: a blue cup, then an
/// apple) as a one-instruction private test set, so the test run is short.
fn one_instruction_test_set(dir: &std::path::Path) -> Instruction {
    let public = kitchen_r_core::assets::assets_dir().join("dataset/test_ground_truth.jsonl");
    let all: Vec<Instruction> = kitchen_r_core::dataset::read_jsonl(&public).unwrap();
    let picked = all[0].clone();
    std::fs::create_dir_all(dir).unwrap();
    std::fs::write(
        dir.join("test_ground_truth.jsonl"),
        serde_json::to_string(&picked).unwrap() + "\n",
    )
    .unwrap();
    std::fs::write(dir.join("dev.jsonl"), "").unwrap();
    let manifest = json!({
        "kind": "private",
        "generator_version": kitchen_r_core::dataset::GENERATOR_VERSION,
        "templates": 58, "dev": 0, "test": 1,
        "private_phrasings": {"templates": 1, "phrasings": 4, "sha256": "0".repeat(64)},
    });
    std::fs::write(dir.join("manifest.json"), manifest.to_string()).unwrap();
    picked
}

/// The object names an observation shows, in its goal and its object list.
fn names(o: &PrivilegedObservation) -> Vec<String> {
    let goal = match &o.goal {
        Goal::Approach { .. } => None,
        Goal::Pick { object, .. } | Goal::Place { object, .. } => Some(object.clone()),
    };
    goal.into_iter()
        .chain(o.objects.iter().map(|o| o.name.clone()))
        .collect()
}

/// A move's goal, turned back into the scene frame with the robot's pose, is the zone's
/// approach point.
fn assert_goal_is_the_zones_approach(o: &PrivilegedObservation, sub_task: &str, scene: &str) {
    let Goal::Approach { x, y, yaw } = o.goal else {
        panic!("{sub_task}: {:?}", o.goal)
    };
    let assets = kitchen_r_core::assets::assets_dir();
    let catalogue = kitchen_r_core::catalogue::Catalogue::load(&assets.join("objects.toml")).unwrap();
    let scene =
        kitchen_r_core::scene::Scene::load(&assets.join(format!("scenes/{scene}.toml")), &catalogue).unwrap();
    let colour = sub_task
        .trim_start_matches("move to the ")
        .trim_end_matches(" zone");
    let zone = scene.zone(colour).unwrap();
    let [bx, by, byaw] = o.base_pose;
    let (c, s) = (byaw.cos(), byaw.sin());
    let world = [bx + c * x - s * y, by + s * x + c * y];
    let heading = (byaw + yaw - zone.approach[2]).sin().abs();
    assert!(
        (world[0] - zone.approach[0]).abs() < 1e-6
            && (world[1] - zone.approach[1]).abs() < 1e-6
            && heading < 1e-6,
        "{sub_task}: goal {:?} from {:?} is not the approach {:?}",
        o.goal,
        o.base_pose,
        zone.approach
    );
}

async fn board(server: &Server, query: &str) -> (u16, Value) {
    get_json(server, &format!("/api/v1/leaderboard?{query}"), None).await
}

/// A one-line dev plan file (the first dev instruction, the one a one-episode dev run
/// evaluates, with its true plan) uploaded by `token`; its id, for an integrated run to link.
async fn dev_plans(server: &Server, token: &str) -> i64 {
    let public = kitchen_r_core::assets::assets_dir().join("dataset/dev.jsonl");
    let first: Instruction = kitchen_r_core::dataset::read_jsonl(&public).unwrap().remove(0);
    let plan: Vec<&str> = first.plan.iter().map(String::as_str).collect();
    let (status, v) = submit(server, Some(token), "dev", line(&first.id, &plan) + "\n").await;
    assert_eq!(status, 201, "{v}");
    v["id"].as_i64().unwrap()
}

/// The teams on a board, in rank order, with each row's track label.
fn teams_on(board: &Value) -> Vec<(&str, &str)> {
    (board["rows"].as_array().unwrap().iter())
        .map(|r| (r["team"].as_str().unwrap(), r["observations"].as_str().unwrap()))
        .collect()
}

#[test]
fn privileged_runs_get_what_their_split_allows_and_are_ranked_apart() {
    let (privileged, seen) = logging_policy(true);
    let (standard, standard_seen) = logging_policy(false);
    let fx = ControlFixture::new(
        "[control]\nprivileged_track = true\ntask_time_limit_s = 1.0\nmax_plan_steps = 4\n",
    );
    let set_dir = fx.dir.path().join("private-set");
    let truth = one_instruction_test_set(&set_dir);
    let config = fx.dir.path().join("server.toml");
    let toml = std::fs::read_to_string(&config).unwrap();
    std::fs::write(&config, format!("test_set = \"{}\"\n{toml}", set_dir.display())).unwrap();
    let server = fx.serve(1);
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let token = team(&server, "Privileged").await;
        let other = team(&server, "Standard").await;
        // `plans`: a plan file to link, which makes the run integrated too.
        let run = |token: String, endpoint: String, split: &'static str, plans: Option<i64>| {
            let server = &server;
            async move {
                let mut body = json!({"endpoint": endpoint, "split": split});
                if split == "dev" {
                    body["episodes"] = json!(1);
                }
                if let Some(id) = plans {
                    body["plans"] = json!(id);
                }
                let (status, reg) = register_policy(server, &token, body).await;
                assert_eq!(status, 201, "{reg}");
                let id = reg["id"].as_i64().unwrap();
                let view = wait_for(server, id, &token, "the run", finished).await;
                (reg, view)
            }
        };

        // Dev, integrated (a plan file linked): every key object of the episode, a goal that
        // matches the scene.
        let plans = dev_plans(&server, &token).await;
        let (reg, view) = run(token.clone(), privileged.url(), "dev", Some(plans)).await;
        assert_eq!(reg["observations"], "privileged", "{reg}");
        assert_eq!(view["policy"]["plans"], plans, "{view}");
        let privileged_dev = reg["id"].as_i64().unwrap();
        assert_eq!(view["policy"]["observations"], "privileged", "{view}");
        // Offline (MSE) episodes asked the policy too: their observations are checked below
        // with the online ones.
        assert!(view["latest_run"]["scores"]["mse"].as_f64().is_some(), "{view:#}");
        let dev: Vec<Seen> = std::mem::take(&mut *seen.lock().unwrap());
        assert!(!dev.is_empty(), "the endpoint was called");
        for s in &dev {
            assert!(!s.reference_state, "a participant never gets the reference state");
            let o = s
                .shown
                .as_ref()
                .unwrap_or_else(|| panic!("no privileged observation: {s:?}"));
            let shown = names(o);
            for object in ["apple", "blue cup"] {
                assert!(shown.iter().any(|n| n == object), "dev shows {object}: {s:?}");
            }
            if s.sub_task.starts_with("move to") {
                assert_goal_is_the_zones_approach(o, &s.sub_task, "kitchen_a");
            }
        }

        // Test: only what the current sub-task names (a move names no object).
        let (_, view) = run(token.clone(), privileged.url(), "test", None).await;
        assert_eq!(view["latest_run"]["evaluation"]["state"], "finished", "{view}");
        let test: Vec<Seen> = std::mem::take(&mut *seen.lock().unwrap());
        let kinds: Vec<&str> = test.iter().map(|s| s.sub_task.as_str()).collect();
        for step in &truth.plan[..4] {
            assert!(kinds.contains(&step.as_str()), "{step} was run: {kinds:?}");
        }
        for s in &test {
            let o = s
                .shown
                .as_ref()
                .unwrap_or_else(|| panic!("no privileged observation: {s:?}"));
            for name in names(o) {
                assert!(s.sub_task.contains(&name), "test split shows {name} during {s:?}");
            }
            match s.sub_task.split_whitespace().next() {
                Some("move") => {
                    assert!(o.objects.is_empty(), "{s:?}");
                    assert_goal_is_the_zones_approach(o, &s.sub_task, &truth.scene);
                }
                Some("pick") => assert!(matches!(&o.goal, Goal::Pick { object, .. } if object == "blue cup")),
                _ => assert!(matches!(&o.goal, Goal::Place { object, .. } if object == "blue cup")),
            }
        }
        assert!(
            test.iter().any(|s| s.sub_task.starts_with("pick"))
                && test.iter().all(|s| {
                    s.shown
                        .as_ref()
                        .is_some_and(|o| !names(o).contains(&"apple".to_string()))
                }),
            "the apple, handled only by later steps, never shows on test"
        );

        // A standard policy on the same server gets no privileged observation.
        let other_plans = dev_plans(&server, &other).await;
        let (reg, _) = run(other.clone(), standard.url(), "dev", Some(other_plans)).await;
        assert_eq!(reg["observations"], "standard", "{reg}");
        let standard_dev = reg["id"].as_i64().unwrap();
        let std_seen = standard_seen.lock().unwrap().clone();
        assert!(!std_seen.is_empty() && std_seen.iter().all(|s| s.shown.is_none() && !s.reference_state));

        // The boards keep the two apart, labelled.
        let (status, std_board) = board(&server, "track=control&split=dev").await;
        assert_eq!(status, 200);
        assert_eq!(std_board["observations"], "standard");
        let teams: Vec<&str> = (std_board["rows"].as_array().unwrap().iter())
            .map(|r| r["team"].as_str().unwrap())
            .collect();
        assert_eq!(teams, ["Standard"], "{std_board}");
        assert_eq!(std_board["rows"][0]["observations"], "standard");
        let (_, priv_board) = board(&server, "track=control&split=dev&observations=privileged").await;
        assert_eq!(priv_board["observations"], "privileged");
        let rows = priv_board["rows"].as_array().unwrap();
        assert_eq!(rows.len(), 1, "{priv_board}");
        assert_eq!(
            (rows[0]["team"].as_str(), rows[0]["rank"].as_u64()),
            (Some("Privileged"), Some(1))
        );
        assert_eq!(rows[0]["observations"], "privileged");
        let (_, test_board) = board(&server, "track=control&split=test&observations=privileged").await;
        assert_eq!(test_board["rows"][0]["team"], "Privileged", "{test_board}");
        let (_, std_test) = board(&server, "track=control&split=test").await;
        assert_eq!(std_test["rows"], json!([]), "{std_test}");

        let csv = get_text(
            &server,
            "/api/v1/leaderboard?track=control&split=dev&observations=privileged&format=csv",
        )
        .await;
        let mut lines = csv.lines();
        // The intervals are appended after the columns there were (docs/reference/leaderboard.md).
        assert!(
            (lines.next().unwrap()).starts_with(
                "rank,team,submission_id,sr,mse,state,baseline,submitted_at,observations,grasp_mode,sr_low,"
            ),
            "{csv}"
        );
        let row = lines.next().unwrap();
        assert!(
            row.starts_with("1,Privileged,") && row.contains(",privileged,abstract,"),
            "{csv}"
        );
        assert_eq!(lines.next(), None, "{csv}");
        let csv = get_text(&server, "/api/v1/leaderboard?track=control&split=dev&format=csv").await;
        assert!(
            csv.lines()
                .skip(1)
                .all(|l| l.contains(",standard,abstract,") && l.contains(",Standard,")),
            "{csv}"
        );

        let page = get_text(&server, "/?split=dev").await;
        assert!(page.contains("Control track — standard observations"), "{page}");
        assert!(
            page.contains("id=\"control-privileged\">Control track — privileged observations"),
            "{page}"
        );
        assert!(
            page.contains("Integrated track — privileged observations"),
            "{page}"
        );
        let id = rows[0]["submission_id"].as_i64().unwrap();
        let entry = get_text(&server, &format!("/leaderboard/control/dev/{id}")).await;
        assert!(
            entry.contains("<th>Observations</th><td>privileged</td>"),
            "{entry}"
        );

        // The integrated boards: each dev run on its own track's board only, with its M and P;
        // the test run linked no plan file, so it is on no integrated board.
        let (status, std_int) = board(&server, "track=integrated&split=dev").await;
        assert_eq!(status, 200, "{std_int}");
        assert_eq!(std_int["observations"], "standard");
        assert_eq!(teams_on(&std_int), [("Standard", "standard")], "{std_int}");
        assert_eq!(std_int["rows"][0]["submission_id"], standard_dev, "{std_int}");
        let (_, priv_int) = board(&server, "track=integrated&split=dev&observations=privileged").await;
        assert_eq!(priv_int["observations"], "privileged");
        assert_eq!(teams_on(&priv_int), [("Privileged", "privileged")], "{priv_int}");
        let row = &priv_int["rows"][0];
        assert_eq!(row["submission_id"], privileged_dev, "{priv_int}");
        assert_eq!(
            (row["rank"].as_u64(), row["state"].as_str()),
            (Some(1), Some("finished"))
        );
        assert!(
            row["scores"]["m"].is_number() && row["scores"]["p"].is_number(),
            "{priv_int}"
        );
        for query in [
            "track=integrated&split=test",
            "track=integrated&split=test&observations=privileged",
        ] {
            let (_, b) = board(&server, query).await;
            assert_eq!(b["rows"], json!([]), "{query}: {b}");
        }
        let entry = get_text(&server, &format!("/leaderboard/integrated/dev/{privileged_dev}")).await;
        assert!(
            entry.contains("<th>Observations</th><td>privileged</td>"),
            "{entry}"
        );

        // The organiser's console names each run's track.
        let (status, admin) = get_json(&server, "/api/v1/admin/runs", Some(ADMIN)).await;
        assert_eq!(status, 200, "{admin}");
        let tracks: Vec<(&str, &str)> = (admin["runs"].as_array().unwrap().iter())
            .map(|r| (r["team"].as_str().unwrap(), r["observations"].as_str().unwrap()))
            .collect();
        assert_eq!(
            tracks,
            [
                ("Standard", "standard"),
                ("Privileged", "privileged"),
                ("Privileged", "privileged")
            ],
            "newest first: {admin:#}"
        );

        // Planning has no privileged board.
        let (status, e) = board(&server, "track=planning&observations=privileged").await;
        assert_eq!(status, 400, "{e}");
    });
}

#[test]
fn a_privileged_policy_is_refused_naming_the_key_when_the_track_is_off() {
    let (privileged, seen) = logging_policy(true);
    let fx = ControlFixture::new("");
    let server = fx.serve(0);
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let token = team(&server, "Eager").await;
        let body = json!({"endpoint": privileged.url(), "split": "dev", "episodes": 1});
        let (status, e) = register_policy(&server, &token, body).await;
        assert_eq!(status, 403, "{e}");
        assert_eq!(e["code"], "privileged_track_disabled", "{e}");
        let why = e["error"].as_str().unwrap();
        assert!(
            why.contains("control.privileged_track") && why.contains("privileged_track = true"),
            "{why}"
        );
        let (_, mine) = get_json(&server, "/api/v1/leaderboard?track=control&split=dev", None).await;
        assert_eq!(mine["rows"], json!([]));
    });
    assert!(
        seen.lock().unwrap().is_empty(),
        "a refused policy is never driven"
    );
}

/// The starter kit's policy server with `--privileged` asks for the track: `check-policy`
/// reports it (and fails it against a server without the track), and local `eval` gives it
/// privileged observations and labels the result.
#[test]
fn the_starter_kit_check_policy_and_local_eval_speak_the_privileged_track() {
    let Some((_kit, url)) = starter_kit(&["--privileged"]) else {
        return;
    };
    let kr = |args: &[&str]| std::process::Command::new(bin()).args(args).output().unwrap();

    let checked = ok(kr(&["check-policy", &url]));
    let report = out(&checked);
    assert!(
        report
            .lines()
            .any(|l| l.starts_with("PASS  privileged") && l.contains("privileged track")),
        "{report}"
    );
    assert!(
        report.contains("PASS  act "),
        "Acts with a privileged observation pass: {report}"
    );
    let refused = kr(&["check-policy", &url, "--standard-only"]);
    assert!(!refused.status.success());
    let report = out(&refused);
    assert!(
        report
            .lines()
            .any(|l| l.starts_with("FAIL  privileged") && l.contains("control.privileged_track")),
        "{report}"
    );

    let dir = tempfile::tempdir().unwrap();
    let eval_cfg = dir.path().join("eval.toml");
    std::fs::write(
        &eval_cfg,
        "task_time_limit = 1.0\nmax_plan_steps = 2\nteleport_on_failure = false\n",
    )
    .unwrap();
    let eval = ok(kr(&[
        "eval",
        "--policy",
        &url,
        "--split",
        "dev",
        "--episodes",
        "1",
        "--jobs",
        "1",
        "--json",
        "--config",
        eval_cfg.to_str().unwrap(),
    ]));
    let report: Value = serde_json::from_str(out(&eval).trim()).unwrap();
    assert_eq!(report["observations"], "privileged", "{report}");
    assert_eq!(
        report["episodes"][0]["tasks"].as_array().map(Vec::len),
        Some(2),
        "{report}"
    );
}
