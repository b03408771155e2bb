#!/usr/bin/env python3
"""Reference SSIM/PSNR values for `crates/metrics/tests/ssim_fixtures.rs`.

Rerun (from the repository root):
    python3 -m pip install scikit-image torch pillow numpy
    python3 tools/make_ssim_fixtures.py crates/metrics/tests/fixtures/ssim

Writes image pairs as 8-bit PNGs (so Rust reads exactly the values Python used) and
`expected.json` with, per pair:
  * `ssim_skimage`: skimage.metrics.structural_similarity(a, b, gaussian_weights=True, sigma=1.5,
    use_sample_covariance=False, data_range=1, channel_axis=-1) on float64 images;
  * `ssim_inria`: the 3DGS training-loss SSIM (Inria `utils/loss_utils.py::ssim`: 11x11 Gaussian
    sigma 1.5, zero-padded conv2d with groups=C, mean over everything), re-stated here in torch
    float64;
  * `psnr`: skimage.metrics.peak_signal_noise_ratio(a, b, data_range=1).
"""
import json
import os
import sys

import numpy as np
from PIL import Image
from skimage.metrics import peak_signal_noise_ratio, structural_similarity

try:
    import torch
    import torch.nn.functional as F
except ImportError:  # the Inria variant is optional for a rerun without torch
    torch = None


def inria_ssim(a, b):
    """The Inria 3DGS `ssim(img1, img2)` (window 11, sigma 1.5, size_average=True), float64."""
    x = torch.from_numpy(a).permute(2, 0, 1)[None].double()
    y = torch.from_numpy(b).permute(2, 0, 1)[None].double()
    channel = x.shape[1]
    k = torch.tensor([np.exp(-((i - 5) ** 2) / (2 * 1.5**2)) for i in range(11)], dtype=torch.float64)
    k = k / k.sum()
    window = (k[:, None] @ k[None, :])[None, None].expand(channel, 1, 11, 11).contiguous()
    mu1 = F.conv2d(x, window, padding=5, groups=channel)
    mu2 = F.conv2d(y, window, padding=5, groups=channel)
    s1 = F.conv2d(x * x, window, padding=5, groups=channel) - mu1 * mu1
    s2 = F.conv2d(y * y, window, padding=5, groups=channel) - mu2 * mu2
    s12 = F.conv2d(x * y, window, padding=5, groups=channel) - mu1 * mu2
    c1, c2 = 0.01**2, 0.03**2
    m = ((2 * mu1 * mu2 + c1) * (2 * s12 + c2)) / ((mu1 * mu1 + mu2 * mu2 + c1) * (s1 + s2 + c2))
    return float(m.mean())


def make_pair(rng, w, h, c, kind):
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    base = 0.5 + 0.4 * np.sin(xx / 3.1 + 0.3 * yy) * np.cos(yy / 4.7)
    base = np.repeat(base[..., None], c, axis=2) + 0.1 * rng.random((h, w, c))
    if kind == "noise":
        other = base + 0.08 * rng.standard_normal((h, w, c))
    elif kind == "blur":
        other = (base + np.roll(base, 1, 0) + np.roll(base, 1, 1) + np.roll(base, -1, 1)) / 4
    else:  # "shift": contrast/brightness change plus a one-pixel shift
        other = 0.8 * np.roll(base, 1, 1) + 0.1
    q = lambda v: np.clip(np.round(np.clip(v, 0, 1) * 255), 0, 255).astype(np.uint8)
    return q(base), q(other)


def main(out):
    os.makedirs(out, exist_ok=True)
    rng = np.random.default_rng(2024)
    cases = [
        (11, 11, 1, "noise"),
        (16, 16, 3, "noise"),
        (33, 21, 3, "blur"),
        (47, 31, 1, "shift"),
        (64, 48, 3, "shift"),
        (25, 40, 3, "noise"),
        (96, 72, 1, "blur"),
        (101, 67, 3, "noise"),
    ]
    expected = []
    for i, (w, h, c, kind) in enumerate(cases):
        a8, b8 = make_pair(rng, w, h, c, kind)
        names = []
        for tag, arr in (("a", a8), ("b", b8)):
            name = f"pair{i:02d}_{tag}.png"
            Image.fromarray(arr[..., 0] if c == 1 else arr).save(os.path.join(out, name))
            names.append(name)
        a, b = a8.astype(np.float64) / 255.0, b8.astype(np.float64) / 255.0
        entry = {
            "a": names[0],
            "b": names[1],
            "width": w,
            "height": h,
            "channels": c,
            "ssim_skimage": float(
                structural_similarity(a, b, gaussian_weights=True, sigma=1.5,
                                      use_sample_covariance=False, data_range=1.0, channel_axis=-1)
            ),
            "psnr": float(peak_signal_noise_ratio(a, b, data_range=1.0)),
        }
        if torch is not None:
            entry["ssim_inria"] = inria_ssim(a, b)
        expected.append(entry)
    with open(os.path.join(out, "expected.json"), "w") as f:
        json.dump({"generator": "tools/make_ssim_fixtures.py", "pairs": expected}, f, indent=1)


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "crates/metrics/tests/fixtures/ssim")
