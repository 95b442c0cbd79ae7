"""A gRPC `Observation` (policy.proto) as the arrays a served baseline reads: its frames, oldest
first, and each frame's colour and depth images. The camera and diffusion-policy baselines read
them alike; their features modules say what they make of them."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, TypeVar

import numpy as np

T = TypeVar("T")


def last(seq: Sequence[T], n: int) -> list[T]:
    """The last `n` entries of `seq`, padded at the front with the first one: a history of `n`
    frames at a task's start, as the contract pads it (and the environment's history does)."""
    tail = list(seq)[-n:]
    return [tail[0]] * (n - len(tail)) + tail


def frames(obs: Any, n: int) -> list[Any]:
    """The last `n` frames of one Act, oldest first: `obs.history` (the steps before, as many as
    GetSpec's observation_history asked for minus one) then the observation itself."""
    return last(list(obs.history) + [obs], n)


def rgb(frame: Any, camera: str) -> np.ndarray:
    """`camera`'s RAW_RGB8 image of one frame as (height, width, 3) uint8, without a copy."""
    for im in frame.images:
        if im.camera == camera:
            if len(im.data) != im.width * im.height * 3:
                raise ValueError(f"`{camera}` image is not RAW_RGB8 {im.width}x{im.height} (GetSpec asks for RAW_RGB8)")
            return np.frombuffer(im.data, dtype=np.uint8).reshape(im.height, im.width, 3)
    raise ValueError(f"observation has no `{camera}` image; the policy's GetSpec asked for it")


def depth(frame: Any, camera: str) -> np.ndarray:
    """`camera`'s depth image of one frame as (height, width) float32 metres (+inf: nothing hit)."""
    for im in frame.depth:
        if im.camera == camera:
            if len(im.data) != im.width * im.height * 4:
                raise ValueError(f"`{camera}` depth is not {im.width}x{im.height} float32")
            return np.frombuffer(im.data, dtype="<f4").reshape(im.height, im.width)
    raise ValueError(f"observation has no `{camera}` depth; the policy's GetSpec asked for it")
