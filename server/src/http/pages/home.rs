//! `GET /contest`: the contest home. The tracks and their metrics in plain words with the
//! paper's formulas (MathML, with a plain-text line beside each for readers without MathML),
//! how to take part, the downloads, and the rules (quotas from the running configuration, what
//! test feedback shows, and the integrity rules the leaderboard page shows too).

use std::fmt::Write as _;

use super::layout::escape;
use crate::content::TestSetKind;
use crate::leaderboard::render::INTEGRITY_RULES;
use crate::service::AppState;

/// `<mfrac>` helpers keep the formulas below readable.
fn frac(num: &str, den: &str) -> String {
    format!("<mfrac><mrow>{num}</mrow><mrow>{den}</mrow></mfrac>")
}

fn sum(var: &str, to: &str, body: &str) -> String {
    format!(
        "<munderover><mo>∑</mo><mrow><mi>{var}</mi><mo>=</mo><mn>1</mn></mrow>{to}</munderover><mrow>{body}</mrow>"
    )
}

fn sub(base: &str, index: &str) -> String {
    format!("<msub><mi>{base}</mi><mi>{index}</mi></msub>")
}

fn formula(math: &str, text: &str) -> String {
    format!("<p><math display=block>{math}</math></p><p class=f>{text}</p>")
}

fn metrics() -> String {
    let n = "<mi>N</mi>";
    let em = formula(
        &format!(
            "<mi>EM</mi><mo>=</mo>{}{}",
            frac("<mn>1</mn>", n),
            sum("i", n, &frac(&sub("PS", "i"), &sub("N", "i")))
        ),
        "EM = (1/N) · Σ_i PS_i / N_i",
    );
    let task_mse = sum("j", &sub("n", "i"), &sub("MSE", "j"));
    let p = formula(
        &format!(
            "<mi>P</mi><mo>=</mo>{}<mo>+</mo>{}{}",
            frac("<mn>1</mn>", "<mi>EM</mi>"),
            frac("<mn>1</mn>", n),
            sum(
                "i",
                n,
                &format!(
                    "<mo>(</mo>{}{task_mse}<mo>)</mo>",
                    frac("<mn>1</mn>", &sub("n", "i"))
                )
            )
        ),
        "P = 1/EM + (1/N) · Σ_i ( (1/n_i) · Σ_j MSE_j )",
    );
    let m = formula(
        &format!(
            "<mi>M</mi><mo>=</mo>{}{}",
            frac("<mn>1</mn>", n),
            sum(
                "i",
                n,
                &format!(
                    "<mo>(</mo>{}{}<mo>)</mo>",
                    frac("<mn>1</mn>", &sub("n", "i")),
                    sum(
                        "j",
                        &sub("n", "i"),
                        &format!(
                            "<mo>(</mo>{}<mo>+</mo>{}<mo>)</mo>",
                            sub("EM", "j"),
                            sub("SR", "j")
                        )
                    )
                )
            )
        ),
        "M = (1/N) · Σ_i ( (1/n_i) · Σ_j (EM_j + SR_j) )",
    );
    format!(
        "<h2 id=tracks>Tracks and metrics</h2>\
<p>An instruction (\"put the bowl on the red counter\") has a ground-truth plan of 4 to 8 steps \
(<code>move to the blue zone</code>, <code>pick the bowl</code>, <code>place the bowl</code>). \
<i>N</i> is the number of instructions, <i>n<sub>i</sub></i> the number of tasks (plan steps) of instruction <i>i</i>.</p>\
<h3>Planning track: Exact Match (EM), higher is better</h3>\
<p>Turn each instruction into its plan. A predicted step counts only when it matches the \
ground-truth step at the same position character for character; <i>PS<sub>i</sub></i> is the \
number of such steps of plan <i>i</i> and <i>N<sub>i</sub></i> its ground-truth length. \
A missing plan counts 0; extra steps do not raise the score.</p>{em}\
<h3>Control track: Success Rate (SR), higher is better, and MSE, lower is better</h3>\
<p>Serve a policy that drives the mobile robot from two cameras and a sub-task sentence, \
16 future actions of 10 values at a time. The simulator always executes the ground-truth plan. \
A task succeeds (SR<sub>j</sub> = 1) when it is completed within its time limit: a navigation task \
when the robot's base centre is within 10 cm of the target, a manipulation task when the object's \
centre is within 5 cm of its target; success is checked after every action. MSE is the mean \
squared error between the policy's predicted action chunks and the expert's, averaged over all \
predictions. The board ranks by SR, then lower MSE.</p>\
<h3>Integrated track: M, higher is better, and P, lower is better</h3>\
<p>A plan file and a policy together. M adds each task's exact-match EM<sub>j</sub> (its plan \
step right or not) and its success SR<sub>j</sub>, averaged per instruction, then over \
instructions (so it runs from 0 to 2):</p>{m}\
<p>P combines planning and imitation error; EM = 0 gives P = ∞ (shown as <code>inf</code>):</p>{p}"
    )
}

fn steps(s: &AppState) -> String {
    let episodes = match s.config().control.dev_episodes {
        0 => "every dev instruction".to_string(),
        n => format!("the first {n} dev instructions"),
    };
    format!(
        "<h2 id=steps>How to take part</h2><ol>\
<li><b>Get a team token.</b> The organiser creates your team (<code>kitchen-r team create NAME</code>) \
and hands you its token once; keep it secret. Command-line tools read it from <code>KITCHEN_R_TOKEN</code>.</li>\
<li><b>Download the data.</b> The instructions and scenes below: the dev split comes with its plans, \
the test split without them.</li>\
<li><b>Planning: submit a plan file.</b> JSON Lines, one <code>{{\"id\": \"dev-0001\", \"plan\": [\"move to the blue zone\", ...]}}</code> \
per instruction: <code>kitchen-r submit plans FILE --split dev</code> or \
<code>POST /api/v1/submissions/plans?split=dev</code> with your token. It is scored at once.</li>\
<li><b>Control: serve your policy and register it.</b> Serve the <code>kitchen_r.policy.v1.Policy</code> \
gRPC service (the starter kit has a Python server), check it with <code>kitchen-r check-policy ENDPOINT</code>, \
then <code>kitchen-r submit policy ENDPOINT --split dev</code> (<code>--plans ID</code> links a plan \
submission for the integrated track). A dev run evaluates {episodes}.</li>\
<li><b>Watch the submission page.</b> <a href=\"/team/login\">Log in with your token</a>: your \
<a href=\"/team\">team page</a> lists every submission; each one's page shows its progress with an ETA \
and, on the dev split, every episode's tasks with why each failed.</li></ol>"
    )
}

fn downloads(s: &AppState) -> String {
    let c = s.content();
    let test_note = match c.test_set.kind {
        TestSetKind::PublicSample => format!(
            " <span class=banner>{}</span>",
            escape(crate::content::PUBLIC_SAMPLE_NOTICE)
        ),
        TestSetKind::Private => String::new(),
    };
    let mut out = format!(
        "<h2 id=data>Dataset and scenes</h2><ul>\
<li><a href=\"/api/v1/dataset/dev\">Dev split</a> ({} instructions, with plans; JSON Lines)</li>\
<li><a href=\"/api/v1/dataset/test\">Test split</a> ({} instructions, no plans){test_note}</li>\
<li><a href=\"/api/v1/dataset/manifest\">What the splits are</a> (JSON) · \
<a href=\"/api/v1/scenes\">all scenes</a> (JSON)</li></ul>\
<p>Each scene's top-down image shows its coloured zones and key objects; its brief describes \
them in words for planners (the robot's policy never sees zone colours).</p><div>",
        c.dataset.dev.len(),
        c.test_set.instructions,
    );
    for scene in c.scene_summaries() {
        let id = escape(&scene.id);
        let _ = write!(
            out,
            "<figure><a href=\"/api/v1/scenes/{id}/topdown.png\"><img src=\"/api/v1/scenes/{id}/topdown.png\" \
alt=\"Top-down view of {name}\" width=320 loading=lazy></a><figcaption><b>{name}</b> (<code>{id}</code>): {desc} \
<a href=\"/api/v1/scenes/{id}/brief\">brief</a> · <a href=\"/api/v1/scenes/{id}\">JSON</a></figcaption></figure>",
            name = escape(&scene.name),
            desc = escape(&scene.description),
        );
    }
    out.push_str("</div>");
    out
}

fn per_day(n: u32) -> String {
    match n {
        0 => "unlimited".into(),
        n => format!("{n} per UTC day"),
    }
}

fn rules(s: &AppState) -> String {
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
    format!(
        "<h2 id=rules>Rules</h2><h3>Quotas</h3><ul>\
<li>Dev split: {dev} submissions; test split: {test} (plan files and policy registrations alike). \
Runs the platform could not evaluate and runs the organiser cancelled do not count.</li>\
<li>{rate}; {concurrent}.</li>\
<li>Each task of a policy run has {limit} simulated seconds.</li></ul>\
<h3>What feedback shows</h3><ul>\
<li>Dev split: everything: per-instruction plan results, and per episode each task's result and why it failed.</li>\
<li>Test split: aggregate only: the scores, progress counts and how often each kind of failure happened.</li></ul>\
<h3>Integrity rules</h3>{INTEGRITY_RULES}",
        dev = per_day(q.dev_per_day),
        test = per_day(q.test_per_day),
        limit = c.task_time_limit_s,
    )
}

/// The contest home's body.
pub(super) fn body(s: &AppState) -> String {
    format!(
        "<p>Kitchen-R is a benchmark for language-guided mobile manipulation in a simulated kitchen: \
plan from an English instruction, then drive a mobile robot through the plan. \
See the <a href=\"/\">leaderboard</a>.</p>\
<p><a href=\"#tracks\">Tracks and metrics</a> · <a href=\"#steps\">How to take part</a> · \
<a href=\"#data\">Dataset and scenes</a> · <a href=\"#rules\">Rules</a> · <a href=\"#api\">API</a></p>\
{}{}{}{}\
<h2 id=api>API</h2><p>JSON over HTTP under <code>/api/v1</code>, with <code>Authorization: Bearer TOKEN</code>: \
<a href=\"/api/v1/leaderboard?track=planning&amp;split=test\">leaderboard</a> \
(<code>?track=planning|control|integrated&amp;split=dev|test&amp;format=json|csv|html</code>), \
<code>POST /api/v1/submissions/plans?split=</code>, <code>POST /api/v1/submissions/policies</code>, \
<code>GET /api/v1/submissions/ID</code>, <a href=\"/api/v1/scenes\">scenes</a>, \
<a href=\"/api/v1/dataset/manifest\">dataset</a>. Errors are <code>{{\"error\", \"code\", \"request_id\"}}</code>.</p>\
<p>Every route, its parameters, bodies and answers: the <a href=\"/api/docs\">API reference</a> \
(<a href=\"/api/v1/openapi.json\">OpenAPI document</a>).</p>",
        metrics(),
        steps(s),
        downloads(s),
        rules(s),
    )
}
