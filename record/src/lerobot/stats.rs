//! Feature statistics as LeRobot computes and aggregates them (`compute_stats.py`): per
//! dimension min, max, mean, std (population), count and the quantiles q01, q10, q50, q90, q99;
//! image features per channel in [0, 1] with shape (3, 1, 1).
//!
//! Per-episode quantiles are exact (sorted values; pixel histograms); aggregated ones are the
//! envelope LeRobot uses (lowest of the lower quantiles, highest of the upper), which bounds
//! the true quantile.

use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

/// LeRobot's `DEFAULT_QUANTILES`.
pub(crate) const QUANTILES: [(&str, f64); 5] = [
    ("q01", 0.01),
    ("q10", 0.10),
    ("q50", 0.50),
    ("q90", 0.90),
    ("q99", 0.99),
];

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct FeatureStats {
    pub min: Vec<f64>,
    pub max: Vec<f64>,
    pub mean: Vec<f64>,
    pub std: Vec<f64>,
    pub count: u64,
    /// One vector per entry of [`QUANTILES`], in that order.
    pub quantiles: Vec<Vec<f64>>,
    /// Per-channel image statistics: written with shape (C, 1, 1).
    #[serde(default)]
    pub image: bool,
}

impl FeatureStats {
    /// Statistics of `rows` (each of `dim` values).
    pub(crate) fn of_rows(values: &[f32], dim: usize) -> FeatureStats {
        let n = values.len().checked_div(dim).unwrap_or(0);
        let column = |d: usize| -> Vec<f64> {
            let mut c: Vec<f64> = (0..n).map(|r| f64::from(values[r * dim + d])).collect();
            c.sort_by(f64::total_cmp);
            c
        };
        let cols: Vec<Vec<f64>> = (0..dim).map(column).collect();
        let mean: Vec<f64> = cols
            .iter()
            .map(|c| c.iter().sum::<f64>() / n.max(1) as f64)
            .collect();
        let std = cols
            .iter()
            .zip(&mean)
            .map(|(c, m)| (c.iter().map(|x| (x - m).powi(2)).sum::<f64>() / n.max(1) as f64).sqrt())
            .collect();
        let quantiles = QUANTILES
            .iter()
            .map(|(_, q)| {
                // LeRobot falls back to the mean below two samples.
                if n < 2 {
                    mean.clone()
                } else {
                    cols.iter().map(|c| interpolate(c, *q)).collect()
                }
            })
            .collect();
        FeatureStats {
            min: cols.iter().map(|c| c.first().copied().unwrap_or(0.0)).collect(),
            max: cols.iter().map(|c| c.last().copied().unwrap_or(0.0)).collect(),
            mean,
            std,
            count: n as u64,
            quantiles,
            image: false,
        }
    }

    /// Per-channel statistics in [0, 1] from 256-bin histograms of 8-bit values, over `frames`
    /// images.
    pub(crate) fn of_histograms(hists: &[[u64; 256]], frames: u64) -> FeatureStats {
        let mut s = FeatureStats {
            min: Vec::new(),
            max: Vec::new(),
            mean: Vec::new(),
            std: Vec::new(),
            count: frames,
            quantiles: vec![Vec::new(); QUANTILES.len()],
            image: true,
        };
        for h in hists {
            let total: u64 = h.iter().sum();
            let n = total.max(1) as f64;
            let mean = h
                .iter()
                .enumerate()
                .map(|(v, c)| v as f64 * *c as f64)
                .sum::<f64>()
                / n;
            let var = h
                .iter()
                .enumerate()
                .map(|(v, c)| (v as f64 - mean).powi(2) * *c as f64)
                .sum::<f64>()
                / n;
            let first = h.iter().position(|c| *c > 0).unwrap_or(0);
            let last = h.iter().rposition(|c| *c > 0).unwrap_or(0);
            s.min.push(first as f64 / 255.0);
            s.max.push(last as f64 / 255.0);
            s.mean.push(mean / 255.0);
            s.std.push(var.sqrt() / 255.0);
            for (i, (_, q)) in QUANTILES.iter().enumerate() {
                let target = q * total as f64;
                let mut seen = 0u64;
                let v = h
                    .iter()
                    .position(|c| {
                        seen += c;
                        seen as f64 >= target
                    })
                    .unwrap_or(255);
                s.quantiles[i].push(v as f64 / 255.0);
            }
        }
        s
    }

    /// LeRobot's `aggregate_feature_stats`: count-weighted mean, pooled variance, extreme
    /// min/max and the quantile envelope.
    pub(crate) fn aggregate(all: &[&FeatureStats]) -> Option<FeatureStats> {
        let first = *all.first()?;
        let dim = first.mean.len();
        let total: u64 = all.iter().map(|s| s.count).sum();
        let n = total.max(1) as f64;
        let per_dim = |f: &dyn Fn(&FeatureStats, usize) -> f64| -> Vec<f64> {
            (0..dim)
                .map(|d| all.iter().map(|s| f(s, d)).sum::<f64>())
                .collect()
        };
        let mean = per_dim(&|s, d| s.mean[d] * s.count as f64 / n);
        let var = per_dim(&|s, d| (s.std[d].powi(2) + (s.mean[d] - mean[d]).powi(2)) * s.count as f64 / n);
        let fold = |pick: &dyn Fn(&FeatureStats) -> &Vec<f64>, low: bool| -> Vec<f64> {
            (0..dim)
                .map(|d| {
                    let it = all.iter().map(|s| pick(s)[d]);
                    if low {
                        it.fold(f64::INFINITY, f64::min)
                    } else {
                        it.fold(f64::NEG_INFINITY, f64::max)
                    }
                })
                .collect()
        };
        let quantiles = QUANTILES
            .iter()
            .enumerate()
            .map(|(i, (_, q))| fold(&|s| &s.quantiles[i], *q <= 0.5))
            .collect();
        Some(FeatureStats {
            min: fold(&|s| &s.min, true),
            max: fold(&|s| &s.max, false),
            mean,
            std: var.into_iter().map(f64::sqrt).collect(),
            count: total,
            quantiles,
            image: first.image,
        })
    }

    /// `(name, values)` of every statistic, `count` last, in LeRobot's naming.
    pub(crate) fn entries(&self) -> Vec<(&'static str, Vec<f64>)> {
        let mut out = vec![
            ("min", self.min.clone()),
            ("max", self.max.clone()),
            ("mean", self.mean.clone()),
            ("std", self.std.clone()),
        ];
        for ((name, _), q) in QUANTILES.iter().zip(&self.quantiles) {
            out.push((name, q.clone()));
        }
        out
    }

    /// The `stats.json` object of this feature.
    pub(crate) fn to_json(&self) -> Value {
        let mut m = serde_json::Map::new();
        for (name, v) in self.entries() {
            m.insert(name.into(), self.shaped(&v));
        }
        m.insert("count".into(), json!([self.count]));
        Value::Object(m)
    }

    /// Image statistics nest each channel's value as `[[v]]` (shape (C, 1, 1)).
    pub(crate) fn shaped(&self, v: &[f64]) -> Value {
        if self.image {
            Value::Array(v.iter().map(|x| json!([[x]])).collect())
        } else {
            json!(v)
        }
    }
}

/// numpy's default (linear) quantile of sorted values.
fn interpolate(sorted: &[f64], q: f64) -> f64 {
    let pos = q * (sorted.len() - 1) as f64;
    let (lo, hi) = (pos.floor() as usize, pos.ceil() as usize);
    sorted[lo] + (sorted[hi] - sorted[lo]) * (pos - lo as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn row_stats_match_numpy() {
        // Two dims: 1..=5 and 10..=50.
        let v: Vec<f32> = (1..=5).flat_map(|i| [i as f32, 10.0 * i as f32]).collect();
        let s = FeatureStats::of_rows(&v, 2);
        assert_eq!(
            (s.min.clone(), s.max.clone(), s.count),
            (vec![1.0, 10.0], vec![5.0, 50.0], 5)
        );
        assert_eq!(s.mean, vec![3.0, 30.0]);
        assert!((s.std[0] - 2f64.sqrt()).abs() < 1e-12);
        assert!(
            (s.quantiles[0][0] - 1.04).abs() < 1e-12,
            "np.quantile(1..5, .01) = 1.04"
        );
        assert_eq!(s.quantiles[2], vec![3.0, 30.0]);
    }

    #[test]
    fn aggregation_pools_mean_and_variance() {
        let a = FeatureStats::of_rows(&[1.0, 2.0], 1);
        let b = FeatureStats::of_rows(&[3.0, 4.0, 5.0], 1);
        let all = FeatureStats::of_rows(&[1.0, 2.0, 3.0, 4.0, 5.0], 1);
        let agg = FeatureStats::aggregate(&[&a, &b]).unwrap();
        assert_eq!(agg.count, 5);
        assert!((agg.mean[0] - all.mean[0]).abs() < 1e-12);
        assert!((agg.std[0] - all.std[0]).abs() < 1e-12);
        assert_eq!((agg.min[0], agg.max[0]), (1.0, 5.0));
    }

    #[test]
    fn image_stats_are_per_channel_in_unit_range_and_nested() {
        let mut h = [[0u64; 256]; 3];
        h[0][0] = 2;
        h[0][255] = 2;
        h[1][51] = 4;
        h[2][255] = 4;
        let s = FeatureStats::of_histograms(&h, 1);
        assert_eq!(s.mean, vec![0.5, 0.2, 1.0]);
        assert_eq!(s.std[0], 0.5);
        assert_eq!(s.to_json()["mean"], json!([[[0.5]], [[0.2]], [[1.0]]]));
        assert_eq!(s.to_json()["count"], json!([1]));
    }
}
