#!/usr/bin/env python3
"""A square copy of a DTU scan in the IDR layout: each image and mask cropped to the centred
square (600 x 600 of 800 x 600) and resized to SIZE x SIZE, the projection matrices changed to
match, so that a run at another resolution and aspect can be compared with the original's.

    python3 tools/make_dtu_square.py SRC_SCAN OUT_DIR [SIZE=384]

Pixel coordinates are continuous with pixel i covering [i, i + 1): cropping by x0 pixels and
resizing by s = SIZE / side maps u to s (u - x0), which is applied to every world_mat as
S @ world_mat. scale_mat (the unit sphere's placement) is unchanged.
"""
import sys
from pathlib import Path

import numpy as np
from PIL import Image


def main() -> None:
    src, out = Path(sys.argv[1]), Path(sys.argv[2])
    size = int(sys.argv[3]) if len(sys.argv) > 3 else 384
    cams = dict(np.load(src / "cameras_sphere.npz"))
    images = sorted((src / "image").glob("*.png"))
    masks = sorted((src / "mask").glob("*.png"))
    if not images:
        sys.exit(f"{src}/image: no PNG images")
    w, h = Image.open(images[0]).size
    side = min(w, h)
    x0, y0 = (w - side) // 2, (h - side) // 2
    s = size / side
    crop = np.array([[s, 0, -s * x0, 0], [0, s, -s * y0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
    for folder, files, resample in [("image", images, Image.LANCZOS), ("mask", masks, Image.BOX)]:
        (out / folder).mkdir(parents=True, exist_ok=True)
        for f in files:
            im = Image.open(f).crop((x0, y0, x0 + side, y0 + side)).resize((size, size), resample)
            if folder == "mask":
                im = im.convert("L").point(lambda v: 255 if v >= 128 else 0)
            im.save(out / folder / f.name)
    for key in list(cams):
        if key.startswith("world_mat_") and not key.startswith("world_mat_inv"):
            i = key[len("world_mat_"):]
            cams[key] = crop @ cams[key]
            cams[f"world_mat_inv_{i}"] = np.linalg.inv(cams[key])
    np.savez(out / "cameras_sphere.npz", **cams)
    print(f"{len(images)} views, {w}x{h} -> {size}x{size} (crop at {x0},{y0}, scale {s:.4f}) in {out}")


if __name__ == "__main__":
    main()
