#!/usr/bin/env python3
"""Writes the lens-distortion fixtures under crates/scene/tests/fixtures/distortion/.

References come from OpenCV (the same equations as COLMAP's camera models):
* `points.json`: per camera model, pixels distorted with `cv2.projectPoints`
  (`cv2.fisheye.distortPoints` for OPENCV_FISHEYE) and undistorted with
  `cv2.undistortPoints` (`cv2.fisheye.undistortPoints`), both with 200 iterations and a
  1e-14 tolerance; `<model>_source.npy`, a 64x48 smooth float32 image, and
  `<model>_undistorted.npy`, it undistorted with `cv2.initUndistortRectifyMap` +
  `cv2.remap` (INTER_LINEAR) to the same camera matrix.
* `detail_source.npy`, a 64x48 float32 image with detail near the pixel scale (sinusoids of
  5-7 px wavelength and a 0/1 checkerboard whose edges make the cubic kernel overshoot), and
  `<model>_undistorted_cubic.npy`, it undistorted by the same maps with `cv2.remap`
  (INTER_CUBIC, BORDER_REPLICATE, as fewview repeats the edge pixel) and clipped to [0, 1] (as
  fewview clamps, and as OpenCV saturates 8- and 16-bit images). On this image bilinear and
  bicubic resampling differ by far more than the tests' tolerance.
* `colmap_binary/`: a COLMAP binary model (cameras.bin, images.bin, points3D.bin, written as
  COLMAP's `WriteCamerasBinary` etc. document the layout) with one camera of each supported
  model, and `colmap_binary.json` with what each holds.

OpenCV puts the top-left pixel's centre at (0, 0); COLMAP and fewview at (0.5, 0.5). Everything
in the JSON is in OpenCV's convention (`K` and pixel positions); the tests add 0.5.

Rerun:
    python3 -m venv /tmp/cvenv && /tmp/cvenv/bin/pip install opencv-python-headless numpy
    /tmp/cvenv/bin/python tools/make_distortion_fixtures.py
"""

import json
import os
import struct

import cv2
import numpy as np

OUT = os.path.join(os.path.dirname(__file__), "..", "crates", "scene", "tests", "fixtures", "distortion")
W, H = 64, 48
CRIT = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-14)

# (name, COLMAP model, COLMAP params (fewview/COLMAP pixel convention), OpenCV D, fisheye?)
CASES = [
    ("simple_radial", "SIMPLE_RADIAL", [50.0, 32.3, 23.8, -0.08], [-0.08, 0, 0, 0], False),
    ("radial", "RADIAL", [48.0, 31.7, 24.4, 0.06, -0.05], [0.06, -0.05, 0, 0], False),
    ("opencv", "OPENCV", [52.0, 49.0, 32.6, 23.9, 0.06, -0.08, 1e-3, -2e-3],
     [0.06, -0.08, 1e-3, -2e-3], False),
    ("full_opencv", "FULL_OPENCV",
     [51.0, 50.0, 31.9, 24.2, 0.1, -0.05, 1e-3, 5e-4, 0.01, 0.05, -0.01, 0.005],
     [0.1, -0.05, 1e-3, 5e-4, 0.01, 0.05, -0.01, 0.005], False),
    ("opencv_fisheye", "OPENCV_FISHEYE", [30.0, 31.0, 32.2, 23.7, 0.05, -0.01, 0.002, -0.0005],
     [0.05, -0.01, 0.002, -0.0005], True),
]


def intrinsics(model, p):
    if model in ("SIMPLE_PINHOLE", "SIMPLE_RADIAL", "RADIAL"):
        return p[0], p[0], p[1], p[2]
    return p[0], p[1], p[2], p[3]


def smooth_image():
    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    r = 0.5 + 0.4 * np.sin(x / 9.0) * np.cos(y / 11.0)
    g = 0.5 + 0.3 * np.cos((x + y) / 13.0)
    b = 0.2 + 0.6 * (x / W) * (y / H)
    return np.stack([r, g, b], axis=-1).astype(np.float32)


def detail_image():
    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    r = 0.5 + 0.35 * np.sin(2 * np.pi * x / 5.0 + 0.3) * np.cos(2 * np.pi * y / 6.5)
    g = 0.5 + 0.35 * np.cos(2 * np.pi * (x + y) / 5.5)
    b = 0.5 + 0.35 * np.sin(2 * np.pi * (x - 0.5 * y) / 7.0)
    checker = ((x // 4 + y // 4) % 2).astype(np.float64)
    corner = (x < W / 2) & (y < H / 2)
    r[corner] = checker[corner]
    return np.stack([r, g, b], axis=-1).astype(np.float32)


def case_fixture(name, model, params, dist, fisheye):
    fx, fy, cx, cy = intrinsics(model, params)
    K = np.array([[fx, 0, cx - 0.5], [0, fy, cy - 0.5], [0, 0, 1]], dtype=np.float64)
    D = np.array(dist, dtype=np.float64)
    rng = np.random.default_rng(7)
    # Distorted pixels over the whole image, borders included.
    px = np.concatenate([
        rng.uniform([-0.5, -0.5], [W - 0.5, H - 0.5], size=(40, 2)),
        np.array([[-0.5, -0.5], [W - 0.5, -0.5], [-0.5, H - 0.5], [W - 0.5, H - 0.5], [cx - 0.5, cy - 0.5]]),
    ])
    src = px.reshape(-1, 1, 2)
    if fisheye:
        und = cv2.fisheye.undistortPoints(src, K, D, criteria=CRIT)
    else:
        und = cv2.undistortPoints(src, K, D, criteria=CRIT)
    und = und.reshape(-1, 2)
    # Ideal normalised points, distorted forward.
    ideal = rng.uniform([-0.6, -0.45], [0.6, 0.45], size=(40, 2))
    if fisheye:
        dist_px = cv2.fisheye.distortPoints(ideal.reshape(-1, 1, 2), K, D).reshape(-1, 2)
    else:
        obj = np.concatenate([ideal, np.ones((len(ideal), 1))], axis=1)
        dist_px, _ = cv2.projectPoints(obj, np.zeros(3), np.zeros(3), K, D)
        dist_px = dist_px.reshape(-1, 2)
    img = smooth_image()
    if fisheye:
        m1, m2 = cv2.fisheye.initUndistortRectifyMap(K, D, np.eye(3), K, (W, H), cv2.CV_32FC1)
    else:
        m1, m2 = cv2.initUndistortRectifyMap(K, D, np.eye(3), K, (W, H), cv2.CV_32FC1)
    out = cv2.remap(img, m1, m2, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
    cubic = cv2.remap(detail_image(), m1, m2, cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE)
    cubic = np.clip(cubic, 0.0, 1.0)
    return {
        "name": name,
        "model": model,
        "params": params,
        "width": W,
        "height": H,
        "K": K.tolist(),
        "D": dist,
        "undistort": {"distorted_px": px.tolist(), "normalized": und.tolist()},
        "distort": {"normalized": ideal.tolist(), "distorted_px": dist_px.tolist()},
    }, img, out, cubic


MODEL_IDS = {"SIMPLE_PINHOLE": 0, "PINHOLE": 1, "SIMPLE_RADIAL": 2, "RADIAL": 3, "OPENCV": 4,
             "OPENCV_FISHEYE": 5, "FULL_OPENCV": 6}


def write_colmap_binary(folder, cameras):
    """cameras: list of (id, model, width, height, params)."""
    os.makedirs(folder, exist_ok=True)
    with open(os.path.join(folder, "cameras.bin"), "wb") as f:
        f.write(struct.pack("<Q", len(cameras)))
        for cid, model, w, h, params in cameras:
            f.write(struct.pack("<IiQQ", cid, MODEL_IDS[model], w, h))
            f.write(struct.pack("<%dd" % len(params), *params))
    with open(os.path.join(folder, "images.bin"), "wb") as f:
        f.write(struct.pack("<Q", len(cameras)))
        for i, (cid, model, w, h, params) in enumerate(cameras):
            angle = 0.1 * i
            q = [np.cos(angle / 2), 0.0, np.sin(angle / 2), 0.0]
            t = [0.1 * i, -0.05 * i, 3.0]
            f.write(struct.pack("<I4d3dI", i + 1, *q, *t, cid))
            f.write(("view_%d.png" % i).encode() + b"\0")
            f.write(struct.pack("<Q", 1))
            f.write(struct.pack("<ddq", 10.0, 12.0, 1))
    with open(os.path.join(folder, "points3D.bin"), "wb") as f:
        f.write(struct.pack("<Q", 1))
        f.write(struct.pack("<Q3d3Bd", 1, 0.1, -0.2, 0.3, 200, 100, 50, 0.5))
        f.write(struct.pack("<Q", len(cameras)))
        for i in range(len(cameras)):
            f.write(struct.pack("<II", i + 1, 0))


def main():
    os.makedirs(OUT, exist_ok=True)
    np.save(os.path.join(OUT, "detail_source.npy"), detail_image())
    cases = []
    for c in CASES:
        case, img, out, cubic = case_fixture(*c)
        np.save(os.path.join(OUT, case["name"] + "_source.npy"), img)
        np.save(os.path.join(OUT, case["name"] + "_undistorted.npy"), out)
        np.save(os.path.join(OUT, case["name"] + "_undistorted_cubic.npy"), cubic)
        cases.append(case)
    with open(os.path.join(OUT, "points.json"), "w") as f:
        json.dump({"opencv": cv2.__version__, "cases": cases}, f, indent=1)
    cameras = [(1, "SIMPLE_PINHOLE", W, H, [50.0, 32.0, 24.0]), (2, "PINHOLE", W, H, [50.0, 51.0, 32.5, 23.5])]
    for i, (name, model, params, dist, fisheye) in enumerate(CASES):
        cameras.append((i + 3, model, W, H, params))
    write_colmap_binary(os.path.join(OUT, "colmap_binary"), cameras)
    with open(os.path.join(OUT, "colmap_binary.json"), "w") as f:
        json.dump({"cameras": [{"id": c, "model": m, "width": w, "height": h, "params": p}
                               for c, m, w, h, p in cameras]}, f, indent=1)


if __name__ == "__main__":
    main()
