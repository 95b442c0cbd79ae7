"""A gRPC `Observation` (policy.proto) as the features `kitchen-r collect --format lerobot` exports
and `lerobot_env_kitchen_r` observes, under the same names, so a LeRobot policy trained on the
export reads served observations as it read its training frames. Needs numpy only: what the serve
command feeds the policy is built here, and tested without LeRobot or torch.

| LeRobot feature               | from the gRPC observation                                     |
| ----------------------------- | ------------------------------------------------------------- |
| `observation.images.<camera>` | the camera's RAW_RGB8 image, (height, width, 3) uint8          |
| `observation.state`           | `robot.base_v, base_omega, ee_pose (x, y, z, qw, qx, qy, qz), gripper` |
| `observation.joints`          | `robot.arm_joints` (6), `robot.gripper`                        |
| `observation.base_pose`       | `robot.base_x, base_y, base_yaw` (odometry from the episode's start) |
| `task`                        | `sub_task`, the current sub-task's sentence (the export's task) |
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..observation import rgb

IMAGE_PREFIX = "observation.images."
STATE = "observation.state"
JOINTS = "observation.joints"
BASE_POSE = "observation.base_pose"
# The names `collect --format lerobot` writes into meta/info.json for each vector, in order.
STATE_NAMES = ("v", "omega", "x", "y", "z", "qw", "qx", "qy", "qz", "gripper")
JOINT_NAMES = tuple(f"joint_{i}" for i in range(6)) + ("gripper",)
BASE_POSE_NAMES = ("x", "y", "yaw")
ACTION_NAMES = ("v", "omega", "x", "y", "z", "qw", "qx", "qy", "qz", "gripper")
VECTORS = {STATE: STATE_NAMES, JOINTS: JOINT_NAMES, BASE_POSE: BASE_POSE_NAMES}


def camera(key: str) -> str | None:
    """The camera an image feature names (`observation.images.base` -> `base`), else None."""
    return key[len(IMAGE_PREFIX) :] if key.startswith(IMAGE_PREFIX) else None


def vector(frame: Any, key: str) -> np.ndarray:
    """One frame's state vector `key` as float32, in the export's order."""
    r = frame.robot
    if key == STATE:
        hand = list(r.ee_pose)
        if len(hand) != 7:
            raise ValueError(f"robot.ee_pose has {len(hand)} values, not 7 (a v1.1 worker fills it)")
        values = [r.base_v, r.base_omega, *hand, r.gripper]
    elif key == JOINTS:
        values = [*r.arm_joints, r.gripper]
    elif key == BASE_POSE:
        values = [r.base_x, r.base_y, r.base_yaw]
    else:
        raise ValueError(f"`{key}` is no feature of the Kitchen-R export: {sorted(VECTORS)} and {IMAGE_PREFIX}<camera>")
    out = np.asarray(values, dtype=np.float32)
    if out.shape != (len(VECTORS[key]),):
        raise ValueError(f"`{key}` has {out.shape[0]} values, not {len(VECTORS[key])}")
    return out


def frame_features(frame: Any, keys: list[str]) -> dict[str, np.ndarray]:
    """The policy's input features `keys` of one frame (images (H, W, 3) uint8, vectors float32)."""
    out = {}
    for key in keys:
        cam = camera(key)
        out[key] = rgb(frame, cam) if cam is not None else vector(frame, key)
    return out


def to_chunk(actions: np.ndarray, horizon: int) -> list[list[float]]:
    """A policy's actions (K, 10), as the contract's chunk of `horizon` actions: cut to `horizon`,
    or padded with the last action (only the first `execute` of them are run); each quaternion
    normalised and the gripper clipped to [0, 1], as a regression head leaves them only close to
    valid (the worker fails a task for a norm off 1 by more than 0.1)."""
    a = np.asarray(actions, dtype=np.float64).reshape(-1, len(ACTION_NAMES))
    if a.shape[0] == 0:
        raise ValueError("the policy returned no action")
    a = a[:horizon]
    if a.shape[0] < horizon:
        a = np.concatenate([a, np.repeat(a[-1:], horizon - a.shape[0], axis=0)])
    q = a[:, 5:9]
    norm = np.linalg.norm(q, axis=1, keepdims=True)
    # A zero quaternion has no direction: the identity rotation stands in for it.
    a[:, 5:9] = np.where(norm > 1e-9, q / np.maximum(norm, 1e-9), np.array([1.0, 0.0, 0.0, 0.0]))
    a[:, 9] = np.clip(a[:, 9], 0.0, 1.0)
    # A non-finite value is sent as it is: the worker fails the task and says why.
    return a.tolist()
