"""The checkpoint file: fp16 EMA weights, the model config, the sub-task vocabulary and the
normalisation statistics, everything serving needs (no dataset at serving time). Kept under
16 MiB so it can be carried back from a GPU machine and committed or attached as it is."""

import io
import os
from pathlib import Path

import torch

from .features import Normaliser
from .model import DiffusionPolicy

MAX_CHECKPOINT_BYTES = 16 * 2**20
FORMAT = "kitchen-r-diffusion-policy/1"


def save_checkpoint(path, model, config, vocab, norm, meta):
    state = {k: (v.half() if v.is_floating_point() else v).cpu() for k, v in model.state_dict().items()}
    blob = {
        "format": FORMAT,
        "config": config,
        "vocab": list(vocab),
        "stats": norm.to_dict(),
        "meta": meta,
        "model": state,
    }
    buf = io.BytesIO()
    torch.save(blob, buf)
    data = buf.getvalue()
    if len(data) > MAX_CHECKPOINT_BYTES:
        raise SystemExit(f"checkpoint would be {len(data)} bytes, over the 16 MiB limit: use a smaller model")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_bytes(data)
    os.replace(tmp, path)
    return len(data)


def load_checkpoint(path, device="cpu"):
    """(model in eval mode on `device`, float32; Normaliser; vocabulary; meta)."""
    blob = torch.load(path, map_location="cpu", weights_only=True)
    if blob.get("format") != FORMAT:
        raise SystemExit(f"{path}: not a diffusion-policy checkpoint of this baseline (format {blob.get('format')!r})")
    # Checkpoints written before the odometry features had none (DEFAULT_CONFIG turns them on).
    config = {"odometry": False, **blob["config"]}
    model = DiffusionPolicy(config, len(blob["vocab"]))
    model.load_state_dict({k: v.float() if v.is_floating_point() else v for k, v in blob["model"].items()})
    model.to(device).eval()
    return model, Normaliser(blob["stats"]), blob["vocab"], blob.get("meta", {})
