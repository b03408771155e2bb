#!/usr/bin/env python3
"""Reference values for the dataset tests of `fewview-scene` (crates/scene/tests/datasets.rs),
computed from the shared data with NumPy, OpenCV and Pillow, independently of the Rust loaders.

Writes crates/scene/tests/fixtures/references.json with:
  fern:  NeRF `load_llff_data(factor=8, recenter=True, bd_factor=0.75)` output, re-implemented
         here in NumPy step by step from the NeRF paper code's description: the 3x4 camera-to-world
         poses in NeRF's OpenGL axes (right, up, back), the scaled bounds and hwf at factor 8.
  dtu:   for every view of scan65 and both cameras_sphere.npz and cameras_linear_init.npz, OpenCV's
         `cv2.decomposeProjectionMatrix((world_mat @ scale_mat)[:3, :4])` as IDR's
         `load_K_Rt_from_P` uses it: K / K[2,2], world-to-camera R and the camera centre; plus
         scale_mat.
  lego:  RGBA of a few pixels of train/r_26.png read by Pillow and their white-background
         composite rgb*a + (1 - a); the pixel where NumPy projects three world points through
         frame r_26's OpenGL camera (u = f*x/(-z) + W/2, v = -f*y/(-z) + H/2).

Rerun (from the repository root, with the data folder of the data README):
    python3 -m venv tools/.venv && tools/.venv/bin/pip install numpy==2.4.6 opencv-python-headless==5.0.0.93 pillow==13.0.0
    FEWVIEW_DATA=/work/shared/data tools/.venv/bin/python tools/make_dataset_references.py
"""

import json
import os

import cv2
import numpy as np
from PIL import Image

DATA = os.environ["FEWVIEW_DATA"]
OUT = os.path.join(os.path.dirname(__file__), "..", "crates", "scene", "tests", "fixtures", "references.json")


def normalize(v):
    return v / np.linalg.norm(v)


def fern():
    arr = np.load(os.path.join(DATA, "llff", "fern", "poses_bounds.npy"))
    poses = arr[:, :15].reshape(-1, 3, 5)
    bounds = arr[:, 15:].copy()
    hwf = poses[:, :, 4].copy()
    hwf[:, :2] = [378, 504]  # NeRF overwrites h, w with the images_8 size
    hwf[:, 2] /= 8.0
    # LLFF (down, right, back) -> NeRF (right, up, back).
    c2w = np.concatenate([poses[:, :, 1:2], -poses[:, :, 0:1], poses[:, :, 2:4]], axis=2)
    sc = 1.0 / (bounds.min() * 0.75)
    c2w[:, :, 3] *= sc
    bounds *= sc
    # Recenter: express every pose in the frame of the average pose.
    center = c2w[:, :, 3].mean(0)
    z = normalize(c2w[:, :, 2].sum(0))
    up = c2w[:, :, 1].sum(0)
    x = normalize(np.cross(up, z))
    y = normalize(np.cross(z, x))
    avg = np.eye(4)
    avg[:3, :] = np.stack([x, y, z, center], axis=1)
    full = np.tile(np.eye(4), (len(c2w), 1, 1))
    full[:, :3, :] = c2w
    rec = np.linalg.inv(avg) @ full
    return {
        "c2w_opengl": rec[:, :3, :].tolist(),
        "bounds": bounds.tolist(),
        "hwf": hwf.tolist(),
        "scale": sc,
        "average_pose": avg.tolist(),
    }


def dtu():
    out = {}
    for name in ["cameras_sphere.npz", "cameras_linear_init.npz"]:
        cams = np.load(os.path.join(DATA, "dtu", "scan65", name))
        views = []
        for i in range(49):
            world = cams[f"world_mat_{i}"].astype(np.float64)
            scale = cams[f"scale_mat_{i}"].astype(np.float64)
            p = (world @ scale)[:3, :4]
            k, r, t = cv2.decomposeProjectionMatrix(p)[:3]
            k = k / k[2, 2]
            views.append({"K": k.tolist(), "R": r.tolist(), "center": (t[:3, 0] / t[3, 0]).tolist()})
        out[name] = {"views": views, "scale_mat": cams["scale_mat_0"].astype(np.float64).tolist()}
    return out


def lego():
    meta = json.load(open(os.path.join(DATA, "nerf_synthetic", "lego", "transforms_train.json")))
    frame = meta["frames"][26]
    assert frame["file_path"].endswith("r_26")
    rgba = np.asarray(Image.open(os.path.join(DATA, "nerf_synthetic", "lego", "train", "r_26.png")).convert("RGBA"))
    rgba = rgba.astype(np.float64) / 255.0
    h, w = rgba.shape[:2]
    pixels = []
    alpha = rgba[:, :, 3]
    # A fully transparent, a fully opaque and a partially transparent pixel.
    picks = [(0, 0)]
    opaque = np.argwhere(alpha == 1.0)
    picks.append(tuple(int(v) for v in opaque[len(opaque) // 2]))
    partial = np.argwhere((alpha > 0.2) & (alpha < 0.8))
    picks.append(tuple(int(v) for v in partial[len(partial) // 2]))
    for y, x in picks:
        c = rgba[y, x]
        pixels.append({"x": x, "y": y, "rgba": c.tolist(), "white": (c[:3] * c[3] + (1 - c[3])).tolist()})
    focal = 0.5 * w / np.tan(0.5 * meta["camera_angle_x"])
    c2w = np.array(frame["transform_matrix"], dtype=np.float64)
    points = [[0.0, 0.0, 0.0], [0.5, -0.3, 0.2], [-0.4, 0.6, -0.1]]
    projections = []
    for p in points:
        xc = c2w[:3, :3].T @ (np.array(p) - c2w[:3, 3])
        projections.append([focal * xc[0] / -xc[2] + w / 2, -focal * xc[1] / -xc[2] + h / 2, -xc[2]])
    return {"focal": focal, "pixels": pixels, "points": points, "projections": projections}


def main():
    refs = {"fern": fern(), "dtu": dtu(), "lego": lego()}
    with open(OUT, "w") as f:
        json.dump(refs, f)
    print("wrote", os.path.normpath(OUT), os.path.getsize(OUT), "bytes")


if __name__ == "__main__":
    main()
