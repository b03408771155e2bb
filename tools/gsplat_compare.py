#!/usr/bin/env python3
r"""gsplat as the yardstick for fewview's rasterizer (issue 32).

Times gsplat's `rasterization()` -- forward, forward+backward and one training step -- on a
Gaussian PLY in the Inria 3DGS layout (what `fewview_splat::write_ply` writes) seen from one
camera, so that the same file and camera can be given to fewview and the two timings compared
on the same GPU. Writes one JSON report.

Modes (one per call):
  --make-scene DIR   write DIR/scene.ply (random Gaussians, seeded, SH degree 3) and
                     DIR/cameras.json (one 1 Mpixel camera), inputs both tools can read
  --build-only       compile (or load) gsplat's CUDA extension and report how long it took
  --check-cpu        verify loading and conversion on a tiny scene without CUDA, with gsplat's
                     pure-PyTorch stages, against `fewview render` when the binary exists
  (default)          time gsplat on --ply and a camera, write --json

Inputs and conversions
  PLY: x y z, f_dc_0..2, f_rest_* (channel-major: f_rest_{c*(K-1)+k-1} is coefficient k of
  channel c), opacity (logit), scale_0..2 (log), rot_0..3 (w, x, y, z; need not be unit).
  gsplat gets means, quats = normalize(rot), scales = exp(scale), opacities = sigmoid(opacity),
  colors = SH as [N, K, 3], sh_degree = the file's degree; the activations are inside the
  autograd graph, so gradients reach the pre-activation parameters as in training.
  Camera: a camera file as fewview reads it (crates/geom/src/io/cameras.rs; a run's
  cameras.json): a camera or a list of them, each
    {"intrinsics": {"fx", "fy", "cx", "cy", "width", "height"},
     "world_to_camera": row-major 4x4}
  or the serde form ("world_to_camera": {"rotation": 9 numbers column-major,
  "translation": 3}); or explicit --fx --fy --cx --cy --width --height --world-to-camera.
  OpenCV axes, world-to-camera, pixel centres at half-integers: the same convention as gsplat
  (pixel (i, j) is sampled at (j + 0.5, i + 0.5)), so the numbers pass through unchanged.

What is timed (CUDA events; --warmup runs, then the median of --reps >= 20 runs)
  forward           rasterization() with autograd recording (as in training), activations included
  forward_no_grad   the same under torch.no_grad() (inference)
  backward          loss.backward() after that forward, loss = sum(render * W) + sum(alpha * W_a)
                    with fixed random weights W (seeded), so every output channel has a gradient
  forward_backward  both, measured in the same runs as `backward`
  train_step        zero_grad, forward, L1 loss (mean |RGB - target|, no SSIM term) against a fixed
                    random target, backward, Adam step: one torch.optim.Adam per parameter
                    (means, quats, scales, opacities, sh0, shN) with the Inria learning rates and
                    eps 1e-15, as gsplat's simple_trainer builds them; no densification
  Peak device memory is torch.cuda.max_memory_allocated() over one run of each, after
  resetting the peak; the report gives it absolute and above what was allocated before.

gsplat versus fewview's rasterizer (what differs besides speed)
  gsplat clamps alpha at 0.999, fewview (as Inria's code) at 0.99; both skip alpha < 1/255,
  stop once the transmittance would fall to 1e-4, add 0.3 px^2 to the 2D covariance, cull
  centres nearer than the near plane (0.2 here), and bin each Gaussian by an opacity-aware
  extent (so neither drops a pixel with alpha >= 1/255); the EWA Jacobian's clamp of off-screen
  centres is the same (1.3 x the half field of view) when the principal point is centred, as in
  --make-scene's camera. render_mode "RGB+D" is fewview's depth channel (sum w_i z_i); "RGB+ED" divides it by
  alpha. Both cost the same.

Running it on the GPU machine (repository root as working directory; .whl/ holds the gsplat
1.5.3 wheel, pure Python: it compiles its CUDA on first use with torch.utils.cpp_extension, the
machine's nvcc and ninja, and needs numpy, jaxtyping, rich and packaging, which the machine has):

  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
          --target /tmp/site .whl/*.whl
  export PYTHONPATH=/tmp/site TORCH_CUDA_ARCH_LIST="9.0" MAX_JOBS=16 TORCH_EXTENSIONS_DIR=/tmp/torch_ext
  python3 tools/gsplat_compare.py --build-only --json $OUT/gsplat_build.json
  python3 tools/gsplat_compare.py --make-scene /tmp/scene
  python3 tools/gsplat_compare.py --ply /tmp/scene/scene.ply --cameras /tmp/scene/cameras.json \
          --json $OUT/gsplat_compare.json

--build-only compiles the extension once and reports how long that took, apart from the
timings; TORCH_CUDA_ARCH_LIST="9.0" builds for Hopper (H100/H200) only and MAX_JOBS sets
ninja's parallel compiles. The timing run then loads the cached build from
TORCH_EXTENSIONS_DIR (its report says how long the load took and whether it had to build).
`--build-only --export-extension $OUT/ext` also copies the built gsplat_cuda.so out, and a
later run on the same torch and Python can skip the compile with `--extension ext/gsplat_cuda.so`.

fewview's side: `fewview bench` times its rasterizer on its own synthetic scene
(bench::SyntheticScene, --gaussians N) at a fixed 504x378, and cannot read a PLY and a camera
yet. To run both on the same inputs it needs, for the `raster` section, `--raster-ply FILE`
(Gaussians for the forward/backward figures instead of the synthetic scene; --gaussians then
does not apply) and `--raster-cameras FILE` (a camera file as `render --cameras` reads; the
first camera, its intrinsics and image size replacing 504x378), plus issue 32's `--device gpu`.
`fewview render --ply FILE --cameras FILE --out DIR` renders the same inputs now (DIR/camera_000.png,
which --compare-png takes).

On a machine without CUDA:
  python3 tools/gsplat_compare.py --check-cpu [--fewview target/release/fewview]
needs torch (CPU is enough), numpy and gsplat (pip install gsplat==1.5.3 --no-deps).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import shutil
import struct
import subprocess
import sys
import tempfile
import time
import zlib
from pathlib import Path

import numpy as np

SH_C0 = 0.28209479177387814
DEFAULT_WIDTH, DEFAULT_HEIGHT = 1155, 866  # 1,000,230 pixels, 4:3 like a camera frame
DEFAULT_GAUSSIANS = 1_000_000
# Inria 3DGS learning rates (means: 1.6e-4 x scene extent; the extent is taken as 1 here).
LEARNING_RATES = {
    "means": 1.6e-4,
    "quats": 1e-3,
    "scales": 5e-3,
    "opacities": 5e-2,
    "sh0": 2.5e-3,
    "shN": 2.5e-3 / 20,
}


class InputError(Exception):
    """Bad input: reported as one line naming the file and the problem."""


# --------------------------------------------------------------------------------------------
# PLY (Inria layout)
# --------------------------------------------------------------------------------------------

PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}


def read_ply_columns(path: Path) -> dict:
    """The `vertex` element of a PLY (binary either endianness, or ASCII) as {property: array}."""
    try:
        f = open(path, "rb")
    except OSError as e:
        raise InputError(f"{path}: cannot open: {e.strerror}") from e
    with f:
        if f.readline().rstrip(b"\r\n") != b"ply":
            raise InputError(f"{path}: not a PLY file (missing `ply` magic)")
        fmt, n, props, in_vertex, seen_vertex = None, None, [], False, False
        while True:
            line = f.readline()
            if not line:
                raise InputError(f"{path}: PLY header ends before `end_header`")
            words = line.decode("ascii", "replace").split()
            if words == ["end_header"]:
                break
            if not words or words[0] in ("comment", "obj_info"):
                continue
            if words[0] == "format":
                fmt = words[1]
            elif words[0] == "element":
                in_vertex = words[1] == "vertex"
                if in_vertex:
                    n, seen_vertex = int(words[2]), True
                elif not seen_vertex:
                    raise InputError(f"{path}: elements before `vertex` are not supported")
            elif words[0] == "property" and in_vertex:
                if words[1] == "list":
                    raise InputError(f"{path}: list properties in `vertex` are not supported")
                if words[1] not in PLY_TYPES:
                    raise InputError(f"{path}: unknown property type `{words[1]}`")
                props.append((words[2], PLY_TYPES[words[1]]))
        if n is None:
            raise InputError(f"{path}: no `vertex` element")
        if n == 0:
            raise InputError(f"{path}: the model has no Gaussians (element vertex 0)")
        if fmt == "ascii":
            data = np.loadtxt(f, dtype=np.float64, max_rows=n, ndmin=2)
            if data.shape != (n, len(props)):
                raise InputError(f"{path}: expected {n} rows of {len(props)} values")
            cols = {name: data[:, i] for i, (name, _) in enumerate(props)}
        elif fmt in ("binary_little_endian", "binary_big_endian"):
            end = "<" if fmt == "binary_little_endian" else ">"
            dtype = np.dtype([(name, end + t) for name, t in props])
            raw = f.read(n * dtype.itemsize)
            if len(raw) < n * dtype.itemsize:
                raise InputError(f"{path}: file ends after {len(raw) // dtype.itemsize} of {n} vertices")
            data = np.frombuffer(raw, dtype=dtype, count=n)
            cols = {name: data[name] for name, _ in props}
        else:
            raise InputError(f"{path}: missing or unknown `format` line ({fmt})")
    return cols


def read_ply(path: Path) -> dict:
    """Reads a Gaussian PLY into pre-activation float32 arrays:
    means [N,3], quats [N,4] (w,x,y,z), log_scales [N,3], opacity_logits [N], sh [N,K,3]."""
    cols = read_ply_columns(path)
    n = len(cols["x"]) if "x" in cols else len(next(iter(cols.values())))

    def need(name):
        if name not in cols:
            raise InputError(f"{path}: missing property `{name}`")
        return np.asarray(cols[name], dtype=np.float32)

    n_rest = 0
    while f"f_rest_{n_rest}" in cols:
        n_rest += 1
    k = n_rest // 3 + 1
    if n_rest % 3 or k not in (1, 4, 9, 16):
        raise InputError(f"{path}: {n_rest} f_rest properties is not 3·(K−1) for K in 1, 4, 9, 16")
    means = np.stack([need(c) for c in ("x", "y", "z")], 1)
    sh = np.empty((n, k, 3), np.float32)
    for c in range(3):
        sh[:, 0, c] = need(f"f_dc_{c}")
        for kk in range(1, k):
            sh[:, kk, c] = need(f"f_rest_{c * (k - 1) + kk - 1}")
    model = {
        "means": means,
        "quats": np.stack([need(f"rot_{i}") for i in range(4)], 1),
        "log_scales": np.stack([need(f"scale_{i}") for i in range(3)], 1),
        "opacity_logits": need("opacity"),
        "sh": sh,
    }
    for name, v in model.items():
        if not np.isfinite(v).all():
            raise InputError(f"{path}: `{name}` holds non-finite values")
    if (np.linalg.norm(model["quats"], axis=1) == 0).any():
        raise InputError(f"{path}: a rotation quaternion is zero")
    return model


def write_ply(path: Path, model: dict) -> None:
    """Writes the Inria layout exactly as fewview_splat::write_ply (binary little-endian float,
    normals zero), atomically."""
    n, k = model["sh"].shape[:2]
    names = ["x", "y", "z", "nx", "ny", "nz"] + [f"f_dc_{c}" for c in range(3)]
    names += [f"f_rest_{i}" for i in range(3 * (k - 1))]
    names += ["opacity"] + [f"scale_{i}" for i in range(3)] + [f"rot_{i}" for i in range(4)]
    header = f"ply\nformat binary_little_endian 1.0\nelement vertex {n}\n"
    header += "".join(f"property float {name}\n" for name in names) + "end_header\n"
    rest = model["sh"][:, 1:, :].transpose(0, 2, 1).reshape(n, 3 * (k - 1))  # channel-major
    body = np.concatenate(
        [
            model["means"],
            np.zeros((n, 3), np.float32),
            model["sh"][:, 0, :],
            rest,
            model["opacity_logits"][:, None],
            model["log_scales"],
            model["quats"],
        ],
        axis=1,
    ).astype("<f4")
    assert body.shape[1] == len(names)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as f:
        f.write(header.encode("ascii"))
        f.write(body.tobytes())
    os.replace(tmp, path)


# --------------------------------------------------------------------------------------------
# Cameras
# --------------------------------------------------------------------------------------------


def camera_from_json(value, where: str) -> dict:
    """One camera of fewview's camera file, either form, as {fx, fy, cx, cy, width, height,
    world_to_camera (4x4 float64, row-major)}."""
    if not isinstance(value, dict) or "intrinsics" not in value:
        raise InputError(f"{where}: camera has no 'intrinsics'")
    k = value["intrinsics"]
    try:
        cam = {key: float(k[key]) for key in ("fx", "fy", "cx", "cy")}
        cam["width"], cam["height"] = int(k["width"]), int(k["height"])
    except (KeyError, TypeError, ValueError) as e:
        raise InputError(f"{where}: bad intrinsics: {e}") from e
    pose = value.get("world_to_camera")
    m = np.eye(4)
    if isinstance(pose, dict):  # serde form: nalgebra column-major rotation
        m[:3, :3] = np.asarray(pose["rotation"], np.float64).reshape(3, 3).T
        m[:3, 3] = np.asarray(pose["translation"], np.float64)
    else:
        rows = np.asarray(pose, np.float64)
        if rows.shape not in ((4, 4), (3, 4)):
            raise InputError(f"{where}: 'world_to_camera' must be a row-major 4×4 (or 3×4) matrix")
        m[: rows.shape[0]] = rows
    cam["world_to_camera"] = m
    check_camera(cam, where)
    return cam


def check_camera(cam: dict, where: str) -> None:
    m = cam["world_to_camera"]
    if not all(math.isfinite(cam[k]) and cam[k] > 0 for k in ("fx", "fy")) or not np.isfinite(m).all():
        raise InputError(f"{where}: non-finite or non-positive camera values")
    if cam["width"] <= 0 or cam["height"] <= 0:
        raise InputError(f"{where}: image size {cam['width']}×{cam['height']} is empty")
    r = m[:3, :3]
    if np.linalg.norm(r.T @ r - np.eye(3)) > 1e-3 or np.linalg.det(r) <= 0:
        raise InputError(f"{where}: world_to_camera's rotation is not a proper rotation")
    if np.abs(m[3] - [0, 0, 0, 1]).max() > 1e-3:
        raise InputError(f"{where}: world_to_camera's last row is not [0, 0, 0, 1]")


def read_camera(path: Path, index: int) -> dict:
    try:
        value = json.loads(Path(path).read_text())
    except OSError as e:
        raise InputError(f"{path}: cannot read: {e.strerror}") from e
    except json.JSONDecodeError as e:
        raise InputError(f"{path}: not JSON: {e}") from e
    items = value if isinstance(value, list) else [value]
    if not 0 <= index < len(items):
        raise InputError(f"{path}: camera index {index} out of range ({len(items)} cameras)")
    return camera_from_json(items[index], f"{path}: camera {index}")


def camera_to_json(cam: dict) -> dict:
    """The friendly form fewview's camera reader takes (and `write_cameras` writes)."""
    intr = {k: cam[k] for k in ("fx", "fy", "cx", "cy")}
    intr.update(width=cam["width"], height=cam["height"])
    return {"intrinsics": intr, "world_to_camera": [[float(x) for x in row] for row in cam["world_to_camera"]]}


def look_at(eye, target, up) -> np.ndarray:
    """World-to-camera 4x4 (OpenCV axes) of a camera at `eye` looking at `target`, image up
    towards `up` (fewview_scene::Camera::look_at)."""
    eye, target, up = (np.asarray(v, np.float64) for v in (eye, target, up))
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    r_c2w = np.stack([x, y, z], 1)
    m = np.eye(4)
    m[:3, :3] = r_c2w.T
    m[:3, 3] = -r_c2w.T @ eye
    return m


# --------------------------------------------------------------------------------------------
# The synthetic scene
# --------------------------------------------------------------------------------------------


def make_scene(n: int, width: int, height: int, seed: int, sh_degree: int = 3):
    """Random Gaussians shaped like a trained forward-facing capture, the distribution of
    fewview's `bench::SyntheticScene`: centres uniform through the view frustum (1.1x the image)
    between depths 2 and 10, screen-space sigma log-uniform in [0.5, 6] px with +-25 % per-axis
    anisotropy, random rotations (quaternions not normalised), opacities sigmoid(N(0, 2^2)),
    SH DC colours uniform in [0, 1] and higher bands uniform in +-0.05. The camera (focal
    0.8 x width, centred principal point) sits at (0.5, -0.3, -4) looking at (0, 0, 2), so the
    world-to-camera pose is not the identity; the Gaussians are placed in its frustum."""
    rng = np.random.default_rng(seed)
    focal = 0.8 * width
    w2c = look_at([0.5, -0.3, -4.0], [0.0, 0.0, 2.0], [0.0, -1.0, 0.0])
    cam = dict(fx=focal, fy=focal, cx=width / 2, cy=height / 2, width=width, height=height,
               world_to_camera=w2c)
    z = 2.0 + 8.0 * rng.random(n)
    u = (rng.random(n) - 0.5) * width * 1.1
    v = (rng.random(n) - 0.5) * height * 1.1
    p_cam = np.stack([u * z / focal, v * z / focal, z], 1)
    r, t = w2c[:3, :3], w2c[:3, 3]
    means = (p_cam - t) @ r  # R^T (p - t), row-wise
    sigma_px = np.exp(math.log(0.5) + math.log(12.0) * rng.random(n))
    base = np.log(sigma_px * z / focal)
    log_scales = base[:, None] + 0.5 * (rng.random((n, 3)) - 0.5)
    quats = rng.random((n, 4)) - 0.5
    opacity_logits = 2.0 * rng.standard_normal(n)
    k = (sh_degree + 1) ** 2
    sh = np.empty((n, k, 3))
    sh[:, 0, :] = (rng.random((n, 3)) - 0.5) / SH_C0
    sh[:, 1:, :] = 0.1 * (rng.random((n, k - 1, 3)) - 0.5)
    f32 = lambda a: np.ascontiguousarray(a, dtype=np.float32)  # noqa: E731
    model = dict(means=f32(means), quats=f32(quats), log_scales=f32(log_scales),
                 opacity_logits=f32(opacity_logits), sh=f32(sh))
    return model, cam


# --------------------------------------------------------------------------------------------
# Tensors and the gsplat call
# --------------------------------------------------------------------------------------------


def to_params(model: dict, device, split_sh: bool = False) -> dict:
    """Leaf tensors (pre-activation) that require grad."""
    import torch

    p = {
        "means": model["means"],
        "quats": model["quats"],
        "scales": model["log_scales"],
        "opacities": model["opacity_logits"],
    }
    if split_sh:
        p["sh0"] = model["sh"][:, :1, :]
        p["shN"] = model["sh"][:, 1:, :]
    else:
        p["sh"] = model["sh"]
    return {k: torch.tensor(np.ascontiguousarray(v), device=device).requires_grad_(True) for k, v in p.items()}


def camera_tensors(cam: dict, device):
    import torch

    viewmats = torch.tensor(cam["world_to_camera"], dtype=torch.float32, device=device)[None]
    ks = torch.tensor(
        [[cam["fx"], 0.0, cam["cx"]], [0.0, cam["fy"], cam["cy"]], [0.0, 0.0, 1.0]],
        dtype=torch.float32,
        device=device,
    )[None]
    return viewmats, ks


def rasterization_kwargs(params: dict, cam: dict, sh_degree: int, render_mode: str,
                         background, near_plane: float) -> dict:
    """The arguments of gsplat.rasterization() for one camera; the activations are part of the
    autograd graph."""
    import torch
    import torch.nn.functional as F

    viewmats, ks = camera_tensors(cam, params["means"].device)
    colors = params["sh"] if "sh" in params else torch.cat([params["sh0"], params["shN"]], 1)
    return dict(
        means=params["means"],
        quats=F.normalize(params["quats"], dim=-1),
        scales=torch.exp(params["scales"]),
        opacities=torch.sigmoid(params["opacities"]),
        colors=colors,
        viewmats=viewmats,
        Ks=ks,
        width=cam["width"],
        height=cam["height"],
        sh_degree=sh_degree,
        near_plane=near_plane,
        packed=False,
        render_mode=render_mode,
        backgrounds=torch.tensor([background], dtype=torch.float32, device=params["means"].device),
    )


def reference_rasterization(means, quats, scales, opacities, colors, viewmats, Ks, width, height,
                            sh_degree, near_plane, packed, render_mode, backgrounds,
                            eps2d=0.3, alpha_max=0.999):
    """gsplat's rasterization() (pinhole, classic, one camera, SH colours) on any device: the
    projection and SH stages are gsplat's own PyTorch reference twins (gsplat.cuda._torch_impl);
    the blend is a dense per-pixel restatement of its CUDA kernel (RasterizeToPixels3DGSFwd.cu:
    pixel centres j + 0.5, alpha = min(alpha_max, o·exp(−σ)), skip σ < 0 or alpha < 1/255, stop
    (exclusive) once T·(1 − alpha) ≤ 1e-4, front to back by depth). Differentiable by autograd.
    gsplat's own pure-PyTorch blend needs its CUDA rasterize_to_indices_in_range and nerfacc."""
    import torch
    from gsplat.cuda._torch_impl import (
        _fully_fused_projection,
        _quat_scale_to_covar_preci,
        _spherical_harmonics,
    )

    assert viewmats.shape[0] == 1, "one camera"
    assert not packed
    covars, _ = _quat_scale_to_covar_preci(quats, scales, True, False, triu=False)
    radii, means2d, depths, conics, _ = _fully_fused_projection(
        means, covars, viewmats, Ks, width, height, eps2d=eps2d, near_plane=near_plane
    )
    valid = (radii > 0).all(-1)[0] & (opacities >= 1.0 / 255.0)  # the CUDA kernel's culls
    campos = torch.inverse(viewmats)[0, :3, 3]
    rgb = _spherical_harmonics(sh_degree, means - campos, colors)
    rgb = torch.clamp_min(rgb + 0.5, 0.0)
    idx = torch.nonzero(valid).flatten()
    idx = idx[torch.argsort(depths[0, idx], stable=True)]
    m2, con, op, d = means2d[0, idx], conics[0, idx], opacities[idx], depths[0, idx]
    feats = rgb[idx]
    if render_mode in ("RGB+D", "RGB+ED"):
        feats = torch.cat([feats, d[:, None]], 1)
    ys, xs = torch.meshgrid(
        torch.arange(height, dtype=means.dtype) + 0.5,
        torch.arange(width, dtype=means.dtype) + 0.5,
        indexing="ij",
    )
    pix = torch.stack([xs.flatten(), ys.flatten()], 1).to(means.device)  # [P, 2]
    dx = pix[:, None, 0] - m2[None, :, 0]
    dy = pix[:, None, 1] - m2[None, :, 1]
    sigma = 0.5 * (con[None, :, 0] * dx * dx + con[None, :, 2] * dy * dy) + con[None, :, 1] * dx * dy
    alpha = torch.clamp_max(op[None, :] * torch.exp(-sigma), alpha_max)
    alpha = torch.where((sigma >= 0) & (alpha >= 1.0 / 255.0), alpha, torch.zeros_like(alpha))
    after = torch.cumprod(1.0 - alpha, dim=1)  # T after each Gaussian, had all been blended
    before = torch.cat([torch.ones_like(after[:, :1]), after[:, :-1]], 1)
    keep = (after > 1e-4).to(alpha.dtype)  # T only falls, so the first stop ends the pixel
    weights = alpha * before * keep
    out = weights @ feats  # [P, D]
    acc = weights.sum(1, keepdim=True)
    bg = backgrounds[0]
    if render_mode in ("RGB+D", "RGB+ED"):
        bg = torch.cat([bg, bg.new_zeros(1)])
    out = out + (1.0 - acc) * bg
    if render_mode == "RGB+ED":
        out = torch.cat([out[:, :-1], out[:, -1:] / acc.clamp(min=1e-10)], 1)
    return (
        out.reshape(1, height, width, -1),
        acc.reshape(1, height, width, 1),
        {"radii": radii, "depths": depths, "n_visible": int(valid.sum())},
    )


# --------------------------------------------------------------------------------------------
# PNG (8-bit, non-interlaced), enough to read fewview's renders and write ours
# --------------------------------------------------------------------------------------------


def to_u8(img: np.ndarray) -> np.ndarray:
    """fewview's Image::to_u8: clamp to [0, 1], ×255, round."""
    return np.round(np.clip(img, 0.0, 1.0) * 255.0).astype(np.uint8)


def write_png(path: Path, rgb_u8: np.ndarray) -> None:
    h, w, c = rgb_u8.shape
    raw = b"".join(b"\x00" + rgb_u8[y].tobytes() for y in range(h))

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    color = {1: 0, 3: 2, 4: 6}[c]
    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, color, 0, 0, 0))
    png += chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b"")
    Path(path).write_bytes(png)


def read_png(path: Path) -> np.ndarray:
    data = Path(path).read_bytes()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise InputError(f"{path}: not a PNG file")
    pos, idat, ihdr = 8, b"", None
    while pos < len(data):
        (length,) = struct.unpack(">I", data[pos : pos + 4])
        kind = data[pos + 4 : pos + 8]
        body = data[pos + 8 : pos + 8 + length]
        if kind == b"IHDR":
            ihdr = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat += body
        pos += 12 + length
    w, h, depth, color, _, _, interlace = ihdr
    channels = {0: 1, 2: 3, 4: 2, 6: 4}.get(color)
    if depth != 8 or interlace or channels is None:
        raise InputError(f"{path}: only 8-bit non-interlaced grey/RGB/RGBA PNGs are read here")
    raw = zlib.decompress(idat)
    stride, bpp = w * channels, channels
    out = np.zeros((h, stride), np.uint8)
    prev = np.zeros(stride, np.int32)
    for y in range(h):
        ftype = raw[y * (stride + 1)]
        line = np.frombuffer(raw, np.uint8, stride, y * (stride + 1) + 1).astype(np.int32)
        cur = np.zeros(stride, np.int32)
        if ftype == 0:
            cur = line
        elif ftype == 2:
            cur = (line + prev) & 255
        else:  # 1 sub, 3 average, 4 Paeth: sequential in x
            for x in range(stride):
                a = cur[x - bpp] if x >= bpp else 0
                b = prev[x]
                cc = prev[x - bpp] if x >= bpp else 0
                if ftype == 1:
                    pred = a
                elif ftype == 3:
                    pred = (a + b) // 2
                else:
                    p = a + b - cc
                    pa, pb, pc = abs(p - a), abs(p - b), abs(p - cc)
                    pred = a if pa <= pb and pa <= pc else (b if pb <= pc else cc)
                cur[x] = (line[x] + pred) & 255
        out[y] = cur
        prev = cur
    return out.reshape(h, w, channels)


def image_difference(a_u8: np.ndarray, b_u8: np.ndarray) -> dict:
    d = np.abs(a_u8.astype(np.int32) - b_u8.astype(np.int32))
    return {
        "max_abs_diff_255": int(d.max()),
        "mean_abs_diff_255": float(d.mean()),
        "fraction_pixels_over_1_255": float((d.max(-1) > 1).mean()),
        "psnr_db": float(10 * np.log10(255.0**2 / max(float((d.astype(np.float64) ** 2).mean()), 1e-12))),
    }


# --------------------------------------------------------------------------------------------
# Environment
# --------------------------------------------------------------------------------------------


def ensure_ninja_on_path() -> None:
    """torch's JIT build runs `ninja`; the pip package's binary may not be on PATH."""
    if shutil.which("ninja"):
        return
    dirs = [os.path.join(p, "bin") for p in sys.path if p]  # `pip install --target DIR` puts it in DIR/bin
    try:
        import ninja  # noqa: PLC0415

        dirs.insert(0, ninja.BIN_DIR)
    except ImportError:
        pass
    for d in dirs:
        if d and os.access(os.path.join(d, "ninja"), os.X_OK):
            os.environ["PATH"] = os.environ.get("PATH", "") + os.pathsep + d
            return


def nvcc_version() -> str | None:
    try:
        from torch.utils.cpp_extension import _find_cuda_home

        home = _find_cuda_home()
        nvcc = os.path.join(home, "bin", "nvcc") if home else "nvcc"
        out = subprocess.run([nvcc, "--version"], capture_output=True, text=True, timeout=30).stdout
        return out.strip().splitlines()[-1] if out.strip() else None
    except Exception:  # noqa: BLE001
        return None


def environment() -> dict:
    import torch

    env = {
        "python": platform.python_version(),
        "torch": torch.__version__,
        "torch_cuda": torch.version.cuda,
        "numpy": np.__version__,
        "host_cpus": os.cpu_count(),
    }
    for var in ("TORCH_CUDA_ARCH_LIST", "MAX_JOBS", "TORCH_EXTENSIONS_DIR"):
        env[var] = os.environ.get(var)
    try:
        import gsplat

        env["gsplat"] = gsplat.__version__
        env["gsplat_path"] = os.path.dirname(gsplat.__file__)
    except ImportError:
        env["gsplat"] = None
    if torch.cuda.is_available():
        env["gpu"] = torch.cuda.get_device_name(0)
        env["gpu_capability"] = ".".join(map(str, torch.cuda.get_device_capability(0)))
        env["gpu_memory_gib"] = round(torch.cuda.get_device_properties(0).total_memory / 2**30, 1)
    env["nvcc"] = nvcc_version()
    return env


def load_backend(extension: Path | None = None) -> dict:
    """Imports gsplat's CUDA extension and times that: `extension` (a gsplat_cuda.so that an
    earlier --build-only --export-extension wrote, for this torch and Python) is loaded as is;
    otherwise gsplat JIT-builds it into TORCH_EXTENSIONS_DIR, or loads that cached build."""
    t0 = time.perf_counter()
    if extension is not None:
        import importlib.util

        import torch  # the extension links against torch's libraries, loaded here

        meta_path = Path(extension).with_suffix(".json")
        if meta_path.exists():
            built = json.loads(meta_path.read_text())
            here = {"torch": torch.__version__, "python": platform.python_version_tuple()[:2]}
            if built.get("torch") != here["torch"] or list(built.get("python", [])) != list(here["python"]):
                raise InputError(f"{extension}: built for torch {built.get('torch')} / Python "
                                 f"{'.'.join(built.get('python', []))}, not {here['torch']} / "
                                 f"{'.'.join(here['python'])}")
        spec = importlib.util.spec_from_file_location("gsplat_cuda", extension)
        if spec is None:
            raise InputError(f"{extension}: not a loadable extension module")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        sys.modules["gsplat.csrc"] = module  # gsplat's _backend imports `gsplat.csrc` first
        import gsplat.cuda._backend as backend

        if backend._C is not module:
            raise RuntimeError(f"gsplat did not take the extension {extension}")
        return {"seconds": round(time.perf_counter() - t0, 2), "was_cached": True,
                "prebuilt_extension": str(extension)}
    ensure_ninja_on_path()
    import sysconfig

    from torch.utils.cpp_extension import _get_build_directory

    include = sysconfig.get_paths()["include"]
    cpath = [d for d in os.environ.get("CPATH", "").split(os.pathsep) if d]
    if not any(os.path.exists(os.path.join(d, "Python.h")) for d in [include, *cpath]):
        raise InputError(
            f"no Python.h in {include} (nor in CPATH): the JIT build of gsplat's extension needs "
            f"Python {platform.python_version()}'s C headers; put a copy of them in a folder named by CPATH"
        )

    build_dir = _get_build_directory("gsplat_cuda", verbose=False)
    cached = os.path.exists(os.path.join(build_dir, "gsplat_cuda.so"))
    t0 = time.perf_counter()
    import gsplat.cuda._backend as backend

    seconds = time.perf_counter() - t0
    if backend._C is None:
        raise RuntimeError(
            "gsplat's CUDA extension is not available (no CUDA toolkit found, or its build failed: "
            "rerun with VERBOSE=1 to see nvcc's output)"
        )
    return {"seconds": round(seconds, 2), "was_cached": cached, "build_dir": build_dir}


def export_extension(build: dict, folder: Path) -> Path:
    """Copies the built gsplat_cuda.so (and what it was built for) to `folder`, so a later run on
    the same software can pass it to --extension and skip the compile."""
    import torch

    folder.mkdir(parents=True, exist_ok=True)
    dst = folder / "gsplat_cuda.so"
    shutil.copyfile(os.path.join(build["build_dir"], "gsplat_cuda.so"), dst)
    meta = {"torch": torch.__version__, "torch_cuda": torch.version.cuda,
            "python": list(platform.python_version_tuple()[:2]),
            "TORCH_CUDA_ARCH_LIST": os.environ.get("TORCH_CUDA_ARCH_LIST")}
    try:
        import gsplat

        meta["gsplat"] = gsplat.__version__
    except ImportError:
        pass
    dst.with_suffix(".json").write_text(json.dumps(meta, indent=1) + "\n")
    return dst


# --------------------------------------------------------------------------------------------
# Timing
# --------------------------------------------------------------------------------------------


def summary(samples_ms: list) -> dict:
    s = np.asarray(samples_ms, np.float64)
    return {
        "median_ms": float(np.median(s)),
        "min_ms": float(s.min()),
        "p10_ms": float(np.percentile(s, 10)),
        "p90_ms": float(np.percentile(s, 90)),
        "mean_ms": float(s.mean()),
        "runs": len(s),
    }


def time_gsplat(args, model: dict, cam: dict, device="cuda", rasterization=None) -> dict:
    """The timings and memory figures (`device` and `rasterization` are replaceable so the
    bookkeeping can be exercised without CUDA)."""
    import torch

    if rasterization is None:
        from gsplat import rasterization
    dev = torch.device(device)
    sh_degree = args.sh_degree if args.sh_degree is not None else int(math.isqrt(model["sh"].shape[1])) - 1
    report = {"inputs": {
        "ply": str(args.ply) if args.ply else None,
        "cameras": str(args.cameras) if args.cameras else None,
        "camera_index": args.camera_index,
        "gaussians": int(model["means"].shape[0]),
        "width": cam["width"],
        "height": cam["height"],
        "pixels": cam["width"] * cam["height"],
        "fx": cam["fx"], "fy": cam["fy"], "cx": cam["cx"], "cy": cam["cy"],
        "world_to_camera": cam["world_to_camera"].tolist(),
        "sh_degree": sh_degree,
        "sh_coeffs_in_file": int(model["sh"].shape[1]),
        "render_mode": args.render_mode,
        "background": args.background,
        "near_plane": args.near_plane,
        "packed": False,
        "rasterize_mode": "classic",
        "warmup": args.warmup,
        "reps": args.reps,
        "seed": args.seed,
    }}
    gen = torch.Generator(device="cpu").manual_seed(args.seed)
    h, w = cam["height"], cam["width"]
    n_ch = 3 if args.render_mode == "RGB" else 4
    weights = torch.rand((1, h, w, n_ch), generator=gen).to(dev)
    weights_alpha = torch.rand((1, h, w, 1), generator=gen).to(dev)
    target = torch.rand((1, h, w, 3), generator=gen).to(dev)

    torch.cuda.synchronize()
    torch.cuda.reset_peak_memory_stats()
    params = to_params(model, dev)
    base_alloc = torch.cuda.memory_allocated()

    def kwargs(p):
        return rasterization_kwargs(p, cam, sh_degree, args.render_mode, args.background, args.near_plane)

    def forward(p):
        return rasterization(**kwargs(p))

    def loss_of(out):
        colors, alphas, _ = out
        return (colors * weights).sum() + (alphas * weights_alpha).sum()

    # What the image is: visible Gaussians, tile intersections, mean colour / alpha / depth.
    with torch.no_grad():
        colors, alphas, meta = forward(params)
        torch.cuda.synchronize()
        radii = meta["radii"]
        report["image"] = {
            "visible_gaussians": int((radii > 0).all(-1).sum()),
            "tile_intersections": int(meta["isect_ids"].numel()),
            "tiles": int(meta["tile_width"] * meta["tile_height"]),
            "mean_rgb": [float(x) for x in colors[0, ..., :3].mean((0, 1))],
            "mean_alpha": float(alphas.mean()),
            "mean_depth_channel": float(colors[0, ..., 3].mean()) if n_ch == 4 else None,
        }
        if args.save_render:
            write_png(args.save_render, to_u8(colors[0, ..., :3].float().cpu().numpy()))
            report["image"]["saved_png"] = str(args.save_render)
        if args.compare_png:
            other = read_png(args.compare_png)[..., :3]
            mine = to_u8(colors[0, ..., :3].float().cpu().numpy())
            if other.shape != mine.shape:
                raise InputError(f"{args.compare_png}: size {other.shape[:2]} is not {mine.shape[:2]}")
            report["image"]["versus_png"] = {"png": str(args.compare_png), **image_difference(mine, other)}
        del colors, alphas, meta, radii

    def run_events(fn, n):
        """Runs fn n times (it returns the CUDA events it recorded); the ms between them, [n][k]."""
        rows = []
        for _ in range(n):
            evs = fn()
            rows.append(evs)
        torch.cuda.synchronize()
        return [[a.elapsed_time(b) for a, b in zip(ev[:-1], ev[1:])] for ev in rows]

    def ev():
        e = torch.cuda.Event(enable_timing=True)
        e.record()
        return e

    def fwd_once():
        e0 = ev()
        out = forward(params)
        e1 = ev()
        del out
        return [e0, e1]

    def fwd_nograd_once():
        with torch.no_grad():
            e0 = ev()
            out = forward(params)
            e1 = ev()
        del out
        return [e0, e1]

    def fwd_bwd_once():
        clear_grads()
        e0 = ev()
        loss = loss_of(forward(params))
        e1 = ev()
        loss.backward()
        e2 = ev()
        return [e0, e1, e2]

    def clear_grads():
        for p in params.values():
            p.grad = None

    def measure(fn):
        run_events(fn, args.warmup)
        clear_grads()  # the start figure holds the parameters, not the last run's gradients
        torch.cuda.synchronize()
        torch.cuda.reset_peak_memory_stats()
        before = torch.cuda.memory_allocated()
        fn()
        torch.cuda.synchronize()
        peak = torch.cuda.max_memory_allocated()
        t0 = time.perf_counter()
        rows = run_events(fn, args.reps)
        wall = (time.perf_counter() - t0) / args.reps * 1e3
        return rows, {"peak_bytes": int(peak), "peak_above_start_bytes": int(peak - before),
                      "wall_clock_mean_ms": wall}

    timings, memory = {}, {}
    rows, memory["forward"] = measure(fwd_once)
    timings["forward"] = summary([r[0] for r in rows])
    rows, memory["forward_no_grad"] = measure(fwd_nograd_once)
    timings["forward_no_grad"] = summary([r[0] for r in rows])
    rows, memory["forward_backward"] = measure(fwd_bwd_once)
    timings["forward_in_backward_runs"] = summary([r[0] for r in rows])
    timings["backward"] = summary([r[1] for r in rows])
    timings["forward_backward"] = summary([r[0] + r[1] for r in rows])
    params.clear()  # frees the tensors (the closures above are not called again)
    torch.cuda.empty_cache()

    # One training step: per-parameter Adam as gsplat's simple_trainer, L1 on RGB.
    tparams = to_params(model, dev, split_sh=True)
    optimizers = {
        name: torch.optim.Adam([{"params": [p], "lr": LEARNING_RATES[name], "name": name}], eps=1e-15)
        for name, p in tparams.items()
    }

    def train_once():
        e0 = ev()
        for opt in optimizers.values():
            opt.zero_grad(set_to_none=True)
        colors, _, _ = rasterization(**rasterization_kwargs(
            tparams, cam, sh_degree, args.render_mode, args.background, args.near_plane))
        loss = (colors[..., :3] - target).abs().mean()
        loss.backward()
        for opt in optimizers.values():
            opt.step()
        e1 = ev()
        return [e0, e1]

    rows, memory["train_step"] = measure(train_once)
    timings["train_step"] = summary([r[0] for r in rows])
    report["train_step"] = {
        "loss": "L1: mean |rendered RGB - fixed random target| (no SSIM term)",
        "optimizer": "torch.optim.Adam per parameter (default foreach implementation), eps 1e-15",
        "learning_rates": LEARNING_RATES,
        "densification": False,
    }
    report["timings"] = timings
    report["peak_memory"] = {"parameters_bytes": int(base_alloc), **memory}
    return report


# --------------------------------------------------------------------------------------------
# The CPU check
# --------------------------------------------------------------------------------------------


def check_cpu(args) -> dict:
    """Tiny scene through the same writer, readers and argument builder as the GPU path, rendered
    with gsplat's PyTorch stages (reference_rasterization); compared with `fewview render`."""
    import inspect

    import torch
    import gsplat

    torch.manual_seed(args.seed)
    n, width, height = args.check_gaussians, args.check_width, args.check_height
    results = {"gaussians": n, "width": width, "height": height, "gsplat": gsplat.__version__,
               "torch": torch.__version__}
    work = Path(tempfile.mkdtemp(prefix="gsplat_check_"))
    model, cam = make_scene(n, width, height, args.seed)
    ply, cams = work / "scene.ply", work / "cameras.json"
    write_ply(ply, model)
    cams.write_text(json.dumps([camera_to_json(cam)], indent=1))

    back = read_ply(ply)
    roundtrip = all(np.array_equal(back[k], model[k]) for k in model)
    results["ply_roundtrip_bit_exact"] = roundtrip
    cam_file = read_camera(cams, 0)
    explicit = explicit_camera(argparse.Namespace(
        fx=cam["fx"], fy=cam["fy"], cx=cam["cx"], cy=cam["cy"], width=width, height=height,
        world_to_camera=",".join(repr(float(x)) for x in cam["world_to_camera"].flatten())))
    results["camera_json_equals_explicit_flags"] = bool(
        np.array_equal(cam_file["world_to_camera"], explicit["world_to_camera"])
        and all(cam_file[k] == explicit[k] for k in ("fx", "fy", "cx", "cy", "width", "height")))

    params = to_params(back, "cpu")
    sh_degree = int(math.isqrt(back["sh"].shape[1])) - 1
    background = list(args.background)
    kw = rasterization_kwargs(params, cam_file, sh_degree, "RGB+ED", background, args.near_plane)
    # The argument names must be gsplat.rasterization()'s.
    inspect.signature(gsplat.rasterization).bind(**kw)
    results["kwargs_bind_to_gsplat_rasterization"] = True

    colors, alphas, meta = reference_rasterization(**kw)
    results["visible_gaussians"] = meta["n_visible"]
    results["mean_rgb"] = [float(x) for x in colors.detach()[0, ..., :3].mean((0, 1))]
    results["mean_alpha"] = float(alphas.detach().mean())
    results["finite"] = bool(torch.isfinite(colors).all() and torch.isfinite(alphas).all())
    gen = torch.Generator().manual_seed(args.seed)
    loss = (colors * torch.rand(colors.shape, generator=gen)).sum() + (alphas * torch.rand(alphas.shape, generator=gen)).sum()
    loss.backward()
    results["gradients"] = {
        k: {"finite": bool(torch.isfinite(p.grad).all()), "nonzero_rows": int((p.grad.reshape(n, -1).abs().sum(1) > 0).sum())}
        for k, p in params.items()
    }

    # SH layout: the first Gaussian's colour (bands 0 and 1) by Inria's eval_sh, from the raw
    # PLY columns (f_rest is channel-major), equals gsplat's SH of the loaded [N, K, 3] tensor.
    with torch.no_grad():
        cols = read_ply_columns(ply)
        k = back["sh"].shape[1]
        kw_nograd = rasterization_kwargs(to_params(back, "cpu"), cam_file, sh_degree, "RGB", background, args.near_plane)
        from gsplat.cuda._torch_impl import _spherical_harmonics
        d = kw_nograd["means"][0] - torch.inverse(kw_nograd["viewmats"][0])[:3, 3]
        x, y, z = (d / d.norm()).double().numpy()
        coef = lambda c, kk: float(cols[f"f_dc_{c}"][0] if kk == 0 else cols[f"f_rest_{c * (k - 1) + kk - 1}"][0])  # noqa: E731
        c1 = 0.4886025119029199
        want = np.array([SH_C0 * coef(c, 0) - c1 * y * coef(c, 1) + c1 * z * coef(c, 2) - c1 * x * coef(c, 3)
                         for c in range(3)])
        got = _spherical_harmonics(1, d[None], kw_nograd["colors"][:1])[0].double().numpy()
        results["sh_band1_matches_inria_eval_sh"] = bool(np.allclose(got, want, atol=1e-5))
        results["sh_degree"] = sh_degree

    # fewview render of the same PLY and camera.
    fewview = Path(args.fewview) if args.fewview else None
    if fewview and fewview.exists():
        out_dir = work / "fewview_render"
        cmd = [str(fewview), "render", "--ply", str(ply), "--cameras", str(cams),
               "--background", ",".join(str(x) for x in background), "--out", str(out_dir)]
        t0 = time.perf_counter()
        proc = subprocess.run(cmd, capture_output=True, text=True)
        results["fewview_render_seconds"] = round(time.perf_counter() - t0, 2)
        if proc.returncode != 0:
            raise RuntimeError(f"fewview render failed: {proc.stderr.strip()}")
        theirs = read_png(out_dir / "camera_000.png")[..., :3]
        with torch.no_grad():
            kw_ref = rasterization_kwargs(to_params(back, "cpu"), cam_file, sh_degree, "RGB", background, args.near_plane)
            gs_999, _, _ = reference_rasterization(**kw_ref, alpha_max=0.999)
            gs_99, _, _ = reference_rasterization(**kw_ref, alpha_max=0.99)
        mine_999 = to_u8(gs_999[0].numpy())
        mine_99 = to_u8(gs_99[0].numpy())
        results["versus_fewview_render"] = {
            "command": " ".join(cmd),
            "gsplat_rules_alpha_max_0.999": image_difference(mine_999, theirs),
            "gsplat_rules_with_alpha_max_0.99_as_fewview": image_difference(mine_99, theirs),
        }
        if args.save_render:
            write_png(args.save_render, np.concatenate([mine_999, theirs], 1))
            results["saved_png_left_gsplat_right_fewview"] = str(args.save_render)
    else:
        results["versus_fewview_render"] = f"skipped: no fewview binary at {fewview}"

    ok = (roundtrip and results["camera_json_equals_explicit_flags"] and results["finite"]
          and results["sh_band1_matches_inria_eval_sh"]
          and all(g["finite"] and g["nonzero_rows"] > 0 for g in results["gradients"].values()))
    if isinstance(results["versus_fewview_render"], dict):
        ok = ok and results["versus_fewview_render"]["gsplat_rules_with_alpha_max_0.99_as_fewview"]["max_abs_diff_255"] <= 1
    results["passed"] = bool(ok)
    if ok:
        shutil.rmtree(work, ignore_errors=True)
    else:
        results["work_dir_kept"] = str(work)
    return results


# --------------------------------------------------------------------------------------------
# Command line
# --------------------------------------------------------------------------------------------


def explicit_camera(a) -> dict:
    try:
        values = [float(x) for x in a.world_to_camera.replace(",", " ").split()]
    except ValueError as e:
        raise InputError(f"--world-to-camera: {e}") from e
    if len(values) not in (12, 16):
        raise InputError("--world-to-camera: give 16 (or 12) numbers, the row-major 4×4 (3×4) matrix")
    m = np.eye(4)
    m[: len(values) // 4] = np.asarray(values).reshape(-1, 4)
    cam = dict(fx=a.fx, fy=a.fy, cx=a.cx, cy=a.cy, width=a.width, height=a.height, world_to_camera=m)
    check_camera(cam, "--world-to-camera and intrinsics")
    return cam


def parse_rgb(s: str):
    try:
        v = [float(x) for x in s.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError("give three numbers in [0, 1], e.g. 0,0,0") from None
    if len(v) != 3 or not all(0 <= x <= 1 for x in v):
        raise argparse.ArgumentTypeError("give three numbers in [0, 1], e.g. 0,0,0")
    return v


def write_json(path: Path, value: dict) -> None:
    path = Path(path)
    if path.parent:
        path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(value, indent=1) + "\n")
    os.replace(tmp, path)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        prog="gsplat_compare.py",
        description=__doc__.split("\n\n")[0] + " Times gsplat.rasterization() forward, "
        "forward+backward and a training step on a Gaussian PLY and one camera, and writes JSON.",
        epilog=__doc__[__doc__.index("Running it on the GPU"):],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    mode = ap.add_mutually_exclusive_group()
    mode.add_argument("--make-scene", metavar="DIR", type=Path,
                      help="write DIR/scene.ply and DIR/cameras.json (random scene, seeded) and exit")
    mode.add_argument("--build-only", action="store_true",
                      help="compile (or load) gsplat's CUDA extension, report the seconds, exit")
    mode.add_argument("--check-cpu", action="store_true",
                      help="check loading and conversion on a tiny scene without CUDA (gsplat's "
                      "PyTorch stages), against `fewview render` when --fewview exists")
    g = ap.add_argument_group("inputs")
    g.add_argument("--ply", type=Path, help="Gaussians, Inria 3DGS PLY layout")
    g.add_argument("--cameras", type=Path, help="camera file (fewview's form; a run's cameras.json)")
    g.add_argument("--camera-index", type=int, default=0, help="which camera of --cameras (default 0)")
    g.add_argument("--fx", type=float, help="focal length x, pixels (instead of --cameras)")
    g.add_argument("--fy", type=float, help="focal length y, pixels")
    g.add_argument("--cx", type=float, help="principal point x, pixels (pixel centres at half-integers)")
    g.add_argument("--cy", type=float, help="principal point y, pixels")
    g.add_argument("--width", type=int, help=f"image width (--make-scene: default {DEFAULT_WIDTH})")
    g.add_argument("--height", type=int, help=f"image height (--make-scene: default {DEFAULT_HEIGHT})")
    g.add_argument("--world-to-camera", metavar="M",
                   help="16 numbers, row-major 4×4 world-to-camera (OpenCV axes), with --fx ... --height")
    r = ap.add_argument_group("rendering")
    r.add_argument("--render-mode", choices=["RGB", "RGB+D", "RGB+ED"], default="RGB+ED",
                   help="gsplat's render_mode (default RGB+ED; RGB+D is fewview's depth channel)")
    r.add_argument("--sh-degree", type=int, help="SH degree to use (default: the file's)")
    r.add_argument("--near-plane", type=float, default=0.2, help="default 0.2, as fewview")
    r.add_argument("--background", type=parse_rgb, default=[0.0, 0.0, 0.0], metavar="R,G,B",
                   help="background colour in [0, 1] (default 0,0,0)")
    t = ap.add_argument_group("timing and output")
    t.add_argument("--warmup", type=int, default=5, help="untimed runs before each measurement (default 5)")
    t.add_argument("--reps", type=int, default=30, help="timed runs, median reported (>= 20; default 30)")
    t.add_argument("--seed", type=int, default=1, help="seed of the scene, loss weights and target (default 1)")
    t.add_argument("--json", type=Path, help="report (default gsplat_compare.json; --check-cpu: none)")
    t.add_argument("--save-render", type=Path, metavar="PNG", help="also write gsplat's RGB render as PNG")
    t.add_argument("--compare-png", type=Path, metavar="PNG",
                   help="compare gsplat's RGB render with this image (e.g. fewview render's camera_000.png)")
    b = ap.add_argument_group("the CUDA extension")
    b.add_argument("--extension", type=Path, metavar="SO",
                   help="load this prebuilt gsplat_cuda.so (from --export-extension, same torch and "
                   "Python) instead of compiling")
    b.add_argument("--export-extension", type=Path, metavar="DIR",
                   help="--build-only: copy the built gsplat_cuda.so (+ .json saying for what) to DIR")
    s = ap.add_argument_group("--make-scene and --check-cpu")
    s.add_argument("--gaussians", type=int, default=DEFAULT_GAUSSIANS, help="--make-scene: count (default 1,000,000)")
    s.add_argument("--check-gaussians", type=int, default=400, help="--check-cpu: count (default 400)")
    s.add_argument("--check-width", type=int, default=96, help="--check-cpu: width (default 96)")
    s.add_argument("--check-height", type=int, default=72, help="--check-cpu: height (default 72)")
    default_fewview = Path(__file__).resolve().parent.parent / "target" / "release" / "fewview"
    s.add_argument("--fewview", default=str(default_fewview),
                   help="--check-cpu: fewview binary to compare with (default target/release/fewview)")
    args = ap.parse_args(argv)

    try:
        if args.make_scene:
            width, height = args.width or DEFAULT_WIDTH, args.height or DEFAULT_HEIGHT
            if args.gaussians < 1 or width < 1 or height < 1:
                ap.error("--gaussians, --width and --height must be positive")
            t0 = time.perf_counter()
            model, cam = make_scene(args.gaussians, width, height, args.seed)
            args.make_scene.mkdir(parents=True, exist_ok=True)
            write_ply(args.make_scene / "scene.ply", model)
            (args.make_scene / "cameras.json").write_text(json.dumps([camera_to_json(cam)], indent=1) + "\n")
            print(f"wrote {args.gaussians} Gaussians ({width}×{height} camera) to {args.make_scene} "
                  f"in {time.perf_counter() - t0:.1f} s")
            return 0

        if args.check_cpu:
            res = check_cpu(args)
            if args.json:
                write_json(args.json, {"check_cpu": res})
            print(json.dumps(res, indent=1))
            print("check-cpu: " + ("passed" if res["passed"] else "FAILED"))
            return 0 if res["passed"] else 1

        import torch

        if not torch.cuda.is_available():
            print("error: no CUDA device (use --check-cpu on a machine without one)", file=sys.stderr)
            return 2
        if args.build_only:
            args.json = args.json or Path("gsplat_build.json")
            build = load_backend(args.extension)
            if args.export_extension:
                if args.extension:
                    ap.error("--export-extension copies a JIT build; it has nothing to copy with --extension")
                dst = export_extension(build, args.export_extension)
                build["exported_to"] = str(dst)
                build["exported_bytes"] = dst.stat().st_size
            report = {"build": build, "environment": environment()}
            write_json(args.json, report)
            state = "loaded the cached build" if build["was_cached"] else "built"
            print(f"gsplat CUDA extension: {state} in {build['seconds']:.1f} s "
                  f"({build.get('build_dir') or build.get('prebuilt_extension')})")
            return 0

        if args.reps < 20:
            ap.error("--reps must be at least 20")
        if args.warmup < 1:
            ap.error("--warmup must be at least 1")
        if not args.ply:
            ap.error("--ply is required to time")
        explicit = [args.fx, args.fy, args.cx, args.cy, args.width, args.height, args.world_to_camera]
        if args.cameras and any(v is not None for v in explicit):
            ap.error("give --cameras or the explicit camera flags, not both")
        if args.cameras:
            cam = read_camera(args.cameras, args.camera_index)
        elif all(v is not None for v in explicit):
            cam = explicit_camera(args)
        else:
            ap.error("give --cameras FILE, or all of --fx --fy --cx --cy --width --height --world-to-camera")
        t0 = time.perf_counter()
        model = read_ply(args.ply)
        ply_seconds = time.perf_counter() - t0
        k = model["sh"].shape[1]
        if args.sh_degree is not None and (args.sh_degree + 1) ** 2 > k:
            ap.error(f"--sh-degree {args.sh_degree} needs {(args.sh_degree + 1) ** 2} SH coefficients; the file has {k}")
        args.json = args.json or Path("gsplat_compare.json")
        build = load_backend(args.extension)
        report = time_gsplat(args, model, cam)
        report["backend_load"] = build
        report["ply_read_seconds"] = round(ply_seconds, 2)
        report["environment"] = environment()
        write_json(args.json, report)
        tm = report["timings"]
        print(f"{report['environment'].get('gpu')}: gsplat {report['environment'].get('gsplat')}, "
              f"{report['inputs']['gaussians']} Gaussians, {cam['width']}×{cam['height']}, {args.render_mode}")
        for name in ("forward", "forward_no_grad", "backward", "forward_backward", "train_step"):
            peak = report["peak_memory"].get(name, {}).get("peak_bytes")
            extra = f"  peak {peak / 2**20:.0f} MiB" if peak is not None else ""
            print(f"  {name:18s} median {tm[name]['median_ms']:8.2f} ms  (min {tm[name]['min_ms']:.2f}){extra}")
        print(f"wrote {args.json}")
        return 0
    except InputError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
