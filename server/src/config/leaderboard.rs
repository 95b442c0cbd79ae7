//! `[leaderboard]`: how the boards rank (docs/reference/leaderboard.md#ties). Every control,
//! integrated and planning score is shown with its 95 % interval; with `interval_ties` on (the
//! default), an entry whose interval on the board's primary metric overlaps that of the entry
//! holding the rank above it shares that rank (competition ranking: 1, 2, 2, 4).

use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LeaderboardConfig {
    /// Entries whose 95 % interval on the primary metric (EM, SR, M) overlaps the interval of the
    /// entry holding the rank above share that rank. Off: every entry has its own rank, in the
    /// board's order.
    pub interval_ties: bool,
}

impl Default for LeaderboardConfig {
    fn default() -> Self {
        LeaderboardConfig { interval_ties: true }
    }
}
