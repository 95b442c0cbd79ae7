"""What the policy sees, computed the same way offline (from the LeRobot export) and online (from
the policy contract's observations), so training and serving never disagree.

- Robot state: the export's `observation.state`, 10 values (v, omega, x, y, z, qw, qx, qy, qz,
  gripper) = measured base velocity, hand pose in the base frame, gripper opening. Online the
  same values are `robot.base_v`, `robot.base_omega`, `robot.ee_pose` (7) and `robot.gripper`
  (the worker and the recorder read them from the same simulator fields). With the model's
  `odometry` switch (on for new checkpoints) 4 more: the export's `observation.base_pose` as
  (x, y, cos yaw, sin yaw), online `robot.base_x`, `base_y`, `base_yaw`: the base pose relative
  to the episode's start, which tells a navigating policy its heading and how far it came.
- Timing: a row k of the export holds the observation *after* action k was executed (and
  action k itself). The worker asks the policy right after an executed action too, so the
  policy's frames are rows k-1, k and the actions it must predict are rows k+1 .. k+16.
- Images: RGB uint8 at the export's 128x128, resized to the model's size with the same
  swscale path (PyAV) in both places.
- Sub-task: the sentence (`task` of a LeRobot frame, `sub_task` of Reset/Act), as word ids over a
  vocabulary built from the training tasks (unknown words map to UNK).
"""

import re

import numpy as np

ACTION_DIM = 10
STATE_DIM = 10
ODOMETRY_DIM = 4
HORIZON = 16
MAX_WORDS = 12
PAD, UNK = 0, 1
CAMERAS = ("base", "gripper")


def state_dim(config):
    """Values per state frame of a model config (old checkpoints have no `odometry` key)."""
    return STATE_DIM + (ODOMETRY_DIM if config.get("odometry") else 0)


def odometry_features(x, y, yaw):
    """(x, y, cos yaw, sin yaw): yaw as a point on the circle, so +pi and -pi are the same.
    Scalars online, or numpy columns for a whole export (the same rule for both)."""
    return [x, y, np.cos(yaw), np.sin(yaw)]


def state_of_robot(robot, odometry=False):
    """The state of one online frame (a policy.proto RobotState): the 10 `observation.state`
    values, then with `odometry` the 4 odometry features."""
    hand = list(robot.ee_pose)
    if len(hand) != 7:
        # v1.0 workers left the hand pose empty; the baseline needs a v1.1 worker.
        raise ValueError("observation has no hand pose (robot.ee_pose): the worker must speak contract v1.1")
    out = [robot.base_v, robot.base_omega] + hand + [robot.gripper]
    if odometry:
        out += [float(v) for v in odometry_features(robot.base_x, robot.base_y, robot.base_yaw)]
    return out


def resize_rgb(rgb, size):
    """Resize an HxWx3 uint8 RGB array to size x size with swscale (bilinear), as for training."""
    if rgb.shape[0] == size and rgb.shape[1] == size:
        return np.ascontiguousarray(rgb)
    import av

    frame = av.VideoFrame.from_ndarray(np.ascontiguousarray(rgb), format="rgb24")
    # PyAV's default swscale interpolation is bilinear (the argument's spelling changed across versions).
    return frame.reformat(width=size, height=size, format="rgb24").to_ndarray()


def words(sentence):
    return re.findall(r"[a-z0-9]+", sentence.lower())


def build_vocab(sentences):
    """Word list: index 0 PAD, 1 UNK, then every word of the training sentences, sorted."""
    seen = sorted({w for s in sentences for w in words(s)})
    return ["<pad>", "<unk>"] + seen


def encode_sentence(sentence, vocab_index):
    ids = [vocab_index.get(w, UNK) for w in words(sentence)][:MAX_WORDS]
    return ids + [PAD] * (MAX_WORDS - len(ids))


class Normaliser:
    """Actions to [-1, 1] by their min/max (as Diffusion Policy does), states by mean/std.

    Dimensions that barely move in the data (e.g. the quaternion's x and z) get a floor on their
    range, so noise in them is not blown up.
    """

    RANGE_FLOOR = 1e-2
    STD_FLOOR = 1e-2

    def __init__(self, stats):
        self.stats = {k: {n: np.asarray(v, dtype=np.float32) for n, v in d.items()} for k, d in stats.items()}
        a = self.stats["action"]
        self.a_mid = (a["max"] + a["min"]) / 2
        self.a_half = np.maximum(a["max"] - a["min"], self.RANGE_FLOOR) / 2
        s = self.stats["observation.state"]
        self.s_mean = s["mean"]
        self.s_std = np.maximum(s["std"], self.STD_FLOOR)

    @staticmethod
    def from_export(stats_json, state=None):
        """Action statistics from the export's `meta/stats.json`; state statistics from it too,
        or, given `state` (the training rows, N x state values), computed from those rows (the
        export has no statistics for the odometry features)."""
        keep = {}
        for key in ("action", "observation.state"):
            d = stats_json[key]
            keep[key] = {n: d[n] for n in ("min", "max", "mean", "std")}
        if state is not None:
            s = np.asarray(state, dtype=np.float64)
            keep["observation.state"] = {
                "min": s.min(0).tolist(),
                "max": s.max(0).tolist(),
                "mean": s.mean(0).tolist(),
                "std": s.std(0).tolist(),
            }
        return Normaliser(keep)

    def to_dict(self):
        return {k: {n: v.tolist() for n, v in d.items()} for k, d in self.stats.items()}

    def action(self, a):
        return (a - self.a_mid) / self.a_half

    def unaction(self, a):
        return a * self.a_half + self.a_mid

    def state(self, s):
        return (s - self.s_mean) / self.s_std


def deadband(chunk, v_min, omega_min):
    """Base commands smaller than (`v_min` m/s, `omega_min` rad/s) set to 0. The expert's base
    speed is 0 at the bottom of its range, which the normalised actions clamp to -1, so a
    denoised "stand still" comes out as a small positive speed; over a 60 s pick that creeps
    the base metres away from the object."""
    out = np.array(chunk, dtype=np.float64)
    out[np.abs(out[:, 0]) < v_min, 0] = 0.0
    out[np.abs(out[:, 1]) < omega_min, 1] = 0.0
    return out


def finish_actions(chunk):
    """Make a predicted chunk valid for the contract: unit quaternions (sign kept with qw >= 0
    where possible is not needed: q and -q are accepted), gripper in [0, 1], finite values."""
    out = np.nan_to_num(np.asarray(chunk, dtype=np.float64), nan=0.0, posinf=0.0, neginf=0.0)
    q = out[:, 5:9]
    norm = np.linalg.norm(q, axis=1, keepdims=True)
    bad = norm[:, 0] < 1e-6
    q = np.where(bad[:, None], np.array([1.0, 0.0, 0.0, 0.0]), q / np.maximum(norm, 1e-6))
    out[:, 5:9] = q
    out[:, 9] = np.clip(out[:, 9], 0.0, 1.0)
    return out
