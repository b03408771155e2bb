#!/usr/bin/env python3
"""Writes a small synthetic COLMAP model, in text and binary, with pycolmap (the reference
implementation of the format), plus the projections pycolmap computes for it.

Output (committed): crates/scene/tests/fixtures/colmap/
    text/{cameras,images,points3D,...}.txt     pycolmap `Reconstruction.write_text`
    binary/{cameras,images,points3D,...}.bin   pycolmap `Reconstruction.write_binary`
    reference.json                             per image: camera model, K, cam_from_world [R|t],
                                               camera centre, and every 3D point projected by
                                               `Image.project_point`; per point: xyz and rgb.

The Rust COLMAP readers must reproduce reference.json from both model folders.

Rerun (from the repository root):
    python3 -m venv tools/.venv && tools/.venv/bin/pip install numpy==2.4.6 pycolmap==4.2.1
    tools/.venv/bin/python tools/make_colmap_fixtures.py
"""

import json
import os
import shutil

import numpy as np
import pycolmap

OUT = os.path.join(os.path.dirname(__file__), "..", "crates", "scene", "tests", "fixtures", "colmap")


def look_at(eye, target, up):
    """cam_from_world (OpenCV axes: x right, y down, z forward) of a camera at `eye`."""
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    r = np.stack([x, y, z])  # rows: camera axes in world coordinates
    return pycolmap.Rigid3d(pycolmap.Rotation3d(r), -r @ eye)


def main():
    rng = np.random.default_rng(7)
    rec = pycolmap.Reconstruction()
    cameras = [
        pycolmap.Camera(camera_id=1, model="SIMPLE_PINHOLE", width=32, height=24, params=[30.0, 16.0, 12.0]),
        pycolmap.Camera(camera_id=2, model="PINHOLE", width=40, height=30, params=[35.0, 33.0, 19.5, 15.25]),
        # Radial distortion exactly zero: a pinhole camera in a distortion model's clothing.
        pycolmap.Camera(camera_id=3, model="SIMPLE_RADIAL", width=32, height=24, params=[28.0, 16.25, 11.75, 0.0]),
    ]
    for cam in cameras:
        rec.add_camera_with_trivial_rig(cam)

    points = rng.uniform(-0.5, 0.5, size=(12, 3))
    colors = rng.integers(0, 256, size=(12, 3), dtype=np.uint8)
    # Names out of order on purpose: loaders sort by name.
    specs = [(1, "c.png", 1, 0.0), (2, "a.png", 2, 1.3), (3, "d.png", 3, 2.6), (4, "b.png", 1, 4.0)]
    for image_id, name, camera_id, angle in specs:
        eye = np.array([3.0 * np.cos(angle), 3.0 * np.sin(angle), 0.7 + 0.1 * image_id])
        pose = look_at(eye, np.array([0.05, -0.02, 0.1]), np.array([0.0, 0.0, 1.0]))
        cam = rec.camera(camera_id)
        keypoints = np.array([cam.img_from_cam(pose * p) for p in points])
        image = pycolmap.Image(name=name, keypoints=keypoints, camera_id=camera_id, image_id=image_id)
        rec.add_image_with_trivial_frame(image, pose)

    for k, (xyz, rgb) in enumerate(zip(points, colors)):
        track = pycolmap.Track()
        for image_id, *_ in specs:
            track.add_element(image_id, k)
        point_id = rec.add_point3D(xyz, track, rgb)
        for image_id, *_ in specs:
            rec.image(image_id).points2D[k].point3D_id = point_id

    for sub in ("text", "binary"):
        path = os.path.join(OUT, sub)
        shutil.rmtree(path, ignore_errors=True)
        os.makedirs(path)
    rec.write_text(os.path.join(OUT, "text"))
    rec.write_binary(os.path.join(OUT, "binary"))

    reference = {"images": {}, "points": []}
    point_ids = sorted(rec.points3D.keys())
    for image_id in sorted(rec.images.keys()):
        image = rec.image(image_id)
        cam = rec.camera(image.camera_id)
        m = image.cam_from_world().matrix()
        reference["images"][image.name] = {
            "model": cam.model.name,
            "width": cam.width,
            "height": cam.height,
            "K": cam.calibration_matrix().tolist(),
            "cam_from_world": m.tolist(),
            "center": image.projection_center().tolist(),
            "projections": [image.project_point(rec.points3D[pid].xyz).tolist() for pid in point_ids],
        }
    for pid in point_ids:
        p = rec.points3D[pid]
        reference["points"].append({"xyz": p.xyz.tolist(), "rgb": [int(c) for c in p.color]})
    with open(os.path.join(OUT, "reference.json"), "w") as f:
        json.dump(reference, f, indent=1)
    print("wrote", os.path.normpath(OUT))


if __name__ == "__main__":
    main()
