"""The privileged baseline's network and checkpoint file.

An MLP from one decision's features (features.py) to the expert's 16x10 chunk, with the
normalisation statistics inside the module, so a checkpoint is one self-contained file: the
weights (fp32), the layer sizes and the statistics. A 4x512 network is 3.6 MiB, far under the
16 MiB a checkpoint may take.
"""

import torch
from torch import nn

from .features import ACTION_DIM, FEATURES, HORIZON, TIME_INDEX

FORMAT = "kitchen-r-privileged-mlp/1"


class PrivilegedMLP(nn.Module):
    def __init__(self, width=512, depth=4, features=FEATURES, task_time=True):
        super().__init__()
        # `task_time=False` (train.py --no-task-time): the task's time is read as 0, in training
        # and serving alike (the checkpoint's config carries it; older checkpoints read it).
        self.config = {"width": width, "depth": depth, "features": features, "task_time": task_time}
        mask = torch.ones(features)
        if not task_time:
            mask[TIME_INDEX] = 0.0
        self.register_buffer("input_mask", mask, persistent=False)
        layers, n = [], features
        for _ in range(depth):
            layers += [nn.Linear(n, width), nn.LayerNorm(width), nn.GELU()]
            n = width
        layers.append(nn.Linear(n, HORIZON * ACTION_DIM))
        self.net = nn.Sequential(*layers)
        self.register_buffer("x_mean", torch.zeros(features))
        self.register_buffer("x_std", torch.ones(features))
        self.register_buffer("y_mean", torch.zeros(HORIZON * ACTION_DIM))
        self.register_buffer("y_std", torch.ones(HORIZON * ACTION_DIM))

    def set_statistics(self, x, y):
        """Normalisation from training rows (std floored: one-hot and constant columns)."""
        x = x * self.input_mask.to(x.device)
        self.x_mean.copy_(x.mean(0))
        self.x_std.copy_(x.std(0).clamp_min(1e-2))
        self.y_mean.copy_(y.mean(0))
        self.y_std.copy_(y.std(0).clamp_min(1e-3))

    def normalise_x(self, x):
        return ((x * self.input_mask - self.x_mean) / self.x_std).clamp(-10.0, 10.0)

    def normalise_y(self, y):
        return (y - self.y_mean) / self.y_std

    def forward(self, x):
        """Normalised prediction from raw features."""
        return self.net(self.normalise_x(x))

    @torch.no_grad()
    def chunk(self, x):
        """Raw chunks (N, 16, 10) from raw features (N, FEATURES)."""
        return (self(x) * self.y_std + self.y_mean).reshape(-1, HORIZON, ACTION_DIM)


def save(path, model, meta):
    state = {k: v.detach().cpu() for k, v in model.state_dict().items()}
    torch.save({"format": FORMAT, "config": model.config, "state": state, "meta": meta}, path)


def load(path, device="cpu"):
    ck = torch.load(path, map_location=device, weights_only=True)
    if ck.get("format") != FORMAT:
        raise ValueError(f"{path}: not a privileged-baseline checkpoint (format {ck.get('format')!r}, want {FORMAT!r})")
    model = PrivilegedMLP(**ck["config"]).to(device)
    model.load_state_dict(ck["state"])
    model.eval()
    return model, ck["meta"]
