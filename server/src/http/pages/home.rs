//! `GET /contest`: the contest home. The tracks and their metrics in plain words with the
//! paper's formulas (MathML, with a plain-text line beside each for readers without MathML),
//! how to take part, the downloads, and the rules (quotas from the running configuration, what
//! test feedback shows, and the integrity rules the leaderboard page shows too).

use maud::{Markup, html};

use crate::content::TestSetKind;
use crate::http::leaderboard::integrity_rules;
use crate::service::AppState;

/// `<mfrac>` and friends keep the formulas below readable.
fn frac(num: Markup, den: Markup) -> Markup {
    html! { mfrac { mrow { (num) } mrow { (den) } } }
}

fn sum(var: &str, to: Markup, body: Markup) -> Markup {
    html! { munderover { mo { "∑" } mrow { mi { (var) } mo { "=" } mn { "1" } } (to) } mrow { (body) } }
}

fn sub(base: &str, index: &str) -> Markup {
    html! { msub { mi { (base) } mi { (index) } } }
}

fn mi(name: &str) -> Markup {
    html! { mi { (name) } }
}

fn one() -> Markup {
    html! { mn { "1" } }
}

fn formula(math: Markup, text: &str) -> Markup {
    html! { p { math display="block" { (math) } } p.f { (text) } }
}

fn metrics() -> Markup {
    let n = || mi("N");
    let em = formula(
        html! { mi { "EM" } mo { "=" } (frac(one(), n())) (sum("i", n(), frac(sub("PS", "i"), sub("N", "i")))) },
        "EM = (1/N) · Σ_i PS_i / N_i",
    );
    let task_mse = sum("j", sub("n", "i"), sub("MSE", "j"));
    let p = formula(
        html! {
            mi { "P" } mo { "=" } (frac(one(), mi("EM"))) mo { "+" } (frac(one(), n()))
            (sum("i", n(), html! { mo { "(" } (frac(one(), sub("n", "i"))) (task_mse) mo { ")" } }))
        },
        "P = 1/EM + (1/N) · Σ_i ( (1/n_i) · Σ_j MSE_j )",
    );
    let task_m = sum(
        "j",
        sub("n", "i"),
        html! { mo { "(" } (sub("EM", "j")) mo { "+" } (sub("SR", "j")) mo { ")" } },
    );
    let m = formula(
        html! {
            mi { "M" } mo { "=" } (frac(one(), n()))
            (sum("i", n(), html! { mo { "(" } (frac(one(), sub("n", "i"))) (task_m) mo { ")" } }))
        },
        "M = (1/N) · Σ_i ( (1/n_i) · Σ_j (EM_j + SR_j) )",
    );
    html! {
        h2 id="tracks" { "Tracks and metrics" }
        p {
            "An instruction (\"put the bowl on the red counter\") has a ground-truth plan of 4 to 8 steps ("
            code { "move to the blue zone" } ", " code { "pick the bowl" } ", " code { "place the bowl" } "). "
            i { "N" } " is the number of instructions, " i { "n" sub { "i" } } " the number of tasks (plan steps) of instruction " i { "i" } "."
        }
        h3 { "Planning track: Exact Match (EM), higher is better" }
        p {
            "Turn each instruction into its plan. A predicted step counts only when it matches the \
             ground-truth step at the same position character for character; " i { "PS" sub { "i" } }
            " is the number of such steps of plan " i { "i" } " and " i { "N" sub { "i" } }
            " its ground-truth length. A missing plan counts 0; extra steps do not raise the score."
        }
        (em)
        h3 { "Control track: Success Rate (SR), higher is better, and MSE, lower is better" }
        p {
            "Serve a policy that drives the mobile robot from two cameras and a sub-task sentence, \
             16 future actions of 10 values at a time. The simulator always executes the ground-truth \
             plan. A task succeeds (SR" sub { "j" } " = 1) when it is completed within its time limit: \
             a navigation task when the robot's base centre is within 10 cm of the target, a \
             manipulation task when the object's centre is within 5 cm of its target; success is \
             checked after every action. MSE is the mean squared error between the policy's predicted \
             action chunks and the expert's, averaged over all predictions. The board ranks by SR, \
             then lower MSE."
        }
        h3 { "Integrated track: M, higher is better, and P, lower is better" }
        p {
            "A plan file and a policy together. M adds each task's exact-match EM" sub { "j" }
            " (its plan step right or not) and its success SR" sub { "j" } ", averaged per \
             instruction, then over instructions (so it runs from 0 to 2):"
        }
        (m)
        p { "P combines planning and imitation error; EM = 0 gives P = ∞ (shown as " code { "inf" } "):" }
        (p)
    }
}

fn steps(s: &AppState) -> Markup {
    let episodes = match s.config().control.dev_episodes {
        0 => "every dev instruction".to_string(),
        n => format!("the first {n} dev instructions"),
    };
    html! {
        h2 id="steps" { "How to take part" }
        ol {
            li {
                b { "Get a team token." } " The organiser creates your team (" code { "kitchen-r team create NAME" }
                ") and hands you its token once; keep it secret. Command-line tools read it from "
                code { "KITCHEN_R_TOKEN" } "."
            }
            li {
                b { "Download the data." } " The instructions and scenes below: the dev split comes \
                with its plans, the test split without them."
            }
            li {
                b { "Planning: submit a plan file." } " JSON Lines, one "
                code { "{\"id\": \"dev-0001\", \"plan\": [\"move to the blue zone\", ...]}" }
                " per instruction: " code { "kitchen-r submit plans FILE --split dev" } " or "
                code { "POST /api/v1/submissions/plans?split=dev" } " with your token. It is scored at once."
            }
            li {
                b { "Control: serve your policy and register it." } " Serve the "
                code { "kitchen_r.policy.v1.Policy" } " gRPC service (the starter kit has a Python \
                server), check it with " code { "kitchen-r check-policy ENDPOINT" } ", then "
                code { "kitchen-r submit policy ENDPOINT --split dev" } " (" code { "--plans ID" }
                " links a plan submission for the integrated track). A dev run evaluates " (episodes) "."
            }
            li {
                b { "Watch the submission page." } " " a href="/team/login" { "Log in with your token" }
                ": your " a href="/team" { "team page" } " lists every submission; each one's page \
                shows its progress with an ETA and, on the dev split, every episode's tasks with why \
                each failed."
            }
        }
    }
}

fn downloads(s: &AppState) -> Markup {
    let c = s.content();
    html! {
        h2 id="data" { "Dataset and scenes" }
        ul {
            li { a href="/api/v1/dataset/dev" { "Dev split" } " (" (c.dataset.dev.len()) " instructions, with plans; JSON Lines)" }
            li {
                a href="/api/v1/dataset/test" { "Test split" } " (" (c.test_set.instructions) " instructions, no plans)"
                @if c.test_set.kind == TestSetKind::PublicSample {
                    " " span.banner { (crate::content::PUBLIC_SAMPLE_NOTICE) }
                }
            }
            li {
                a href="/api/v1/dataset/manifest" { "What the splits are" } " (JSON) · "
                a href="/api/v1/scenes" { "all scenes" } " (JSON)"
            }
        }
        p {
            "Each scene's top-down image shows its coloured zones and key objects; its brief \
             describes them in words for planners (the robot's policy never sees zone colours)."
        }
        div {
            @for scene in c.scene_summaries() {
                @let at = format!("/api/v1/scenes/{}", scene.id);
                figure {
                    a href={ (at) "/topdown.png" } {
                        img src={ (at) "/topdown.png" } alt={ "Top-down view of " (scene.name) } width="320" loading="lazy";
                    }
                    figcaption {
                        b { (scene.name) } " (" code { (scene.id) } "): " (scene.description) " "
                        a href={ (at) "/brief" } { "brief" } " · " a href=(at) { "JSON" }
                    }
                }
            }
        }
    }
}

fn per_day(n: u32) -> String {
    match n {
        0 => "unlimited".into(),
        n => format!("{n} per UTC day"),
    }
}

fn rules(s: &AppState) -> Markup {
    let q = s.config().quota;
    let c = s.config().control;
    let rate = match q.per_minute {
        0 => "no rate limit".to_string(),
        n => format!("at most {n} upload attempts per minute and split (a burst that refills at that rate)"),
    };
    let concurrent = match q.concurrent_runs {
        0 => "no limit on policy runs evaluating at once".to_string(),
        n => format!("at most {n} policy runs evaluating at once"),
    };
    html! {
        h2 id="rules" { "Rules" }
        h3 { "Quotas" }
        ul {
            li {
                "Dev split: " (per_day(q.dev_per_day)) " submissions; test split: " (per_day(q.test_per_day))
                " (plan files and policy registrations alike). Runs the platform could not evaluate \
                 and runs the organiser cancelled do not count."
            }
            li { (rate) "; " (concurrent) "." }
            li { "Each task of a policy run has " (c.task_time_limit_s) " simulated seconds." }
        }
        h3 { "What feedback shows" }
        ul {
            li { "Dev split: everything: per-instruction plan results, and per episode each task's result and why it failed." }
            li { "Test split: aggregate only: the scores, progress counts and how often each kind of failure happened." }
        }
        h3 { "Integrity rules" }
        (integrity_rules())
    }
}

/// The contest home's body.
pub(super) fn body(s: &AppState) -> Markup {
    html! {
        p {
            "Kitchen-R is a benchmark for language-guided mobile manipulation in a simulated kitchen: \
             plan from an English instruction, then drive a mobile robot through the plan. See the "
            a href="/" { "leaderboard" } "."
        }
        p {
            a href="#tracks" { "Tracks and metrics" } " · " a href="#steps" { "How to take part" } " · "
            a href="#data" { "Dataset and scenes" } " · " a href="#rules" { "Rules" } " · " a href="#api" { "API" }
        }
        (metrics())
        (steps(s))
        (downloads(s))
        (rules(s))
        h2 id="api" { "API" }
        p {
            "JSON over HTTP under " code { "/api/v1" } ", with " code { "Authorization: Bearer TOKEN" } ": "
            a href="/api/v1/leaderboard?track=planning&split=test" { "leaderboard" }
            " (" code { "?track=planning|control|integrated&split=dev|test&format=json|csv|html" } "), "
            code { "POST /api/v1/submissions/plans?split=" } ", " code { "POST /api/v1/submissions/policies" } ", "
            code { "GET /api/v1/submissions/ID" } ", " a href="/api/v1/scenes" { "scenes" } ", "
            a href="/api/v1/dataset/manifest" { "dataset" } ". Errors are "
            code { "{\"error\", \"code\", \"request_id\"}" } "."
        }
        p {
            "Every route, its parameters, bodies and answers: the " a href="/api/docs" { "API reference" }
            " (" a href="/api/v1/openapi.json" { "OpenAPI document" } ")."
        }
    }
}
