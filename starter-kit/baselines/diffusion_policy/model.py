"""The network: Diffusion Policy (Chi et al., 2023) as the Kitchen-R paper modifies it.

- One vision encoder per camera (no shared weights): a ResNet-18 trunk from torchvision
  (`weights=None`, GroupNorm instead of BatchNorm) up to layer2, then a strided 3x3 compression
  convolution and average pooling to a small grid of spatial tokens (the paper's "spatial
  features with a compression layer"). layer3 and layer4 are left out so that the checkpoint
  stays under 16 MiB in fp16 (the whole model has about 7.7 M parameters).
- The robot state of each history frame (with odometry: 14 values) through a linear layer, one
  token per frame; the
  sub-task sentence as learned word embeddings, one token per word.
- The tokens (with learned camera/frame/position embeddings) pass a small transformer encoder and
  form the condition sequence that every residual block of a 1-D temporal U-Net (the reference's
  ConditionalUnet1D layout) reads through cross-attention, in place of the reference's FiLM.
  The diffusion step enters each block by FiLM of its sinusoidal embedding.
- DDPM training with 100 steps (squared-cosine schedule, epsilon prediction); DDIM sampling with
  few steps at inference.
"""

import math

import torch
import torch.nn as nn
import torch.nn.functional as F

from .features import ACTION_DIM, CAMERAS, HORIZON, MAX_WORDS, state_dim

DEFAULT_CONFIG = {
    "image_size": 96,
    "n_obs": 2,
    "horizon": HORIZON,
    "d_model": 128,
    "grid": 3,
    "ctx_layers": 2,
    "heads": 4,
    "down_dims": [64, 128, 256],
    "kernel": 5,
    "diffusion_steps": 100,
    # The odometry features in the state (features.py); checkpoints without the key predate them.
    "odometry": True,
}


def _resnet_trunk():
    import torchvision

    r = torchvision.models.resnet18(weights=None, norm_layer=lambda c: nn.GroupNorm(c // 16, c))
    return nn.Sequential(r.conv1, r.bn1, r.relu, r.maxpool, r.layer1, r.layer2)


class CameraEncoder(nn.Module):
    """uint8 images (N, S, S, 3) -> (N, grid*grid, d) tokens."""

    def __init__(self, d, grid):
        super().__init__()
        self.trunk = _resnet_trunk()
        self.compress = nn.Sequential(nn.Conv2d(128, d, 3, 2, 1), nn.GroupNorm(8, d), nn.ReLU())
        self.pool = nn.AdaptiveAvgPool2d(grid)

    def forward(self, x):
        x = x.permute(0, 3, 1, 2).float() / 127.5 - 1.0
        x = self.pool(self.compress(self.trunk(x)))
        return x.flatten(2).transpose(1, 2)


class Conv1dBlock(nn.Module):
    def __init__(self, cin, cout, k):
        super().__init__()
        self.block = nn.Sequential(nn.Conv1d(cin, cout, k, padding=k // 2), nn.GroupNorm(8, cout), nn.Mish())

    def forward(self, x):
        return self.block(x)


class CrossAttnResBlock(nn.Module):
    """Two conv blocks with FiLM of the diffusion step between them, then cross-attention to the
    condition tokens."""

    def __init__(self, cin, cout, tdim, d, heads, k):
        super().__init__()
        self.b1 = Conv1dBlock(cin, cout, k)
        self.b2 = Conv1dBlock(cout, cout, k)
        self.film = nn.Sequential(nn.Mish(), nn.Linear(tdim, 2 * cout))
        self.res = nn.Conv1d(cin, cout, 1) if cin != cout else nn.Identity()
        self.norm = nn.LayerNorm(cout)
        self.attn = nn.MultiheadAttention(cout, heads, kdim=d, vdim=d, batch_first=True)

    def forward(self, x, temb, ctx):
        h = self.b1(x)
        scale, bias = self.film(temb).unsqueeze(-1).chunk(2, dim=1)
        h = self.b2(h * (1 + scale) + bias) + self.res(x)
        q = self.norm(h.transpose(1, 2))
        a, _ = self.attn(q, ctx, ctx, need_weights=False)
        return h + a.transpose(1, 2)


def _step_embedding(t, dim):
    half = dim // 2
    f = torch.exp(-math.log(10000) * torch.arange(half, device=t.device) / (half - 1))
    e = t.float()[:, None] * f[None]
    return torch.cat([e.sin(), e.cos()], dim=-1)


class UNet1D(nn.Module):
    def __init__(self, d, down_dims, heads, k):
        super().__init__()
        tdim = d
        self.tdim = tdim
        self.step_mlp = nn.Sequential(nn.Linear(tdim, 4 * tdim), nn.Mish(), nn.Linear(4 * tdim, tdim))
        dims = [ACTION_DIM] + list(down_dims)
        self.down = nn.ModuleList()
        for i, (a, b) in enumerate(zip(dims[:-1], dims[1:])):
            last = i == len(down_dims) - 1
            self.down.append(
                nn.ModuleList(
                    [
                        CrossAttnResBlock(a, b, tdim, d, heads, k),
                        CrossAttnResBlock(b, b, tdim, d, heads, k),
                        nn.Conv1d(b, b, 3, 2, 1) if not last else nn.Identity(),
                    ]
                )
            )
        m = down_dims[-1]
        self.mid = nn.ModuleList([CrossAttnResBlock(m, m, tdim, d, heads, k) for _ in range(2)])
        self.up = nn.ModuleList()
        rev = list(reversed(list(zip(dims[1:-1], dims[2:]))))
        for a, b in rev:
            self.up.append(
                nn.ModuleList(
                    [
                        CrossAttnResBlock(2 * b, a, tdim, d, heads, k),
                        CrossAttnResBlock(a, a, tdim, d, heads, k),
                        nn.ConvTranspose1d(a, a, 4, 2, 1),
                    ]
                )
            )
        self.final = nn.Sequential(Conv1dBlock(down_dims[0], down_dims[0], k), nn.Conv1d(down_dims[0], ACTION_DIM, 1))

    def forward(self, x, t, ctx):
        """x: (B, horizon, 10) noisy actions, t: (B,) steps, ctx: (B, L, d) -> predicted noise."""
        temb = self.step_mlp(_step_embedding(t, self.tdim))
        h = x.transpose(1, 2)
        skips = []
        for r1, r2, down in self.down:
            h = r2(r1(h, temb, ctx), temb, ctx)
            skips.append(h)
            h = down(h)
        for r in self.mid:
            h = r(h, temb, ctx)
        for r1, r2, up in self.up:
            h = torch.cat([h, skips.pop()], dim=1)
            h = up(r2(r1(h, temb, ctx), temb, ctx))
        return self.final(h).transpose(1, 2)


class DiffusionPolicy(nn.Module):
    def __init__(self, config, vocab_size):
        super().__init__()
        c = {**DEFAULT_CONFIG, **config}
        self.config = c
        d, g, n = c["d_model"], c["grid"], c["n_obs"]
        self.cams = nn.ModuleDict({cam: CameraEncoder(d, g) for cam in CAMERAS})
        self.img_pos = nn.Parameter(torch.randn(len(CAMERAS), n, g * g, d) * 0.02)
        self.state_proj = nn.Linear(state_dim(c), d)
        self.state_pos = nn.Parameter(torch.randn(n, d) * 0.02)
        self.word = nn.Embedding(vocab_size, d, padding_idx=0)
        self.word_pos = nn.Parameter(torch.randn(MAX_WORDS, d) * 0.02)
        layer = nn.TransformerEncoderLayer(d, c["heads"], 4 * d, dropout=0.0, batch_first=True, norm_first=True)
        self.ctx = nn.TransformerEncoder(layer, c["ctx_layers"], enable_nested_tensor=False)
        self.ctx_norm = nn.LayerNorm(d)
        self.unet = UNet1D(d, c["down_dims"], c["heads"], c["kernel"])
        T = c["diffusion_steps"]
        # Squared-cosine schedule (Nichol & Dhariwal), as the reference's DDPM scheduler.
        s = torch.arange(T + 1, dtype=torch.float64) / T
        f = torch.cos((s + 0.008) / 1.008 * math.pi / 2) ** 2
        betas = torch.clamp(1 - f[1:] / f[:-1], max=0.999)
        self.register_buffer("alphas_cumprod", torch.cumprod(1 - betas, 0).float(), persistent=False)

    def vision_parameters(self):
        return list(self.cams.parameters())

    def encode(self, images, state, words):
        """images: {cam: (B, n, S, S, 3) uint8}, state: (B, n, 10) normalised, words: (B, W)."""
        toks = []
        for i, cam in enumerate(CAMERAS):
            x = images[cam]
            B, n = x.shape[:2]
            t = self.cams[cam](x.flatten(0, 1)).view(B, n, -1, self.config["d_model"])
            toks.append((t + self.img_pos[i]).flatten(1, 2))
        toks.append(self.state_proj(state) + self.state_pos)
        toks.append(self.word(words) + self.word_pos)
        return self.ctx_norm(self.ctx(torch.cat(toks, dim=1)))

    def loss(self, images, state, words, actions):
        ctx = self.encode(images, state, words)
        B = actions.shape[0]
        t = torch.randint(0, self.config["diffusion_steps"], (B,), device=actions.device)
        noise = torch.randn_like(actions)
        ac = self.alphas_cumprod[t].view(B, 1, 1)
        noisy = ac.sqrt() * actions + (1 - ac).sqrt() * noise
        return F.mse_loss(self.unet(noisy, t, ctx).float(), noise)

    @torch.no_grad()
    def sample(self, images, state, words, steps=10, noise=None):
        """DDIM (deterministic given `noise`) sampling with `steps` of the 100 training steps;
        returns normalised actions (B, horizon, 10)."""
        ctx = self.encode(images, state, words)
        B = state.shape[0]
        T = self.config["diffusion_steps"]
        shape = (B, self.config["horizon"], ACTION_DIM)
        x = torch.randn(shape, device=state.device) if noise is None else noise.to(state.device)
        ts = torch.linspace(T - 1, 0, max(1, steps)).round().long().tolist()
        ac = self.alphas_cumprod
        for i, t in enumerate(ts):
            tt = torch.full((B,), t, device=state.device, dtype=torch.long)
            eps = self.unet(x, tt, ctx).float()
            a = ac[t]
            x0 = ((x - (1 - a).sqrt() * eps) / a.sqrt()).clamp(-1, 1)
            eps = (x - a.sqrt() * x0) / (1 - a).sqrt()
            a_prev = ac[ts[i + 1]] if i + 1 < len(ts) else torch.tensor(1.0, device=x.device)
            x = a_prev.sqrt() * x0 + (1 - a_prev).sqrt() * eps
        return x
