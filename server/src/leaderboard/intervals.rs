//! The 95 % interval of every score a board shows (docs/reference/leaderboard.md#intervals),
//! computed from what the score was computed from: a plan run's instructions, a policy run's
//! recorded episodes. Pure: the service hands the numbers in.
//!
//! - EM, SR and M are means of values in `[0, 1]` (M: `[0, 2]`, halved) over instructions
//!   (planning EM: the split's plans; SR and M: the online episodes). Their interval is Wilson's
//!   of that mean over that many units (`kitchen_r_core::interval::wilson95_of_mean`), which a
//!   mean of values in `[0, 1]` never needs wider.
//! - SR per task kind (navigation, manipulation, pick, place) is a proportion of tasks: Wilson's
//!   interval of successes out of tasks.
//! - MSE is a mean over predictions weighted by samples: the normal interval over offline tasks
//!   (each task's mean MSE weighted by its samples), clamped at 0.
//! - P = 1/EM + T: its bounds take EM's interval and the normal interval of T (the mean over
//!   instructions of their tasks' mean MSE); unbounded above while EM's interval reaches 0.

use std::collections::BTreeMap;

use kitchen_r_core::interval::{Z95, wilson95, wilson95_of_mean};
use kitchen_r_core::metrics::mean;
use kitchen_r_core::plan::Step;
use kitchen_r_core::scoring::{Episode, Mode};
use serde::Serialize;
use serde::ser::{SerializeSeq, Serializer};

/// A 95 % interval `[low, high]`; JSON writes it as a two-element list, `"inf"` for an
/// unbounded end (P's, while EM's interval reaches 0).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Interval {
    pub low: f64,
    pub high: f64,
}

impl Interval {
    fn of((low, high): (f64, f64)) -> Interval {
        Interval { low, high }
    }

    /// Whether the two intervals share a point.
    pub(crate) fn overlaps(&self, other: &Interval) -> bool {
        kitchen_r_core::interval::overlap((self.low, self.high), (other.low, other.high))
    }
}

impl Serialize for Interval {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let bound = |x: f64| match x {
            x if x.is_finite() => serde_json::json!(x),
            x if x > 0.0 => serde_json::json!("inf"),
            _ => serde_json::json!("-inf"),
        };
        let mut seq = s.serialize_seq(Some(2))?;
        seq.serialize_element(&bound(self.low))?;
        seq.serialize_element(&bound(self.high))?;
        seq.end()
    }
}

/// An interval in the OpenAPI document: two scores, `[low, high]`, either of which may be
/// `"inf"`.
fn interval_schema() -> impl Into<utoipa::openapi::RefOr<utoipa::openapi::schema::Schema>> {
    utoipa::openapi::schema::ArrayBuilder::new()
        .items(
            Into::<utoipa::openapi::RefOr<utoipa::openapi::schema::Schema>>::into(
                crate::scores::score_schema(),
            ),
        )
        .min_items(Some(2))
        .max_items(Some(2))
        .description(Some("A 95 % interval [low, high]; an unbounded end is \"inf\"."))
}

/// SR over the tasks of one kind.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, utoipa::ToSchema)]
pub(crate) struct KindSr {
    pub successes: u64,
    pub tasks: u64,
    pub sr: f64,
    /// 95 % Wilson interval `[low, high]` of successes out of tasks.
    #[schema(schema_with = interval_schema)]
    pub interval: Interval,
}

/// The task kinds of the per-kind SR, in the CSV's column order.
pub(crate) const KINDS: [&str; 4] = ["navigation", "manipulation", "pick", "place"];

/// The 95 % intervals of a row's scores, each `[low, high]`; a score the row does not show has
/// none.
#[derive(Debug, Clone, Default, PartialEq, Serialize, utoipa::ToSchema)]
pub(crate) struct Intervals {
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(schema_with = interval_schema, nullable = false)]
    pub em: Option<Interval>,
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(schema_with = interval_schema, nullable = false)]
    pub sr: Option<Interval>,
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(schema_with = interval_schema, nullable = false)]
    pub mse: Option<Interval>,
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(schema_with = interval_schema, nullable = false)]
    pub m: Option<Interval>,
    /// P's upper end is `"inf"` while EM's interval reaches 0.
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(schema_with = interval_schema, nullable = false)]
    pub p: Option<Interval>,
    /// Policy rows: SR per task kind (`navigation`, `manipulation`, `pick`, `place`) with
    /// Wilson's interval of successes out of tasks.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub sr_by_kind: BTreeMap<String, KindSr>,
}

/// A planning row: EM over `instructions` plans.
pub(crate) fn planning(em: Option<f64>, instructions: u64) -> Intervals {
    Intervals {
        em: em.map(|em| Interval::of(wilson95_of_mean(em, instructions))),
        ..Intervals::default()
    }
}

/// The scores a policy row shows, as stored (`em`: the linked plans' EM of an integrated run).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct PolicyScores {
    pub sr: Option<f64>,
    pub mse: Option<f64>,
    pub em: Option<f64>,
    pub m: Option<f64>,
    pub p: Option<f64>,
}

/// A policy row: its scores and the recorded episodes they were computed from.
pub(crate) fn policy(scores: PolicyScores, episodes: &[Episode]) -> Intervals {
    let online: Vec<&Episode> = episodes.iter().filter(|e| e.mode == Mode::Online).collect();
    let offline: Vec<&Episode> = episodes.iter().filter(|e| e.mode == Mode::Offline).collect();
    let n_online = online.len() as u64;
    let sr = scores.sr.map(|sr| Interval::of(wilson95_of_mean(sr, n_online)));
    let m = scores.m.map(|m| {
        let (lo, hi) = wilson95_of_mean(m / 2.0, n_online);
        Interval::of((2.0 * lo, 2.0 * hi))
    });
    let mse = scores.mse.map(|centre| {
        let tasks: Vec<(f64, f64)> = (offline.iter())
            .flat_map(|e| e.mse_samples())
            .map(|(mse, k)| (mse, f64::from(k)))
            .collect();
        Interval::of(weighted_normal(centre, &tasks))
    });
    let p = scores.p.zip(scores.em).map(|(p, em)| {
        let n = if online.is_empty() {
            offline.len()
        } else {
            online.len()
        };
        let (em_lo, em_hi) = wilson95_of_mean(em, n as u64);
        let term = if p.is_finite() && em > 0.0 {
            p - 1.0 / em
        } else {
            0.0
        };
        let per_instruction: Vec<(f64, f64)> = (offline.iter())
            .map(|e| (mean(e.mse_samples().into_iter().map(|(m, _)| m)), 1.0))
            .collect();
        let (t_lo, t_hi) = weighted_normal(term, &per_instruction);
        let high = if em_lo > 0.0 {
            1.0 / em_lo + t_hi
        } else {
            f64::INFINITY
        };
        let low = if em_hi > 0.0 {
            1.0 / em_hi + t_lo
        } else {
            f64::INFINITY
        };
        Interval { low, high }
    });
    Intervals {
        em: None,
        sr,
        mse,
        m,
        p,
        sr_by_kind: by_kind(&online),
    }
}

/// The normal 95 % interval around `centre` of values weighted as given (`(value, weight)`),
/// with the effective count `(Σw)² / Σw²`; clamped at 0 (MSEs are not negative). Fewer than
/// two values give no spread to estimate: the point itself.
fn weighted_normal(centre: f64, values: &[(f64, f64)]) -> (f64, f64) {
    let total: f64 = values.iter().map(|(_, w)| w).sum();
    if values.len() < 2 || total <= 0.0 || !centre.is_finite() {
        return (centre, centre);
    }
    let mu = values.iter().map(|(v, w)| v * w).sum::<f64>() / total;
    let var = values.iter().map(|(v, w)| w * (v - mu).powi(2)).sum::<f64>() / total;
    let n_eff = total * total / values.iter().map(|(_, w)| w * w).sum::<f64>();
    let half = Z95 * (var / n_eff).sqrt();
    ((centre - half).max(0.0), centre + half)
}

/// The kinds a plan step counts under (as `kitchen-r eval` reports them): none for a step that
/// is not canonical.
fn kinds(step: &str) -> &'static [&'static str] {
    match step.parse::<Step>() {
        Ok(Step::MoveTo { .. }) => &["navigation"],
        Ok(Step::Pick { .. }) => &["manipulation", "pick"],
        Ok(Step::Place { .. }) => &["manipulation", "place"],
        Err(_) => &[],
    }
}

fn by_kind(online: &[&Episode]) -> BTreeMap<String, KindSr> {
    let mut tally: BTreeMap<&'static str, (u64, u64)> = BTreeMap::new();
    for e in online {
        for (step, ok) in e.plan.iter().zip(e.successes()) {
            for k in kinds(step) {
                let t = tally.entry(k).or_default();
                *t = (t.0 + u64::from(ok), t.1 + 1);
            }
        }
    }
    (tally.into_iter())
        .map(|(k, (ok, n))| {
            let sr = KindSr {
                successes: ok,
                tasks: n,
                sr: ok as f64 / n.max(1) as f64,
                interval: Interval::of(wilson95(ok, n)),
            };
            (k.to_string(), sr)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use kitchen_r_core::scoring::TaskOutcome;

    fn online(plan: &[&str], ok: &[bool]) -> Episode {
        Episode {
            mode: Mode::Online,
            instruction_id: "dev-0001".into(),
            plan: plan.iter().map(|s| s.to_string()).collect(),
            task_count: plan.len(),
            tasks: (ok.iter().enumerate())
                .map(|(i, s)| TaskOutcome {
                    index: i as u32,
                    success: *s,
                    ..TaskOutcome::default()
                })
                .collect(),
            failure: None,
        }
    }

    #[test]
    fn sr_and_its_kinds_get_wilson_intervals() {
        let plan = ["move to the red zone", "pick the bowl", "place the bowl"];
        let eps = vec![
            online(&plan, &[true, true, false]),
            online(&plan, &[true, false, false]),
        ];
        let sr = Some(0.5);
        let iv = policy(
            PolicyScores {
                sr,
                ..PolicyScores::default()
            },
            &eps,
        );
        let got = iv.sr.unwrap();
        let (lo, hi) = wilson95_of_mean(0.5, 2);
        assert_eq!((got.low, got.high), (lo, hi));
        let nav = iv.sr_by_kind["navigation"];
        assert_eq!((nav.successes, nav.tasks), (2, 2));
        assert_eq!((nav.interval.low, nav.interval.high), wilson95(2, 2));
        assert_eq!(iv.sr_by_kind["manipulation"].tasks, 4);
        assert_eq!(iv.sr_by_kind["place"].successes, 0);
        assert!(iv.mse.is_none() && iv.p.is_none() && iv.em.is_none());
    }

    #[test]
    fn p_is_unbounded_above_while_em_may_be_zero_and_written_inf() {
        let iv = policy(
            PolicyScores {
                em: Some(0.0),
                p: Some(f64::INFINITY),
                ..PolicyScores::default()
            },
            &[],
        );
        let p = iv.p.unwrap();
        assert!(p.high.is_infinite());
        assert_eq!(serde_json::to_string(&p).unwrap(), r#"[1.0,"inf"]"#);
    }

    #[test]
    fn mse_interval_is_normal_over_weighted_tasks_and_never_negative() {
        let (lo, hi) = weighted_normal(0.1, &[(0.0, 1.0), (0.2, 1.0)]);
        assert!(lo == 0.0 && hi > 0.2, "{lo} {hi}");
        assert_eq!(weighted_normal(0.3, &[(0.3, 5.0)]), (0.3, 0.3));
    }

    #[test]
    fn planning_em_is_wilson_over_instructions() {
        let iv = planning(Some(0.8), 10).em.unwrap();
        assert_eq!((iv.low, iv.high), wilson95(8, 10));
        assert!(planning(None, 10).em.is_none());
    }
}
