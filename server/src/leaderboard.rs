//! The leaderboard: ranking (from the store), its data renderings (JSON, CSV; see [`render`])
//! and a cache of rendered bodies. The HTML page is the HTTP adapter's; the service hands it a
//! [`BoardPage`] and caches what it renders ([`RenderPage`]).
//!
//! Tracks: planning (EM desc), control (SR desc, then MSE asc) and integrated (M desc, then P
//! asc; P may be +inf). Best entry per team, then earliest submission, then id; unscored or
//! failed entries last. Organiser reference runs are baseline rows (`baseline: true`, no rank):
//! each one is shown, none is a team's best.
//!
//! The control and integrated tracks have a standard and a privileged board
//! (docs/participant/privileged.md): runs whose policy received privileged observations are ranked
//! only among themselves, and every rendering names the board (`observations` in JSON, a CSV
//! column, the page's headings).
//!
//! Those two boards exist once per grasp mode (docs/twin/robot.md): a run is ranked only among runs
//! of the grasp mode it ran in, and every policy rendering names the mode (`grasp_mode` in JSON,
//! the CSV's last column, the page's headings). The contest's mode (`[control] grasp`) is the board
//! answered by default and shown first; the other mode's boards appear only when they hold runs
//! (made before the organiser changed the setting), each row labelled.
//!
//! Below the service: this module holds the ranking types, the data renderings and the cache;
//! the service (`service/board.rs`) reads the store and fills them.
//!
//! Every score carries its 95 % interval ([`intervals`]), and with `[leaderboard]
//! interval_ties` on (the default) an entry whose interval on the board's primary metric overlaps
//! the interval of the entry holding the rank above shares that rank ([`ranked`]; the words every
//! rendering carries are [`TIES_BY_INTERVAL`] and [`TIES_STRICT`]). Each row carries its results
//! card ([`Card`]): what anyone needs to run it again with local `kitchen-r eval`.
//!
//! Policy: rendered bodies are cached per (track, observations, split, format) and dropped on every write that
//! can change a ranking (a new submission, a rescore, a policy run finishing), so reads under
//! load are a hash lookup and a reference-count increment. A generation counter makes a render
//! that raced with a write unfit for caching instead of serving stale data.

pub(crate) mod intervals;
pub(crate) mod render;

use std::collections::HashMap;
use std::sync::RwLock;
use std::sync::atomic::{AtomicU64, Ordering};

use bytes::Bytes;
use kitchen_r_core::GraspMode;
use kitchen_r_core::dataset::Split;
use kitchen_r_core::observations::ObservationTrack;
use serde::Serialize;

use crate::error::ServiceError;
use crate::scores::Scores;
use intervals::{Interval, Intervals};

/// The ranked tracks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub(crate) enum Track {
    Planning,
    Control,
    Integrated,
}

impl Track {
    pub(crate) const ALL: [Track; 3] = [Track::Planning, Track::Control, Track::Integrated];

    pub(crate) fn as_str(self) -> &'static str {
        match self {
            Track::Planning => "planning",
            Track::Control => "control",
            Track::Integrated => "integrated",
        }
    }
}

impl std::str::FromStr for Track {
    type Err = ServiceError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "" | "planning" => Ok(Track::Planning),
            "control" => Ok(Track::Control),
            "integrated" => Ok(Track::Integrated),
            other => Err(ServiceError::BadRequest(format!(
                "unknown track {other:?} (expected `planning`, `control` or `integrated`)"
            ))),
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub(crate) enum Format {
    Json,
    Csv,
    Html,
}

#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub(crate) struct Leaderboard {
    pub track: Track,
    /// Control and integrated: the board shown, `standard` or `privileged` (runs whose policy
    /// received privileged observations, ranked apart); absent for planning.
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(value_type = Option<String>, example = "standard")]
    pub observations: Option<ObservationTrack>,
    /// Control and integrated: the grasp mode of every run on this board, `abstract` or
    /// `physical` (runs of one mode are ranked together; the default board is the contest's
    /// mode); absent for planning.
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(value_type = Option<crate::schema::GraspModeName>, example = "abstract")]
    pub grasp_mode: Option<GraspMode>,
    #[schema(value_type = crate::schema::SplitName)]
    pub split: Split,
    /// Whether entries whose intervals overlap share a rank (`[leaderboard] interval_ties`).
    pub interval_ties: bool,
    /// How ties are decided, in words (the page says the same).
    pub ties: &'static str,
    pub rows: Vec<Row>,
}

/// How ties are decided with `interval_ties` on.
pub(crate) const TIES_BY_INTERVAL: &str = "Ranks are shared by entries whose 95 % intervals \
     overlap: an entry whose interval on the board's primary metric (EM for planning, SR for \
     control, M for integrated) overlaps the interval of the entry holding the rank above it \
     takes that rank (competition ranking: 1, 2, 2, 4). Rows stay in the order of the scores, \
     then the earlier submission. Entries not scored yet have ranks of their own.";

/// How ties are decided with `interval_ties` off.
pub(crate) const TIES_STRICT: &str = "Every entry has a rank of its own, in the order of the \
     scores (EM for planning; SR, then MSE, for control; M, then P, for integrated), then the \
     earlier submission; intervals are shown but do not share ranks.";

/// A row's results card: what its score was computed with, so that anyone can run it again
/// with local `kitchen-r eval` (docs/reference/leaderboard.md#results-cards). `"unknown"` where
/// the run was made before the server stored it.
#[derive(Debug, Clone, PartialEq, Serialize, utoipa::ToSchema)]
pub(crate) struct Card {
    /// The scoring run the row shows.
    pub run_id: i64,
    /// The kitchen-r server that queued (policy) or scored (plans) the run.
    pub binary_version: String,
    /// Policy runs: the first 16 hex digits of the sha256 of `config`'s lines joined by
    /// newlines; `"n/a"` for plan files, `"unknown"` when no episode was recorded.
    pub config_hash: String,
    /// Policy runs: the episode rules every job carried, one line per distinct set (one for a
    /// run made under one config), in `configs/eval.toml`'s keys: `seed`, `task_time_limit`,
    /// `execute`, `teleport_on_failure`, `max_plan_steps`, then `grasp` and
    /// `privileged_observations`.
    pub config: Vec<String>,
    /// The dataset digest the scores were computed against (the manifest's `version`).
    pub dataset: String,
    /// The run seeds its episodes were built from (one for a run made by one config).
    pub seeds: Vec<u64>,
    /// Policy runs: the grasp mode and observation track.
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(value_type = Option<crate::schema::GraspModeName>)]
    pub grasp_mode: Option<GraspMode>,
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(value_type = Option<String>)]
    pub observations: Option<ObservationTrack>,
    /// Episodes recorded (policy runs: online and offline), or instructions scored (plans).
    pub episodes: u64,
    pub scorer_version: String,
}

#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub(crate) struct Row {
    /// 1-based position among teams' entries; absent for baseline rows.
    pub rank: Option<usize>,
    pub team: String,
    pub submission_id: i64,
    pub scores: Scores,
    pub submitted_at: String,
    /// Policy tracks: `active` while evaluating, `finished`, `platform_failed` or `cancelled`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub state: Option<String>,
    /// An organiser reference run.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub baseline: bool,
    /// Policy tracks: `standard` or `privileged`, the board this row is ranked on.
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(value_type = Option<String>)]
    pub observations: Option<ObservationTrack>,
    /// Policy tracks: the grasp mode the row's run ran in (`abstract` or `physical`).
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(value_type = Option<crate::schema::GraspModeName>)]
    pub grasp_mode: Option<GraspMode>,
    /// The 95 % interval of each score shown (docs/reference/leaderboard.md#intervals).
    pub intervals: Intervals,
    /// The results card; absent for a submission without a scoring run.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub card: Option<Card>,
}

impl Row {
    /// The interval of the board's primary metric, for ties: only a scored, finished entry has
    /// one (an evaluating run's partial numbers never tie).
    fn primary(&self, track: Track) -> Option<Interval> {
        let finished = self.state.as_deref().is_none_or(|s| s == "finished");
        let (score, interval) = match track {
            Track::Planning => (self.scores.em, self.intervals.em),
            Track::Control => (self.scores.sr, self.intervals.sr),
            Track::Integrated => (self.scores.m, self.intervals.m),
        };
        score.and(interval).filter(|_| finished)
    }
}

/// What the public page shows: boards of one split (see `AppState::leaderboard_page`), whether
/// that split is the public test sample, and the contest's grasp mode (`[control] grasp`), which
/// the page names and against which it labels boards of the other mode.
#[derive(Debug, Clone)]
pub(crate) struct BoardPage {
    pub split: Split,
    pub boards: Vec<Leaderboard>,
    pub public_sample: bool,
    pub contest: GraspMode,
}

/// How the HTTP adapter renders a [`BoardPage`] as HTML. The service calls it on a cache miss,
/// so the page's bytes are cached and invalidated with the JSON and CSV bodies.
pub(crate) type RenderPage = fn(&BoardPage) -> String;

/// Key of a cached body: `None` track is the all-tracks page at `/`.
pub(crate) type CacheKey = (Option<Track>, ObservationTrack, GraspMode, Split, Format);

#[derive(Debug, Default)]
pub(crate) struct LeaderboardCache {
    generation: AtomicU64,
    rendered: RwLock<HashMap<CacheKey, (u64, Bytes)>>,
}

impl LeaderboardCache {
    pub(crate) fn invalidate(&self) {
        self.generation.fetch_add(1, Ordering::SeqCst);
        self.rendered.write().unwrap_or_else(|p| p.into_inner()).clear();
    }

    pub(crate) fn get(&self, key: CacheKey) -> (u64, Option<Bytes>) {
        let generation = self.generation.load(Ordering::SeqCst);
        let map = self.rendered.read().unwrap_or_else(|p| p.into_inner());
        let hit = map
            .get(&key)
            .filter(|(g, _)| *g == generation)
            .map(|(_, b)| b.clone());
        (generation, hit)
    }

    pub(crate) fn put(&self, key: CacheKey, generation: u64, body: &Bytes) {
        let mut map = self.rendered.write().unwrap_or_else(|p| p.into_inner());
        if self.generation.load(Ordering::SeqCst) == generation {
            map.insert(key, (generation, body.clone()));
        }
    }
}

/// Give teams' rows, in board order, their ranks; baseline rows get none and are passed over.
///
/// Competition ranking: a row's rank is its position among teams' rows, unless `interval_ties`
/// and its primary interval ([`Row::primary`]) overlaps that of the row holding the rank above
/// (the first row given that rank): then it takes that rank. Comparing with the rank's first
/// row, not the row just above, keeps ties from chaining down a board of close scores.
pub(crate) fn ranked(rows: impl IntoIterator<Item = Row>, track: Track, interval_ties: bool) -> Vec<Row> {
    let mut position = 0;
    let mut holder: Option<(usize, Interval)> = None;
    rows.into_iter()
        .map(|mut r| {
            if r.baseline {
                return r;
            }
            position += 1;
            let mine = r.primary(track);
            let rank = match (holder, mine) {
                (Some((rank, above)), Some(iv)) if interval_ties && above.overlaps(&iv) => rank,
                _ => {
                    holder = mine.map(|iv| (position, iv));
                    position
                }
            };
            r.rank = Some(rank);
            r
        })
        .collect()
}

#[cfg(test)]
pub(crate) mod tests;
#[cfg(test)]
mod ties_tests;
