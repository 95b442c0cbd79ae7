//! Where the robot went (docs/reference/pages.md): the path a worker reported with an online
//! episode, checked and stored with the result, and drawn on demand over the scene's top-down map.

use kitchen_r_core::scoring::TaskOutcome;
use kitchen_r_core::topdown::{PathPlot, PlotGoal};
use kitchen_r_proto::worker::v1 as pb;

/// The most points kept from a report (workers send at most 4096).
pub(crate) const MAX_POINTS: usize = 8192;
/// The most goals kept (one per task).
const MAX_GOALS: usize = 256;
/// Coordinates further than this from the origin are garbage, metres.
const FAR: f32 = 1000.0;

/// The reported path as the server stores it; `None` when absent or malformed (a bad path never
/// costs the episode its score, it only has no plot).
pub(crate) fn from_report(path: Option<&pb::EpisodePath>, tasks: &[TaskOutcome]) -> Option<PathPlot> {
    let p = path?;
    let n = p.task.len();
    if n == 0 || n > MAX_POINTS || p.base_xy.len() != 2 * n || p.object_xy.len() != 2 * n {
        return None;
    }
    let ok = |v: f32| v.is_finite() && v.abs() < FAR;
    let point = |xy: &[f32]| (ok(xy[0]) && ok(xy[1])).then(|| [xy[0], xy[1]]);
    let base = (p.base_xy.chunks(2).zip(&p.task))
        .filter_map(|(xy, t)| point(xy).map(|q| (q, *t)))
        .collect();
    let object = p.object_xy.chunks(2).map(point).collect();
    let goals = (p.goals.iter().take(MAX_GOALS))
        .map(|g| PlotGoal {
            task: g.index,
            kind: g.kind.chars().take(16).collect(),
            at: point(&[g.x, g.y]).unwrap_or([f32::NAN; 2]),
            radius: if ok(g.radius) {
                g.radius.clamp(0.0, 1.0)
            } else {
                0.0
            },
            end: point(&[g.end_x, g.end_y]).unwrap_or([f32::NAN; 2]),
            failed: tasks.iter().any(|t| t.index == g.index && !t.success),
        })
        .collect();
    Some(PathPlot { base, object, goals })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn malformed_paths_are_dropped_and_garbage_points_skipped() {
        assert_eq!(from_report(None, &[]), None);
        let mut p = pb::EpisodePath {
            base_xy: vec![1.0, 2.0, f32::NAN, 0.0],
            object_xy: vec![f32::NAN, f32::NAN, 1.5, 2.0],
            task: vec![0, 1],
            goals: vec![pb::PathGoal {
                index: 1,
                kind: "place".into(),
                x: 1.0,
                y: 1.0,
                radius: 0.05,
                end_x: 1.2,
                end_y: 1.1,
            }],
        };
        let failed = TaskOutcome {
            index: 1,
            ..Default::default()
        };
        let plot = from_report(Some(&p), &[failed]).unwrap();
        assert_eq!(plot.base, vec![([1.0, 2.0], 0)]);
        assert_eq!(plot.object, vec![None, Some([1.5, 2.0])]);
        assert!(plot.goals[0].failed);
        p.task.push(2);
        assert_eq!(from_report(Some(&p), &[]), None, "lengths disagree");
    }
}
