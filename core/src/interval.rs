//! Confidence intervals of success rates: the Wilson score interval, sound at 0 and 1 and for
//! small counts, unlike the normal approximation (which gives `[1, 1]` for 5 successes of 5).

/// z of a two-sided 95 % interval.
pub const Z95: f64 = 1.959_963_984_540_054;

/// The 95 % Wilson score interval `(low, high)` of `successes` out of `n`; `(0, 1)` when `n` is
/// 0 (nothing is known).
pub fn wilson95(successes: u64, n: u64) -> (f64, f64) {
    wilson(successes, n, Z95)
}

/// The Wilson score interval for `z` standard deviations.
pub fn wilson(successes: u64, n: u64, z: f64) -> (f64, f64) {
    wilson_of_mean(successes.min(n) as f64 / n.max(1) as f64, n, z)
}

/// The 95 % Wilson interval of a mean of `n` values each in `[0, 1]` (a mean of per-episode
/// success rates, an exact-match proportion over instructions): the proportion's formula with
/// `mean` for `successes / n`. Such values vary at most as much as successes and failures do,
/// so the interval is at least as wide as it needs to be. `(0, 1)` when `n` is 0.
pub fn wilson95_of_mean(mean: f64, n: u64) -> (f64, f64) {
    wilson_of_mean(mean, n, Z95)
}

fn wilson_of_mean(mean: f64, n: u64, z: f64) -> (f64, f64) {
    if n == 0 || mean.is_nan() {
        return (0.0, 1.0);
    }
    let (p, n) = (mean.clamp(0.0, 1.0), n as f64);
    let z2 = z * z;
    let centre = (p + z2 / (2.0 * n)) / (1.0 + z2 / n);
    let half = z / (1.0 + z2 / n) * (p * (1.0 - p) / n + z2 / (4.0 * n * n)).sqrt();
    ((centre - half).max(0.0), (centre + half).min(1.0))
}

/// Whether two intervals share a point.
pub fn overlap(a: (f64, f64), b: (f64, f64)) -> bool {
    a.0 <= b.1 && b.0 <= a.1
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wilson_matches_hand_computed_values() {
        // 8 of 10: centre 0.7167, half-width 0.2096 (e.g. Newcombe 1998, method 3).
        let (lo, hi) = wilson95(8, 10);
        assert!((lo - 0.4902).abs() < 1e-4, "{lo}");
        assert!((hi - 0.9433).abs() < 1e-4, "{hi}");
        // Sound at the edges: 0 of 5 and 5 of 5 are not points.
        let (lo, hi) = wilson95(0, 5);
        assert_eq!(lo, 0.0);
        assert!((hi - 0.4345).abs() < 1e-4, "{hi}");
        let (lo, hi) = wilson95(5, 5);
        assert!((lo - 0.5655).abs() < 1e-4, "{lo}");
        assert!((hi - 1.0).abs() < 1e-12, "{hi}");
        assert_eq!(wilson95(0, 0), (0.0, 1.0));
        assert!(overlap(wilson95(5, 10), wilson95(7, 10)));
        assert!(!overlap(wilson95(0, 50), wilson95(50, 50)));
        assert_eq!(wilson95_of_mean(0.8, 10), wilson95(8, 10));
        assert_eq!(wilson95_of_mean(0.5, 0), (0.0, 1.0));
    }
}
