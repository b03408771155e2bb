#!/usr/bin/env python3
"""OpenCV StereoSGBM references for `crates/geom/tests/sgbm_fixtures.rs`.

Rerun (from the repository root):
    python3 -m pip install opencv-python-headless numpy pillow
    cargo build --release -p fewview
    python3 tools/make_sgbm_fixtures.py crates/geom/tests/fixtures/sgbm [--data ../shared/data]

Writes, per case, the 8-bit input pair (`<case>_left.png`, `<case>_right.png`), OpenCV's
fixed-point disparity (`<case>_opencv.npy`, int16, 1/16 px, invalid = (minDisparity - 1) * 16)
and the parameters plus OpenCV's version and its median wall time per `compute` call in
`cases.json`.

Synthetic cases are generated here (a textured background plane and a nearer rectangle, so that
the left-right check and the speckle filter have occlusions to act on). With `--data`, two real
cases are added: the rectified LLFF fern pair (views 1, 10) and a pair of the demo scene
(views 2, 11), both rectified by `fewview stereo` and matched over the disparity range it chose
(so the fixture tests the matcher alone, on the images the matcher sees in the pipeline). Both use
OpenCV's MODE_SGBM (5 paths); compare with `--border opencv`-style matching (see the test).
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import cv2
import numpy as np
from PIL import Image


def textured(rng, h, w, channels):
    img = rng.random((h, w, channels)) * 255
    img = cv2.GaussianBlur(img, (0, 0), 1.2)
    img = (img - img.min()) / (img.max() - img.min()) * 235 + 10
    return img


def synthetic_pair(seed, h, w, channels, d_back, d_front):
    """Left/right views of a background at disparity d_back and a rectangle at d_front."""
    rng = np.random.default_rng(seed)
    back = textured(rng, h, w + 64, channels)
    front = textured(rng, h, w + 64, channels)
    y0, y1, x0, x1 = h // 4, 3 * h // 4, w // 2 - w // 8, w // 2 + w // 5
    left = back[:, :w].copy()
    left[y0:y1, x0:x1] = front[y0:y1, x0:x1]
    right = back[:, d_back:d_back + w].copy()
    right[y0:y1, x0 - d_front:x1 - d_front] = front[y0:y1, x0:x1]
    to8 = lambda a: np.clip(np.round(a), 0, 255).astype(np.uint8)
    return to8(left), to8(right)


def sgbm(params, channels):
    bs = params["block_size"]
    mode = {"five": cv2.STEREO_SGBM_MODE_SGBM, "eight": cv2.STEREO_SGBM_MODE_HH}[params["paths"]]
    return cv2.StereoSGBM_create(
        minDisparity=params["min_disparity"],
        numDisparities=params["num_disparities"],
        blockSize=bs,
        P1=8 * channels * bs * bs,
        P2=32 * channels * bs * bs,
        disp12MaxDiff=params["disp12_max_diff"],
        preFilterCap=params["pre_filter_cap"],
        uniquenessRatio=params["uniqueness_ratio"],
        speckleWindowSize=params["speckle_window_size"],
        speckleRange=params["speckle_range"],
        mode=mode,
    )


def params(min_d=0, num_d=64, bs=5, paths="five", speckle=100):
    return {
        "min_disparity": min_d,
        "num_disparities": num_d,
        "block_size": bs,
        "pre_filter_cap": 63,
        "uniqueness_ratio": 10,
        "disp12_max_diff": 1,
        "speckle_window_size": speckle,
        "speckle_range": 2,
        "paths": paths,
    }


def run_case(out, name, left, right, p, cases):
    channels = 1 if left.ndim == 2 else left.shape[2]
    matcher = sgbm(p, channels)
    # OpenCV reads BGR, we RGB: the cost is a sum over channels, so the order does not matter.
    disp = matcher.compute(left, right)
    times = []
    for _ in range(5):
        t = time.perf_counter()
        matcher.compute(left, right)
        times.append(time.perf_counter() - t)
    Image.fromarray(left).save(os.path.join(out, f"{name}_left.png"))
    Image.fromarray(right).save(os.path.join(out, f"{name}_right.png"))
    np.save(os.path.join(out, f"{name}_opencv.npy"), disp.astype(np.int16))
    invalid = (p["min_disparity"] - 1) * 16
    cases[name] = {
        "params": p,
        "channels": channels,
        "opencv_valid_fraction": float((disp != invalid).mean()),
        "opencv_seconds": float(np.median(times)),
        "opencv_threads": cv2.getNumThreads(),
    }
    print(f"{name}: {left.shape} valid {cases[name]['opencv_valid_fraction']:.3f} "
          f"{cases[name]['opencv_seconds'] * 1e3:.1f} ms")


def rectified(data_args, views):
    """The rectified pair `fewview stereo` writes for `views`, and its disparity range."""
    with tempfile.TemporaryDirectory() as tmp:
        cmd = ["target/release/fewview", "stereo", *data_args, "--views", views, "--out", tmp]
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
        load = lambda n: np.array(Image.open(os.path.join(tmp, n)).convert("RGB"))
        with open(os.path.join(tmp, "stereo.json")) as f:
            p = json.load(f)["params"]
        return load("rectified_left.png"), load("rectified_right.png"), p["min_disparity"], p["num_disparities"]


def time_fern_crop(out, p):
    """OpenCV's median time on the central 504x378 of the rectified fern pair with 64
    disparities from the pair's smallest, on 2 threads and on 1: the pair `fewview bench` times."""
    left = np.array(Image.open(os.path.join(out, "fern_1_10_left.png")))
    right = np.array(Image.open(os.path.join(out, "fern_1_10_right.png")))
    h, w = left.shape[:2]
    y0, x0 = (h - 378) // 2, (w - 504) // 2
    crop = lambda a: np.ascontiguousarray(a[y0:y0 + 378, x0:x0 + 504])
    timing = {}
    for threads in (2, 1):
        cv2.setNumThreads(threads)
        for paths in ("five", "eight"):
            q = dict(p, num_disparities=64, paths=paths)
            matcher = sgbm(q, 3)
            matcher.compute(crop(left), crop(right))
            times = []
            for _ in range(7):
                t = time.perf_counter()
                matcher.compute(crop(left), crop(right))
                times.append(time.perf_counter() - t)
            timing[f"{paths}_paths_{threads}_threads_seconds"] = float(np.median(times))
    cv2.setNumThreads(2)
    print("fern crop 504x378x64:", timing)
    return timing


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("--data", help="the shared data folder (adds the fern and demo cases)")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    cv2.setNumThreads(2)
    cases = {}
    left, right = synthetic_pair(1, 96, 160, 1, 6, 14)
    run_case(args.out, "planes_gray", left, right, params(num_d=32), cases)
    left, right = synthetic_pair(2, 96, 160, 3, 5, 13)
    run_case(args.out, "planes_rgb_eight", left, right, params(num_d=32, bs=3, paths="eight"), cases)
    left, right = synthetic_pair(3, 96, 160, 3, 9, 17)
    run_case(args.out, "planes_rgb_min4", left, right, params(min_d=4, num_d=16, speckle=20), cases)
    if args.data:
        fern = os.path.join(args.data, "llff", "fern")
        # Each pair with the disparity range `fewview stereo` chose from its depth bounds.
        left, right, min_d, num_d = rectified(["--data", fern], "1,10")
        run_case(args.out, "fern_1_10", left, right, params(min_d=min_d, num_d=num_d), cases)
        left, right, min_d, num_d = rectified(["--demo"], "2,11")
        run_case(args.out, "demo_2_11", left, right, params(min_d=min_d, num_d=num_d), cases)
    meta = {"opencv_version": cv2.__version__, "cases": cases}
    if "fern_1_10" in cases:
        meta["timing"] = time_fern_crop(args.out, cases["fern_1_10"]["params"])
    with open(os.path.join(args.out, "cases.json"), "w") as f:
        json.dump(meta, f, indent=2, sort_keys=True)


if __name__ == "__main__":
    sys.exit(main())
