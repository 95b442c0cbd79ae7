//! What the participant pages read beyond a submission view: a team's submissions, its quota
//! left today, and a running evaluation's ETA. Read-only; the rules stay where they are
//! ([`super::plan_uploads`] counts the daily quota the same way).

use kitchen_r_core::dataset::Split;

use super::{AppState, now_ms, rfc3339};
use crate::error::ServiceError;
use crate::store::Team;
use crate::store::portal::{self, TeamSubmission};
use crate::store::{self, runs as run_store};

const DAY_MS: i64 = 86_400_000;
/// Most submissions the team page lists.
const TEAM_PAGE_ROWS: i64 = 200;

/// A team's daily quota on one split.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct SplitQuota {
    pub split: Split,
    /// Submissions allowed per UTC day; `None` is unlimited.
    pub limit: Option<u32>,
    /// Submissions counted today (platform failures and cancelled runs are not).
    pub used: i64,
    /// When the count starts again (next UTC midnight), RFC 3339.
    pub resets_at: String,
}

impl SplitQuota {
    pub(crate) fn remaining(&self) -> Option<i64> {
        self.limit.map(|l| (i64::from(l) - self.used).max(0))
    }
}

/// A team's quotas as its page shows them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct QuotaView {
    pub splits: Vec<SplitQuota>,
    /// Upload attempts per minute and split (a burst refilling at that rate); 0 = unlimited.
    pub per_minute: u32,
    /// Policy runs evaluating at once; 0 = unlimited.
    pub concurrent_runs: u32,
    /// The team's policy runs evaluating now.
    pub active_runs: i64,
}

/// When a running evaluation should finish.
#[derive(Debug, Clone, PartialEq, serde::Serialize, utoipa::ToSchema)]
pub(crate) struct Eta {
    /// RFC 3339, UTC.
    pub at: String,
    /// Seconds from now.
    pub in_s: f64,
}

impl AppState {
    /// `team`'s latest submissions, newest first.
    pub(crate) async fn team_submissions(&self, team: &Team) -> Result<Vec<TeamSubmission>, ServiceError> {
        Ok(portal::team_submissions(self.read_pool(), team.id, TEAM_PAGE_ROWS).await?)
    }

    /// `team`'s quota left today on each split, and its concurrent runs.
    pub(crate) async fn team_quota(&self, team: &Team) -> Result<QuotaView, ServiceError> {
        let q = self.config().quota;
        let now = now_ms();
        let day_start = now - now.rem_euclid(DAY_MS);
        let mut splits = Vec::with_capacity(2);
        for (split, limit) in [(Split::Dev, q.dev_per_day), (Split::Test, q.test_per_day)] {
            let used = store::count_submissions_since(self.read_pool(), team.id, split, day_start).await?;
            splits.push(SplitQuota {
                split,
                limit: (limit > 0).then_some(limit),
                used,
                resets_at: rfc3339(day_start + DAY_MS),
            });
        }
        Ok(QuotaView {
            splits,
            per_minute: q.per_minute,
            concurrent_runs: q.concurrent_runs,
            active_runs: run_store::active_runs(self.read_pool(), team.id).await?,
        })
    }

    /// The ETA of policy run `run` with `done` of `total` episodes recorded: the pace so far
    /// (time since its first episode started per recorded episode) times the episodes left.
    /// `None` until an episode has finished.
    pub(crate) async fn run_eta(&self, run: i64, done: i64, total: i64) -> Result<Option<Eta>, ServiceError> {
        let left = (total - done).max(0);
        if done == 0 || left == 0 {
            return Ok(None);
        }
        let Some(started) = portal::run_started_at(self.read_pool(), run).await? else {
            return Ok(None);
        };
        let now = now_ms();
        let ms = (now - started).max(0) as f64 / done as f64 * left as f64;
        Ok(Some(Eta {
            at: rfc3339(now + ms as i64),
            in_s: ms / 1000.0,
        }))
    }
}
