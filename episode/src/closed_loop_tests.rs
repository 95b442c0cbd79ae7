//! The closed-loop expert (docs/twin/oracle.md): from states the oracle's own plan never visits
//! (the arm pushed off its path, the base driven away, mid-task) it plans again from the state and
//! completes the task; undisturbed it never re-plans, so its own episodes are unchanged.

use kitchen_r_core::dataset::{Instruction, Split};
use kitchen_r_sim::Assets;

use crate::eval::{episode_configs, instructions};
use crate::oracle::OraclePolicy;
use crate::policy::{ACTION_DIM, HORIZON, Policy, PolicyError, PolicyInput, PolicySpec};
use crate::runner::{RunOptions, run_episode};
use crate::test_oracle::blind_sim;

/// The oracle as a learner's teacher: it is asked at every step, and `learner` turns its label
/// into the action the learner executes (or keeps it).
struct Driven<L> {
    oracle: OraclePolicy,
    learner: L,
}

/// What a learner makes of the expert's label at one step: `None` keeps the whole chunk.
trait Learner {
    fn act(&mut self, input: &PolicyInput<'_>, label: [f64; ACTION_DIM]) -> Option<[f64; ACTION_DIM]>;
    /// A new task starts.
    fn reset(&mut self) {}
}

impl<L: Learner + Send> Policy for Driven<L> {
    fn spec(&self) -> &PolicySpec {
        self.oracle.spec()
    }
    fn wants_images(&self) -> bool {
        false
    }
    fn reset(&mut self, episode: &str, task: usize, sub_task: &str) -> Result<(), PolicyError> {
        self.learner.reset();
        self.oracle.reset(episode, task, sub_task)
    }
    fn act(&mut self, input: &PolicyInput<'_>) -> Result<Vec<[f64; ACTION_DIM]>, PolicyError> {
        let chunk = self.oracle.act(input)?;
        Ok(match self.learner.act(input, chunk[0]) {
            Some(a) => vec![a; HORIZON],
            None => chunk,
        })
    }
}

/// For `len` steps from the `from`-th step of task `task` the actions are disturbed: the hand
/// target moved by up to `reach` m and random base velocities, as a learner's rollout might
/// leave the robot.
struct Disturbed {
    task: usize,
    from: u64,
    len: u64,
    reach: f64,
    task_start: Option<u64>,
    rng: u64,
}

impl Disturbed {
    fn noise(&mut self) -> f64 {
        self.rng ^= self.rng << 13;
        self.rng ^= self.rng >> 7;
        self.rng ^= self.rng << 17;
        (self.rng >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }
}

impl Learner for Disturbed {
    fn reset(&mut self) {
        self.task_start = None;
    }
    fn act(&mut self, input: &PolicyInput<'_>, mut a: [f64; ACTION_DIM]) -> Option<[f64; ACTION_DIM]> {
        let start = *self.task_start.get_or_insert(input.step);
        let k = input.step - start;
        if input.task_index != self.task || !(self.from..self.from + self.len).contains(&k) {
            return None;
        }
        // Where the oracle would go, off by up to `reach` in each direction; the base driven.
        let (dx, dy, dz) = (self.noise(), self.noise(), self.noise());
        a[2] += dx * self.reach;
        a[3] += dy * self.reach;
        a[4] += dz * self.reach;
        a[0] = self.noise() * 0.1;
        a[1] = self.noise() * 0.3;
        Some(a)
    }
}

/// Instructions of the dev split with `kind` ("pick" or "place") steps: (instruction, the index
/// of its first such step).
fn tasks_of(kind: &str, n: usize) -> Vec<(Instruction, usize)> {
    (instructions(Split::Dev, None).unwrap().into_iter())
        .filter_map(|i| {
            let j = i.plan.iter().position(|s| s.starts_with(kind))?;
            Some((i, j))
        })
        .step_by(7)
        .take(n)
        .collect()
}

/// Run `ins` disturbed at task `task`; whether that task succeeded, and the oracle's re-plans.
fn disturbed_run(
    assets: &Assets,
    ins: &Instruction,
    task: usize,
    from: u64,
    reach: f64,
) -> (bool, u64, String) {
    let cfg = &episode_configs(assets, std::slice::from_ref(ins), 0, None).unwrap()[0];
    let mut sim = blind_sim(assets, cfg);
    let mut policy = Driven {
        oracle: OraclePolicy::new(assets).without_images(),
        learner: Disturbed {
            task,
            from,
            len: 30,
            reach,
            task_start: None,
            rng: 0x2545_F491_4F6C_DD1D ^ task as u64,
        },
    };
    let run = RunOptions {
        execute: 1,
        privileged: true,
        max_tasks: Some(task + 1),
        ..RunOptions::default()
    };
    let out = run_episode(&mut sim, &mut policy, &run, None, &mut ()).unwrap();
    let t = &out.tasks[task];
    (
        t.success,
        policy.oracle.replans(),
        format!("{} task {task} from step {from}: {:?}", ins.id, t.failure),
    )
}

/// Disturbed for 30 steps after 25, 60 and 90 of its own (the arm's prelude, the approach and
/// grasp, the lift or lowering), the expert completes every sampled pick and place.
#[test]
fn from_disturbed_states_the_expert_replans_and_completes_picks_and_places() {
    let assets = Assets::load_default().unwrap();
    for kind in ["pick", "place"] {
        let (mut failed, mut runs, mut replanned) = (Vec::new(), 0, 0);
        for (ins, j) in &tasks_of(kind, 5) {
            for from in [25, 60, 90] {
                let (ok, replans, why) = disturbed_run(&assets, ins, *j, from, 0.08);
                runs += 1;
                replanned += usize::from(replans > 0);
                if !ok {
                    failed.push(why);
                }
            }
        }
        eprintln!(
            "{kind}: {} of {runs} disturbed tasks completed; the expert re-planned in {replanned}",
            runs - failed.len()
        );
        assert!(replanned > 0, "no disturbance left the plan");
        assert!(
            failed.is_empty(),
            "{kind} tasks the expert did not complete after a disturbance: {failed:#?}"
        );
    }
}

/// Task-v0 starts: a fresh expert, put where the expert stood at a task's start
/// (`expert_starts`), completes that task alone, as `KitchenR/Task-v0` runs it; among them the
/// two the issue found failing (dev-0005 task 3, "place the apple"; dev-0020 task 5, a pick).
#[test]
fn from_every_sampled_task_start_a_fresh_expert_completes_the_task() {
    let assets = Assets::load_default().unwrap();
    let all = instructions(Split::Dev, None).unwrap();
    let named = |id: &str, j: usize| (all.iter().find(|i| i.id == id).unwrap().clone(), j);
    let mut cases = vec![named("dev-0005", 3), named("dev-0020", 5)];
    for kind in ["pick", "place", "move"] {
        cases.extend(tasks_of(kind, 4));
    }
    let mut failed = Vec::new();
    for (ins, j) in &cases {
        let cfg = &episode_configs(&assets, std::slice::from_ref(ins), 0, None).unwrap()[0];
        let mut sim = blind_sim(&assets, cfg);
        let starts = crate::teleport::expert_starts(&mut sim, cfg, &assets).unwrap();
        let run = RunOptions {
            execute: 1,
            privileged: true,
            max_tasks: Some(j + 1),
            ..RunOptions::default()
        };
        let mut fresh = OraclePolicy::new(&assets).without_images();
        let out =
            crate::runner::run_from_task(&mut sim, &mut fresh, &run, Some(&starts), &mut (), *j).unwrap();
        let t = out.tasks.iter().find(|t| t.index == *j).unwrap();
        if !t.success {
            failed.push(format!("{} task {j} {:?}: {:?}", ins.id, ins.plan[*j], t.failure));
        }
    }
    eprintln!(
        "{} of {} task starts completed",
        cases.len() - failed.len(),
        cases.len()
    );
    assert!(failed.is_empty(), "{failed:#?}");
}

/// A learner whose hand moves at a fraction of the speed the expert asks for: each step it
/// commands `lag` of the way from where the hand is to the expert's label, on task `task`; the
/// rest of the label (base, gripper) as given. The expert labels every step it reaches.
struct Lagging {
    task: usize,
    lag: f64,
    /// The furthest the expert's label (its first hand target) was from the hand, m.
    label_ahead: f64,
}

impl Learner for Lagging {
    fn act(&mut self, input: &PolicyInput<'_>, mut a: [f64; ACTION_DIM]) -> Option<[f64; ACTION_DIM]> {
        if input.task_index != self.task {
            return None;
        }
        let ahead = (0..3)
            .map(|i| (a[2 + i] - input.ee_pose[i]).powi(2))
            .sum::<f64>()
            .sqrt();
        self.label_ahead = self.label_ahead.max(ahead);
        for i in 0..3 {
            a[2 + i] = input.ee_pose[i] + self.lag * (a[2 + i] - input.ee_pose[i]);
        }
        Some(a)
    }
}

/// What DAgger needs of the expert (docs/twin/oracle.md): a learner that lags it is labelled with
/// the way on from where it is. Driven by a hand at 40 % of the asked speed, the expert's labels
/// still take every sampled pick and place to success. Re-planned from the task's start instead
/// (the hand sent home, the base squared up again, the approach from above: the expert before
/// `TaskCtl::resume`), the same labels completed 0 of these 5 picks, at 40 % and at 25 %: each
/// re-plan undid the progress the lagging hand had made. And the labels are the way on from the
/// hand, not the plan's clock: at most 3.6 cm ahead of it, where the plan's own clock (before
/// `TaskCtl::follow_hand`) put them up to 11.8 cm ahead (fingers told to close above an object
/// the hand had not reached yet).
#[test]
fn a_learner_lagging_the_expert_is_labelled_on_to_success() {
    let assets = Assets::load_default().unwrap();
    let run = RunOptions {
        execute: 1,
        privileged: true,
        ..RunOptions::default()
    };
    for kind in ["pick", "place"] {
        let (mut failed, mut runs, mut secs, mut ahead) = (Vec::new(), 0, 0.0, 0.0f64);
        for (ins, j) in &tasks_of(kind, 5) {
            let cfg = &episode_configs(&assets, std::slice::from_ref(ins), 0, None).unwrap()[0];
            let mut sim = blind_sim(&assets, cfg);
            let mut policy = Driven {
                oracle: OraclePolicy::new(&assets).without_images(),
                learner: Lagging {
                    task: *j,
                    lag: 0.4,
                    label_ahead: 0.0,
                },
            };
            let run = RunOptions {
                max_tasks: Some(j + 1),
                ..run.clone()
            };
            let out = run_episode(&mut sim, &mut policy, &run, None, &mut ()).unwrap();
            let t = &out.tasks[*j];
            runs += 1;
            secs += t.sim_time;
            ahead = ahead.max(policy.learner.label_ahead);
            if !t.success {
                failed.push(format!("{} task {j}: {:?}", ins.id, t.failure));
            }
        }
        eprintln!(
            "{kind}: a lagging hand completed {} of {runs}, {:.1} s a task on average; labels at most {ahead:.3} m ahead of the hand",
            runs - failed.len(),
            secs / runs as f64
        );
        assert!(
            failed.is_empty(),
            "{kind} tasks a lagging learner failed under the expert's labels: {failed:#?}"
        );
        assert!(
            ahead < 0.05,
            "{kind}: a label {ahead:.3} m ahead of the hand is the plan's clock, not the way on from the hand"
        );
    }
}
