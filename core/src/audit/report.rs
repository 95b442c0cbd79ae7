//! The audit's verdict: one check per threshold, and the readable summary.

use std::fmt::Write as _;

use serde::Serialize;

use super::{AuditReport, Thresholds};

/// One threshold applied to one figure.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Check {
    pub name: &'static str,
    /// `None` when the figure could not be computed (no ground truth, oracle not run).
    pub value: Option<f64>,
    pub limit: f64,
    pub passed: bool,
    /// What to do when it fails.
    pub advice: &'static str,
}

const ATTACK_ADVICE: &str = "public templates and dev instructions invert this set: generate it with private \
     phrasings that no public file contains (`kitchen-r dataset generate --seed SECRET --phrasings \
     FILE --out DIR`)";
const PHRASING_ADVICE: &str = "some test instructions use a public phrasing (assets/templates.toml or the \
     public dev split): remove or reword those phrasings in the private phrasings file and regenerate";
const SHARED_ADVICE: &str = "too many test plans repeat a public plan in the same scene (a dev plan, or \
     the public sample's answer under the same id, which a reused public seed gives): regenerate with \
     another secret seed";
const MENTIONS_ADVICE: &str = "the objects and places an instruction mentions, in the order mentioned, give its \
     plan away: compose the test split with language features (`dataset generate --language all`, the \
     default with --phrasings) or vary mention order in the private phrasings";
const PARSER_ADVICE: &str = "the starter kit's rule-based parser solves this set, so it cannot tell planners \
     apart: compose the test split with language features (the default with --phrasings) and give \
     the private phrasings file a [language] table of wording no public file contains";
const ORACLE_ADVICE: &str = "the oracle cannot complete the listed instructions: fix the scenes or \
     templates that produce them (see the reasons) and regenerate; a contest set must be executable";

impl AuditReport {
    /// Every threshold against this report. A figure that was not computed passes (and says so).
    pub fn checks(&self, t: &Thresholds) -> Vec<Check> {
        let check = |name, value: Option<f64>, limit: f64, advice| Check {
            name,
            value,
            limit,
            passed: value.is_none_or(|v| v <= limit + 1e-12),
            advice,
        };
        vec![
            check(
                "attack EM",
                self.attack.as_ref().map(|a| a.em),
                t.max_attack_em,
                ATTACK_ADVICE,
            ),
            check(
                "public phrasing share",
                Some(self.public_phrasing_share),
                t.max_public_phrasing_share,
                PHRASING_ADVICE,
            ),
            check(
                "shared (scene, plan) pairs",
                self.shared_plans.as_ref().map(|s| s.len() as f64),
                t.max_shared_plans as f64,
                SHARED_ADVICE,
            ),
            check(
                "bag-of-mentions EM",
                self.attack.as_ref().map(|a| a.fallback_em),
                t.max_bag_of_mentions_em,
                MENTIONS_ADVICE,
            ),
            check(
                "parser EM",
                self.parser.as_ref().map(|p| p.em),
                t.max_parser_em,
                PARSER_ADVICE,
            ),
            check(
                "oracle failures",
                self.oracle.as_ref().map(|o| o.failures.len() as f64),
                t.max_oracle_failures as f64,
                ORACLE_ADVICE,
            ),
        ]
    }

    /// The summary printed by `kitchen-r dataset audit`.
    pub fn render(&self, checks: &[Check]) -> String {
        let mut s = String::new();
        let n = self.test_instructions;
        let kind = self.kind.as_deref().unwrap_or("none given");
        let _ = writeln!(s, "audit of {}  (kind: {kind}, {n} test instructions)", self.dir);
        let _ = writeln!(
            s,
            "attack library: {} template phrasings, {} dev phrasings (public material only)",
            self.library_template_phrasings, self.library_dev_phrasings
        );
        let _ = writeln!(s, "\npublic phrasings in the test split");
        let row = |s: &mut String, what: &str, k: usize| {
            let _ = writeln!(s, "  {what:<34} {k:>5}  {:>6.1} %", pct(k, n));
        };
        row(&mut s, "template phrasing", self.template_phrasing);
        row(&mut s, "dev phrasing (abstracted)", self.dev_phrasing);
        row(&mut s, "dev text verbatim", self.dev_text);
        row(&mut s, "any of these", self.public_phrasing);
        for l in self.leaks.iter().take(5) {
            let _ = writeln!(s, "    {} ({}): {:?} via {}", l.id, l.scene, l.instruction, l.via);
        }
        if self.leaks.len() > 5 {
            let _ = writeln!(s, "    … {} more (--json lists all)", self.leaks.len() - 5);
        }
        match &self.attack {
            Some(a) => {
                let _ = writeln!(
                    s,
                    "\nplanners that do not understand language (EM against the ground truth)"
                );
                let _ = writeln!(
                    s,
                    "  bag-of-mentions guess              {:.3}  (mentions in order, most common public plan shape)",
                    a.fallback_em
                );
                let _ = writeln!(s, "  public template inverter           {:.3}", a.em);
                match (&self.parser, &self.parser_note) {
                    (Some(p), note) => {
                        let _ = writeln!(
                            s,
                            "  starter kit's parser               {:.3}  ({})",
                            p.em,
                            note.as_deref().unwrap_or("plans given")
                        );
                    }
                    (None, Some(note)) => {
                        let _ = writeln!(s, "  starter kit's parser               not run: {note}");
                    }
                    (None, None) => {
                        let _ = writeln!(s, "  starter kit's parser               not run");
                    }
                }
                let _ = writeln!(s, "\ntemplate-inversion attack");
                row(&mut s, "inverted by a public phrasing", a.inverted);
                row(&mut s, "plans entirely right", a.perfect);
                if let Some(p) = &self.parser {
                    let _ = writeln!(s, "\nstarter kit's parser");
                    row(&mut s, "plans entirely right", p.perfect);
                    row(&mut s, "no plan given", p.missing);
                }
            }
            None => {
                let _ = writeln!(
                    s,
                    "\nno test_ground_truth.jsonl: attack EM, planner EMs and shared plans not computed"
                );
            }
        }
        if let Some(l) = &self.language {
            let features: Vec<&str> = l.features.iter().map(|f| f.as_str()).collect();
            let _ = writeln!(s, "\nlanguage features: {}", features.join(", "));
            row(&mut s, "composed", l.composed);
            row(&mut s, "kept the template phrasing", l.template_phrased);
            let refused: usize = l.rejected.values().sum();
            let _ = writeln!(s, "  renderings refused by the uniqueness checker: {refused}");
            for (reason, k) in &l.rejected {
                let _ = writeln!(s, "    {reason:<32} {k:>5}");
            }
        }
        if let Some(shared) = &self.shared_plans {
            let _ = writeln!(
                s,
                "\n(scene, plan) pairs also in public material (dev split, or the public sample's answer \
                 under the same id): {}",
                shared.len()
            );
            for p in shared.iter().take(5) {
                let _ = writeln!(s, "    {} = {} ({})", p.test_id, p.public_id, p.scene);
            }
        }
        if let Some(o) = &self.oracle {
            let _ = writeln!(
                s,
                "\noracle: {} of {} instructions not completed",
                o.failures.len(),
                o.episodes
            );
            for f in &o.failures {
                let _ = writeln!(s, "    {} ({}): {}", f.id, f.scene, f.reasons.join("; "));
            }
        }
        let _ = writeln!(s, "\nchecks");
        for c in checks {
            let value = c
                .value
                .map_or_else(|| "not run".to_string(), |v| format!("{v:.3}"));
            let verdict = if c.value.is_none() {
                "-"
            } else if c.passed {
                "PASS"
            } else {
                "FAIL"
            };
            let _ = writeln!(
                s,
                "  {verdict:<4}  {:<28} {value:>8}  (limit {:.3})",
                c.name, c.limit
            );
        }
        let failed: Vec<&Check> = checks.iter().filter(|c| !c.passed).collect();
        if failed.is_empty() {
            let _ = writeln!(s, "\nthe set passes the audit");
        } else {
            let _ = writeln!(s, "\nthe set FAILS the audit:");
            for c in &failed {
                let _ = writeln!(s, "  - {}: {}", c.name, c.advice);
            }
        }
        if self.public_sample {
            let _ = writeln!(
                s,
                "\nnote: this is a public sample (manifest kind: {kind}): its answers can be rebuilt \
                 from public files, so failing the audit is expected. A contest runs on a private set \
                 generated outside the repository with a secret seed and private phrasings."
            );
        }
        s
    }
}

fn pct(k: usize, n: usize) -> f64 {
    if n == 0 { 0.0 } else { 100.0 * k as f64 / n as f64 }
}
