//! The privileged track's observation on the wire and back (`policy.proto`,
//! `PrivilegedObservation`). What it shows on each split is decided before it gets here
//! (`kitchen_r_episode::policy::privileged`): this file only changes its form.

use kitchen_r_episode::policy::{Goal, PrivilegedObject, PrivilegedObservation};
use kitchen_r_proto::policy::v1 as pb;

pub(crate) fn to_wire(p: &PrivilegedObservation) -> pb::PrivilegedObservation {
    let goal = match &p.goal {
        Goal::Approach { x, y, yaw } => pb::goal::Goal::Approach(pb::ApproachGoal {
            x: *x,
            y: *y,
            yaw: *yaw,
        }),
        Goal::Pick { object, pose } => pb::goal::Goal::Pick(pb::ObjectGoal {
            object: object.clone(),
            pose: pose.to_vec(),
        }),
        Goal::Place { object, target } => pb::goal::Goal::Place(pb::PlaceGoal {
            object: object.clone(),
            target: target.to_vec(),
        }),
    };
    pb::PrivilegedObservation {
        base_x: p.base_pose[0],
        base_y: p.base_pose[1],
        base_yaw: p.base_pose[2],
        goal: Some(pb::Goal { goal: Some(goal) }),
        objects: (p.objects.iter())
            .map(|o| pb::PrivilegedObject {
                name: o.name.clone(),
                model: o.model.clone(),
                pose: o.pose.to_vec(),
            })
            .collect(),
    }
}

pub(crate) fn from_wire(p: &pb::PrivilegedObservation) -> Result<PrivilegedObservation, String> {
    fn values<const N: usize>(v: &[f64], what: &str) -> Result<[f64; N], String> {
        v.try_into()
            .map_err(|_| format!("privileged_observation: {what} has {} values, not {N}", v.len()))
    }
    let goal = match p.goal.as_ref().and_then(|g| g.goal.as_ref()) {
        Some(pb::goal::Goal::Approach(a)) => Goal::Approach {
            x: a.x,
            y: a.y,
            yaw: a.yaw,
        },
        Some(pb::goal::Goal::Pick(o)) => Goal::Pick {
            object: o.object.clone(),
            pose: values(&o.pose, "goal.pick.pose")?,
        },
        Some(pb::goal::Goal::Place(pl)) => Goal::Place {
            object: pl.object.clone(),
            target: values(&pl.target, "goal.place.target")?,
        },
        None => return Err("privileged_observation.goal is missing".into()),
    };
    Ok(PrivilegedObservation {
        base_pose: [p.base_x, p.base_y, p.base_yaw],
        goal,
        objects: (p.objects.iter())
            .map(|o| {
                Ok(PrivilegedObject {
                    name: o.name.clone(),
                    model: o.model.clone(),
                    pose: values(&o.pose, "object pose")?,
                })
            })
            .collect::<Result<_, String>>()?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_goal_kind_survives_the_wire_bit_for_bit() {
        let cup = PrivilegedObject {
            name: "red cup".into(),
            model: "cup".into(),
            pose: [1.0, -2.0, 0.9, 0.5, 0.5, 0.5, 0.5],
        };
        for goal in [
            Goal::Approach {
                x: 0.1,
                y: -0.2,
                yaw: 3.0,
            },
            Goal::Pick {
                object: "red cup".into(),
                pose: [0.4, 0.0, 0.9, 1.0, 0.0, 0.0, 0.0],
            },
            Goal::Place {
                object: "red cup".into(),
                target: [0.5, 0.1, 0.95],
            },
        ] {
            let p = PrivilegedObservation {
                base_pose: [1.5, 2.5, -0.3],
                goal,
                objects: vec![cup.clone()],
            };
            assert_eq!(from_wire(&to_wire(&p)).unwrap(), p);
        }
    }

    #[test]
    fn a_malformed_observation_is_refused_with_the_field() {
        let mut w = to_wire(&PrivilegedObservation {
            base_pose: [0.0; 3],
            goal: Goal::Place {
                object: "bowl".into(),
                target: [0.0; 3],
            },
            objects: Vec::new(),
        });
        if let Some(pb::goal::Goal::Place(p)) = w.goal.as_mut().and_then(|g| g.goal.as_mut()) {
            p.target.pop();
        }
        assert!(
            from_wire(&w)
                .unwrap_err()
                .contains("goal.place.target has 2 values")
        );
        w.goal = None;
        assert!(from_wire(&w).unwrap_err().contains("goal is missing"));
    }
}
