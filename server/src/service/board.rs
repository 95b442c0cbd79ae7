//! The leaderboard as the service answers it: rows from the store, ranked, rendered and cached
//! ([`crate::leaderboard`] holds the types, data renderings and cache). The HTML page is the
//! HTTP adapter's: it passes its renderer ([`RenderPage`]) in, and the service caches the bytes.

use bytes::Bytes;
use kitchen_r_core::GraspMode;
use kitchen_r_core::dataset::Split;
use kitchen_r_core::observations::ObservationTrack;

use super::{AppState, rfc3339};
use crate::error::ServiceError;
use crate::leaderboard::intervals::{self, Intervals, PolicyScores};
use crate::leaderboard::{
    BoardPage, Card, Format, Leaderboard, RenderPage, Row, TIES_BY_INTERVAL, TIES_STRICT, Track, ranked,
    render,
};
use crate::scores::Scores;
use crate::store::{board, queue};

mod card;

impl AppState {
    /// The standard ranking of one track and split, in the contest's grasp mode.
    pub(crate) async fn leaderboard(&self, track: Track, split: Split) -> Result<Leaderboard, ServiceError> {
        self.board(track, ObservationTrack::Standard, None, split).await
    }

    /// The contest's grasp mode (`[control] grasp`): the boards answered by default.
    pub(crate) fn contest_grasp(&self) -> GraspMode {
        self.config().control.grasp
    }

    /// The ranking of one track, observation track, grasp mode (`None`: the contest's) and
    /// split, read from the maintained entries. Planning has no privileged board and no grasp
    /// mode: plan files receive no observations and grasp nothing.
    pub(crate) async fn board(
        &self,
        track: Track,
        observations: ObservationTrack,
        grasp: Option<GraspMode>,
        split: Split,
    ) -> Result<Leaderboard, ServiceError> {
        let policy = track != Track::Planning;
        if !policy && observations == ObservationTrack::Privileged {
            return Err(ServiceError::BadRequest(
                "the planning track has no privileged board: `observations=privileged` applies to \
                 the control and integrated tracks"
                    .into(),
            ));
        }
        if !policy && grasp.is_some() {
            return Err(ServiceError::BadRequest(
                "the planning track has no grasp mode: `grasp_mode` applies to the control and \
                 integrated tracks"
                    .into(),
            ));
        }
        // Plan runs carry the default mode in the store.
        let mode = match policy {
            true => grasp.unwrap_or_else(|| self.contest_grasp()),
            false => GraspMode::default(),
        };
        let stored =
            board::read_observed(self.read_pool(), track.as_str(), observations, mode, split).await?;
        let integrated = track == Track::Integrated;
        let label = policy.then_some(observations);
        let grasp_label = policy.then_some(mode);
        let mut rows = Vec::with_capacity(stored.len());
        for r in stored {
            let scores = match track {
                Track::Planning => Scores::em(r.em),
                Track::Control | Track::Integrated => Scores {
                    em: None,
                    sr: r.sr,
                    mse: r.mse,
                    m: r.m.filter(|_| integrated),
                    p: r.p.filter(|_| integrated),
                },
            };
            let (intervals, card) = self.evidence(track, &r, scores, observations, split).await?;
            rows.push(Row {
                rank: None,
                team: r.team,
                submission_id: r.submission_id,
                scores,
                submitted_at: rfc3339(r.submitted_at),
                state: r.state.map(|s| s.as_str().to_string()),
                baseline: r.baseline,
                observations: label,
                grasp_mode: policy.then_some(r.grasp_mode),
                intervals,
                card,
            });
        }
        let ties = self.config().leaderboard.interval_ties;
        Ok(Leaderboard {
            track,
            observations: label,
            grasp_mode: grasp_label,
            split,
            interval_ties: ties,
            ties: if ties { TIES_BY_INTERVAL } else { TIES_STRICT },
            rows: ranked(rows, track, ties),
        })
    }

    /// A row's intervals and results card, from the run it shows: a plan run's EM over the
    /// split's instructions, a policy run's recorded episodes. Read on a cache miss only.
    async fn evidence(
        &self,
        track: Track,
        row: &board::BoardRow,
        scores: Scores,
        observations: ObservationTrack,
        split: Split,
    ) -> Result<(Intervals, Option<Card>), ServiceError> {
        let Some(run) = board::shown_run(self.read_pool(), row.submission_id).await? else {
            return Ok((Intervals::default(), None));
        };
        if track == Track::Planning {
            let n = self.content().ground_truth(split).len() as u64;
            return Ok((intervals::planning(scores.em, n), Some(card::planning(&run, n))));
        }
        let mut conn = self.read_pool().acquire().await.map_err(anyhow::Error::from)?;
        let episodes = queue::episodes(&mut conn, run.episodes_run).await?;
        drop(conn);
        let scored: Vec<_> = episodes.iter().map(|e| e.scoring()).collect();
        let shown = PolicyScores {
            sr: scores.sr,
            mse: scores.mse,
            em: row.em,
            m: scores.m,
            p: scores.p,
        };
        let specs: Vec<_> = episodes.iter().map(|e| &e.spec).collect();
        Ok((
            intervals::policy(shown, &scored),
            Some(card::policy(&run, &specs, row.grasp_mode, observations)),
        ))
    }

    /// The leaderboard rendered in `format` (HTML by `html`, the adapter's page), from the cache
    /// when nothing was written since.
    pub(crate) async fn leaderboard_rendered(
        &self,
        track: Track,
        observations: ObservationTrack,
        grasp: Option<GraspMode>,
        split: Split,
        format: Format,
        html: RenderPage,
    ) -> Result<Bytes, ServiceError> {
        let contest = self.contest_grasp();
        let key = (Some(track), observations, grasp.unwrap_or(contest), split, format);
        let cache = self.leaderboard_cache();
        let (generation, hit) = cache.get(key);
        if let Some(body) = hit {
            return Ok(body);
        }
        let board = self.board(track, observations, grasp, split).await?;
        let body: Bytes = match format {
            Format::Json => serde_json::to_vec(&board).map_err(anyhow::Error::from)?.into(),
            Format::Csv => render::csv(&board).into(),
            Format::Html => html(&self.board_page(split, vec![board], contest)).into(),
        };
        cache.put(key, generation, &body);
        Ok(body)
    }

    /// `boards` of `split` with what the page says about them.
    fn board_page(&self, split: Split, boards: Vec<Leaderboard>, contest: GraspMode) -> BoardPage {
        BoardPage {
            split,
            boards,
            public_sample: self.content().test_set.kind == crate::content::TestSetKind::PublicSample,
            contest,
        }
    }

    /// The public page at `/`: all three tracks of `split`, and the privileged boards of the
    /// policy tracks when this server runs the privileged track or they hold entries (from a
    /// time it did), all in the contest's grasp mode; then the policy boards of any other grasp
    /// mode that hold entries (runs made before the organiser changed `[control] grasp`).
    /// `html` renders them (the HTTP adapter's page); its bytes are cached.
    pub(crate) async fn leaderboard_page(
        &self,
        split: Split,
        html: RenderPage,
    ) -> Result<Bytes, ServiceError> {
        let contest = self.contest_grasp();
        let key = (None, ObservationTrack::Standard, contest, split, Format::Html);
        let cache = self.leaderboard_cache();
        let (generation, hit) = cache.get(key);
        if let Some(body) = hit {
            return Ok(body);
        }
        let mut boards = Vec::with_capacity(Track::ALL.len() + 2);
        for track in Track::ALL {
            boards.push(self.leaderboard(track, split).await?);
        }
        let running = self.config().control.privileged_track;
        for track in [Track::Control, Track::Integrated] {
            let board = self
                .board(track, ObservationTrack::Privileged, None, split)
                .await?;
            if running || !board.rows.is_empty() {
                boards.push(board);
            }
        }
        for other in GraspMode::ALL.into_iter().filter(|m| *m != contest) {
            for observations in ObservationTrack::ALL {
                for track in [Track::Control, Track::Integrated] {
                    let board = self.board(track, observations, Some(other), split).await?;
                    if !board.rows.is_empty() {
                        boards.push(board);
                    }
                }
            }
        }
        let body: Bytes = html(&self.board_page(split, boards, contest)).into();
        cache.put(key, generation, &body);
        Ok(body)
    }
}
