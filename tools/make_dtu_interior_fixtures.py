#!/usr/bin/env python3
"""Object interiors of DTU test views as the sparse-view peers' `metrics_dtu.py` takes them, for
`crates/splat/tests/benchmark.rs` (`the_dtu_interior_is_the_peers_resized_mask_that_is_exactly_one`).

Rerun (from the repository root, with ../shared/data beside it):
    python3 -m pip install pillow numpy
    python3 tools/make_dtu_interior_fixtures.py ../shared/data/dtu/scan65 crates/splat/tests/fixtures/dtu_interior

The peers (CoR-GS and DNGaussian, `metrics_dtu.py`) open each object mask, resize it to the test
size with Pillow's `Image.resize` and its default filter (bicubic, antialiased), and score PSNR
where the result equals 1. Here the shared 800x600 masks are resized to 400x300 the same way and
`== 255` is written as a 0/255 grey PNG per view, named by the view's index.
"""
import os
import sys

import numpy as np
from PIL import Image

VIEWS = [1, 12, 33, 45]


def main(scene, out):
    os.makedirs(out, exist_ok=True)
    for v in VIEWS:
        mask = Image.open(os.path.join(scene, "mask", f"{v:03d}.png")).convert("L")
        small = np.asarray(mask.resize((400, 300)))
        interior = np.where(small == 255, 255, 0).astype(np.uint8)
        Image.fromarray(interior, mode="L").save(os.path.join(out, f"{v:03d}.png"))
        print(v, int((interior > 0).sum()), "interior pixels")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
