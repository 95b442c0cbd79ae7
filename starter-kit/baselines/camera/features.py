"""What the camera baseline sees (standard track: no privileged information), computed alike from
the Python environment / `ExpertSamples` dicts (training) and from a gRPC `Observation` (serving).

One decision's inputs, over the last HISTORY = 2 control steps (0.1 s apart; at a task's first
decision both are the task's first frame, in the environment as in the contract's padding):
- images: both cameras (`base`, `gripper`), RGB uint8 as rendered (128x128, the sensors config;
  the server asks for that size too), resized to the model's `image_size` by `resize_images`,
  the one resize both paths use: (N, cameras, HISTORY, S, S, 3) uint8;
- state, STATE_DIM values: per frame (oldest first) the robot's 26 proprioceptive values —
  measured base velocity `v, w`, the 6 arm joints, gripper opening, hand pose in the base frame
  (7), the previous action (10; zeros at a task's start and after a teleport) — then odometry
  relative to the episode's start as `x, y, sin yaw, cos yaw` (allowed on the standard track);
  then the task's time: seconds since the task's first decision / 60, capped at 3;
- sub-task: the sentence as MAX_WORDS word ids over a vocabulary built from the dev split's plan
  steps (saved in the checkpoint; unknown words map to UNK, padding is PAD);
- depth (optional, `train.py --depth`): each camera's depth image as two more views after the
  colour ones, metres mapped to uint8 over [0, DEPTH_RANGE] (farther and "nothing hit" are 255)
  and repeated on 3 channels, so the same trunk reads them: (N, 2 * cameras, HISTORY, S, S, 3).
"""

import math
import re

import numpy as np

from .. import observation

CAMERAS = ("base", "gripper")
HISTORY = 2
RENDER_SIZE = 128
ROBOT = 26
PER_FRAME = ROBOT + 4
STATE_DIM = HISTORY * PER_FRAME + 1
HORIZON, ACTION_DIM = 16, 10
TIME_SCALE = 60.0
CONTROL_DT = 0.1
EXECUTE = 8
MAX_WORDS = 8
PAD, UNK = 0, 1
KINDS = ("move", "pick", "place")
DEPTH_RANGE = 4.0  # metres: the kitchen's far wall from the base camera


def views(depth):
    """The images a model reads: the cameras' colour, then (with depth) their depth."""
    return len(CAMERAS) * (2 if depth else 1)


def depth_u8(d):
    """Depth in metres (..., H, W) float32, +inf where nothing was hit -> (..., H, W, 3) uint8."""
    d = np.nan_to_num(np.asarray(d, dtype=np.float32), nan=DEPTH_RANGE, posinf=DEPTH_RANGE, neginf=0.0)
    u = np.rint(np.clip(d / DEPTH_RANGE, 0.0, 1.0) * 255.0).astype(np.uint8)
    return np.repeat(u[..., None], 3, axis=-1)


# Sub-task words ----------------------------------------------------------------------------


def words(sentence):
    return re.findall(r"[a-z0-9]+", sentence.lower())


def build_vocab(sentences):
    """Index 0 PAD, 1 UNK, then every word of `sentences`, sorted."""
    return ["<pad>", "<unk>"] + sorted({w for s in sentences for w in words(s)})


def dev_vocab():
    """The vocabulary of the dev split's plan steps (what train.py saves in the checkpoint)."""
    from gym_kitchen_r import KitchenREnv

    env = KitchenREnv(images=False)
    try:
        return build_vocab(s for i in env.instruction_ids() for s in env.instruction_of(i)["plan"])
    finally:
        env.close()


def encode(sentence, vocab_index):
    ids = [vocab_index.get(w, UNK) for w in words(sentence)][:MAX_WORDS]
    return np.array(ids + [PAD] * (MAX_WORDS - len(ids)), dtype=np.int64)


# State ------------------------------------------------------------------------------------


def _frame_values(robot26, x, y, yaw):
    return list(robot26) + [x, y, math.sin(yaw), math.cos(yaw)]


def state_vector(frames, task_time):
    """`frames`: HISTORY lists of PER_FRAME values, oldest first; `task_time` in seconds."""
    v = np.zeros(STATE_DIM, dtype=np.float32)
    v[: HISTORY * PER_FRAME] = np.asarray(frames, dtype=np.float64).reshape(-1)
    v[-1] = min(task_time, 3 * TIME_SCALE) / TIME_SCALE
    return v


def from_env(obs, task_time, depth=False):
    """(images (views(depth), HISTORY, 128, 128, 3) uint8, state (STATE_DIM,)) of an environment
    observation or an `ExpertSamples` dict (`images`, `state` with STATE_FIELDS, and `depth`
    when asked for)."""
    s = np.asarray(obs["state"], dtype=np.float64).reshape(-1, 29)
    # STATE_FIELDS: odom 0-2, base_v 3, base_w 4, joints 5-10, gripper 11, ee 12-18, prev 19-28
    frames = [_frame_values(r[3:29], r[0], r[1], r[2]) for r in observation.last(s, HISTORY)]
    ims = []
    for c in CAMERAS:
        a = np.asarray(obs["images"][c])
        a = a.reshape((-1,) + a.shape[-3:])
        ims.append(np.stack(observation.last(a, HISTORY)))
    if depth:
        for c in CAMERAS:
            d = np.asarray(obs["depth"][c])
            d = d.reshape((-1,) + d.shape[-2:])
            ims.append(depth_u8(np.stack(observation.last(d, HISTORY))))
    return np.stack(ims), state_vector(frames, task_time)


def _grpc_frame_values(f):
    r = f.robot
    if len(r.ee_pose) != 7:
        raise ValueError("observation has no hand pose (robot.ee_pose): the worker must speak contract v1.1")
    joints = list(r.arm_joints)[:6] + [0.0] * max(0, 6 - len(r.arm_joints))
    previous = list(f.previous_action) or [0.0] * ACTION_DIM
    robot = [r.base_v, r.base_omega] + joints + [r.gripper] + list(r.ee_pose) + previous
    return _frame_values(robot, r.base_x, r.base_y, r.base_yaw)


def from_grpc(obs, task_time, depth=False):
    """As `from_env`, from one gRPC `Observation` (history, then the observation itself)."""
    frames = observation.frames(obs, HISTORY)
    views_ = [np.stack([observation.rgb(f, c) for f in frames]) for c in CAMERAS]
    if depth:
        views_ += [depth_u8(np.stack([observation.depth(f, c) for f in frames])) for c in CAMERAS]
    return np.stack(views_), state_vector([_grpc_frame_values(f) for f in frames], task_time)


# Images -----------------------------------------------------------------------------------


def resize_images(images, size):
    """uint8 images (..., H, W, 3) (numpy or torch, any device) to (..., size, size, 3) uint8
    torch, bilinear with antialiasing; the same call in training (on the training device) and
    serving."""
    import torch
    from torch.nn import functional as F

    t = torch.as_tensor(images)
    if t.shape[-3] == size and t.shape[-2] == size:
        return t
    lead = t.shape[:-3]
    x = t.reshape((-1,) + tuple(t.shape[-3:])).permute(0, 3, 1, 2).float()
    x = F.interpolate(x, size=(size, size), mode="bilinear", antialias=True, align_corners=False)
    x = x.round_().clamp_(0, 255).to(torch.uint8).permute(0, 2, 3, 1)
    return x.reshape(tuple(lead) + (size, size, 3))


# Actions ----------------------------------------------------------------------------------


def finish(chunk):
    """A predicted chunk (16x10) made valid: finite, unit quaternions, gripper in [0, 1]."""
    c = np.nan_to_num(np.asarray(chunk, dtype=np.float64).reshape(HORIZON, ACTION_DIM), nan=0.0, posinf=0.0, neginf=0.0)
    q = c[:, 5:9]
    n = np.linalg.norm(q, axis=1, keepdims=True)
    c[:, 5:9] = np.where(n > 1e-6, q / np.maximum(n, 1e-6), np.array([1.0, 0.0, 0.0, 0.0]))
    c[:, 9] = c[:, 9].clip(0.0, 1.0)
    return c


# Auxiliary target (training only) ------------------------------------------------------------
# The privileged goal in the robot frame, which a camera policy must find in its images: a
# move's approach point and heading, a pick's object position, a place's target. `train.py
# --aux-weight` asks the network to predict it from what it sees (never an input: the standard
# track does not send it), so the encoder learns to localise.
AUX_DIM = 10


def aux_target(privileged):
    """(values, mask), AUX_DIM each, from a privileged observation dict (Python env or
    ExpertSamples); the mask marks the values the goal's kind defines."""
    v = np.zeros(AUX_DIM, dtype=np.float32)
    m = np.zeros(AUX_DIM, dtype=np.float32)
    g = privileged["goal"]
    if g["kind"] == "move":
        x, y, yaw = g["pose"]
        v[0:4], m[0:4] = [x, y, np.sin(yaw), np.cos(yaw)], 1.0
    elif g["kind"] == "pick":
        v[4:7], m[4:7] = g["pose"][:3], 1.0
    elif g["kind"] == "place":
        v[7:10], m[7:10] = g["position"], 1.0
    return v, m


def kind_of(sentence):
    return sentence.split()[0]
