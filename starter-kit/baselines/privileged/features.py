"""What the privileged baseline sees, computed alike from the Python environment (training) and
from a gRPC observation (serving), so the two can never drift apart.

One decision's feature vector (FEATURES = 56 values):
- robot, 26: measured base velocity `v, w`, the 6 arm joints, gripper opening, hand pose in the
  base frame (7), the previous action (10; zeros at a task's start and after a teleport);
- base pose in the scene frame, 4: `x, y, sin yaw, cos yaw` (privileged track);
- the task's time, 1: seconds since the task's first decision / 60, so the expert's timed
  pick-and-place phases can be told apart where the arm stands still;
- the goal (privileged track, robot frame), 25: kind one-hot (move, pick, place), then
  move: `x, y, sin yaw, cos yaw, distance`; pick: the object's pose (7); place: the target (3)
  and the held object's pose in the robot frame (7, from the scene-frame pose the observation
  carries for the object the sub-task names).
No image, no sub-task words: on the privileged track the goal says what the sentence says.
"""

import math

import numpy as np

KINDS = ("move", "pick", "place")
ROBOT = 26
FEATURES = ROBOT + 4 + 1 + 3 + 5 + 7 + 10
# The task-time column (a model trained with `--no-task-time` reads it as 0).
TIME_INDEX = ROBOT + 4
HORIZON, ACTION_DIM = 16, 10
TIME_SCALE = 60.0
CONTROL_DT = 0.1
EXECUTE = 8


def _quat_mul(a, b):
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return (
        w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
        w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
        w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
        w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
    )


def to_robot_frame(base, pose):
    """A scene-frame pose `[x, y, z, qw, qx, qy, qz]` in the frame of a base at `base = (x, y,
    yaw)` (the privileged observation's convention: x forward, y left, origin on the floor)."""
    bx, by, yaw = base
    c, s = math.cos(yaw), math.sin(yaw)
    dx, dy = pose[0] - bx, pose[1] - by
    inv = (math.cos(-yaw / 2), 0.0, 0.0, math.sin(-yaw / 2))
    q = _quat_mul(inv, tuple(pose[3:7]))
    if q[0] < 0:  # one sign for the same rotation
        q = tuple(-v for v in q)
    return [c * dx + s * dy, -s * dx + c * dy, pose[2], *q]


def vector(robot, base, goal_kind, goal_values, held_pose, task_time):
    """The feature vector. `robot`: the 26 robot values in the order above; `base`: scene-frame
    `(x, y, yaw)`; `goal_kind`: one of KINDS; `goal_values`: move `(x, y, yaw)`, pick the pose
    (7), place the target (3); `held_pose`: the named object's scene-frame pose (place only, else
    None); `task_time`: seconds since the task's first decision."""
    v = np.zeros(FEATURES, dtype=np.float32)
    v[:ROBOT] = robot
    i = ROBOT
    v[i : i + 4] = [base[0], base[1], math.sin(base[2]), math.cos(base[2])]
    i += 4
    v[i] = min(task_time, 3 * TIME_SCALE) / TIME_SCALE
    i += 1
    v[i + KINDS.index(goal_kind)] = 1.0
    i += 3
    if goal_kind == "move":
        x, y, yaw = goal_values
        v[i : i + 5] = [x, y, math.sin(yaw), math.cos(yaw), math.hypot(x, y)]
    i += 5
    if goal_kind == "pick":
        q = list(goal_values[3:7])
        if q[0] < 0:
            q = [-c for c in q]
        v[i : i + 7] = list(goal_values[:3]) + q
    i += 7
    if goal_kind == "place":
        v[i : i + 3] = goal_values
        if held_pose is not None:
            v[i + 3 : i + 10] = to_robot_frame(base, held_pose)
    return v


def from_env(state, privileged, task_time):
    """Features of a Python-environment decision: `state` is `obs["state"]` (STATE_FIELDS, the
    newest frame), `privileged` is `info["privileged_observation"]`."""
    s = np.asarray(state, dtype=np.float64)
    # STATE_FIELDS: odom 0-2, base_v 3, base_w 4, joints 5-10, gripper 11, ee 12-18, prev 19-28
    robot = np.concatenate([s[3:5], s[5:11], s[11:12], s[12:19], s[19:29]])
    g = privileged["goal"]
    kind = g["kind"]
    values = g["pose"] if kind in ("move", "pick") else g["position"]
    held = None
    if kind == "place":
        held = next((o["pose"] for o in privileged["objects"] if o["name"] == g["object"]), None)
    return vector(robot, privileged["base_pose"], kind, values, held, task_time)


def from_grpc(obs, task_time):
    """Features of one gRPC `Observation` on the privileged track."""
    r = obs.robot
    previous = list(obs.previous_action) or [0.0] * ACTION_DIM
    joints = list(r.arm_joints)[:6] + [0.0] * max(0, 6 - len(r.arm_joints))
    robot = [r.base_v, r.base_omega] + joints + [r.gripper] + list(r.ee_pose) + previous
    p = obs.privileged_observation
    which = p.goal.WhichOneof("goal")
    held = None
    if which == "approach":
        kind, values = "move", (p.goal.approach.x, p.goal.approach.y, p.goal.approach.yaw)
    elif which == "pick":
        kind, values = "pick", tuple(p.goal.pick.pose)
    elif which == "place":
        kind, values = "place", tuple(p.goal.place.target)
        held = next((tuple(o.pose) for o in p.objects if o.name == p.goal.place.object), None)
    else:
        raise ValueError("the observation carries no privileged goal: was the policy registered with --privileged?")
    return vector(robot, (p.base_x, p.base_y, p.base_yaw), kind, values, held, task_time)


def finish(chunk):
    """A predicted chunk (16x10) made valid: unit quaternions (sign-stable), gripper in [0, 1]."""
    c = np.asarray(chunk, dtype=np.float64).reshape(HORIZON, ACTION_DIM).copy()
    q = c[:, 5:9]
    n = np.linalg.norm(q, axis=1, keepdims=True)
    q = np.where(n > 1e-6, q / np.maximum(n, 1e-6), np.array([1.0, 0.0, 0.0, 0.0]))
    c[:, 5:9] = q
    c[:, 9] = c[:, 9].clip(0.0, 1.0)
    return c
