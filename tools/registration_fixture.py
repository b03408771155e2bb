#!/usr/bin/env python3
"""Registration fixture (the surface paper Alg. 3) and Open3D's reference result on it.

Makes two partial, noisy point clouds of the Stanford bunny, moves the source by a random
similarity, simulates the camera-based pre-alignment, and runs Open3D's FPFH + RANSAC + ICP on
them. Everything the Rust test needs is written to the output folder:

  source.ply     source cloud (binary PLY), in the "reconstruction" frame
  target.ply     target cloud, in the ground-truth frame
  fixture.json   the true source→target similarity, the pre-alignment, all parameters, and
                 Open3D's recovered transforms with their errors

Procedure (seeded, numpy's default_rng):
  1. Sample N points uniformly (area-weighted, uniform barycentric) on the mesh, twice.
  2. Cut along a random direction d: with a = 1/1.3, the target keeps samples whose
     projection on d is at or below the a-quantile, the source those at or above the
     (1 - a)-quantile (quantiles of a dense 200k-point sample): each keeps a of the surface and
     70 % of each cloud lies in the shared part.
  3. Add independent Gaussian noise, sigma = --noise (default 1 %) of the mesh's bounding-box
     diagonal.
  4. Move the source by x -> s R x + t: R uniform (normalised Gaussian quaternion),
     s ~ U(0.5, 2), t ~ U(-2, 2) * diagonal per axis.
  5. Cameras: 6 centres on a ring (radius 2 * diagonal) around the bunny; their source-frame
     images get Gaussian noise (2 % of the ring radius, times s); the pre-alignment is the
     Umeyama similarity from the noisy source-frame centres to the true ones.
  6. Open3D: pre-align, voxel_down_sample(v), estimate_normals(Hybrid(2v, 30)),
     compute_fpfh_feature(Hybrid(5v, 100)), registration_ransac_based_on_feature_matching(
     mutual_filter=False, 1.5v, PointToPoint(False), ransac_n=3, [EdgeLength(0.9),
     Distance(1.5v)], RANSACConvergenceCriteria(100000, 0.999)), then registration_icp(
     thr, PointToPoint(with_scaling=False), ICPConvergenceCriteria(max_iteration=100)) on the
     full clouds for thr = 0.02, 0.01, 0.005, 0.003 in turn (multi-scale ICP).

Errors: rotation = angle of R_est R_true^T in degrees; displacement = RMS over the mesh's
vertices (moved into the source frame) of |T_est(x) - T_true(x)|, as a fraction of the
diagonal; scale = s_est / s_true - 1.

Rerun (Open3D 0.20.0 via the open3d-cpu wheel, Python 3.11, numpy 2.x):
  python3 -m pip install open3d-cpu==0.20.0
  python3 tools/registration_fixture.py --bunny ../shared/data/meshes/bunny.obj \
      --out crates/geom/tests/fixtures/registration
  python3 tools/registration_fixture.py --bunny ../shared/data/meshes/bunny.obj --noise 0.002 \
      --out crates/geom/tests/fixtures/registration_low_noise
"""

import argparse
import json
import os

import numpy as np
import open3d as o3d

SEED = 20250501
N = 12000
OVERLAP = 0.7
VOXEL = 0.008
# thr_icp, coarse to fine (multi-scale ICP: each stage starts from the previous result).
THR_ICP = [0.02, 0.01, 0.005, 0.003]


def load_obj(path):
    v, f = [], []
    with open(path) as fh:
        for line in fh:
            w = line.split()
            if not w:
                continue
            if w[0] == "v":
                v.append([float(x) for x in w[1:4]])
            elif w[0] == "f":
                idx = [int(x.split("/")[0]) - 1 for x in w[1:]]
                for k in range(1, len(idx) - 1):
                    f.append([idx[0], idx[k], idx[k + 1]])
    return np.array(v, dtype=np.float64), np.array(f, dtype=np.int64)


def sample(rng, v, f, n):
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    face = rng.choice(len(f), size=n, p=area / area.sum())
    r1 = np.sqrt(rng.random(n))[:, None]
    r2 = rng.random(n)[:, None]
    return a[face] * (1 - r1) + b[face] * (r1 * (1 - r2)) + c[face] * (r1 * r2)


def umeyama(src, dst):
    mu_s, mu_d = src.mean(0), dst.mean(0)
    a, b = src - mu_s, dst - mu_d
    cov = b.T @ a / len(src)
    u, d, vt = np.linalg.svd(cov)
    s = np.eye(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        s[2, 2] = -1
    r = u @ s @ vt
    scale = np.trace(np.diag(d) @ s) / (a * a).sum(1).mean()
    t = mu_d - scale * r @ mu_s
    m = np.eye(4)
    m[:3, :3] = scale * r
    m[:3, 3] = t
    return m


def split(m):
    s = np.cbrt(np.linalg.det(m[:3, :3]))
    return s, m[:3, :3] / s, m[:3, 3]


def errors(m_est, m_true, verts_src, diag):
    s_e, r_e, _ = split(m_est)
    s_t, r_t, _ = split(m_true)
    cos = np.clip((np.trace(r_e @ r_t.T) - 1) / 2, -1, 1)
    h = np.c_[verts_src, np.ones(len(verts_src))]
    disp = (h @ m_est.T)[:, :3] - (h @ m_true.T)[:, :3]
    return {
        "rotation_deg": float(np.degrees(np.arccos(cos))),
        "displacement_rms_rel": float(np.sqrt((disp ** 2).sum(1).mean()) / diag),
        "scale_rel": float(s_e / s_t - 1),
    }


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bunny", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--noise", type=float, default=0.01,
                    help="Gaussian noise sigma as a fraction of the bounding-box diagonal")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    rng = np.random.default_rng(SEED)
    v, f = load_obj(args.bunny)
    lo, hi = v.min(0), v.max(0)
    diag = float(np.linalg.norm(hi - lo))
    sigma = args.noise * diag
    d = rng.normal(size=3)
    d /= np.linalg.norm(d)
    a = 1.0 / (2.0 - OVERLAP)  # overlap / a = (2a - 1) / a = OVERLAP
    dense = sample(rng, v, f, 200_000) @ d
    q_hi, q_lo = np.quantile(dense, a), np.quantile(dense, 1 - a)
    xt = sample(rng, v, f, N)
    xt = xt[xt @ d <= q_hi]
    xs = sample(rng, v, f, N)
    xs = xs[xs @ d >= q_lo]
    xt = xt + rng.normal(scale=sigma, size=xt.shape)
    xs = xs + rng.normal(scale=sigma, size=xs.shape)
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    r = np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])
    s = rng.uniform(0.5, 2.0)
    t = rng.uniform(-2.0, 2.0, size=3) * diag
    move = np.eye(4)
    move[:3, :3] = s * r
    move[:3, 3] = t
    xs = xs @ (s * r).T + t
    true = np.linalg.inv(move)  # source frame -> ground truth frame
    centre = 0.5 * (lo + hi)
    ring = 2.0 * diag
    ang = np.arange(6) / 6 * 2 * np.pi
    cams_gt = centre + np.c_[ring * np.cos(ang), ring * np.sin(ang), 0.3 * ring * np.ones(6)]
    cams_src = cams_gt @ (s * r).T + t + rng.normal(scale=0.02 * ring * s, size=(6, 3))
    pre = umeyama(cams_src, cams_gt)

    def cloud(p):
        pc = o3d.geometry.PointCloud()
        pc.points = o3d.utility.Vector3dVector(p)
        return pc

    src, tgt = cloud(xs), cloud(xt)
    o3d.io.write_point_cloud(os.path.join(args.out, "source.ply"), src, write_ascii=False)
    o3d.io.write_point_cloud(os.path.join(args.out, "target.ply"), tgt, write_ascii=False)

    o3d.utility.random.seed(0)
    pcd = cloud(xs).transform(pre)

    def prep(pc):
        down = pc.voxel_down_sample(VOXEL)
        down.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=2 * VOXEL, max_nn=30))
        fpfh = o3d.pipelines.registration.compute_fpfh_feature(
            down, o3d.geometry.KDTreeSearchParamHybrid(radius=5 * VOXEL, max_nn=100))
        return down, fpfh

    sd, sf = prep(pcd)
    td, tf = prep(tgt)
    reg = o3d.pipelines.registration
    ransac = reg.registration_ransac_based_on_feature_matching(
        sd, td, sf, tf, False, 1.5 * VOXEL,
        reg.TransformationEstimationPointToPoint(False), 3,
        [reg.CorrespondenceCheckerBasedOnEdgeLength(0.9),
         reg.CorrespondenceCheckerBasedOnDistance(1.5 * VOXEL)],
        reg.RANSACConvergenceCriteria(100000, 0.999))
    transform = ransac.transformation
    for thr in THR_ICP:
        icp = reg.registration_icp(
            pcd, tgt, thr, transform,
            reg.TransformationEstimationPointToPoint(with_scaling=False),
            reg.ICPConvergenceCriteria(max_iteration=100))
        transform = icp.transformation
    verts_src = v @ (s * r).T + t
    out = {
        "generator": "tools/registration_fixture.py",
        "open3d_version": o3d.__version__,
        "seed": SEED,
        "samples_per_cloud_before_cut": N,
        "overlap": OVERLAP,
        "noise_sigma": sigma,
        "bbox_diagonal": diag,
        "source_points": len(xs),
        "target_points": len(xt),
        "voxel_size": VOXEL,
        "icp_threshold": THR_ICP,
        "true_source_to_target": true.tolist(),
        "prealignment": pre.tolist(),
        "prealignment_errors": errors(pre, true, verts_src, diag),
        "camera_centres_gt": cams_gt.tolist(),
        "camera_centres_source": cams_src.tolist(),
        "mesh_vertices_in_source_frame_rms_reference": "errors use the bunny's vertices moved by s R x + t",
        "open3d": {
            "ransac_transformation": (ransac.transformation).tolist(),
            "ransac_fitness": ransac.fitness,
            "ransac_inlier_rmse": ransac.inlier_rmse,
            "icp_transformation": (icp.transformation @ pre).tolist(),
            "icp_fitness": icp.fitness,
            "icp_inlier_rmse": icp.inlier_rmse,
            "ransac_errors": errors(ransac.transformation @ pre, true, verts_src, diag),
            "errors": errors(icp.transformation @ pre, true, verts_src, diag),
        },
        "true_similarity": {"scale": s, "rotation": r.tolist(), "translation": t.tolist()},
    }
    with open(os.path.join(args.out, "fixture.json"), "w") as fh:
        json.dump(out, fh, indent=1)
    print(json.dumps({k: out[k] for k in ("source_points", "target_points", "prealignment_errors")}, indent=1))
    print(json.dumps(out["open3d"]["errors"], indent=1), json.dumps(out["open3d"]["ransac_errors"]))


if __name__ == "__main__":
    main()
