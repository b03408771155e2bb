#!/usr/bin/env python3
"""Fixtures in the ZJU-MoCap layout for the `fewview-human` ZJU loader and its tests.

    python3 tools/make_zju_fixture.py HUMAN_DIR OUT_DIR

HUMAN_DIR is the synthetic human dataset (`$FEWVIEW_DATA/human`). Writes three folders into
OUT_DIR (the committed copy is `crates/human/tests/fixtures/`):

* `zju_small/`: seq_a cameras 0, 3, 6, 9 on frames 0, 1, 2, as ZJU-MoCap stores a capture:
  `annots.npy` (a pickled dict, `np.save(..., allow_pickle=True)`) with
  `cams = {K, R, T (millimetres), D (zeros)}` and `ims = [{'ims': [path per camera]}]`;
  images `Camera_B{id+1}/{frame:06d}.jpg` (seq_a's JPEG files, byte for byte: cameras named by
  their seq_a id, so the names are B1, B4, B7, B10, not the list positions); masks
  `mask/Camera_B{id+1}/{frame:06d}.png` with values 0/1; world joints `joints3d/{frame}.npy`
  (17, 3) float32 with `joints3d/parents.json` (seq_a's skeleton); and SMPL-style `params/{frame}.npy` dicts (`poses`, `Rh`, `Th`, `shapes`)
  whose values are placeholders (zeros, `Th` = the pelvis): they only exercise the reader.
  The first frame's `ims` is a NumPy string array, the others Python lists (releases differ).
* `zju_distorted/`: one 64 x 48 camera with non-zero distortion D = (k1, k2, p1, p2, k3), its
  distorted image and mask (a crop of seq_a cam_00 frame 0), and under `reference/` OpenCV's
  undistortion to the same K: `map_x.npy`, `map_y.npy` (`cv2.initUndistortRectifyMap`, float32
  maps, source pixel per output pixel), `image.npy` (float32 H x W x 3 in [0, 1]: the image
  sampled bilinearly at OpenCV's map in float64, zero outside), `cv2_image.png`
  (`cv2.remap`, INTER_LINEAR, BORDER_CONSTANT 0) and `mask.png` (`cv2.remap`, INTER_NEAREST).
* `pickle/`: object arrays pickled with protocols 2, 4 and 5 (float64, float32, int64, bool,
  unicode and bytes arrays, nested lists, dicts, tuples, a NumPy float scalar and None), each
  `case_p{N}.npy`, and the expected values of the arrays and scalars as JSON (`expected.json`).

Pixel coordinates here are OpenCV's (pixel centres at integer coordinates), as in ZJU-MoCap.
"""
import json
import pickle
import shutil
import sys
from pathlib import Path

import cv2
import numpy as np
from PIL import Image

CAMERAS = [0, 3, 6, 9]
FRAMES = [0, 1, 2]


def save_pickled(path: Path, obj, protocol: int | None = None) -> None:
    """`np.save(path, obj, allow_pickle=True)`, or the same with another pickle protocol."""
    arr = np.empty((), dtype=object)
    arr[()] = obj
    if protocol is None:
        np.save(path, arr, allow_pickle=True)
        return
    with open(path, "wb") as f:
        np.lib.format.write_array_header_1_0(f, np.lib.format.header_data_from_array_1_0(arr))
        pickle.dump(arr, f, protocol=protocol)


def small(human: Path, out: Path) -> None:
    cams = json.loads((human / "cameras.json").read_text())["cameras"]
    joints = np.load(human / "seq_a" / "joints3d.npy")
    annots = {"cams": {"K": [], "R": [], "T": [], "D": []}, "ims": []}
    for c in CAMERAS:
        cam = cams[c]
        annots["cams"]["K"].append(np.array(cam["K"], dtype=np.float64))
        annots["cams"]["R"].append(np.array(cam["R"], dtype=np.float64))
        annots["cams"]["T"].append(np.array(cam["t"], dtype=np.float64).reshape(3, 1) * 1000.0)
        annots["cams"]["D"].append(np.zeros((5, 1)))
    for f in FRAMES:
        paths = [f"Camera_B{c + 1}/{f:06d}.jpg" for c in CAMERAS]
        annots["ims"].append({"ims": np.array(paths) if f == FRAMES[0] else paths})
        for c, rel in zip(CAMERAS, paths):
            src = human / "seq_a"
            (out / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(src / "images" / f"cam_{c:02d}" / f"frame_{f:04d}.jpg", out / rel)
            mask = np.array(Image.open(src / "masks" / f"cam_{c:02d}" / f"frame_{f:04d}.png"))
            mask_path = out / "mask" / rel.replace(".jpg", ".png")
            mask_path.parent.mkdir(parents=True, exist_ok=True)
            Image.fromarray((mask > 127).astype(np.uint8)).save(mask_path)
        (out / "joints3d").mkdir(exist_ok=True)
        np.save(out / "joints3d" / f"{f}.npy", joints[f].astype(np.float32))
        (out / "params").mkdir(exist_ok=True)
        params = {
            "poses": np.zeros((1, 72), np.float32),
            "Rh": np.zeros((1, 3), np.float32),
            "Th": joints[f, 0:1].astype(np.float32),
            "shapes": np.zeros((1, 10), np.float32),
        }
        save_pickled(out / "params" / f"{f}.npy", params)
    parents = json.loads((human / "joints.json").read_text())["parents"]
    (out / "joints3d" / "parents.json").write_text(json.dumps(parents) + "\n")
    save_pickled(out / "annots.npy", annots)


def bilinear(img: np.ndarray, mx: np.ndarray, my: np.ndarray) -> np.ndarray:
    """Bilinear sampling at (mx, my) with pixel centres at integers, zero outside the image."""
    h, w = img.shape[:2]
    x0, y0 = np.floor(mx).astype(int), np.floor(my).astype(int)
    fx, fy = (mx - x0)[..., None], (my - y0)[..., None]
    out = np.zeros(mx.shape + img.shape[2:], np.float64)
    for dy, wy in [(0, 1 - fy), (1, fy)]:
        for dx, wx in [(0, 1 - fx), (1, fx)]:
            xs, ys = x0 + dx, y0 + dy
            ok = (xs >= 0) & (xs < w) & (ys >= 0) & (ys < h)
            vals = np.zeros_like(out)
            vals[ok] = img[ys[ok], xs[ok]]
            out += wx * wy * vals
    return out


def distorted(human: Path, out: Path) -> None:
    src = human / "seq_a"
    full = Image.open(src / "images" / "cam_00" / "frame_0000.jpg").convert("RGB")
    mask_full = Image.open(src / "masks" / "cam_00" / "frame_0000.png")
    box = (160, 120, 352, 264)  # 192 x 144 around the torso, scaled by 1/3 to 64 x 48
    img = np.array(full.crop(box).resize((64, 48), Image.LANCZOS))
    mask = (np.array(mask_full.crop(box).resize((64, 48), Image.NEAREST)) > 127).astype(np.uint8)
    (out / "Camera_B1").mkdir(parents=True, exist_ok=True)
    (out / "mask" / "Camera_B1").mkdir(parents=True, exist_ok=True)
    Image.fromarray(img).save(out / "Camera_B1" / "000000.png")
    Image.fromarray(mask).save(out / "mask" / "Camera_B1" / "000000.png")
    k = np.array([[58.0, 0.0, 31.7], [0.0, 57.0, 23.2], [0.0, 0.0, 1.0]])
    d = np.array([-0.28, 0.09, 0.0015, -0.0012, -0.012]).reshape(5, 1)
    annots = {
        "cams": {"K": [k], "R": [np.eye(3)], "T": [np.array([[0.0], [0.0], [2500.0]])], "D": [d]},
        "ims": [{"ims": ["Camera_B1/000000.png"]}],
    }
    save_pickled(out / "annots.npy", annots)
    mx, my = cv2.initUndistortRectifyMap(k, d, None, k, (64, 48), cv2.CV_32FC1)
    ref = out / "reference"
    ref.mkdir(exist_ok=True)
    np.save(ref / "map_x.npy", mx)
    np.save(ref / "map_y.npy", my)
    exact = bilinear(img.astype(np.float64) / 255.0, mx.astype(np.float64), my.astype(np.float64))
    np.save(ref / "image.npy", exact.astype(np.float32))
    cv_img = cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    Image.fromarray(cv_img).save(ref / "cv2_image.png")
    cv_mask = cv2.remap(mask * 255, mx, my, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT)
    Image.fromarray(cv_mask).save(ref / "mask.png")


def pickles(out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    value = {
        "f8": np.arange(6, dtype=np.float64).reshape(2, 3) / 4.0,
        "f4": np.array([[1.5, -2.25]], dtype=np.float32),
        "fortran": np.asfortranarray(np.arange(6, dtype=np.float64).reshape(2, 3)),
        "big_endian": np.array([1.0, 2.0], dtype=">f8"),
        "i8": np.array([3, -7], dtype=np.int64),
        "u1": np.array([0, 255], dtype=np.uint8),
        "bool": np.array([True, False]),
        "unicode": np.array(["Camera_B1/000000.jpg", "é"]),
        "bytes": np.array([b"ab", b"c"]),
        "nested": [np.eye(2), (1, 2.5, "x"), {"deep": [None, True]}],
        "scalar": np.float64(0.125),
        "big_int": 2**40,
        "none": None,
    }
    expected = {
        "f8": {"shape": [2, 3], "data": (np.arange(6) / 4.0).tolist()},
        "f4": {"shape": [1, 2], "data": [1.5, -2.25]},
        "fortran": {"shape": [2, 3], "data": [0.0, 1.0, 2.0, 3.0, 4.0, 5.0]},
        "big_endian": {"shape": [2], "data": [1.0, 2.0]},
        "i8": {"shape": [2], "data": [3.0, -7.0]},
        "u1": {"shape": [2], "data": [0.0, 255.0]},
        "bool": {"shape": [2], "data": [1.0, 0.0]},
        "unicode": ["Camera_B1/000000.jpg", "é"],
        "bytes": ["ab", "c"],
        "scalar": 0.125,
        "big_int": 2**40,
    }
    for protocol in [2, 4, 5]:
        save_pickled(out / f"case_p{protocol}.npy", value, protocol)
    (out / "expected.json").write_text(json.dumps(expected, indent=1) + "\n")


def main() -> None:
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    human, out = Path(sys.argv[1]), Path(sys.argv[2])
    small(human, out / "zju_small")
    distorted(human, out / "zju_distorted")
    pickles(out / "pickle")


if __name__ == "__main__":
    main()
