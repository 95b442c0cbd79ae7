//! The states and kinds the store keeps as TEXT columns, as enums: compared and matched as types,
//! mapped to and from SQLite with `sqlx::Type` (the strings are the schema's `CHECK` values).
//! A leaf module: it imports nothing of this crate.

use serde::Serialize;

/// `submissions.kind`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, sqlx::Type)]
#[sqlx(type_name = "TEXT", rename_all = "snake_case")]
#[serde(rename_all = "snake_case")]
pub(crate) enum SubmissionKind {
    Plans,
    Policy,
}

impl SubmissionKind {
    pub(crate) fn as_str(self) -> &'static str {
        match self {
            SubmissionKind::Plans => "plans",
            SubmissionKind::Policy => "policy",
        }
    }
}

/// `scoring_runs.state`: plan runs are `finished` at once; policy runs are `active` until their
/// last job closes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, sqlx::Type, utoipa::ToSchema)]
#[sqlx(type_name = "TEXT", rename_all = "snake_case")]
#[serde(rename_all = "snake_case")]
pub(crate) enum RunState {
    Active,
    Finished,
    /// No episode could run because of the platform: such a run does not use quota.
    PlatformFailed,
    /// Stopped by the organiser (`cancelled_at`, `cancelled_by`): uses no quota, ranks nowhere.
    Cancelled,
}

impl RunState {
    pub(crate) fn as_str(self) -> &'static str {
        match self {
            RunState::Active => "active",
            RunState::Finished => "finished",
            RunState::PlatformFailed => "platform_failed",
            RunState::Cancelled => "cancelled",
        }
    }
}

/// `jobs.state`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, sqlx::Type, utoipa::ToSchema)]
#[sqlx(type_name = "TEXT", rename_all = "snake_case")]
#[serde(rename_all = "snake_case")]
pub(crate) enum JobState {
    Queued,
    Leased,
    Done,
    Failed,
    Cancelled,
}

impl JobState {
    pub(crate) fn as_str(self) -> &'static str {
        match self {
            JobState::Queued => "queued",
            JobState::Leased => "leased",
            JobState::Done => "done",
            JobState::Failed => "failed",
            JobState::Cancelled => "cancelled",
        }
    }

    /// Still waiting for a worker or being worked on.
    pub(crate) fn is_open(self) -> bool {
        matches!(self, JobState::Queued | JobState::Leased)
    }
}

impl std::fmt::Display for JobState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The enums read and write exactly the strings the schema's CHECK constraints allow.
    #[tokio::test]
    async fn states_round_trip_through_sqlite() {
        let pool = sqlx::sqlite::SqlitePoolOptions::new()
            .connect("sqlite::memory:")
            .await
            .unwrap();
        for s in [
            RunState::Active,
            RunState::Finished,
            RunState::PlatformFailed,
            RunState::Cancelled,
        ] {
            let text: String = sqlx::query_scalar("SELECT ?")
                .bind(s)
                .fetch_one(&pool)
                .await
                .unwrap();
            assert_eq!(text, s.as_str());
            let back: RunState = sqlx::query_scalar("SELECT ?")
                .bind(s.as_str())
                .fetch_one(&pool)
                .await
                .unwrap();
            assert_eq!(back, s);
        }
        for s in [
            JobState::Queued,
            JobState::Leased,
            JobState::Done,
            JobState::Failed,
            JobState::Cancelled,
        ] {
            let back: JobState = sqlx::query_scalar("SELECT ?")
                .bind(s.as_str())
                .fetch_one(&pool)
                .await
                .unwrap();
            assert_eq!(back, s);
        }
        for k in [SubmissionKind::Plans, SubmissionKind::Policy] {
            let back: SubmissionKind = sqlx::query_scalar("SELECT ?")
                .bind(k.as_str())
                .fetch_one(&pool)
                .await
                .unwrap();
            assert_eq!(back, k);
        }
    }
}
