"""What the learned control baselines (`privileged/`, `camera/`) share, so training and serving
keep one definition each:

- `TaskClock`: a served policy's memory of when the current task's first Act came, per
  episode; the task's time is one of both baselines' features (the expert's pick-and-place
  phases are timed from a task's start);
- `sr_by_kind`: success counts per task kind of the episodes a policy drove in training;
- `instruction_range` / `train_instructions`: the `--instructions A-B` range a run trains on or a
  gate evaluates (the dev instructions outside a training range stay held out);
- `add_round_args`: the training scripts' `--instructions` and `--dagger-kinds`, one text each.
"""

import re
import sys
import threading

KINDS = ("move", "pick", "place")


class TaskClock:
    """Seconds since the current task's first Act, per episode, from the Acts alone."""

    def __init__(self, control_dt=0.1):
        self.control_dt = control_dt
        self.lock = threading.Lock()
        self.start = {}

    def reset(self, episode_id):
        with self.lock:
            self.start.pop(episode_id, None)

    def seconds(self, obs):
        """The task's time at `obs` (a gRPC Observation: `episode_id`, `task_index`, `step`)."""
        with self.lock:
            task, start = self.start.get(obs.episode_id, (None, None))
            if task != obs.task_index:
                start = obs.step
                self.start[obs.episode_id] = (obs.task_index, start)
        return (obs.step - start) * self.control_dt


def sr_by_kind(outcomes):
    """`outcomes`: (kind, success, ...) per ended task -> {kind: {success, tasks, sr}}."""
    out = {}
    for k in KINDS:
        n = sum(1 for o in outcomes if o[0] == k)
        s = sum(1 for o in outcomes if o[0] == k and o[1])
        out[k] = {"success": s, "tasks": n, "sr": s / n if n else None}
    return out


def instruction_range(text, count):
    """`A-B` (1-based, inclusive) -> (first index, last index + 1), checked against the split's
    `count` instructions; anything else exits with a message saying what to pass."""
    m = re.fullmatch(r"(\d+)-(\d+)", text or "")
    if not m or not 1 <= int(m.group(1)) <= int(m.group(2)) <= count:
        sys.exit(f"--instructions {text!r}: give A-B with 1 <= A <= B <= {count} (the split's instructions)")
    return int(m.group(1)) - 1, int(m.group(2))


def train_instructions(text):
    """The dev instruction ids of the 1-based inclusive range `A-B` (the rest stay held out)."""
    from gym_kitchen_r import KitchenREnv

    probe = KitchenREnv(images=False)
    try:
        ids = probe.instruction_ids()
    finally:
        probe.close()
    lo, hi = instruction_range(text, len(ids))
    return ids[lo:hi]


def add_round_args(ap):
    """`--instructions` and `--dagger-kinds`, as both training scripts take them."""
    ap.add_argument(
        "--instructions",
        default="1-100",
        help="dev instructions (1-based inclusive range) the expert episodes and DAgger rounds draw from; "
        "the rest are held out for evaluation",
    )
    ap.add_argument(
        "--dagger-kinds",
        default="move",
        help="task kinds whose policy-driven decisions the expert labels (comma-separated: move, pick, "
        "place). Navigation only by default: labelling pick and place lowered both baselines' pick and "
        "place round by round, with the timed expert and with the closed-loop one alike "
        "(docs/measured/baseline-gates.md, run 3); with the camera baseline's --round-env task the rounds "
        "run steps of these kinds",
    )
