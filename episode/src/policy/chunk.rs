//! Tolerant, accounted chunk checks (contract v1.1, `ActionChunk` in `policy.proto`).
//!
//! Learned models emit f32 quaternions whose norm drifts and gripper values a hair outside
//! [0, 1]; failing a whole task for that measures numerics, not manipulation. Within the
//! organiser's [`ChunkTolerance`] such values are corrected (quaternion normalised, gripper
//! clamped) and every correction is counted, so the participant sees a warning with the task;
//! beyond it the task fails with the reason, as before.

use serde::{Deserialize, Serialize};

use super::{ACTION_DIM, PolicyError};

/// A quaternion norm this close to 1 is f32 rounding, not a slip: left exactly as sent and not
/// counted, so a well-behaved policy's actions reach the simulator bit for bit.
const QUIET_NORM_ERROR: f64 = 1e-6;

/// How far a chunk may be off before it fails the task (`[policy]` in the server config).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ChunkTolerance {
    /// Largest |‖q‖ − 1| of an action's quaternion that is normalised instead of failing.
    pub quat_norm: f64,
    /// Largest distance of a gripper value outside [0, 1] that is clamped instead of failing.
    pub gripper_margin: f64,
}

impl Default for ChunkTolerance {
    fn default() -> Self {
        ChunkTolerance {
            quat_norm: 0.1,
            gripper_margin: 0.05,
        }
    }
}

impl ChunkTolerance {
    /// Both tolerances finite and in [0, 1] (a wider margin would hide real errors).
    pub fn validate(&self) -> Result<(), String> {
        for (name, v) in [
            ("quat_norm_tolerance", self.quat_norm),
            ("gripper_margin", self.gripper_margin),
        ] {
            if !(0.0..=1.0).contains(&v) {
                return Err(format!("{name} is {v}, must be in [0, 1]"));
            }
        }
        Ok(())
    }
}

/// What [`check_chunk`] corrected, summed over a task's chunks.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Corrections {
    /// Quaternions normalised.
    pub quaternions: u32,
    /// Gripper values clamped to [0, 1].
    pub grippers: u32,
    /// Largest |‖q‖ − 1| normalised.
    pub max_quat_error: f64,
    /// Largest distance of a clamped gripper value from [0, 1].
    pub max_gripper_excess: f64,
}

impl Corrections {
    pub fn total(&self) -> u32 {
        self.quaternions + self.grippers
    }

    pub fn add(&mut self, o: &Corrections) {
        self.quaternions += o.quaternions;
        self.grippers += o.grippers;
        self.max_quat_error = self.max_quat_error.max(o.max_quat_error);
        self.max_gripper_excess = self.max_gripper_excess.max(o.max_gripper_excess);
    }

    /// The warning shown with the task; `None` when nothing was corrected.
    pub fn warning(&self) -> Option<String> {
        if self.total() == 0 {
            return None;
        }
        let mut parts = Vec::new();
        if self.quaternions > 0 {
            parts.push(format!(
                "{} quaternions normalised (largest norm error {:.4})",
                self.quaternions, self.max_quat_error
            ));
        }
        if self.grippers > 0 {
            parts.push(format!(
                "{} gripper values clamped to [0, 1] (largest excess {:.4})",
                self.grippers, self.max_gripper_excess
            ));
        }
        Some(format!("{} corrections: {}", self.total(), parts.join(", ")))
    }
}

/// Check `chunk` in place: shape, finiteness, then each action's quaternion and gripper within
/// `tol`, corrected where needed. `Err` names the first defect beyond tolerance.
pub fn check_chunk(
    chunk: &mut [[f64; ACTION_DIM]],
    horizon: usize,
    tol: &ChunkTolerance,
) -> Result<Corrections, PolicyError> {
    if chunk.len() != horizon {
        return Err(PolicyError::BadChunk(format!(
            "expected {horizon} actions of {ACTION_DIM} values, got {} actions",
            chunk.len()
        )));
    }
    let mut c = Corrections::default();
    for (i, a) in chunk.iter_mut().enumerate() {
        if let Some(j) = a.iter().position(|v| !v.is_finite()) {
            return Err(PolicyError::BadChunk(format!(
                "action {i} value {j} is not finite"
            )));
        }
        let g = a[9];
        let excess = (-g).max(g - 1.0);
        if excess > tol.gripper_margin {
            return Err(PolicyError::BadChunk(format!(
                "action {i}: gripper {g} outside [0, 1] (margin {})",
                tol.gripper_margin
            )));
        }
        if excess > 0.0 {
            a[9] = g.clamp(0.0, 1.0);
            c.grippers += 1;
            c.max_gripper_excess = c.max_gripper_excess.max(excess);
        }
        let n = a[5..9].iter().map(|q| q * q).sum::<f64>().sqrt();
        let err = (n - 1.0).abs();
        if err > tol.quat_norm.max(QUIET_NORM_ERROR) {
            return Err(PolicyError::BadChunk(format!(
                "action {i}: quaternion norm {n:.4} is not 1 (tolerance {})",
                tol.quat_norm
            )));
        }
        if err > QUIET_NORM_ERROR {
            // q and -q are the same rotation: the sign is kept as sent.
            a[5..9].iter_mut().for_each(|q| *q /= n);
            c.quaternions += 1;
            c.max_quat_error = c.max_quat_error.max(err);
        }
    }
    Ok(c)
}

#[cfg(test)]
mod tests {
    use super::super::HORIZON;
    use super::*;

    const GOOD: [f64; 10] = [0.0, 0.0, 0.4, 0.0, 0.9, 1.0, 0.0, 0.0, 0.0, 1.0];

    fn check(chunk: &mut [[f64; 10]]) -> Result<Corrections, PolicyError> {
        check_chunk(chunk, HORIZON, &ChunkTolerance::default())
    }

    #[test]
    fn a_well_formed_chunk_passes_untouched() {
        let mut chunk = [GOOD; HORIZON];
        // f32 rounding of a unit quaternion is not a correction.
        let r = std::f64::consts::FRAC_1_SQRT_2;
        chunk[1][5..9].copy_from_slice(&[f64::from(r as f32), 0.0, 0.0, -f64::from(r as f32)]);
        let before = chunk;
        assert_eq!(check(&mut chunk).unwrap(), Corrections::default());
        assert_eq!(chunk, before, "bit for bit");
    }

    #[test]
    fn slips_within_tolerance_are_corrected_and_counted() {
        let mut chunk = [GOOD; HORIZON];
        chunk[2][5..9].copy_from_slice(&[-1.02, 0.0, 0.0, 0.0]);
        chunk[3][5..9].copy_from_slice(&[0.0, 0.0, 0.0, 0.95]);
        chunk[4][9] = 1.0001;
        chunk[5][9] = -0.03;
        let c = check(&mut chunk).unwrap();
        assert_eq!((c.quaternions, c.grippers, c.total()), (2, 2, 4));
        assert!((c.max_quat_error - 0.05).abs() < 1e-12, "{c:?}");
        assert!((c.max_gripper_excess - 0.03).abs() < 1e-12, "{c:?}");
        assert_eq!(chunk[2][5..9], [-1.0, 0.0, 0.0, 0.0], "normalised, sign kept");
        assert_eq!(chunk[3][5..9], [0.0, 0.0, 0.0, 1.0]);
        assert_eq!((chunk[4][9], chunk[5][9]), (1.0, 0.0), "clamped");
        let w = c.warning().unwrap();
        assert!(w.starts_with("4 corrections: 2 quaternions normalised"), "{w}");
        let mut sum = Corrections::default();
        sum.add(&c);
        sum.add(&c);
        assert_eq!(sum.total(), 8);
        assert_eq!(Corrections::default().warning(), None);
    }

    #[test]
    fn each_defect_beyond_tolerance_is_named() {
        let mut nan = [GOOD; HORIZON];
        nan[3][4] = f64::NAN;
        let mut grip = [GOOD; HORIZON];
        grip[0][9] = 1.06;
        let mut quat = [GOOD; HORIZON];
        quat[7][5] = 1.2;
        let mut short = [GOOD; 3];
        let cases: [(&mut [[f64; 10]], &str); 4] = [
            (&mut short, "got 3 actions"),
            (&mut nan, "action 3 value 4 is not finite"),
            (&mut grip, "action 0: gripper 1.06 outside [0, 1] (margin 0.05)"),
            (
                &mut quat,
                "action 7: quaternion norm 1.2000 is not 1 (tolerance 0.1)",
            ),
        ];
        for (chunk, needle) in cases {
            let err = check(chunk).unwrap_err().to_string();
            assert!(err.contains(needle), "{err:?} lacks {needle:?}");
        }
    }

    #[test]
    fn zero_tolerance_is_strict() {
        let strict = ChunkTolerance {
            quat_norm: 0.0,
            gripper_margin: 0.0,
        };
        let mut chunk = [GOOD; HORIZON];
        chunk[0][9] = 1.0001;
        assert!(check_chunk(&mut chunk, HORIZON, &strict).is_err());
        assert!(
            ChunkTolerance {
                quat_norm: -1.0,
                ..strict
            }
            .validate()
            .is_err()
        );
        assert!(ChunkTolerance::default().validate().is_ok());
    }
}
