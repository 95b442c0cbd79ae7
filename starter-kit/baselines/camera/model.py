"""The camera baseline's network, checkpoint file and batched inference.

`CameraPolicy`: one pretrained EfficientNet-Lite0 trunk (encoder.py, frozen BatchNorm) shared by
both cameras and both history frames; each image's 320-channel stride-32 map is projected to
`d_model` and pooled to `grid x grid` spatial tokens (3x3 at 96x96). With a state token (MLP
of the normalised state), the sub-task's word tokens and a readout token, a small pre-norm
transformer encoder reads them all; the readout regresses the normalised 16x10 chunk (MSE,
deterministic). Token embeddings say which camera, frame and cell a token comes from.
Normalisation statistics live in buffers, so a checkpoint is one file: fp16 weights, config,
vocabulary, meta (about 11 MiB at the defaults; save() refuses more than 16 MiB).

`Batcher`: concurrent callers (DAgger rollout threads, gRPC Act calls) submit one decision each;
one thread runs them through the network together.
"""

import io
import logging

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from ..batching import RequestBatcher
from . import features as FT
from .encoder import OUT_CHANNELS, Trunk

FORMAT = "kitchen-r-camera-policy/1"
MAX_BYTES = 16 * 2**20


class CameraPolicy(nn.Module):
    def __init__(
        self,
        vocab_size,
        image_size=96,
        d_model=256,
        layers=3,
        heads=4,
        grid=3,
        pretrained=False,
        aux=False,
        depth=False,
    ):
        super().__init__()
        self.config = {
            "vocab_size": vocab_size,
            "image_size": image_size,
            "d_model": d_model,
            "layers": layers,
            "heads": heads,
            "grid": grid,
            "aux": aux,
            "depth": depth,
        }
        d = d_model
        self.trunk = Trunk(pretrained=pretrained)
        self.proj = nn.Conv2d(OUT_CHANNELS, d, 1)
        n_img = FT.views(depth) * FT.HISTORY * grid * grid
        self.img_pos = nn.Parameter(torch.randn(n_img, d) * 0.02)
        self.state_mlp = nn.Sequential(nn.Linear(FT.STATE_DIM, d), nn.GELU(), nn.Linear(d, d))
        self.word = nn.Embedding(vocab_size, d, padding_idx=FT.PAD)
        self.word_pos = nn.Parameter(torch.randn(FT.MAX_WORDS, d) * 0.02)
        self.readout = nn.Parameter(torch.randn(2, d) * 0.02)  # readout token, state token's type
        layer = nn.TransformerEncoderLayer(
            d, heads, 4 * d, dropout=0.0, activation="gelu", batch_first=True, norm_first=True
        )
        self.transformer = nn.TransformerEncoder(layer, layers, enable_nested_tensor=False)
        self.out = nn.Sequential(nn.LayerNorm(d), nn.Linear(d, FT.HORIZON * FT.ACTION_DIM))
        # The auxiliary goal head (train.py --aux-weight): trained, never read when serving.
        self.aux = nn.Sequential(nn.LayerNorm(d), nn.Linear(d, FT.AUX_DIM)) if aux else None
        self.register_buffer("s_mean", torch.zeros(FT.STATE_DIM))
        self.register_buffer("s_std", torch.ones(FT.STATE_DIM))
        self.register_buffer("y_mean", torch.zeros(FT.HORIZON * FT.ACTION_DIM))
        self.register_buffer("y_std", torch.ones(FT.HORIZON * FT.ACTION_DIM))

    def encoder_parameters(self):
        return list(self.trunk.parameters())

    def head_parameters(self):
        ids = {id(p) for p in self.encoder_parameters()}
        return [p for p in self.parameters() if id(p) not in ids]

    def set_statistics(self, s, y):
        """Normalisation from training rows (std floored: constant columns such as padding)."""
        self.s_mean.copy_(s.float().mean(0))
        self.s_std.copy_(s.float().std(0).clamp_min(1e-2))
        self.y_mean.copy_(y.float().mean(0))
        self.y_std.copy_(y.float().std(0).clamp_min(1e-3))

    def normalise_y(self, y):
        return (y - self.y_mean) / self.y_std

    def forward(self, images, state, words, shift=0, with_aux=False):
        """Normalised chunk (B, 160) from images (B, views, HISTORY, S, S, 3) uint8, raw state
        (B, STATE_DIM) and word ids (B, MAX_WORDS). `shift`: random-shift augmentation in pixels
        (training only; one shift per sample and camera, the same for its frames). `with_aux`:
        also the auxiliary goal prediction (B, AUX_DIM) of a model built with `aux=True`."""
        b, nc, nh, s = images.shape[:4]
        x = images.reshape(b * nc * nh, s, s, 3).permute(0, 3, 1, 2).float()
        if shift:
            x = random_shift(x.reshape(b * nc, nh * 3, s, s), shift).reshape(b * nc * nh, 3, s, s)
        x = x.contiguous(memory_format=torch.channels_last)
        f = self.proj(self.trunk(x))
        g = self.config["grid"]
        if f.shape[-1] != g or f.shape[-2] != g:
            f = F.adaptive_avg_pool2d(f, g)
        img = f.flatten(2).transpose(1, 2).reshape(b, nc * nh * g * g, -1) + self.img_pos
        st = self.state_mlp(((state - self.s_mean) / self.s_std).clamp(-10, 10)) + self.readout[1]
        w = self.word(words) + self.word_pos
        tokens = torch.cat([self.readout[0].expand(b, 1, -1), st[:, None], w, img], 1)
        pad = torch.zeros(tokens.shape[:2], dtype=torch.bool, device=tokens.device)
        pad[:, 2 : 2 + FT.MAX_WORDS] = words == FT.PAD
        h = self.transformer(tokens, src_key_padding_mask=pad)
        if with_aux:
            return self.out(h[:, 0]).float(), self.aux(h[:, 0]).float()
        return self.out(h[:, 0]).float()

    @torch.no_grad()
    def chunk(self, images, state, words):
        """Raw chunks (B, 16, 10) as numpy."""
        y = self(images, state, words)
        return (y * self.y_std + self.y_mean).reshape(-1, FT.HORIZON, FT.ACTION_DIM).cpu().numpy()


def random_shift(x, pad):
    """Shift each image (N, C, S, S) by up to `pad` pixels (edge replicated): DrQ's augmentation."""
    n, _, s, _ = x.shape
    x = F.pad(x, (pad, pad, pad, pad), mode="replicate")
    eps = 1.0 / (s + 2 * pad)
    ar = torch.linspace(-1.0 + eps, 1.0 - eps, s + 2 * pad, device=x.device)[:s]
    base = torch.stack(torch.meshgrid(ar, ar, indexing="xy"), -1)[None].expand(n, -1, -1, -1)
    off = torch.randint(0, 2 * pad + 1, (n, 1, 1, 2), device=x.device).float() * 2.0 * eps
    return F.grid_sample(x, base + off, padding_mode="zeros", align_corners=False)


def save(path, model, vocab, meta):
    """fp16 weights (fp32 statistics), config, vocabulary and meta in one file (<= 16 MiB)."""
    state = {
        k: (
            v.detach().cpu().half()
            if v.is_floating_point() and not k.endswith(("_mean", "_std", "running_var", "running_mean"))
            else v.detach().cpu()
        )
        for k, v in model.state_dict().items()
    }
    buf = io.BytesIO()
    torch.save({"format": FORMAT, "config": model.config, "state": state, "vocab": list(vocab), "meta": meta}, buf)
    if buf.tell() > MAX_BYTES:
        raise ValueError(
            f"checkpoint is {buf.tell() / 2**20:.1f} MiB, over the 16 MiB limit: use a smaller --d-model/--layers"
        )
    with open(path, "wb") as fh:
        fh.write(buf.getvalue())


def load(path, device="cpu"):
    ck = torch.load(path, map_location="cpu", weights_only=True)
    if ck.get("format") != FORMAT:
        raise ValueError(f"{path}: not a camera-baseline checkpoint (format {ck.get('format')!r}, want {FORMAT!r})")
    model = CameraPolicy(**ck["config"])
    model.load_state_dict({k: v.float() if v.is_floating_point() else v for k, v in ck["state"].items()})
    model.to(device).eval()
    return model, ck["vocab"], ck["meta"]


class Batcher(RequestBatcher):
    """Runs concurrent `decide(images, state, words)` calls through `model` in batches of up to
    `max_batch` (images at render size: resized here, on the model's device); each caller gets
    its chunk made valid (features.finish). `lock` is held while the weights run: DAgger holds it
    to change them.

    `graphs=True` (serving, on CUDA) replays each padded batch size's pass as a CUDA graph: the
    eager pass is bound by launching its kernels (8.1 ms at batch 1 and 8.7 ms at 16 on an H200,
    wall time equal to CPU time: `forward_speed.py`), CPU time the server's one Python thread then
    lacks for the calls around it. A size whose capture fails runs eagerly, with a warning."""

    def __init__(self, model, max_batch=32, autocast=True, graphs=False):
        self.model = model
        # The weights stay on one device (DAgger changes them in place), so read it once.
        self.device = next(model.parameters()).device
        self.autocast = autocast
        self.graphs = {} if graphs else None
        super().__init__(self._decide, max_batch)

    def decide(self, images, state, words):
        return self.submit((images, state, words))

    def warm_up(self):
        """One forward of every batch shape `_forward` pads to (on the CPU, of batch 1); with
        `graphs`, each shape's graph is captured here, before the server takes calls."""
        dev = self.device
        top = max(1, self.max_batch - 1).bit_length()
        z = FT.RENDER_SIZE
        x = (
            np.zeros((FT.views(self.model.config.get("depth", False)), FT.HISTORY, z, z, 3), np.uint8),
            np.zeros(FT.STATE_DIM, np.float32),
            np.zeros(FT.MAX_WORDS, np.int64),
        )
        for n in [1 << k for k in range(top + 1)] if dev.type == "cuda" else [1]:
            with self.lock:
                self._forward([x] * n)

    def _decide(self, inputs):
        return [FT.finish(y) for y in self._forward(inputs)]

    def _pass(self, ims, st, wd):
        """The network on device tensors: raw chunks (B, 16 * 10), denormalised."""
        m = self.model
        ims = FT.resize_images(ims, m.config["image_size"])
        # No autocast cache: a CUDA graph must cast the weights inside the capture.
        with torch.autocast("cuda", dtype=torch.bfloat16, enabled=self.autocast and ims.is_cuda, cache_enabled=False):
            y = m(ims, st, wd)
        return y * m.y_std + m.y_mean

    @torch.no_grad()
    def _forward(self, inputs):
        dev = self.device
        # Batches padded to a power of two: few shapes, so cuDNN's autotuning runs only a few times.
        n = 1 << (len(inputs) - 1).bit_length() if dev.type == "cuda" else len(inputs)
        items = list(inputs) + [inputs[0]] * (n - len(inputs))
        ims = torch.from_numpy(np.stack([x[0] for x in items]))
        st = torch.from_numpy(np.stack([x[1] for x in items]))
        wd = torch.from_numpy(np.stack([x[2] for x in items]))
        graph = self._graph(n, (ims, st, wd)) if self.graphs is not None and dev.type == "cuda" else None
        if graph is None:
            y = self._pass(ims.to(dev), st.to(dev), wd.to(dev))
        else:
            g, static, y = graph
            for buf, x in zip(static, (ims, st, wd)):
                buf.copy_(x)
            g.replay()
        return y.reshape(-1, FT.HORIZON, FT.ACTION_DIM)[: len(inputs)].float().cpu().numpy()

    def _graph(self, n, like):
        """Batch size `n`'s captured pass (graph, static inputs, static output), or None when its
        capture failed (that size then runs eagerly)."""
        if n in self.graphs:
            return self.graphs[n]
        static = [x.to(self.device) for x in like]
        try:
            side = torch.cuda.Stream()
            side.wait_stream(torch.cuda.current_stream())
            with torch.cuda.stream(side):
                for _ in range(3):  # warm-up passes off the default stream, as capture requires
                    self._pass(*static)
            torch.cuda.current_stream().wait_stream(side)
            g = torch.cuda.CUDAGraph()
            with torch.cuda.graph(g):
                out = self._pass(*static)
            self.graphs[n] = (g, static, out)
        except Exception as e:  # noqa: BLE001 — any capture failure means: run this size eagerly
            logging.warning("CUDA graph capture at batch %d failed (%s): that size runs eagerly", n, e)
            self.graphs[n] = None
        return self.graphs[n]
