//! The leaderboard as the service answers it: rows from the store, ranked, rendered and cached
//! ([`crate::leaderboard`] holds the types, renderings and cache).

use bytes::Bytes;
use kitchen_r_core::dataset::Split;

use super::{AppState, rfc3339};
use crate::error::ServiceError;
use crate::leaderboard::{Format, Leaderboard, Row, Track, ranked, render};
use crate::scores::Scores;
use crate::store::board;

impl AppState {
    /// The ranking of one track and split, read from the maintained entries.
    pub(crate) async fn leaderboard(&self, track: Track, split: Split) -> Result<Leaderboard, ServiceError> {
        let stored = board::read(self.read_pool(), track.as_str(), split).await?;
        let integrated = track == Track::Integrated;
        let rows = stored.into_iter().map(|r| Row {
            rank: None,
            team: r.team,
            submission_id: r.submission_id,
            scores: match track {
                Track::Planning => Scores::em(r.em),
                Track::Control | Track::Integrated => Scores {
                    em: None,
                    sr: r.sr,
                    mse: r.mse,
                    m: r.m.filter(|_| integrated),
                    p: r.p.filter(|_| integrated),
                },
            },
            submitted_at: rfc3339(r.submitted_at),
            state: r.state.map(|s| s.as_str().to_string()),
            baseline: r.baseline,
        });
        Ok(Leaderboard {
            track,
            split,
            rows: ranked(rows),
        })
    }

    /// The leaderboard rendered in `format`, from the cache when nothing was written since.
    pub(crate) async fn leaderboard_rendered(
        &self,
        track: Track,
        split: Split,
        format: Format,
    ) -> Result<Bytes, ServiceError> {
        let key = (Some(track), split, format);
        let cache = self.leaderboard_cache();
        let (generation, hit) = cache.get(key);
        if let Some(body) = hit {
            return Ok(body);
        }
        let board = self.leaderboard(track, split).await?;
        let body: Bytes = match format {
            Format::Json => serde_json::to_vec(&board).map_err(anyhow::Error::from)?.into(),
            Format::Csv => render::csv(&board).into(),
            Format::Html => render::page(split, &[board], self.public_sample()).into(),
        };
        cache.put(key, generation, &body);
        Ok(body)
    }

    fn public_sample(&self) -> bool {
        self.content().test_set.kind == crate::content::TestSetKind::PublicSample
    }

    /// The public page at `/`: all three tracks of `split`.
    pub(crate) async fn leaderboard_page(&self, split: Split) -> Result<Bytes, ServiceError> {
        let key = (None, split, Format::Html);
        let cache = self.leaderboard_cache();
        let (generation, hit) = cache.get(key);
        if let Some(body) = hit {
            return Ok(body);
        }
        let mut boards = Vec::with_capacity(Track::ALL.len());
        for track in Track::ALL {
            boards.push(self.leaderboard(track, split).await?);
        }
        let body: Bytes = render::page(split, &boards, self.public_sample()).into();
        cache.put(key, generation, &body);
        Ok(body)
    }
}
