#!/usr/bin/env python3
"""How well do a DTU scan's images agree with its calibrated poses, and how firmly do a set of
matches fix the poses?

An independent check of the reference the surface method is scored against: matches joined into
tracks, then a three-view bundle adjustment (SciPy, Huber loss on reprojection errors,
intrinsics fixed) started from the calibrated poses, scored against them with the surface paper's
Alg. 1/2 (the pose metric `fewview surface` reports: pairwise similarity alignment, arccos
clamped at 1 - 1e-6), and the 1-sigma rotation uncertainty of each adjusted view from the
curvature of the cost. If the images' own optimum lay far from the calibration, no method could
reach a rotation error below that distance; if the uncertainty is small, the matches do fix the
poses and a method that misses them loses information on the way.

Two sources of matches:
  * a `fewview surface` run made with `--pose-noise 0 --iterations 1` (its `matches.json`, and
    `poses_initial.json` as the calibration in the run's frame and image scale):
        python3 tools/dtu_pose_consistency.py --run RUN
  * OpenCV SIFT on the scan's images (ratio 0.8, mutual, inside the masks; few on DTU's
    textureless objects):
        python3 tools/dtu_pose_consistency.py --scan DATA/dtu/scan37 [--views 22,25,28]

DTU's scans share one calibration (the robot's positions), so a scan whose capture drifted from
it would show up here.
"""
import argparse
import itertools
import json

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation


def load_view(scan, i):
    cams = np.load(f"{scan}/cameras_sphere.npz")
    p = cams[f"world_mat_{i}"][:3, :4]
    k, r, c = cv2.decomposeProjectionMatrix(p)[:3]
    k = k / k[2, 2]
    c = (c[:3] / c[3]).ravel()
    t = -r @ c
    image = cv2.imread(f"{scan}/image/{i:06d}.png", cv2.IMREAD_GRAYSCALE)
    mask = cv2.imread(f"{scan}/mask/{i:03d}.png", cv2.IMREAD_GRAYSCALE)
    if mask is None:
        mask = cv2.imread(f"{scan}/mask/{i:06d}.png", cv2.IMREAD_GRAYSCALE)
    return k, r, t, image, mask


def sift_matches(a, b, sift):
    ka, da = sift.detectAndCompute(a[3], (a[4] > 127).astype(np.uint8))
    kb, db = sift.detectAndCompute(b[3], (b[4] > 127).astype(np.uint8))
    matcher = cv2.BFMatcher(cv2.NORM_L2)
    fwd = matcher.knnMatch(da, db, k=2)
    bwd = {m.queryIdx: m.trainIdx for m in matcher.match(db, da)}
    pairs = []
    for m, n in fwd:
        if m.distance < 0.8 * n.distance and bwd.get(m.trainIdx) == m.queryIdx:
            pairs.append((ka[m.queryIdx].pt, kb[m.trainIdx].pt))
    return np.array([p for p, _ in pairs]), np.array([q for _, q in pairs])


def ransac_inliers(pa, pb, ka, kb):
    na = cv2.undistortPoints(pa.reshape(-1, 1, 2), ka, None).reshape(-1, 2)
    nb = cv2.undistortPoints(pb.reshape(-1, 1, 2), kb, None).reshape(-1, 2)
    f = 0.5 * (ka[0, 0] + kb[0, 0])
    _, inl = cv2.findEssentialMat(na, nb, np.eye(3), cv2.RANSAC, 0.999, 1.0 / f)
    return inl.ravel() > 0


def tracks_from_pairs(views, pair_matches):
    """Union of the pairwise matches by pixel position (SIFT keypoints repeat exactly)."""
    parent = {}

    def find(x):
        while parent.setdefault(x, x) != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    for (i, j), (pa, pb) in pair_matches.items():
        for p, q in zip(pa, pb):
            a, b = find((i, tuple(np.round(p, 3)))), find((j, tuple(np.round(q, 3))))
            parent[a] = b
    groups = {}
    for node in list(parent):
        groups.setdefault(find(node), []).append(node)
    tracks = []
    for members in groups.values():
        seen = {}
        for v, p in members:
            seen.setdefault(v, []).append(p)
        if len(seen) >= 2 and all(len(ps) == 1 for ps in seen.values()):
            tracks.append({v: np.array(ps[0]) for v, ps in seen.items()})
    return tracks


def triangulate(track, cams):
    rows = []
    for v, p in track.items():
        k, r, t = cams[v]
        proj = k @ np.hstack([r, t[:, None]])
        rows.append(p[0] * proj[2] - proj[0])
        rows.append(p[1] * proj[2] - proj[1])
    x = np.linalg.svd(np.array(rows))[2][-1]
    return x[:3] / x[3]


def bundle_adjust(cams, tracks, fixed, max_evaluations=300):
    """Poses of every view but `fixed` (a left rotation-vector and translation update) and the
    tracks' points, Huber loss at 1 px; the Jacobian's sparsity is given to SciPy."""
    from scipy.sparse import lil_matrix

    # Work in units of the mean camera distance, so rotations, translations and points share
    # one scale in the solver.
    unit = np.mean([np.linalg.norm(r.T @ t) for _, r, t in cams.values()])
    cams = {v: (k, r, t / unit) for v, (k, r, t) in cams.items()}
    free = [v for v in cams if v != fixed]
    points0 = np.array([triangulate(tr, cams) for tr in tracks])
    obs = [(ti, v, p) for ti, tr in enumerate(tracks) for v, p in tr.items()]
    track_of = np.array([o[0] for o in obs])
    view_of = [o[1] for o in obs]
    pixels = np.array([o[2] for o in obs])
    n_pose = 6 * len(free)

    def poses(x):
        out = {}
        for v, (k, r, t) in cams.items():
            if v == fixed:
                out[v] = (k, r, t)
                continue
            i = free.index(v)
            d = Rotation.from_rotvec(x[6 * i : 6 * i + 3]).as_matrix()
            out[v] = (k, d @ r, d @ t + x[6 * i + 3 : 6 * i + 6])
        return out

    def residuals(x):
        pts = x[n_pose:].reshape(-1, 3)
        out = np.empty((len(obs), 2))
        for v, (k, r, t) in poses(x).items():
            sel = np.array([w == v for w in view_of])
            q = (k @ (r @ pts[track_of[sel]].T + t[:, None])).T
            out[sel] = q[:, :2] / q[:, 2:] - pixels[sel]
        return out.ravel()

    sparsity = lil_matrix((2 * len(obs), n_pose + points0.size), dtype=int)
    for n, (ti, v, _) in enumerate(obs):
        rows = [2 * n, 2 * n + 1]
        if v != fixed:
            i = free.index(v)
            for r in rows:
                sparsity[r, 6 * i : 6 * i + 6] = 1
        for r in rows:
            sparsity[r, n_pose + 3 * ti : n_pose + 3 * ti + 3] = 1
    x0 = np.concatenate([np.zeros(n_pose), points0.ravel()])
    fit = least_squares(
        residuals, x0, jac_sparsity=sparsity, loss="huber", f_scale=1.0, ftol=1e-12, xtol=1e-12, gtol=1e-12,
        x_scale="jac", method="trf", max_nfev=max_evaluations,
    )
    res = residuals(fit.x)
    adjusted = {v: (k, r, t * unit) for v, (k, r, t) in poses(fit.x).items()}
    return adjusted, np.median(np.linalg.norm(res.reshape(-1, 2), axis=1)), rotation_std(fit, res, free)


def rotation_std(fit, res, free):
    """1-sigma rotation uncertainty (degrees) of each free view: the pose block of
    sigma^2 (J^T J)^+ (the pseudo-inverse drops the scale gauge, which moves no rotation), with
    sigma the residuals' robust standard deviation (1.4826 x median absolute value)."""
    jac = fit.jac.toarray() if hasattr(fit.jac, "toarray") else fit.jac
    sigma = 1.4826 * np.median(np.abs(res))
    cov = sigma**2 * np.linalg.pinv(jac.T @ jac, rcond=1e-12, hermitian=True)
    out = {}
    for i, v in enumerate(free):
        block = cov[6 * i : 6 * i + 3, 6 * i : 6 * i + 3]
        out[v] = np.degrees(np.sqrt(np.trace(block)))
    return out


def c2w(r, t):
    m = np.eye(4)
    m[:3, :3] = r.T
    m[:3, 3] = -r.T @ t
    return m


def paper_pose_error(est, gt):
    """The surface paper Alg. 1/2: best pairwise similarity alignment, mean rotation (degrees) and
    translation errors over the views."""
    views = list(gt)
    e = np.array([c2w(*est[v][1:]) for v in views])
    g = np.array([c2w(*gt[v][1:]) for v in views])
    best = (np.inf, None, None)
    for a, b in itertools.permutations(range(len(views)), 2):
        s = np.linalg.norm(g[a, :3, 3] - g[b, :3, 3]) / np.linalg.norm(e[a, :3, 3] - e[b, :3, 3])
        scaled = e.copy()
        scaled[:, :3, 3] *= s
        aligned = (g[a] @ np.linalg.inv(scaled[a]))[None] @ scaled
        cos = (np.einsum("nij,nij->n", aligned[:, :3, :3], g[:, :3, :3]) - 1) / 2
        er = np.degrees(np.arccos(np.clip(cos, -1 + 1e-6, 1 - 1e-6)))
        et = np.linalg.norm(aligned[:, :3, 3] - g[:, :3, 3], axis=1)
        if er.mean() * et.mean() < best[0]:
            best = (er.mean() * et.mean(), er.mean(), et.mean())
    return best[1], best[2]


def run_cameras(path):
    out = {}
    for i, p in enumerate(json.load(open(path))):
        k = p["intrinsics"]
        kk = np.array([[k["fx"], 0, k["cx"]], [0, k["fy"], k["cy"]], [0, 0, 1.0]])
        m = np.array(p["world_to_camera"])
        out[i] = (kk, m[:3, :3], m[:3, 3])
    return out


def run_matches(path):
    pairs = {}
    for c in json.load(open(path))["correspondences"]:
        a, b = pairs.setdefault((c["view_a"], c["view_b"]), ([], []))
        a.append(c["a"])
        b.append(c["b"])
    return {k: (np.array(a), np.array(b)) for k, (a, b) in pairs.items()}


def sift_inputs(scan, ids):
    loaded = {i: load_view(scan, i) for i in ids}
    cams = {i: loaded[i][:3] for i in ids}
    sift = cv2.SIFT_create(nfeatures=8000, contrastThreshold=0.02)
    pair_matches = {}
    for i, j in itertools.combinations(ids, 2):
        pa, pb = sift_matches(loaded[i], loaded[j], sift)
        keep = ransac_inliers(pa, pb, cams[i][0], cams[j][0])
        pair_matches[(i, j)] = (pa[keep], pb[keep])
    return cams, pair_matches


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--run", help="a fewview surface run made with --pose-noise 0")
    ap.add_argument("--scan", help="a DTU scan folder (IDR layout)")
    ap.add_argument("--views", default="22,25,28")
    ap.add_argument("--max-evaluations", type=int, default=300)
    args = ap.parse_args()
    if args.run:
        cams = run_cameras(f"{args.run}/poses_initial.json")
        pair_matches = run_matches(f"{args.run}/matches.json")
    elif args.scan:
        cams, pair_matches = sift_inputs(args.scan, [int(v) for v in args.views.split(",")])
    else:
        ap.error("give --run or --scan")
    for (i, j), (pa, _) in pair_matches.items():
        print(f"pair {i}-{j}: {len(pa)} matches")
    ids = list(cams)
    tracks = tracks_from_pairs(ids, pair_matches)
    triple = sum(len(t) == len(ids) for t in tracks)
    print(f"{len(tracks)} tracks, {triple} seen in all {len(ids)} views")
    adjusted, median, std = bundle_adjust(cams, tracks, ids[0], args.max_evaluations)
    print(f"median reprojection error after adjustment: {median:.3f} px")
    rot, trans = paper_pose_error(adjusted, cams)
    print(f"adjusted poses vs the calibration (the surface paper Alg. 1/2): rotation {rot:.3f} deg, "
          f"translation {trans:.5f}")
    for v, s in std.items():
        print(f"view {v}: rotation 1-sigma {s:.4f} deg")


if __name__ == "__main__":
    main()
