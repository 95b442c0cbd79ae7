//! The rule-based path-following controller of the paper (§Navigation Module, after Alhaddad et
//! al. 2022): it turns a waypoint polyline and odometry into base commands `(v, ω)` at 10 Hz.
//!
//! Rules, all constants in [`FollowParams`] (defaults are the paper's):
//! - The active waypoint `k_v` advances while the distance to it, `d_e`, is below 0.35 m. The last
//!   waypoint (the goal) is never advanced past; arrival decides there.
//! - `θe = atan2(sin(α − θ), cos(α − θ))`, α the bearing of the active waypoint.
//! - `|θe| < 0.1`: `v` ramps toward `max_v` = 0.18 m/s by `acc_v·dt` per step (`acc_v` = 0.04
//!   m/s²), `ω = θe`.
//! - `0.1 ≤ |θe| < 1.25`: `ω = k·θe` with `k` = 0.9, 0.85, 0.8, 0.75 on the bands split at 0.38,
//!   0.7 and 1.0 rad. The paper says only that the linear speed limit is "reduced" there; we scale
//!   it by 0.75, 0.5, 0.3 and 0.15 band by band (so the robot arcs gently when slightly off and
//!   barely creeps when nearly sideways), and `v` still ramps up by `acc_v·dt` at most but drops
//!   to the band's limit at once.
//! - `|θe| ≥ 1.25`: `v = 0`, turn in place with `ω = θe` clamped to ±0.7 rad/s. As in the paper
//!   the clamp belongs to this rule only: the 1.0–1.25 band may command up to 0.75·1.25 rad/s and
//!   the twin's own limits apply.
//! - Near-goal deceleration, on the final segment within 1.5 m of the goal. The paper's trigger
//!   also needs `v_cmd > 0.3` m/s, which can never hold under `max_v` = 0.18, so taken literally
//!   the rule would never act. We keep its intent (shrink the local `max_v` each step as the goal
//!   nears, so the 0.09 m arrival circle is not overshot) with a braking curve: the local limit is
//!   `√(2·acc_v·(d_s − 0.09))`, the speed from which `acc_v` stops the robot on the arrival
//!   circle, floored at `min_v` = 0.02 m/s so the last centimetres take finitely many steps.
//! - Arrival when `d_s ≤ 0.09` m (`d_s` the distance to the final goal): `v = 0` from then on and
//!   the final heading correction turns at `ω = ±0.15` rad/s (the sign of `θ_fin − θ`, wrapped)
//!   until `|θ_fin − θ| < 0.1`, then the follower is done and commands zero.

use super::geometry::{P2, dist};

/// A floor pose `[x, y, yaw]` in the world frame (odometry).
pub type Pose2 = [f64; 3];

/// One angular-error band: applies while `|θe| < upto` (and above the previous band).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Band {
    pub upto: f64,
    /// `ω = gain · θe`.
    pub gain: f64,
    /// Fraction of the (local) `max_v` allowed in this band.
    pub v_scale: f64,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FollowParams {
    /// Control period, s (10 Hz).
    pub dt: f64,
    /// A waypoint is reached when closer than this, m.
    pub waypoint_radius: f64,
    pub max_v: f64,
    pub acc_v: f64,
    /// Below this `|θe|` the robot drives straight on at up to `max_v` with `ω = θe`.
    pub aligned: f64,
    /// The gain table; the last band's `upto` is where turning in place starts.
    pub bands: [Band; 4],
    /// |ω| limit when turning in place, rad/s.
    pub max_w: f64,
    /// Deceleration is considered within this distance of the goal on the final segment, m.
    pub decel_distance: f64,
    /// Floor of the decelerating speed limit, m/s.
    pub min_v: f64,
    /// Arrival radius around the final goal, m.
    pub arrive: f64,
    /// Turn rate of the final heading correction, rad/s.
    pub final_w: f64,
    /// The final heading is good when the error is below this, rad.
    pub final_tolerance: f64,
}

impl Default for FollowParams {
    fn default() -> Self {
        let band = |upto, gain, v_scale| Band { upto, gain, v_scale };
        FollowParams {
            dt: 0.1,
            waypoint_radius: 0.35,
            max_v: 0.18,
            acc_v: 0.04,
            aligned: 0.1,
            bands: [
                band(0.38, 0.9, 0.75),
                band(0.7, 0.85, 0.5),
                band(1.0, 0.8, 0.3),
                band(1.25, 0.75, 0.15),
            ],
            max_w: 0.7,
            decel_distance: 1.5,
            min_v: 0.02,
            arrive: 0.09,
            final_w: 0.15,
            final_tolerance: 0.1,
        }
    }
}

/// What the follower is doing this step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FollowStatus {
    /// Driving toward the active waypoint (|θe| < 1.25).
    Driving,
    /// Turning in place toward the active waypoint (|θe| ≥ 1.25).
    Turning,
    /// Arrived; turning in place to the final heading.
    FinalHeading,
    /// Arrived and facing the final heading; commands are zero.
    Done,
}

#[derive(Debug, Clone)]
pub struct PathFollower {
    path: Vec<P2>,
    final_heading: f64,
    params: FollowParams,
    k: usize,
    v: f64,
    arrived: bool,
    done: bool,
}

/// Wraps an angle to `[-π, π]` exactly as the paper writes it.
pub fn wrap(a: f64) -> f64 {
    a.sin().atan2(a.cos())
}

impl PathFollower {
    /// `path` = waypoints to visit in order, the last being the goal (a
    /// [`super::theta_star::PlannedPath`]'s `waypoints`); `final_heading` = θ_fin, rad.
    pub fn new(path: Vec<P2>, final_heading: f64, params: FollowParams) -> PathFollower {
        PathFollower {
            path,
            final_heading,
            params,
            k: 0,
            v: 0.0,
            arrived: false,
            done: false,
        }
    }

    /// Index `k_v` of the active waypoint.
    pub fn waypoint_index(&self) -> usize {
        self.k
    }

    pub fn params(&self) -> &FollowParams {
        &self.params
    }

    /// One 10 Hz control step from the current odometry pose: `(v, ω, status)`.
    pub fn step(&mut self, odom: Pose2) -> (f64, f64, FollowStatus) {
        if self.done {
            return (0.0, 0.0, FollowStatus::Done);
        }
        let p = self.params;
        let here = [odom[0], odom[1]];
        let Some(&goal) = self.path.last() else {
            return self.final_turn(odom[2]);
        };
        if self.arrived || dist(here, goal) <= p.arrive {
            self.arrived = true;
            self.v = 0.0;
            return self.final_turn(odom[2]);
        }
        let last = self.path.len() - 1;
        while self.k < last && dist(here, self.path[self.k]) < p.waypoint_radius {
            self.k += 1;
        }
        let target = self.path[self.k];
        let alpha = (target[1] - here[1]).atan2(target[0] - here[0]);
        let theta_e = wrap(alpha - odom[2]);
        let mut max_v = p.max_v;
        if self.k == last && dist(here, target) < p.decel_distance {
            let braking = (2.0 * p.acc_v * (dist(here, goal) - p.arrive)).sqrt();
            max_v = max_v.min(braking.max(p.min_v));
        }
        let e = theta_e.abs();
        let ramp = self.v + p.acc_v * p.dt;
        let (v, w, status) = if e >= p.bands[3].upto {
            (0.0, theta_e.clamp(-p.max_w, p.max_w), FollowStatus::Turning)
        } else if e < p.aligned {
            (ramp.min(max_v), theta_e, FollowStatus::Driving)
        } else {
            let band = p.bands.iter().find(|b| e < b.upto).unwrap_or(&p.bands[3]);
            (
                ramp.min(max_v * band.v_scale),
                band.gain * theta_e,
                FollowStatus::Driving,
            )
        };
        self.v = v;
        (v, w, status)
    }

    fn final_turn(&mut self, yaw: f64) -> (f64, f64, FollowStatus) {
        let theta_e = wrap(self.final_heading - yaw);
        if theta_e.abs() < self.params.final_tolerance {
            self.done = true;
            return (0.0, 0.0, FollowStatus::Done);
        }
        (
            0.0,
            self.params.final_w.copysign(theta_e),
            FollowStatus::FinalHeading,
        )
    }
}
