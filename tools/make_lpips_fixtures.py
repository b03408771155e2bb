#!/usr/bin/env python3
"""Reference LPIPS distances for `crates/metrics/tests/lpips.rs`.

Rerun (from the repository root; torch/torchvision from PyPI, CPU is enough):
    python3 -m pip install torch torchvision torchsummary tqdm pillow numpy
    python3 -m pip install --no-deps lpips==0.1.4 stlpips-pytorch==0.0.2
    python3 tools/make_lpips_fixtures.py crates/metrics/tests/fixtures/lpips

What is compared with what (torchvision's ImageNet backbones cannot be downloaded here, so the
plain `lpips` code path runs with other weights of the same shapes):
  * st_alex:  stlpips.LPIPS(net='alex', variant='shift_tolerant') — the package's own
              code and shipped weights (the network fewview embeds as its default).
  * st_vgg:   stlpips.LPIPS(net='vgg', variant='shift_tolerant'), likewise.
  * lpips_alex: lpips.LPIPS(net='alex', version='0.1') with the package's v0.1 linear heads and
              the ST-LPIPS AlexNet convolution weights copied, in layer order, into the plain
              torchvision AlexNet backbone (same shapes, different strides/pooling).
  * lpips_vgg: lpips.LPIPS(net='vgg') likewise with the ST-LPIPS VGG16 convolutions.
  * lpips_squeeze: lpips.LPIPS(net='squeeze') with seeded random SqueezeNet 1.1 weights
              (torch.manual_seed(0), rounded to float16 so that the committed file
              `squeeze_random_f16.pth` holds exactly the values used).
All with `normalize=True` (inputs in [0, 1]); images are 8-bit PNGs so Rust reads the same values.
"""
import json
import os
import sys
import warnings

import numpy as np
import torch
from PIL import Image

warnings.filterwarnings("ignore")
import lpips  # noqa: E402
import stlpips_pytorch  # noqa: E402
from stlpips_pytorch import stlpips  # noqa: E402  (the package __init__ is empty)

SIZES = [(64, 64), (48, 80), (100, 75), (37, 53), (128, 96), (72, 72),
         (90, 60), (64, 100), (51, 51), (80, 120), (96, 64), (160, 120)]
VGG_PAIRS = 5  # the VGG variants on the first few pairs (CPU time in the Rust test)


def make_pair(rng, w, h, kind):
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    base = np.stack([0.5 + 0.35 * np.sin(xx / (3 + c) + yy / (5 - c)) * np.cos(yy / 7.0 + c) for c in range(3)], -1)
    base += 0.15 * rng.random((h, w, 3))
    if kind == 0:
        other = base + 0.1 * rng.standard_normal((h, w, 3))
    elif kind == 1:
        other = (base + np.roll(base, 1, 0) + np.roll(base, 1, 1) + np.roll(base, (1, 1), (0, 1))) / 4
    elif kind == 2:
        other = np.roll(base, 2, 1) * 0.9 + 0.05
    else:
        other = base[..., ::-1] * 0.8 + 0.1
    q = lambda v: np.clip(np.round(np.clip(v, 0, 1) * 255), 0, 255).astype(np.uint8)
    return q(base), q(other)


def to_tensor(a):
    return torch.from_numpy(a.astype(np.float32) / 255.0).permute(2, 0, 1)[None]


def copy_convs_by_order(src_state, dst_module):
    """Copies the conv weights/biases of `src_state` (net.* keys) into `dst_module` in layer order."""
    def order(keys):
        def k(name):
            parts = name.split(".")
            return (int(parts[1][5:]), int(parts[2]))  # sliceK, layer index
        return sorted(keys, key=k)
    src_w = order([k for k in src_state if k.startswith("net.") and k.endswith(".weight") and src_state[k].dim() == 4])
    dst_state = dst_module.state_dict()
    dst_w = order(["net." + k for k in dst_state if k.endswith(".weight")])
    assert len(src_w) == len(dst_w), (len(src_w), len(dst_w))
    new = {}
    for s, d in zip(src_w, dst_w):
        d = d[4:]
        assert dst_state[d].shape == src_state[s].shape, (s, d)
        new[d] = src_state[s]
        new[d[:-len("weight")] + "bias"] = src_state[s[:-len("weight")] + "bias"]
    dst_module.load_state_dict(new)


def main(out):
    os.makedirs(out, exist_ok=True)
    torch.set_grad_enabled(False)
    rng = np.random.default_rng(11)
    st_dir = os.path.join(os.path.dirname(stlpips_pytorch.__file__), "weights", "vST0.0")

    st_alex = stlpips.LPIPS(net="alex", variant="shift_tolerant", verbose=False).eval()
    st_vgg = stlpips.LPIPS(net="vgg", variant="shift_tolerant", verbose=False).eval()

    lp_alex = lpips.LPIPS(net="alex", version="0.1", pnet_rand=True, verbose=False).eval()
    copy_convs_by_order(torch.load(os.path.join(st_dir, "alex_shift_tolerant.pth"), map_location="cpu"), lp_alex.net)
    lp_vgg = lpips.LPIPS(net="vgg", version="0.1", pnet_rand=True, verbose=False).eval()
    copy_convs_by_order(torch.load(os.path.join(st_dir, "vgg_shift_tolerant.pth"), map_location="cpu"), lp_vgg.net)

    torch.manual_seed(0)
    lp_sq = lpips.LPIPS(net="squeeze", version="0.1", pnet_rand=True, verbose=False).eval()
    half = {}
    for k, v in lp_sq.net.state_dict().items():
        v16 = v.half()
        half["features." + k.split(".", 1)[1]] = v16.clone()
        v.copy_(v16.float())
    torch.save(half, os.path.join(out, "squeeze_random_f16.pth"))

    pairs = []
    for i, (w, h) in enumerate(SIZES):
        a8, b8 = make_pair(rng, w, h, i % 4)
        names = []
        for tag, arr in (("a", a8), ("b", b8)):
            name = f"pair{i:02d}_{tag}.png"
            Image.fromarray(arr).save(os.path.join(out, name))
            names.append(name)
        a, b = to_tensor(a8), to_tensor(b8)
        e = {"a": names[0], "b": names[1], "width": w, "height": h,
             "st_alex": float(st_alex(a, b, normalize=True)),
             "lpips_alex": float(lp_alex(a, b, normalize=True)),
             "lpips_squeeze": float(lp_sq(a, b, normalize=True))}
        if i < VGG_PAIRS:
            e["st_vgg"] = float(st_vgg(a, b, normalize=True))
            e["lpips_vgg"] = float(lp_vgg(a, b, normalize=True))
        pairs.append(e)
    meta = {"generator": "tools/make_lpips_fixtures.py", "torch": torch.__version__,
            "lpips": "0.1.4", "stlpips_pytorch": "0.0.2", "pairs": pairs}
    with open(os.path.join(out, "expected.json"), "w") as f:
        json.dump(meta, f, indent=1)


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "crates/metrics/tests/fixtures/lpips")
