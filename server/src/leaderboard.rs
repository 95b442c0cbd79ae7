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
//! Policy: rendered bodies are cached per (track, observations, split, format) and dropped on every write that
//! can change a ranking (a new submission, a rescore, a policy run finishing), so reads under
//! load are a hash lookup and a reference-count increment. A generation counter makes a render
//! that raced with a write unfit for caching instead of serving stale data.

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
    pub rows: Vec<Row>,
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

/// Give teams' rows their ranks in order; baseline rows get none.
pub(crate) fn ranked(rows: impl IntoIterator<Item = Row>) -> Vec<Row> {
    let mut next = 0;
    rows.into_iter()
        .map(|mut r| {
            if !r.baseline {
                next += 1;
                r.rank = Some(next);
            }
            r
        })
        .collect()
}

#[cfg(test)]
pub(crate) mod tests;
