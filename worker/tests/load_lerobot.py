"""Loads a Kitchen-R LeRobotDataset export with LeRobot itself and iterates one batch.

Usage: load_lerobot.py ROOT   (needs `pip install lerobot`; offline: nothing is fetched)
Prints a JSON summary of the first batch.
"""
import json
import os
import sys

os.environ.setdefault("HF_HUB_OFFLINE", "1")

import torch  # noqa: E402
from lerobot.datasets.lerobot_dataset import LeRobotDataset  # noqa: E402


def main(root):
    # PyAV decodes with the FFmpeg its wheel bundles; LeRobot's default (torchcodec) needs the
    # system's FFmpeg libraries, which a fresh machine does not have.
    ds = LeRobotDataset("kitchen-r/collect", root=root, video_backend="pyav")
    loader = torch.utils.data.DataLoader(ds, batch_size=4, shuffle=True, num_workers=0)
    batch = next(iter(loader))
    cams = [k for k in ds.meta.camera_keys]
    print(json.dumps({
        "episodes": ds.num_episodes,
        "frames": ds.num_frames,
        "fps": ds.fps,
        "cameras": cams,
        "image_shape": list(batch[cams[0]].shape),
        "image_range": [float(batch[cams[0]].min()), float(batch[cams[0]].max())],
        "state_shape": list(batch["observation.state"].shape),
        "action_shape": list(batch["action"].shape),
        "task": batch["task"][0],
        "last_item_index": int(ds[len(ds) - 1]["index"]),
    }))


if __name__ == "__main__":
    main(sys.argv[1])
